//! The GPU side: device, targets, buffers, and one frame's commands.
//!
//! Both eyes are drawn into one texture, side by side (two viewports, one pass): this works on
//! every backend (multiview gave wrong output on the software driver), and it is already the
//! side-by-side output. The anaglyph is a second, full-screen pass that reads both halves; a
//! window gets the same pass into its surface. "Photon" is when the frame's GPU work is
//! complete: after submitting, the renderer waits for that submission on the device.
//!
//! A frame starts from the static layer's image (the floor and the resting blocks away from the
//! hand, `static_layer.rs`), redrawn only when one of them changed, and draws the rest on it.

use std::sync::Arc;
use std::time::Duration;

use common::config::scene::Scene;
use common::{monotonic_ns, HandSample, WorldView};
use glam::Vec3;
use wgpu::util::DeviceExt;

use crate::camera::{stereo, EyeView};
use crate::draw_list::{instance_capacity, BlockDraw, DrawList, PALM_VERTEX_CAPACITY};
use crate::error::RenderError;
use crate::image::Image;
use crate::mesh::{Meshes, Vertex};
use crate::pipeline::{
    composite_bind_group, composite_pipeline, scene_pipelines, shader, CompositePipeline,
    CompositeUniform, EyeUniform, Globals, Instance, ScenePipelines, COLOR_FORMAT, DEPTH_FORMAT,
    EYE_UNIFORM_STRIDE,
};
use crate::settings::{OutputMode, RenderSettings};
use crate::static_layer::{LayerFrame, StaticLayer};

/// A frame's GPU work should take milliseconds; a device that needs this long is lost.
const GPU_TIMEOUT: Duration = Duration::from_secs(10);

/// When a frame's parts happened (CLOCK_MONOTONIC, ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameTimes {
    pub started_ns: u64,
    /// Commands submitted to the GPU.
    pub submitted_ns: u64,
    /// The GPU finished the frame: its pixels are done ("photon").
    pub done_ns: u64,
}

/// What a scene pass draws into.
#[derive(Debug, Clone, Copy)]
enum PassTarget {
    /// The static layer's image, drawn afresh; its depth is kept for the frames that start
    /// from it.
    LayerImage,
    /// The frame: on a copy of the layer's image, or (`from_nothing`, the layer off) on a
    /// cleared target; its depth is discarded when the frame is done.
    Frame { from_nothing: bool },
}

/// A window's surface and the pass that fills it.
pub(crate) struct Presenter {
    pub surface: wgpu::Surface<'static>,
    pub config: wgpu::SurfaceConfiguration,
    pub composite: CompositePipeline,
    pub bind_group: wgpu::BindGroup,
    pub uniform: wgpu::Buffer,
}

/// The anaglyph's own target (headless anaglyph output).
struct AnaglyphTarget {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    bind_group: wgpu::BindGroup,
    pipeline: CompositePipeline,
    _uniform: wgpu::Buffer,
}

pub struct Renderer {
    settings: RenderSettings,
    adapter_name: String,
    pub(crate) device: wgpu::Device,
    queue: wgpu::Queue,
    eyes: wgpu::Texture,
    eyes_view: wgpu::TextureView,
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
    /// The static layer's image (`static_layer.rs`): colour and depth, as `eyes` and `depth`.
    layer_color: wgpu::Texture,
    layer_color_view: wgpu::TextureView,
    layer_depth: wgpu::Texture,
    layer_depth_view: wgpu::TextureView,
    layer: StaticLayer,
    /// Whether frames start from the static layer's image (on unless a caller turns it off).
    use_layer: bool,
    scene: ScenePipelines,
    module: wgpu::ShaderModule,
    bind_group: wgpu::BindGroup,
    vertex_buf: wgpu::Buffer,
    index_buf: wgpu::Buffer,
    palm_buf: wgpu::Buffer,
    instance_buf: wgpu::Buffer,
    meshes: Meshes,
    list: DrawList,
    eye_views: [EyeView; 2],
    /// The eyes' uniforms: left, right, the preview's camera.
    eye_buf: wgpu::Buffer,
    anaglyph: Option<AnaglyphTarget>,
    pub(crate) presenter: Option<Presenter>,
    readback: Vec<wgpu::Buffer>,
}

