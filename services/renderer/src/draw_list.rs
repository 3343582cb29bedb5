//! What one frame draws, from a world and a hand sample: instances (matrices and colours) and
//! draw ranges, in buffers kept across frames so that a frame allocates nothing once warm.
//!
//! Blocks are drawn instanced: the blocks that share a mesh (the scene's blocks of one shape)
//! have contiguous instances and one draw call, so a frame's draw calls grow with the shapes
//! of a scene, not its blocks.
//!
//! A two-hand session's left hand (`HandSample::side` 1) is drawn beside the right from its
//! own sample, as tracked: the world's drawn finger points (relocated onto a grasped block)
//! are the right hand's. Its joints, segments and palm join the right hand's ranges (the
//! same draws), so a one-hand frame's list is what it was before there were two.
//!
//! Anything non-finite in a sample (a NaN pose from a device or a bug upstream) skips that
//! block, finger segment or palm for the frame instead of drawing garbage or failing.

use std::ops::Range;

use common::samples::{MAX_FINGERS, MAX_FINGER_POINTS, MAX_PALM_VERTICES};
use common::{BlockMode, HandSample, WorldView};
use glam::{DQuat, DVec3, Mat4, Vec3};
use shapes::hull_triangles_into;

use crate::mesh::Vertex;
use crate::pipeline::Instance;

/// The outline colour of a block in each mode (linear rgb), chosen to be told apart at a
/// glance and by the tests. A block's faces keep its own colour ([`block_colors`]) so that
/// "red" stays red whatever it does; its mode shows in its outline (`shaders.wgsl`, `fs_solid`:
/// a resting block keeps the thin dark outline, any other mode gets a thicker one in this
/// colour), and the preview's overlay names it in the same colour (its legend).
pub fn mode_color(mode: BlockMode) -> [f32; 3] {
    match mode {
        BlockMode::Free => [0.20, 0.40, 0.95],
        BlockMode::Resting => [0.80, 0.12, 0.08],
        BlockMode::Tipping => [0.95, 0.45, 0.02],
        BlockMode::Pushed => [0.90, 0.80, 0.05],
        BlockMode::Grasped => [0.08, 0.75, 0.12],
        BlockMode::Carried => [0.55, 0.15, 0.85],
        BlockMode::Supported => [0.05, 0.65, 0.70],
    }
}

/// The same colours as sRGB bytes (for text drawn over an image: the preview's overlay).
pub fn mode_color_srgb(mode: BlockMode) -> [u8; 3] {
    mode_color(mode).map(|c| (linear_to_srgb(c) * 255.0 + 0.5) as u8)
}

// A block's own colour is the scene's (`common::config::colors`): the live view draws the
// same colours.
pub use common::config::colors::{block_colors, color_for_name, NAMED_COLORS, PALETTE};

/// Finger points per finger.
type FingerPoints = [[[f64; 3]; MAX_FINGER_POINTS]; MAX_FINGERS];

/// The fingers a frame draws: the world's (relocated onto a grasped block's surface,
/// docs/model.md R5) when it carries them, else the hand's own check points: (fingers, points
/// per finger, the points).
pub(crate) fn drawn_fingers<'a>(
    world: &'a common::WorldHeader,
    hand: &'a HandSample,
) -> (u32, &'a [u32; MAX_FINGERS], &'a FingerPoints) {
    if world.finger_count > 0 {
        (
            world.finger_count,
            &world.finger_point_count,
            &world.finger_points,
        )
    } else {
        (
            hand.finger_count,
            &hand.finger_point_count,
            &hand.finger_points,
        )
    }
}

/// An sRGB component (0 to 1) as linear light, as the shader's colours are.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light (0 to 1) as an sRGB component.
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.0031308 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// A block instance's alpha: 1 + its mode's index, which the shader reads for the outline's
/// colour (0 is "no outline": the floor, fingers and palm).
pub fn mode_alpha(mode: BlockMode) -> f32 {
    1.0 + mode as u32 as f32
}

