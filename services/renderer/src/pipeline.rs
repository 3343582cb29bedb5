//! The GPU pipelines: one shader module (shaders.wgsl), four render pipelines (floor, shadow,
//! solid, composite) and the layouts they share.

use std::num::NonZeroU64;

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::mesh::Vertex;

/// The scene's colour target: sRGB, so shaders work in linear light and PNGs get sRGB bytes.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Uniform buffers bound with a dynamic offset must start on this boundary (WebGPU's
/// minUniformBufferOffsetAlignment is at most 256 everywhere).
pub const EYE_UNIFORM_STRIDE: u64 = 256;

/// Per-draw data, one per drawn object: its model matrix (body to world) and colour.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Instance {
    pub model: [[f32; 4]; 4],
    /// Linear rgb; a = 1 draws polygon edges.
    pub color: [f32; 4],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Globals {
    pub light_dir: [f32; 4],
    pub params: [f32; 4],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct EyeUniform {
    pub view_proj: [[f32; 4]; 4],
    pub eye_pos: [f32; 4],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct CompositeUniform {
    pub mode: [u32; 4],
    pub dst: [f32; 4],
}

/// What the scene pass needs.
pub struct ScenePipelines {
    pub floor: wgpu::RenderPipeline,
    pub grid: wgpu::RenderPipeline,
    pub shadow: wgpu::RenderPipeline,
    pub solid: wgpu::RenderPipeline,
    pub layout: wgpu::BindGroupLayout,
}

pub fn shader(device: &wgpu::Device) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("handblocks shaders"),
        source: wgpu::ShaderSource::Wgsl(include_str!("shaders.wgsl").into()),
    })
}

fn uniform_entry(binding: u32, dynamic: bool, size: u64) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: NonZeroU64::new(size),
        },
        count: None,
    }
}

const TRIANGLES: wgpu::PrimitiveTopology = wgpu::PrimitiveTopology::TriangleList;
const LINES: wgpu::PrimitiveTopology = wgpu::PrimitiveTopology::LineList;

pub fn scene_pipelines(device: &wgpu::Device, module: &wgpu::ShaderModule) -> ScenePipelines {
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("scene"),
        entries: &[
            uniform_entry(0, false, std::mem::size_of::<Globals>() as u64),
            uniform_entry(1, true, std::mem::size_of::<EyeUniform>() as u64),
        ],
    });
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("scene"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let vertex_attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x4];
    let instance_attrs = wgpu::vertex_attr_array![
        2 => Float32x4, 3 => Float32x4, 4 => Float32x4, 5 => Float32x4, 6 => Float32x4
    ];
    let buffers = [
        Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &vertex_attrs,
        }),
        Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Instance>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &instance_attrs,
        }),
    ];
    let make = |label: &str,
                vs: &str,
                fs: &str,
                topology: wgpu::PrimitiveTopology,
                cull: bool,
                depth_write: bool| {
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(label),
            layout: Some(&pl),
            vertex: wgpu::VertexState {
                module,
                entry_point: Some(vs),
                compilation_options: Default::default(),
                buffers: &buffers,
            },
            primitive: wgpu::PrimitiveState {
                topology,
                front_face: wgpu::FrontFace::Ccw,
                cull_mode: cull.then_some(wgpu::Face::Back),
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(depth_write),
                depth_compare: Some(wgpu::CompareFunction::LessEqual),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module,
                entry_point: Some(fs),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: COLOR_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        })
    };
    ScenePipelines {
        floor: make("floor", "vs_main", "fs_floor", TRIANGLES, true, true),
        grid: make("grid", "vs_main", "fs_grid", LINES, false, false),
        // Shadows overlap without darkening twice because each writes the same colour and
        // none writes depth. Culled: a closed mesh projected onto the floor covers its shadow
        // twice, once with the faces towards the light and once with those away from it, and
        // the two sets wind opposite ways as the camera sees the floor, so culling one keeps a
        // whole shadow at half the triangles and pixels.
        shadow: make("shadow", "vs_shadow", "fs_shadow", TRIANGLES, true, false),
        solid: make("solid", "vs_main", "fs_solid", TRIANGLES, true, true),
        layout,
    }
}

/// The output pass into a target of `format`.
pub struct CompositePipeline {
    pub pipeline: wgpu::RenderPipeline,
    pub layout: wgpu::BindGroupLayout,
}

pub fn composite_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    format: wgpu::TextureFormat,
) -> CompositePipeline {
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("composite"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            uniform_entry(1, false, std::mem::size_of::<CompositeUniform>() as u64),
        ],
    });
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("composite"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("composite"),
        layout: Some(&pl),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_full"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: Default::default(),
        depth_stencil: None,
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_composite"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    });
    CompositePipeline { pipeline, layout }
}

/// The composite pass's inputs: the eye texture and what to do with it.
pub fn composite_bind_group(
    device: &wgpu::Device,
    c: &CompositePipeline,
    eyes: &wgpu::TextureView,
    uniform: &CompositeUniform,
) -> (wgpu::BindGroup, wgpu::Buffer) {
    let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("composite uniform"),
        contents: bytemuck::bytes_of(uniform),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
    });
    let bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("composite"),
        layout: &c.layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(eyes),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: buf.as_entire_binding(),
            },
        ],
    });
    (bg, buf)
}