/// The scene's light: high and to the right, so shadows fall close to what casts them.
fn light_dir() -> Vec3 {
    Vec3::new(0.35, 1.0, 0.25).normalize()
}

pub(crate) fn instance_descriptor() -> wgpu::InstanceDescriptor {
    let mut d = wgpu::InstanceDescriptor::new_without_display_handle().with_env();
    // Vulkan only: it is what the crate is built with (and Mesa's llvmpipe provides it).
    d.backends = wgpu::Backends::VULKAN;
    d
}

pub(crate) fn request_adapter(
    instance: &wgpu::Instance,
    surface: Option<&wgpu::Surface<'_>>,
) -> Result<(wgpu::Adapter, wgpu::Device, wgpu::Queue), RenderError> {
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: surface,
        ..Default::default()
    }))
    .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("handblocks renderer"),
        required_features: wgpu::Features::empty(),
        required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
        ..Default::default()
    }))
    .map_err(|e| RenderError::Device(e.to_string()))?;
    Ok((adapter, device, queue))
}

impl Renderer {
    /// A renderer that draws offscreen (no window, no display needed).
    pub fn new_headless(settings: &RenderSettings, scene: &Scene) -> Result<Renderer, RenderError> {
        settings.validate().map_err(RenderError::Settings)?;
        let instance = wgpu::Instance::new(instance_descriptor());
        let (adapter, device, queue) = request_adapter(&instance, None)?;
        Renderer::with_device(settings, scene, &adapter, device, queue)
    }