/// Fingers and palm.
pub const SKIN: [f32; 3] = [0.85, 0.60, 0.45];
/// Radius used when a hand sample gives none (bare check-point hands).
pub const DEFAULT_FINGER_RADIUS: f64 = 0.008;

/// The hands a frame draws at most: every hand slot of a shared world (this person's right,
/// or a one-hand session's only hand, and left; each other participant's two).
pub const HANDS: usize = common::HAND_SLOTS;
const SEGMENTS: usize = MAX_FINGERS * (MAX_FINGER_POINTS - 1);
const JOINTS: usize = MAX_FINGERS * MAX_FINGER_POINTS;
/// Instance slots for a scene of `blocks` blocks: floor, palm, blocks, finger segments and
/// finger joints of every hand ([`HANDS`]).
pub const fn instance_capacity(blocks: usize) -> usize {
    2 + blocks + HANDS * (SEGMENTS + JOINTS)
}
/// One palm's hull: at most one triangle per point triple.
const HAND_PALM_VERTICES: usize =
    3 * MAX_PALM_VERTICES * (MAX_PALM_VERTICES - 1) * (MAX_PALM_VERTICES - 2) / 6;
/// Every hand's palm hull.
pub const PALM_VERTEX_CAPACITY: usize = HANDS * HAND_PALM_VERTICES;

const FLOOR_INSTANCE: u32 = 0;
const PALM_INSTANCE: u32 = 1;

/// One instanced draw of blocks: their shared mesh's vertex range and their instances.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockDraw {
    /// The mesh's range of the index buffer.
    pub indices: Range<u32>,
    pub instances: Range<u32>,
}

/// The blocks of one mesh, fixed by the scene.
struct MeshGroup {
    indices: Range<u32>,
    /// Scene indices of its blocks, ascending.
    blocks: Vec<u32>,
}

/// A frame's draws.
pub struct DrawList {
    pub instances: Vec<Instance>,
    /// One per mesh with a block to draw live this frame.
    pub blocks: Vec<BlockDraw>,
    /// One per mesh with a block in the static layer (`static_layer.rs`): drawn only when
    /// that layer's image is redrawn.
    pub static_blocks: Vec<BlockDraw>,
    /// Which instance each block got this frame (u32::MAX: not drawn), in scene order.
    pub block_instance: Vec<u32>,
    groups: Vec<MeshGroup>,
    /// Each block's own colour, linear, in scene order (grey past the end: none was set).
    block_rgb: Vec<[f32; 3]>,
    pub floor_instance: u32,
    pub segments: Range<u32>,
    pub joints: Range<u32>,
    pub palm_instance: u32,
    pub palm_vertices: Vec<Vertex>,
    palm_points: Vec<DVec3>,
    palm_tris: Vec<[DVec3; 3]>,
    segment_scratch: Vec<Instance>,
}

impl DrawList {
    /// A draw list for a scene whose blocks have these index ranges (equal ranges: one mesh,
    /// drawn instanced); blocks of a world beyond them are not drawn.
    pub fn new(block_meshes: &[Range<u32>]) -> DrawList {
        let mut groups: Vec<MeshGroup> = Vec::new();
        for (i, mesh) in block_meshes.iter().enumerate() {
            match groups.iter_mut().find(|g| g.indices == *mesh) {
                Some(g) => g.blocks.push(i as u32),
                None => groups.push(MeshGroup {
                    indices: mesh.clone(),
                    blocks: vec![i as u32],
                }),
            }
        }
        DrawList {
            instances: Vec::with_capacity(instance_capacity(block_meshes.len())),
            blocks: Vec::with_capacity(groups.len()),
            static_blocks: Vec::with_capacity(groups.len()),
            block_instance: vec![u32::MAX; block_meshes.len()],
            groups,
            block_rgb: Vec::new(),
            floor_instance: FLOOR_INSTANCE,
            segments: 0..0,
            joints: 0..0,
            palm_instance: PALM_INSTANCE,
            palm_vertices: Vec::with_capacity(PALM_VERTEX_CAPACITY),
            palm_points: Vec::with_capacity(MAX_PALM_VERTICES),
            palm_tris: Vec::with_capacity(HAND_PALM_VERTICES / 3),
            segment_scratch: Vec::with_capacity(HANDS * SEGMENTS),
        }
    }
}

impl DrawList {
    /// Gives the blocks their own colours (sRGB, 0 to 1, in scene order: [`block_colors`]).
    pub fn set_block_colors(&mut self, srgb: &[[f32; 3]]) {
        self.block_rgb = srgb.iter().map(|c| c.map(srgb_to_linear)).collect();
    }
}

/// A block's face colour when none was set: a mid grey.
const UNSET_BLOCK_RGB: [f32; 3] = [0.35, 0.35, 0.35];

/// `outline`: 0 for none, else a block's [`mode_alpha`].
fn instance(model: Mat4, rgb: [f32; 3], outline: f32) -> Instance {
    Instance {
        model: model.to_cols_array_2d(),
        color: [rgb[0], rgb[1], rgb[2], outline],
    }
}

fn finite3(p: &[f64; 3]) -> Option<DVec3> {
    let v = DVec3::from_array(*p);
    v.is_finite().then_some(v)
}

impl DrawList {
    /// Fills the list for `world` and `hand`, every block live.
    pub fn build(&mut self, world: WorldView<'_>, hand: &HandSample) {
        self.build_layered(world, hand, &[], false);
    }

    /// Fills the list for `world` and `hand`: the blocks `in_static_layer` marks (by scene
    /// index; past its end, none) in `static_blocks` when `draw_static` (the layer's image is
    /// drawn this frame), else not at all (a frame that reuses the image neither builds nor
    /// uploads their instances); the others in `blocks`.
    pub fn build_layered(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
        in_static_layer: &[bool],
        draw_static: bool,
    ) {
        self.build_hands(world, hand, None, in_static_layer, draw_static);
    }

    /// [`Self::build_layered`] with a two-hand session's `left` hand too, drawn from its own
    /// sample (its check points as tracked). `None`: the one hand, exactly as
    /// [`Self::build_layered`] draws it.
    pub fn build_hands(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
        left: Option<&HandSample>,
        in_static_layer: &[bool],
        draw_static: bool,
    ) {
        self.build_people(world, hand, left, &[], in_static_layer, draw_static);
    }