    pub(crate) fn with_device(
        settings: &RenderSettings,
        scene: &Scene,
        adapter: &wgpu::Adapter,
        device: wgpu::Device,
        queue: wgpu::Queue,
    ) -> Result<Renderer, RenderError> {
        settings.validate().map_err(RenderError::Settings)?;
        let shapes: Vec<_> = scene.blocks.iter().map(|b| &b.shape).collect();
        let meshes = Meshes::build(&shapes).map_err(|e| {
            let name = scene
                .blocks
                .get(e.block)
                .map(|b| b.name.as_str())
                .unwrap_or("?");
            RenderError::Settings(format!("block {name:?}: {}", e.problem))
        })?;
        let (w, h) = (settings.width, settings.height);
        let max = device.limits().max_texture_dimension_2d;
        if 2 * w > max || h > max {
            return Err(RenderError::Settings(format!(
                "{w} x {h} per eye needs a {} x {h} texture; this GPU allows {max}",
                2 * w
            )));
        }
        let texture = |label, width, height, format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let eyes = texture(
            "eyes",
            2 * w,
            h,
            COLOR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let eyes_view = eyes.create_view(&Default::default());
        let depth = texture(
            "depth",
            2 * w,
            h,
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_DST,
        );
        let depth_view = depth.create_view(&Default::default());
        let layer_usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let layer_color = texture("static layer", 2 * w, h, COLOR_FORMAT, layer_usage);
        let layer_color_view = layer_color.create_view(&Default::default());
        let layer_depth = texture("static layer depth", 2 * w, h, DEPTH_FORMAT, layer_usage);
        let layer_depth_view = layer_depth.create_view(&Default::default());
        let module = shader(&device);
        let scene_p = scene_pipelines(&device, &module);

        let globals = Globals {
            light_dir: light_dir().extend(0.0).to_array(),
            params: [0.0008, 0.45, 0.0, 0.0],
        };
        let globals_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("globals"),
            contents: bytemuck::bytes_of(&globals),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let eye_views = stereo(&settings.camera, w, h);
        // Both eyes, and a third slot for the preview's own camera (`render_preview`).
        let mut eye_bytes = vec![0u8; 3 * EYE_UNIFORM_STRIDE as usize];
        for (i, e) in eye_views.iter().enumerate() {
            let u = EyeUniform {
                view_proj: e.view_projection().to_cols_array_2d(),
                eye_pos: e.position.as_vec3().extend(1.0).to_array(),
            };
            let at = i * EYE_UNIFORM_STRIDE as usize;
            eye_bytes[at..at + std::mem::size_of::<EyeUniform>()]
                .copy_from_slice(bytemuck::bytes_of(&u));
        }
        let eye_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("eyes"),
            contents: &eye_bytes,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("scene"),
            layout: &scene_p.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: globals_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &eye_buf,
                        offset: 0,
                        size: std::num::NonZeroU64::new(std::mem::size_of::<EyeUniform>() as u64),
                    }),
                },
            ],
        });
        let vertex_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("meshes"),
            contents: bytemuck::cast_slice(&meshes.vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let index_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("mesh indices"),
            contents: bytemuck::cast_slice(&meshes.indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        let palm_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("palm"),
            size: (PALM_VERTEX_CAPACITY * std::mem::size_of::<Vertex>()) as u64,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let instance_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("instances"),
            size: (instance_capacity(meshes.blocks.len()) * std::mem::size_of::<Instance>()) as u64,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let anaglyph = (settings.output == OutputMode::Anaglyph).then(|| {
            let texture = texture(
                "anaglyph",
                w,
                h,
                COLOR_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            );
            let view = texture.create_view(&Default::default());
            let pipeline = composite_pipeline(&device, &module, COLOR_FORMAT);
            let (bind_group, uniform) = composite_bind_group(
                &device,
                &pipeline,
                &eyes_view,
                &CompositeUniform {
                    mode: [1, w, h, 0],
                    dst: [w as f32, h as f32, 0.0, 0.0],
                },
            );
            AnaglyphTarget {
                texture,
                view,
                bind_group,
                pipeline,
                _uniform: uniform,
            }
        });
        let info = adapter.get_info();
        let mut list = DrawList::new(&meshes.blocks);
        list.set_block_colors(&crate::draw_list::block_colors(scene));
        Ok(Renderer {
            settings: settings.clone(),
            adapter_name: format!("{} ({:?}, {:?})", info.name, info.device_type, info.backend),
            device,
            queue,
            eyes,
            eyes_view,
            depth,
            depth_view,
            layer_color,
            layer_color_view,
            layer_depth,
            layer_depth_view,
            layer: StaticLayer::new(meshes.blocks.len()),
            use_layer: true,
            scene: scene_p,
            module,
            bind_group,
            vertex_buf,
            index_buf,
            palm_buf,
            instance_buf,
            meshes,
            list,
            eye_views,
            eye_buf,
            anaglyph,
            presenter: None,
            readback: Vec::new(),
        })
    }

    /// The adapter in words, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Cpu, Vulkan)".
    pub fn adapter_name(&self) -> &str {
        &self.adapter_name
    }

    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Both eyes' matrices (tests project points with them).
    pub fn eye_views(&self) -> &[EyeView; 2] {
        &self.eye_views
    }

    pub(crate) fn module(&self) -> &wgpu::ShaderModule {
        &self.module
    }

    pub(crate) fn eyes_view(&self) -> &wgpu::TextureView {
        &self.eyes_view
    }

    pub(crate) fn write_composite_uniform(&self, u: &CompositeUniform) {
        if let Some(p) = &self.presenter {
            self.queue
                .write_buffer(&p.uniform, 0, bytemuck::bytes_of(u));
        }
    }

    /// Whether frames start from the static layer's image (`static_layer.rs`; on by default).
    /// Off, every frame draws every block: the same bytes, at the whole scene's cost.
    pub fn set_static_layer(&mut self, on: bool) {
        self.use_layer = on;
        self.layer.clear();
    }

    /// How many blocks the static layer held in the last frame.
    pub fn static_layer_blocks(&self) -> usize {
        self.layer.len()
    }

    /// Draws one frame of `world` and `hand` and waits until the GPU has finished it.
    ///
    /// A frame is drawn in two layers (`static_layer.rs`): the static one (the floor, the
    /// resting blocks of the layer and their shadows), drawn again only when it changed and
    /// otherwise copied from its image, and the live one on top (the other blocks, the hand,
    /// their shadows, the grid lines).
    pub fn render(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
    ) -> Result<FrameTimes, RenderError> {
        self.render_hands(world, hand, None)
    }

    /// [`Self::render`] with a two-hand session's `left` hand too (`HandSample::side` 1),
    /// drawn from its own sample as tracked; `hand` is the right hand, drawn at the world's
    /// finger points when it carries them. `None`: exactly [`Self::render`]'s frame.
    pub fn render_hands(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
        left: Option<&HandSample>,
    ) -> Result<FrameTimes, RenderError> {
        self.render_people(world, hand, left, &[])
    }

    /// [`Self::render_hands`] with the other people's hands of a shared world (`others`, each
    /// drawn as tracked).
    pub fn render_people(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
        left: Option<&HandSample>,
        others: &[HandSample],
    ) -> Result<FrameTimes, RenderError> {
        let started_ns = monotonic_ns();
        let layer = if self.use_layer {
            self.layer.update_hands(world, hand, left)
        } else {
            LayerFrame::Off
        };
        let members: &[bool] = match layer {
            LayerFrame::Off => &[],
            _ => self.layer.members(),
        };
        self.list.build_people(
            world,
            hand,
            left,
            others,
            members,
            layer == LayerFrame::Redraw,
        );
        self.upload_draw_list();
        let list = &self.list;
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        if layer == LayerFrame::Redraw {
            let mut pass = self.scene_pass(&mut encoder, PassTarget::LayerImage);
            for eye in 0..2u32 {
                self.begin_eye(&mut pass, eye);
                self.draw_floor(&mut pass);
                pass.set_pipeline(&self.scene.solid);
                Self::draw_blocks(&mut pass, &list.static_blocks);
                if self.settings.shadows {
                    pass.set_pipeline(&self.scene.shadow);
                    Self::draw_blocks(&mut pass, &list.static_blocks);
                }
            }
        }
        if layer != LayerFrame::Off {
            let size = self.eyes.size();
            encoder.copy_texture_to_texture(
                self.layer_color.as_image_copy(),
                self.eyes.as_image_copy(),
                size,
            );
            encoder.copy_texture_to_texture(
                self.layer_depth.as_image_copy(),
                self.depth.as_image_copy(),
                size,
            );
        }
        {
            let from_nothing = layer == LayerFrame::Off;
            let mut pass = self.scene_pass(&mut encoder, PassTarget::Frame { from_nothing });
            for eye in 0..2u32 {
                self.begin_eye(&mut pass, eye);
                if layer == LayerFrame::Off {
                    self.draw_floor(&mut pass);
                }
                // Solids first: they write depth, so the shadows and grid lines under them
                // fail the depth test before any shading (what the shadows cost is then only
                // the floor they darken).
                pass.set_pipeline(&self.scene.solid);
                self.draw_live(&mut pass);
                if self.settings.shadows {
                    pass.set_pipeline(&self.scene.shadow);
                    self.draw_live(&mut pass);
                }
                // Over the floor and the shadows, under everything else (depth).
                pass.set_pipeline(&self.scene.grid);
                pass.set_vertex_buffer(0, self.vertex_buf.slice(..));
                let fi = list.floor_instance;
                pass.draw_indexed(self.meshes.grid.clone(), 0, fi..fi + 1);
            }
        }
        if let Some(a) = &self.anaglyph {
            composite_pass(&mut encoder, &a.view, &a.pipeline, &a.bind_group);
        }
        let frame = match &self.presenter {
            Some(p) => match p.surface.get_current_texture() {
                wgpu::CurrentSurfaceTexture::Success(t)
                | wgpu::CurrentSurfaceTexture::Suboptimal(t) => {
                    let view = t.texture.create_view(&Default::default());
                    composite_pass(&mut encoder, &view, &p.composite, &p.bind_group);
                    Some(t)
                }
                wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                    p.surface.configure(&self.device, &p.config);
                    None
                }
                // Timeout, occluded (minimised) or a validation error: skip presenting.
                _ => None,
            },
            None => None,
        };
        let index = self.queue.submit([encoder.finish()]);
        let submitted_ns = monotonic_ns();
        if let Some(t) = frame {
            self.queue.present(t);
        }
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(index),
                timeout: Some(GPU_TIMEOUT),
            })
            .map_err(|e| RenderError::Gpu(e.to_string()))?;
        Ok(FrameTimes {
            started_ns,
            submitted_ns,
            done_ns: monotonic_ns(),
        })
    }

    /// The draw list's instances and palm into their GPU buffers, for the next pass.
    fn upload_draw_list(&self) {
        let list = &self.list;
        self.queue
            .write_buffer(&self.instance_buf, 0, bytemuck::cast_slice(&list.instances));
        if !list.palm_vertices.is_empty() {
            self.queue
                .write_buffer(&self.palm_buf, 0, bytemuck::cast_slice(&list.palm_vertices));
        }
    }

    /// A pass of the scene into `target`.
    fn scene_pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        target: PassTarget,
    ) -> wgpu::RenderPass<'e> {
        let background = wgpu::Color {
            r: 0.30,
            g: 0.36,
            b: 0.45,
            a: 1.0,
        };
        let (label, color, depth, clear, keep_depth) = match target {
            PassTarget::LayerImage => (
                "static layer",
                &self.layer_color_view,
                &self.layer_depth_view,
                true,
                true,
            ),
            PassTarget::Frame { from_nothing } => (
                "live layer",
                &self.eyes_view,
                &self.depth_view,
                from_nothing,
                false,
            ),
        };
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: if clear {
                        wgpu::LoadOp::Clear(background)
                    } else {
                        wgpu::LoadOp::Load
                    },
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: if clear {
                        wgpu::LoadOp::Clear(1.0)
                    } else {
                        wgpu::LoadOp::Load
                    },
                    store: if keep_depth {
                        wgpu::StoreOp::Store
                    } else {
                        wgpu::StoreOp::Discard
                    },
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }

    /// One eye's viewport, uniforms and buffers.
    fn begin_eye(&self, pass: &mut wgpu::RenderPass<'_>, eye: u32) {
        self.begin_view(pass, eye, eye);
    }

    /// Draws into eye `viewport`'s half with the camera of uniform slot `slot` (0, 1: the
    /// eyes; 2: the preview's camera).
    fn begin_view(&self, pass: &mut wgpu::RenderPass<'_>, viewport: u32, slot: u32) {
        let (w, h) = (self.settings.width as f32, self.settings.height as f32);
        pass.set_viewport(viewport as f32 * w, 0.0, w, h, 0.0, 1.0);
        pass.set_bind_group(0, &self.bind_group, &[slot * EYE_UNIFORM_STRIDE as u32]);
        pass.set_vertex_buffer(1, self.instance_buf.slice(..));
        pass.set_vertex_buffer(0, self.vertex_buf.slice(..));
        pass.set_index_buffer(self.index_buf.slice(..), wgpu::IndexFormat::Uint32);
    }

    fn draw_floor(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_pipeline(&self.scene.floor);
        let fi = self.list.floor_instance;
        pass.draw_indexed(self.meshes.floor.clone(), 0, fi..fi + 1);
    }

    fn draw_blocks(pass: &mut wgpu::RenderPass<'_>, draws: &[BlockDraw]) {
        for b in draws {
            pass.draw_indexed(b.indices.clone(), 0, b.instances.clone());
        }
    }

    /// The live blocks and the hand, with the pipeline set (solid or shadow).
    fn draw_live(&self, pass: &mut wgpu::RenderPass<'_>) {
        let list = &self.list;
        pass.set_vertex_buffer(0, self.vertex_buf.slice(..));
        Self::draw_blocks(pass, &list.blocks);
        if !list.segments.is_empty() {
            pass.draw_indexed(self.meshes.cylinder.clone(), 0, list.segments.clone());
        }
        if !list.joints.is_empty() {
            pass.draw_indexed(self.meshes.sphere.clone(), 0, list.joints.clone());
        }
        let palm_n = list.palm_vertices.len() as u32;
        if palm_n > 0 {
            pass.set_vertex_buffer(0, self.palm_buf.slice(..));
            let pi = list.palm_instance;
            pass.draw(0..palm_n, pi..pi + 1);
        }
    }

    /// Draws `world` and `hand` (and a two-hand session's `left` hand, as
    /// [`Self::render_hands`]) into the left eye's half, seen by `camera`'s left eye, every
    /// block live (the static layer, drawn for the session's camera, is left alone), and waits
    /// for the GPU; read it with [`Self::read_back_left_eye_into`]. The next [`Self::render`]
    /// draws the session's view again. For the preview, which frames the whole session's
    /// action once the session is over (module `preview`).
    pub fn render_preview(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
        left: Option<&HandSample>,
        camera: &crate::camera::CameraSettings,
    ) -> Result<EyeView, RenderError> {
        let (w, h) = (self.settings.width, self.settings.height);
        let [eye, _] = stereo(camera, w, h);
        let u = EyeUniform {
            view_proj: eye.view_projection().to_cols_array_2d(),
            eye_pos: eye.position.as_vec3().extend(1.0).to_array(),
        };
        self.queue.write_buffer(
            &self.eye_buf,
            2 * EYE_UNIFORM_STRIDE,
            bytemuck::bytes_of(&u),
        );
        self.list.build_hands(world, hand, left, &[], false);
        self.upload_draw_list();
        let list = &self.list;
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("preview"),
            });
        {
            let mut pass = self.scene_pass(&mut encoder, PassTarget::Frame { from_nothing: true });
            self.begin_view(&mut pass, 0, 2);
            self.draw_floor(&mut pass);
            pass.set_pipeline(&self.scene.solid);
            self.draw_live(&mut pass);
            if self.settings.shadows {
                pass.set_pipeline(&self.scene.shadow);
                self.draw_live(&mut pass);
            }
            pass.set_pipeline(&self.scene.grid);
            pass.set_vertex_buffer(0, self.vertex_buf.slice(..));
            let fi = list.floor_instance;
            pass.draw_indexed(self.meshes.grid.clone(), 0, fi..fi + 1);
        }
        self.queue.submit([encoder.finish()]);
        Ok(eye)
    }

    /// The last frame as the output mode shows it: side by side and separate give both eyes
    /// in one 2W x H image (`Image::eye` splits it), anaglyph a W x H image. Reuses its
    /// buffers: `out` keeps its allocation across calls.
    pub fn read_back_into(&mut self, out: &mut Image) -> Result<(), RenderError> {
        let (texture, width) = match &self.anaglyph {
            Some(a) => (a.texture.clone(), self.settings.width),
            None => (self.eyes.clone(), 2 * self.settings.width),
        };
        self.read_back_region(&texture, width, out)
    }

    /// The left eye's image alone (tightly packed RGBA), whatever the output mode: the
    /// preview shows one eye, in the blocks' own colours (an anaglyph's would be tinted).
    pub fn read_back_left_eye_into(&mut self, out: &mut Image) -> Result<(), RenderError> {
        let texture = self.eyes.clone();
        self.read_back_region(&texture, self.settings.width, out)
    }

    /// The `width` leftmost columns of `texture`, all its rows, into `out`.
    fn read_back_region(
        &mut self,
        texture: &wgpu::Texture,
        width: u32,
        out: &mut Image,
    ) -> Result<(), RenderError> {
        let height = self.settings.height;
        let padded = (width * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let size = padded as u64 * height as u64;
        // One buffer per size read (the whole frame, the left eye): kept across frames.
        let buffer = match self.readback.iter().find(|b| b.size() == size) {
            Some(b) => b.clone(),
            None => {
                let b = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("readback"),
                    size,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                self.readback.push(b.clone());
                b
            }
        };
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
        );
        let index = self.queue.submit([encoder.finish()]);
        let mapped = Arc::new(std::sync::Mutex::new(None));
        let m = mapped.clone();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            if let Ok(mut slot) = m.lock() {
                *slot = Some(r);
            }
        });
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(index),
                timeout: Some(GPU_TIMEOUT),
            })
            .map_err(|e| RenderError::Gpu(e.to_string()))?;
        let result = mapped.lock().ok().and_then(|mut s| s.take());
        match result {
            Some(Ok(())) => {}
            Some(Err(e)) => return Err(RenderError::Gpu(format!("reading the frame back: {e}"))),
            None => {
                return Err(RenderError::Gpu(
                    "reading the frame back: not mapped".into(),
                ))
            }
        }
        {
            let view = buffer
                .slice(..)
                .get_mapped_range()
                .map_err(|e| RenderError::Gpu(e.to_string()))?;
            out.width = width;
            out.height = height;
            out.rgba.clear();
            let row = (width * 4) as usize;
            for y in 0..height as usize {
                let at = y * padded as usize;
                out.rgba.extend_from_slice(&view[at..at + row]);
            }
        }
        buffer.unmap();
        Ok(())
    }

    /// [`Self::read_back_into`] into a new image.
    pub fn read_back(&mut self) -> Result<Image, RenderError> {
        let mut img = Image::default();
        self.read_back_into(&mut img)?;
        Ok(img)
    }
}