    /// [`Self::build_hands`] with the hands of the other people in a shared world (`others`:
    /// each as tracked, its own check points and palm, after this machine's hands): the host's
    /// renderer draws every participant's.
    pub fn build_people(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
        left: Option<&HandSample>,
        others: &[HandSample],
        in_static_layer: &[bool],
        draw_static: bool,
    ) {
        self.instances.clear();
        self.blocks.clear();
        self.static_blocks.clear();
        self.block_instance.fill(u32::MAX);
        self.instances.push(instance(Mat4::IDENTITY, [0.0; 3], 0.0));
        self.instances.push(instance(Mat4::IDENTITY, SKIN, 0.0));

        let states = world.blocks();
        for g in &self.groups {
            let layers: &[bool] = if draw_static {
                &[true, false]
            } else {
                &[false]
            };
            for &layer_static in layers {
                let start = self.instances.len() as u32;
                for &i in &g.blocks {
                    let Some(b) = states.get(i as usize) else {
                        break; // ascending: the rest are past the world's blocks too
                    };
                    if in_static_layer.get(i as usize).copied().unwrap_or(false) != layer_static {
                        continue;
                    }
                    if !b.pose.is_finite() {
                        continue;
                    }
                    let q = DQuat::from_array(b.pose.rotation);
                    let len = q.length();
                    if !(len > 0.5 && len < 2.0) {
                        continue; // not a rotation: skip rather than draw a sheared block
                    }
                    let model = Mat4::from_rotation_translation(
                        (q / len).as_quat(),
                        DVec3::from_array(b.pose.position).as_vec3(),
                    );
                    let mode = if world.grasped_block == i as i32 {
                        BlockMode::Grasped
                    } else {
                        b.mode()
                    };
                    self.block_instance[i as usize] = self.instances.len() as u32;
                    let rgb = self
                        .block_rgb
                        .get(i as usize)
                        .copied()
                        .unwrap_or(UNSET_BLOCK_RGB);
                    self.instances.push(instance(model, rgb, mode_alpha(mode)));
                }
                let end = self.instances.len() as u32;
                if end > start {
                    let draws = if layer_static {
                        &mut self.static_blocks
                    } else {
                        &mut self.blocks
                    };
                    draws.push(BlockDraw {
                        indices: g.indices.clone(),
                        instances: start..end,
                    });
                }
            }
        }

        let (count, counts, points) = drawn_fingers(world.header, hand);
        self.segment_scratch.clear();
        let joints_start = self.instances.len() as u32;
        push_fingers(
            &mut self.instances,
            &mut self.segment_scratch,
            (count, counts, points),
            &hand.finger_radius,
        );
        for h in left.into_iter().chain(others) {
            push_fingers(
                &mut self.instances,
                &mut self.segment_scratch,
                (h.finger_count, &h.finger_point_count, &h.finger_points),
                &h.finger_radius,
            );
        }
        self.joints = joints_start..self.instances.len() as u32;
        let seg_start = self.instances.len() as u32;
        self.instances.extend_from_slice(&self.segment_scratch);
        self.segments = seg_start..self.instances.len() as u32;

        self.palm_vertices.clear();
        for h in std::iter::once(hand).chain(left).chain(others) {
            self.palm_points.clear();
            self.palm_points.extend(
                h.palm()
                    .iter()
                    .take(MAX_PALM_VERTICES)
                    .map(|p| DVec3::from_array(*p)),
            );
            hull_triangles_into(&self.palm_points, &mut self.palm_tris);
            for t in &self.palm_tris {
                for p in t {
                    self.palm_vertices.push(Vertex {
                        position: p.as_vec3().to_array(),
                        edge: [1.0; 4],
                    });
                }
            }
        }
    }
}

/// One hand's fingers: a joint instance per finite check point into `instances`, a segment
/// instance per pair of finite neighbours into `segments`.
fn push_fingers(
    instances: &mut Vec<Instance>,
    segments: &mut Vec<Instance>,
    (count, counts, points): (u32, &[u32; MAX_FINGERS], &FingerPoints),
    radii: &[f64; MAX_FINGERS],
) {
    for f in 0..(count as usize).min(MAX_FINGERS) {
        let r = radii[f];
        let r = if r.is_finite() && r > 0.0 && r < 0.1 {
            r
        } else {
            DEFAULT_FINGER_RADIUS
        };
        let n = (counts[f] as usize).min(MAX_FINGER_POINTS);
        let pts = &points[f][..n];
        for (k, p) in pts.iter().enumerate() {
            let Some(a) = finite3(p) else { continue };
            let joint = Mat4::from_scale_rotation_translation(
                Vec3::splat(r as f32),
                glam::Quat::IDENTITY,
                a.as_vec3(),
            );
            instances.push(instance(joint, SKIN, 0.0));
            let Some(b) = pts.get(k + 1).and_then(finite3) else {
                continue;
            };
            if let Some(m) = segment_matrix(a, b, r) {
                segments.push(instance(m, SKIN, 0.0));
            }
        }
    }
}

/// The unit cylinder (radius 1, y from 0 to 1) stretched from `a` to `b` with radius `r`, as a
/// right-handed basis so that its triangles keep their winding.
fn segment_matrix(a: DVec3, b: DVec3, r: f64) -> Option<Mat4> {
    let axis = b - a;
    let len = axis.length();
    if len.is_nan() || len <= 1e-9 {
        return None;
    }
    let y = axis / len;
    let x = y.any_orthonormal_vector();
    let z = x.cross(y);
    Some(
        glam::DMat4::from_cols(
            (x * r).extend(0.0),
            axis.extend(0.0),
            (z * r).extend(0.0),
            a.extend(1.0),
        )
        .as_mat4(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::BlockState;

    use common::WorldSample;

    fn world_with(n: usize) -> WorldSample {
        let mut w = WorldSample::with_blocks(n);
        for i in 0..n {
            w.blocks[i] = BlockState {
                pose: common::Pose {
                    position: [i as f64 * 0.1, 0.05, 0.0],
                    rotation: [0.0, 0.0, 0.0, 1.0],
                },
                mode: BlockMode::Resting as u32,
                held_by: 0,
            };
        }
        w
    }

    #[test]
    fn nan_poses_skip_only_that_block_and_that_finger_point() {
        let meshes = vec![0..36, 36..72, 72..108];
        let mut w = world_with(3);
        w.blocks[1].pose.position[0] = f64::NAN;
        w.blocks[2].pose.rotation = [0.0; 4];
        let mut h = HandSample {
            finger_count: 1,
            ..Default::default()
        };
        h.finger_point_count[0] = 3;
        h.finger_points[0] = [
            [0.0, 0.2, 0.0],
            [f64::NAN, 0.2, 0.0],
            [0.0, 0.2, 0.05],
            [0.0; 3],
            [0.0; 3],
        ];
        let mut d = DrawList::new(&meshes);
        d.build(w.view(), &h);
        assert_eq!(d.blocks.len(), 1);
        assert_eq!(d.blocks[0].indices, 0..36);
        assert_eq!(d.blocks[0].instances.len(), 1);
        assert_eq!(d.block_instance[1..], [u32::MAX, u32::MAX]);
        assert_eq!(d.joints.len(), 2); // the NaN point is skipped
        assert_eq!(d.segments.len(), 0); // both segments touch it
    }

    #[test]
    fn the_grasped_block_takes_the_grasp_colour_and_world_fingers_win() {
        let mut w = world_with(2);
        w.grasped_block = 1;
        w.finger_count = 1;
        w.finger_point_count[0] = 2;
        w.finger_points[0][0] = [0.0, 0.3, 0.0];
        w.finger_points[0][1] = [0.0, 0.3, 0.04];
        let mut h = HandSample {
            finger_count: 2,
            ..Default::default()
        };
        h.finger_point_count = [2, 2, 0, 0, 0];
        let mut d = DrawList::new(&[0..3, 3..6]);
        d.build(w.view(), &h);
        let grasped = &d.instances[d.block_instance[1] as usize];
        assert_eq!(grasped.color[3], mode_alpha(BlockMode::Grasped));
        assert_eq!(d.joints.len(), 2);
        assert_eq!(d.segments.len(), 1);
        let m = Mat4::from_cols_array_2d(&d.instances[d.segments.start as usize].model);
        let tip = m.transform_point3(Vec3::Y);
        assert!(tip.distance(Vec3::new(0.0, 0.3, 0.04)) < 1e-6, "{tip}");
        assert!(m.determinant() > 0.0);
    }

    /// Blocks that share a mesh are one draw with contiguous instances, whatever their order
    /// in the scene; each keeps its own pose and colour.
    #[test]
    fn blocks_of_one_mesh_are_one_instanced_draw() {
        let n = 4096;
        let mut w = world_with(n);
        w.blocks[7].mode = BlockMode::Free as u32;
        // Every third block another shape.
        let meshes: Vec<_> = (0..n)
            .map(|i| if i % 3 == 0 { 36..72 } else { 0..36 })
            .collect();
        let mut d = DrawList::new(&meshes);
        let colors: Vec<[f32; 3]> = (0..n).map(|i| PALETTE[i % PALETTE.len()]).collect();
        d.set_block_colors(&colors);
        d.build(w.view(), &HandSample::default());
        assert_eq!(d.blocks.len(), 2, "two meshes, two draws");
        assert_eq!(d.blocks[0].indices, 36..72);
        assert_eq!(d.blocks[0].instances.len(), n.div_ceil(3));
        assert_eq!(d.blocks[1].instances.len(), n - n.div_ceil(3));
        for (i, b) in w.blocks.iter().enumerate() {
            let inst = &d.instances[d.block_instance[i] as usize];
            let m = Mat4::from_cols_array_2d(&inst.model);
            let p = m.transform_point3(Vec3::ZERO);
            assert!((p.x as f64 - b.pose.position[0]).abs() < 1e-3, "block {i}");
            assert_eq!(inst.color[..3], colors[i].map(srgb_to_linear), "block {i}");
            assert_eq!(inst.color[3], mode_alpha(b.mode()), "block {i}");
        }
    }

    #[test]
    fn a_block_takes_its_tables_colour_else_its_names_else_the_palettes() {
        assert_eq!(color_for_name("red"), Some(NAMED_COLORS[0].1));
        assert_eq!(color_for_name("Red-cube"), Some(NAMED_COLORS[0].1));
        assert_eq!(color_for_name("blue_3_0_1"), Some(NAMED_COLORS[2].1));
        assert_eq!(color_for_name("green2"), Some(NAMED_COLORS[1].1));
        assert_eq!(color_for_name("redder"), None);
        assert_eq!(color_for_name("cube"), None);
        let block = |name: &str| common::config::scene::BlockSpec {
            name: name.into(),
            shape: common::config::scene::ShapeSpec::Box { size: [0.1; 3] },
            position: [0.0; 3],
            rotation: [0.0, 0.0, 0.0, 1.0],
            velocity: [0.0; 3],
        };
        let mut scene = common::config::Scene {
            file: "t.toml".into(),
            world: Default::default(),
            effects: Default::default(),
            blocks: vec![block("red"), block("a"), block("b"), block("green")],
            hand: None,
            left_hand: None,
        };
        scene.world.block_colors = vec![None, None, None, Some([0.1, 0.2, 0.3])];
        let c = block_colors(&scene);
        assert_eq!(c[0], NAMED_COLORS[0].1, "by name");
        assert_eq!(c[1], PALETTE[1], "by index");
        assert_eq!(c[2], PALETTE[2], "by index");
        assert_eq!(c[3], [0.1, 0.2, 0.3], "the table's own wins over the name");
        // A lattice's copies share their table's colour.
        scene.blocks = vec![
            block("cube_0_0_0"),
            block("cube_1_0_0"),
            block("x_1"),
            block("y"),
        ];
        scene.world.block_colors.clear();
        let c = block_colors(&scene);
        assert_eq!(
            [c[0], c[1], c[2], c[3]],
            [PALETTE[0], PALETTE[0], PALETTE[1], PALETTE[2]]
        );
        // The colour stays the block's in every mode: only the outline (alpha) changes.
        let mut w = world_with(1);
        let one_mesh: Range<u32> = 0..36;
        let mut d = DrawList::new(std::slice::from_ref(&one_mesh));
        d.set_block_colors(&c[..1]);
        for mode in BlockMode::ALL {
            w.blocks[0].mode = mode as u32;
            d.build(w.view(), &HandSample::default());
            let inst = &d.instances[d.block_instance[0] as usize];
            assert_eq!(inst.color[..3], c[0].map(srgb_to_linear), "{mode:?}");
            assert_eq!(inst.color[3], mode_alpha(mode));
        }
    }

    /// The shader's outline colours are `mode_color`'s, in `BlockMode`'s order.
    #[test]
    fn the_shaders_mode_colours_are_mode_color() {
        let src = include_str!("shaders.wgsl");
        let table = src
            .split("const MODE_RGB")
            .nth(1)
            .and_then(|t| t.split(");").next())
            .expect("MODE_RGB in the shader");
        let rows: Vec<[f32; 3]> = table
            .split("vec3<f32>(")
            .skip(1) // what comes before the first row
            .map(|r| {
                let v: Vec<f32> = r
                    .split(')')
                    .next()
                    .unwrap()
                    .split(',')
                    .map(|x| x.trim().parse().unwrap())
                    .collect();
                [v[0], v[1], v[2]]
            })
            .collect();
        let want: Vec<[f32; 3]> = BlockMode::ALL.iter().map(|m| mode_color(*m)).collect();
        assert_eq!(rows, want);
    }

    /// A hand of `fingers` fingers of 3 points each, along x at height `y`, and a palm of 4
    /// points (a tetrahedron) there.
    fn hand_at(x: f64, y: f64, fingers: usize) -> HandSample {
        let mut h = HandSample {
            finger_count: fingers as u32,
            palm_vertex_count: 4,
            ..Default::default()
        };
        for f in 0..fingers {
            h.finger_point_count[f] = 3;
            h.finger_radius[f] = 0.009;
            for k in 0..3 {
                h.finger_points[f][k] = [x + f as f64 * 0.02, y, k as f64 * 0.03];
            }
        }
        h.palm_vertices[..4].copy_from_slice(&[
            [x, y, -0.05],
            [x + 0.06, y, -0.05],
            [x, y + 0.03, -0.05],
            [x, y, -0.09],
        ]);
        h
    }

    /// A two-hand session's left hand adds its joints, segments and palm, at its own tracked
    /// points (the world's drawn points are the right hand's); with no left hand the list is
    /// the one-hand list, instance for instance.
    #[test]
    fn a_left_hand_adds_its_own_geometry_and_one_hand_is_unchanged() {
        let mut w = world_with(2);
        w.grasped_block = 0;
        // The right hand's points as drawn: relocated by the stepper (one finger, 2 points).
        w.finger_count = 1;
        w.finger_point_count[0] = 2;
        w.finger_points[0][0] = [0.0, 0.3, 0.0];
        w.finger_points[0][1] = [0.0, 0.3, 0.04];
        let right = hand_at(0.0, 0.2, 2);
        let mut left = hand_at(-0.4, 0.25, 3);
        left.side = common::HandSide::Left.code();
        let mut d = DrawList::new(&[0..3, 3..6]);

        d.build(w.view(), &right);
        let one = (
            d.instances.clone(),
            d.blocks.clone(),
            d.joints.clone(),
            d.segments.clone(),
            d.palm_vertices.clone(),
        );
        d.build_hands(w.view(), &right, None, &[], false);
        let none = (
            d.instances.clone(),
            d.blocks.clone(),
            d.joints.clone(),
            d.segments.clone(),
            d.palm_vertices.clone(),
        );
        assert_eq!(none, one, "no left hand: the one-hand list");
        assert_eq!((one.2.len(), one.3.len()), (2, 1), "the world's points");

        d.build_hands(w.view(), &right, Some(&left), &[], false);
        // Floor, palm, blocks and the right hand's joints come first, as before.
        let before_joints = one.2.end as usize;
        assert_eq!(d.instances[..before_joints], one.0[..before_joints]);
        assert_eq!(d.blocks, one.1);
        assert_eq!(d.joints.start, one.2.start);
        assert_eq!(d.joints.len(), 2 + 3 * 3, "right 2, left 3 fingers of 3");
        assert_eq!(d.segments.len(), 1 + 3 * 2);
        assert_eq!(d.instances.len() as u32, d.segments.end);
        // The left joints are at the left hand's own points, with its radius.
        let left_joints = &d.instances[before_joints..d.joints.end as usize];
        for (inst, p) in left_joints
            .iter()
            .zip((0..3).flat_map(|f| left.finger_points[f][..3].iter()))
        {
            let m = Mat4::from_cols_array_2d(&inst.model);
            let at = m.transform_point3(Vec3::ZERO);
            assert!(at.distance(DVec3::from_array(*p).as_vec3()) < 1e-6, "{at}");
            assert!((m.x_axis.length() - 0.009).abs() < 1e-6);
        }
        // Each segment starts at a joint of its own hand.
        let right_segment = Mat4::from_cols_array_2d(&d.instances[d.segments.start as usize].model);
        assert!(
            right_segment
                .transform_point3(Vec3::ZERO)
                .distance(Vec3::new(0.0, 0.3, 0.0))
                < 1e-6
        );
        let left_segment =
            Mat4::from_cols_array_2d(&d.instances[d.segments.start as usize + 1].model);
        let p = left.finger_points[0][0];
        assert!(
            left_segment
                .transform_point3(Vec3::ZERO)
                .distance(DVec3::from_array(p).as_vec3())
                < 1e-6
        );
        // Both palms: the right hull's vertices, then the left's.
        let n = one.4.len();
        assert!(n > 0);
        assert_eq!(d.palm_vertices[..n], one.4[..]);
        assert_eq!(d.palm_vertices.len(), 2 * n, "two tetrahedra");
        assert!(d.palm_vertices[n..]
            .iter()
            .all(|v| v.position[0] <= -0.4 + 0.06 + 1e-6));
        assert!(d.instances.len() <= instance_capacity(2));
        assert!(d.palm_vertices.len() <= PALM_VERTEX_CAPACITY);
    }

    #[test]
    fn every_hand_slot_full_fits_the_buffers_and_allocates_nothing_once_warm() {
        let w = world_with(common::MAX_SCENE_BLOCKS);
        let full = |x: f64| {
            let mut h = HandSample {
                finger_count: 5,
                finger_point_count: [5; 5],
                palm_vertex_count: 16,
                ..Default::default()
            };
            for (i, p) in h.palm_vertices.iter_mut().enumerate() {
                *p = [
                    x + (i % 2) as f64,
                    ((i / 2) % 2) as f64,
                    ((i / 4) % 4) as f64 * 0.3,
                ];
            }
            for f in 0..5 {
                for k in 0..5 {
                    h.finger_points[f][k] = [x + f as f64 * 0.02, 0.2, k as f64 * 0.02];
                }
            }
            h
        };
        let (right, mut left) = (full(0.0), full(-2.0));
        left.side = 1;
        // The other participants of a shared world: both hands each.
        let others: Vec<HandSample> = (1..common::MAX_PARTICIPANTS as u32)
            .flat_map(|p| {
                (0..2u32).map(move |side| HandSample {
                    participant: p,
                    side,
                    ..full(2.0 * p as f64 + side as f64)
                })
            })
            .collect();
        assert_eq!(2 + others.len(), HANDS);
        let meshes: Vec<_> = (0..common::MAX_SCENE_BLOCKS as u32)
            .map(|i| i * 3..i * 3 + 3)
            .collect();
        let mut d = DrawList::new(&meshes);
        let caps = (
            d.instances.capacity(),
            d.palm_vertices.capacity(),
            d.segment_scratch.capacity(),
        );
        d.build_people(w.view(), &right, Some(&left), &others, &[], false);
        d.build_people(w.view(), &right, Some(&left), &others, &[], false);
        assert_eq!(
            (
                d.instances.capacity(),
                d.palm_vertices.capacity(),
                d.segment_scratch.capacity()
            ),
            caps
        );
        assert_eq!(d.instances.len(), instance_capacity(meshes.len()));
        assert!(d.palm_vertices.len() <= PALM_VERTEX_CAPACITY);
    }

    #[test]
    fn a_frame_allocates_nothing_once_warm() {
        let w = world_with(common::MAX_SCENE_BLOCKS);
        let mut h = HandSample {
            finger_count: 5,
            finger_point_count: [5; 5],
            palm_vertex_count: 16,
            ..Default::default()
        };
        for (i, p) in h.palm_vertices.iter_mut().enumerate() {
            *p = [
                (i % 2) as f64,
                ((i / 2) % 2) as f64,
                ((i / 4) % 4) as f64 * 0.3,
            ];
        }
        for f in 0..5 {
            for k in 0..5 {
                h.finger_points[f][k] = [f as f64 * 0.02, 0.2, k as f64 * 0.02];
            }
        }
        let meshes: Vec<_> = (0..common::MAX_SCENE_BLOCKS as u32)
            .map(|i| i * 3..i * 3 + 3)
            .collect();
        let mut d = DrawList::new(&meshes);
        let caps = (d.instances.capacity(), d.palm_vertices.capacity());
        d.build(w.view(), &h);
        d.build(w.view(), &h);
        assert_eq!((d.instances.capacity(), d.palm_vertices.capacity()), caps);
        assert!(d.instances.len() <= instance_capacity(meshes.len()));
        assert!(!d.palm_vertices.is_empty());
    }
}