fn composite_pass(
    encoder: &mut wgpu::CommandEncoder,
    target: &wgpu::TextureView,
    pipeline: &CompositePipeline,
    bind_group: &wgpu::BindGroup,
) {
    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("composite"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: target,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: None,
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    pass.set_pipeline(&pipeline.pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.draw(0..3, 0..1);
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::config::scene::{BlockSpec, ShapeSpec};
    use common::{BlockMode, BlockState, HandSide, Pose, WorldSample};

    /// A hand of three fingers along -z at (`x`, 0.15), with a palm behind them.
    fn hand_at(x: f64, side: HandSide) -> HandSample {
        let mut h = HandSample {
            finger_count: 3,
            palm_vertex_count: 4,
            side: side.code(),
            ..Default::default()
        };
        for f in 0..3 {
            h.finger_point_count[f] = 4;
            h.finger_radius[f] = 0.01;
            for k in 0..4 {
                h.finger_points[f][k] = [x + 0.025 * f as f64, 0.15, 0.1 - 0.03 * k as f64];
            }
        }
        h.palm_vertices[..4].copy_from_slice(&[
            [x, 0.15, 0.12],
            [x + 0.06, 0.15, 0.12],
            [x, 0.18, 0.12],
            [x + 0.03, 0.15, 0.18],
        ]);
        h
    }

    /// Without a left hand, [`Renderer::render_hands`] draws [`Renderer::render`]'s frame
    /// byte for byte; with one, its pixels appear where it is, and the rest of the frame (the
    /// right hand's half of the image) is unchanged.
    #[test]
    fn the_left_hand_is_drawn_and_one_hand_frames_are_unchanged() {
        let scene = Scene {
            file: "t.toml".into(),
            world: Default::default(),
            effects: Default::default(),
            blocks: vec![BlockSpec {
                name: "red".into(),
                shape: ShapeSpec::Box { size: [0.05; 3] },
                position: [0.0; 3],
                rotation: [0.0, 0.0, 0.0, 1.0],
                velocity: [0.0; 3],
            }],
            hand: None,
            left_hand: None,
        };
        let settings = RenderSettings {
            width: 160,
            height: 120,
            shadows: true,
            ..RenderSettings::default()
        };
        let mut r = match Renderer::new_headless(&settings, &scene) {
            Ok(r) => r,
            Err(RenderError::NoAdapter(e)) => {
                eprintln!("no GPU adapter ({e}): skipped");
                return;
            }
            Err(e) => panic!("{e}"),
        };
        let mut w = WorldSample::with_blocks(1);
        w.blocks[0] = BlockState {
            pose: Pose {
                position: [0.0, 0.025, 0.0],
                rotation: [0.0, 0.0, 0.0, 1.0],
            },
            mode: BlockMode::Resting as u32,
            held_by: 0,
        };
        let right = hand_at(0.1, HandSide::Right);
        let left = hand_at(-0.16, HandSide::Left);
        r.render(w.view(), &right).unwrap();
        let one = r.read_back().unwrap();
        r.render_hands(w.view(), &right, None).unwrap();
        assert!(
            r.read_back().unwrap() == one,
            "no left hand: the one-hand frame"
        );
        r.render_hands(w.view(), &right, Some(&left)).unwrap();
        let two = r.read_back().unwrap();
        // Count changed pixels left and right of each eye's centre.
        let (mut on_left, mut on_right) = (0, 0);
        for y in 0..one.height {
            for x in 0..one.width {
                let i = ((y * one.width + x) * 4) as usize;
                if one.rgba[i..i + 4] != two.rgba[i..i + 4] {
                    if x % settings.width < settings.width / 2 {
                        on_left += 1;
                    } else {
                        on_right += 1;
                    }
                }
            }
        }
        assert!(on_left > 100, "{on_left} pixels changed for the left hand");
        assert!(
            on_right < on_left / 10,
            "{on_right} pixels changed on the right"
        );
    }
}
