//! The session's scene as Foxglove's 3D panel draws it: a `foxglove.SceneUpdate` of the floor,
//! each block (its own shape, its own colour, and a label naming it and its mode) and the hand
//! (a line per finger, knuckle to tip, and the palm's hull). A two-hand session's left hand
//! (`HandSample::side` 1) is an entity of its own, [`LEFT_HAND_ID`], after the right hand's
//! ([`HAND_ID`]); it exists from the first left hand on, so a one-hand session's update is
//! what it was before there were two hands.
//!
//! One implementation serves the live view (the bridge sends it on `/scene`) and recordings
//! (the recorder writes it on the same `/scene` channel), so a recording opens in the 3D panel
//! exactly as the live session shows, and a layout made on one works on the other.
//!
//! **Frames.** handblocks is y-up; Foxglove's 3D panel is z-up (ROS REP 103). The poses are
//! *converted* here, not transformed by a `FrameTransform`: every entity is in the frame
//! [`FRAME_ID`] (`world`), z-up, with a point `(x, y, z)` of handblocks at `(x, -z, y)` (a
//! rotation of +90 degrees about x, [`z_up`], [`z_up_rotation`]). A converted pose needs no
//! transform to have arrived first, which a panel opened half-way through a recording would lack.
//! The sample topics (`/world`, `/hand`, ...) keep handblocks' own y-up numbers.
//!
//! **The hand's frames.** Beside the drawing, the view keeps the hand as a tree of frames,
//! `world` -> `hand` (the wrist) -> each finger's joints, a `foxglove.FrameTransforms` sent on
//! [`TF_CHANNEL`] (`/tf`) with each scene ([`HandFrames`], the `frames` module): the 3D panel
//! shows every joint's axes, and a panel may follow the hand. The scene does not depend on it.
//!
//! **Cost.** The update is built once ([`SceneView::new`]) and then rewritten in place: a new
//! world changes poses and, when a mode changes, a label; a new hand refills the finger and palm
//! point lists, whose capacity stays. After the first updates nothing is allocated.

use std::f64::consts::FRAC_1_SQRT_2;
use std::fmt::Write as _;

use common::config::scene::ShapeSpec;
use common::config::Scene;
use common::samples::{BlockMode, BlockState, HandSample, HandSide};
use foxglove::schemas::{
    Color, CubePrimitive, LinePrimitive, Point3, Pose, Quaternion, SceneEntity, SceneUpdate,
    TextPrimitive, TriangleListPrimitive, Vector3,
};
use foxglove::Encode as _;
use glam::{DQuat, DVec3};

mod frames;
pub use frames::{
    hand_frame, joint_frame, HandFrames, FINGER_JOINTS, FINGER_NAMES, TF_CHANNEL, THUMB_JOINTS,
};

/// The channel (topic) name, live and recorded.
pub const CHANNEL: &str = "/scene";
/// The frame every entity is in: z-up (see the module's doc).
pub const FRAME_ID: &str = "world";
/// The hand's entity: the right hand, or a one-hand session's only hand.
pub const HAND_ID: &str = "hand";
/// A two-hand session's left hand's entity.
pub const LEFT_HAND_ID: &str = "hand-left";

/// A handblocks (y-up) point in Foxglove's z-up frame: `(x, y, z)` -> `(x, -z, y)`.
pub fn z_up(p: [f64; 3]) -> [f64; 3] {
    [p[0], -p[2], p[1]]
}

/// A handblocks rotation (unit quaternion `[x, y, z, w]`) in Foxglove's z-up frame: the
/// rotation from y-up to z-up (+90 degrees about x) applied after it.
pub fn z_up_rotation(q: [f64; 4]) -> [f64; 4] {
    let to_z_up = DQuat::from_xyzw(FRAC_1_SQRT_2, 0.0, 0.0, FRAC_1_SQRT_2);
    (to_z_up * DQuat::from_array(q)).to_array()
}

/// Each block's colour, RGB 0-1 (sRGB): the scene's rule (`common::config::colors`), the one
/// the renderer draws with. A block keeps its colour whatever its mode; the mode is its label's.
pub fn block_colours(scene: &Scene) -> Vec<[f64; 3]> {
    common::config::colors::block_colors(scene)
        .into_iter()
        .map(|c| c.map(f64::from))
        .collect()
}

/// Why a scene cannot be drawn.
#[derive(Debug)]
pub struct SceneViewError {
    pub block: String,
    pub problem: String,
}

impl std::fmt::Display for SceneViewError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "block {:?}: {}", self.block, self.problem)
    }
}

impl std::error::Error for SceneViewError {}

/// The scene as one `SceneUpdate`, rewritten in place as worlds and hands arrive.
pub struct SceneView {
    update: SceneUpdate,
    /// Per block: its name (for its label), how far its label sits above its centre, and the
    /// mode its label says now (None before the first world).
    labels: Vec<(String, f64, Option<BlockMode>)>,
    /// The palm's points (y-up) and their hull's triangles, kept for their capacity.
    palm_points: Vec<DVec3>,
    palm_triangles: Vec<[DVec3; 3]>,
    /// The newest hand, drawn (its hull built) only with the next world: hands come at the
    /// source's rate, scenes go out at a fraction of it, or not at all.
    hand: Option<HandSample>,
    /// A two-hand session's newest left hand, drawn as `hand` is.
    left: Option<HandSample>,
    /// The drawn hands as frames (`/tf`), rewritten with each drawing.
    frames: HandFrames,
}

/// Entity 0 is the floor, 1..=n the blocks, n + 1 the hand, n + 2 the left hand (once there is
/// one); a hand has a line per finger.
const FINGERS: usize = 5;

/// A hand's entity, empty: a line strip per finger and the palm's triangles.
fn hand_entity(id: &str) -> SceneEntity {
    let mut hand = entity(id);
    let skin = rgba([0.93, 0.76, 0.62], 0.9);
    for _ in 0..FINGERS {
        hand.lines.push(LinePrimitive {
            r#type: 0, // a line strip, knuckle to tip
            pose: Some(identity()),
            thickness: 0.0,
            scale_invariant: false,
            points: Vec::new(),
            color: skin,
            ..Default::default()
        });
    }
    hand.triangles.push(TriangleListPrimitive {
        pose: Some(identity()),
        color: skin,
        ..Default::default()
    });
    hand
}

fn point(p: [f64; 3]) -> Point3 {
    let [x, y, z] = z_up(p);
    Point3 { x, y, z }
}

fn pose(position: [f64; 3], rotation: [f64; 4]) -> Pose {
    let [x, y, z] = z_up(position);
    let [qx, qy, qz, qw] = z_up_rotation(rotation);
    Pose {
        position: Some(Vector3 { x, y, z }),
        orientation: Some(Quaternion {
            x: qx,
            y: qy,
            z: qz,
            w: qw,
        }),
    }
}

fn identity() -> Pose {
    Pose {
        position: Some(Vector3::default()),
        orientation: Some(Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    }
}

fn rgba([r, g, b]: [f64; 3], a: f64) -> Option<Color> {
    Some(Color { r, g, b, a })
}

fn entity(id: &str) -> SceneEntity {
    SceneEntity {
        frame_id: FRAME_ID.into(),
        id: id.into(),
        ..Default::default()
    }
}

impl SceneView {
    /// The floor, the scene's blocks at their start poses (mode not yet known), and no hand.
    pub fn new(scene: &Scene) -> Result<SceneView, SceneViewError> {
        let mut entities = Vec::with_capacity(scene.blocks.len() + 2);
        let mut labels = Vec::with_capacity(scene.blocks.len());
        // The floor (y = 0) under the blocks' start positions, a metre beyond them each way.
        let (mut lo, mut hi) = (DVec3::splat(-0.5), DVec3::splat(0.5));
        for b in &scene.blocks {
            let p = DVec3::from_array(b.position);
            lo = lo.min(p - 1.0);
            hi = hi.max(p + 1.0);
        }
        let mut floor = entity("floor");
        let centre = (lo + hi) / 2.0;
        floor.cubes.push(CubePrimitive {
            pose: Some(pose([centre.x, -0.0005, centre.z], [0.0, 0.0, 0.0, 1.0])),
            // Sizes are in the entity's (z-up) frame: x, then handblocks' z, then its y.
            size: Some(Vector3 {
                x: hi.x - lo.x,
                y: hi.z - lo.z,
                z: 0.001,
            }),
            color: rgba([0.42, 0.44, 0.47], 1.0),
        });
        entities.push(floor);
        let colours = block_colours(scene);
        for (b, &colour) in scene.blocks.iter().zip(&colours) {
            let mut e = entity(&b.name);
            let start = pose(b.position, b.rotation);
            let radius = match &b.shape {
                ShapeSpec::Box { size } => {
                    // A cube's size is along its own axes, which the rotation carries.
                    e.cubes.push(CubePrimitive {
                        pose: Some(start),
                        size: Some(Vector3 {
                            x: size[0],
                            y: size[1],
                            z: size[2],
                        }),
                        color: rgba(colour, 1.0),
                    });
                    DVec3::from_array(*size).length() / 2.0
                }
                spec => {
                    let solid =
                        shapes::Solid::from_spec(spec).map_err(|problem| SceneViewError {
                            block: b.name.clone(),
                            problem,
                        })?;
                    // The points stay in the block's own frame (its pose does the rest).
                    let points = solid
                        .triangles
                        .iter()
                        .flat_map(|t| t.iter().map(|&i| solid.vertices[i as usize]))
                        .map(|v| Point3 {
                            x: v.x,
                            y: v.y,
                            z: v.z,
                        })
                        .collect();
                    e.triangles.push(TriangleListPrimitive {
                        pose: Some(start),
                        points,
                        color: rgba(colour, 1.0),
                        ..Default::default()
                    });
                    solid
                        .vertices
                        .iter()
                        .map(|v| v.length())
                        .fold(0.0, f64::max)
                }
            };
            let above = radius + 0.03;
            let mut text = String::with_capacity(b.name.len() + 16);
            text.push_str(&b.name);
            e.texts.push(TextPrimitive {
                pose: Some(pose(
                    [b.position[0], b.position[1] + above, b.position[2]],
                    [0.0, 0.0, 0.0, 1.0],
                )),
                billboard: true,
                font_size: 14.0,
                scale_invariant: true,
                color: rgba(colour.map(|c| (c * 1.3).min(1.0)), 1.0),
                text,
            });
            entities.push(e);
            labels.push((b.name.clone(), above, None));
        }
        entities.push(hand_entity(HAND_ID));
        Ok(SceneView {
            update: SceneUpdate {
                deletions: Vec::new(),
                entities,
            },
            labels,
            palm_points: Vec::new(),
            palm_triangles: Vec::new(),
            hand: None,
            left: None,
            frames: HandFrames::default(),
        })
    }

    /// The update as it stands.
    pub fn update(&self) -> &SceneUpdate {
        &self.update
    }

    /// The hands drawn so far as frames (`/tf`): empty before the first hand is drawn.
    pub fn frames(&self) -> &HandFrames {
        &self.frames
    }

    /// [`SceneView::frames`], to stamp them ([`HandFrames::stamp`]) before they are sent.
    pub fn frames_mut(&mut self) -> &mut HandFrames {
        &mut self.frames
    }

    /// Block `i`'s state: its pose, and its label when its mode changed. Blocks beyond the
    /// scene's are ignored (a world always carries the scene's blocks).
    pub fn set_block(&mut self, i: usize, state: &BlockState) {
        let (Some(e), Some((name, above, said))) =
            (self.update.entities.get_mut(1 + i), self.labels.get_mut(i))
        else {
            return;
        };
        let p = pose(state.pose.position, state.pose.rotation);
        if let Some(c) = e.cubes.first_mut() {
            c.pose = Some(p);
        } else if let Some(t) = e.triangles.first_mut() {
            t.pose = Some(p);
        }
        let at = state.pose.position;
        if let Some(label) = e.texts.first_mut() {
            label.pose = Some(pose([at[0], at[1] + *above, at[2]], [0.0, 0.0, 0.0, 1.0]));
            let mode = state.mode();
            if *said != Some(mode) {
                *said = Some(mode);
                label.text.clear();
                let _ = write!(label.text, "{name}: {}", mode.name());
            }
        }
    }

    /// A world's blocks: `block(i)` is block `i`'s state, for `i` below `count`; and the
    /// newest hand since the last world.
    pub fn set_world(&mut self, count: usize, block: impl Fn(usize) -> BlockState) {
        for i in 0..count.min(self.labels.len()) {
            self.set_block(i, &block(i));
        }
        let right = 1 + self.labels.len();
        if let Some(hand) = self.hand.take() {
            self.draw_hand(right, &hand);
            self.frames.set_hand(&hand);
        }
        if let Some(left) = self.left.take() {
            if self.update.entities.len() == right + 1 {
                // The first left hand: its entity, once (a one-hand session never has it).
                self.update.entities.push(hand_entity(LEFT_HAND_ID));
            }
            self.draw_hand(right + 1, &left);
            self.frames.set_hand(&left);
        }
    }

    /// The newest hand of its side (`HandSample::side`: the left hand of a two-hand session,
    /// else the right): kept, and drawn with the next world ([`SceneView::set_world`]).
    pub fn set_hand(&mut self, hand: &HandSample) {
        match HandSide::from_code(hand.side) {
            HandSide::Left => self.left = Some(*hand),
            HandSide::Right => self.hand = Some(*hand),
        }
    }

    /// The hand of entity `index`: a line strip per finger (as thick as the finger), the
    /// palm's hull.
    fn draw_hand(&mut self, index: usize, hand: &HandSample) {
        let Some(e) = self.update.entities.get_mut(index) else {
            return;
        };
        let fingers = (hand.finger_count as usize).min(hand.finger_points.len());
        for (f, line) in e.lines.iter_mut().enumerate() {
            line.points.clear();
            if f < fingers {
                line.thickness = 2.0 * hand.finger_radius.get(f).copied().unwrap_or(0.0);
                line.points.extend(hand.finger(f).iter().map(|p| point(*p)));
            }
        }
        self.palm_points.clear();
        self.palm_points
            .extend(hand.palm().iter().map(|p| DVec3::from_array(*p)));
        shapes::hull_triangles_into(&self.palm_points, &mut self.palm_triangles);
        if let Some(palm) = e.triangles.first_mut() {
            palm.points.clear();
            palm.points.extend(
                self.palm_triangles
                    .iter()
                    .flat_map(|t| t.iter().map(|v| point(v.to_array()))),
            );
        }
    }

    /// The update, protobuf-encoded into `out` (cleared first; its capacity is kept).
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        out.clear();
        // A Vec grows as needed: encoding into one cannot run out of room.
        let _ = self.update.encode(out);
    }

    /// The schema of the channel: (name, encoding, data), as an MCAP schema record wants them.
    pub fn schema() -> (String, String, Vec<u8>) {
        match SceneUpdate::get_schema() {
            Some(s) => (s.name, s.encoding, s.data.into_owned()),
            None => ("foxglove.SceneUpdate".into(), "protobuf".into(), Vec::new()),
        }
    }

    /// The message encoding of the channel (`protobuf`).
    pub fn message_encoding() -> String {
        SceneUpdate::get_message_encoding()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_blocks() -> Scene {
        let block = |name: &str, x: f64| common::config::scene::BlockSpec {
            name: name.into(),
            shape: ShapeSpec::Box { size: [0.05; 3] },
            position: [x, 0.025, 0.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
            velocity: [0.0; 3],
        };
        Scene {
            file: "t.toml".into(),
            world: Default::default(),
            effects: Default::default(),
            blocks: vec![block("red", 0.0), block("blue", 0.1)],
            hand: None,
            left_hand: None,
        }
    }

    fn hand_at(x: f64, side: HandSide) -> HandSample {
        let mut h = HandSample {
            finger_count: 2,
            palm_vertex_count: 4,
            side: side.code(),
            ..Default::default()
        };
        h.finger_point_count[..2].copy_from_slice(&[3, 3]);
        h.finger_radius[..2].copy_from_slice(&[0.008, 0.008]);
        for f in 0..2 {
            for k in 0..3 {
                h.finger_points[f][k] = [x + 0.02 * f as f64, 0.2, 0.03 * k as f64];
            }
        }
        h.palm_vertices[..4].copy_from_slice(&[
            [x, 0.2, -0.05],
            [x + 0.06, 0.2, -0.05],
            [x, 0.23, -0.05],
            [x, 0.2, -0.09],
        ]);
        h
    }

    fn ids(v: &SceneView) -> Vec<&str> {
        v.update().entities.iter().map(|e| e.id.as_str()).collect()
    }

    /// A left hand (side 1) is an entity of its own, after the right hand's, which it leaves
    /// alone; a one-hand session never has it, and its update is a prefix of the two-hand one.
    #[test]
    fn a_left_hand_is_its_own_entity_and_one_hand_is_unchanged() {
        let scene = two_blocks();
        let block = |_: usize| BlockState {
            pose: common::Pose::IDENTITY,
            ..Default::default()
        };
        let right = hand_at(0.0, HandSide::Right);
        let left = hand_at(-0.4, HandSide::Left);

        let mut one = SceneView::new(&scene).expect("a view");
        one.set_hand(&right);
        one.set_world(2, block);
        assert_eq!(ids(&one), ["floor", "red", "blue", HAND_ID]);
        let mut one_bytes = Vec::new();
        one.encode_into(&mut one_bytes);

        let mut two = SceneView::new(&scene).expect("a view");
        two.set_hand(&right);
        two.set_hand(&left);
        two.set_world(2, block);
        assert_eq!(ids(&two), ["floor", "red", "blue", HAND_ID, LEFT_HAND_ID]);
        let mut two_bytes = Vec::new();
        two.encode_into(&mut two_bytes);
        // The same entities first, the left hand's appended.
        assert!(two_bytes.len() > one_bytes.len());
        assert!(two_bytes.starts_with(&one_bytes));
        assert_eq!(two.update().entities[..4], one.update().entities[..]);

        let (r, l) = (&two.update().entities[3], &two.update().entities[4]);
        assert_eq!(l.frame_id, FRAME_ID);
        assert_eq!(l.lines.len(), FINGERS);
        let x0 = |e: &SceneEntity| e.lines[0].points.first().map(|p| p.x);
        assert_eq!(x0(r), Some(0.0));
        assert_eq!(x0(l), Some(-0.4));
        assert_eq!(l.lines[0].points.len(), 3);
        assert!(l.lines[2].points.is_empty());
        assert_eq!(l.triangles[0].points.len(), r.triangles[0].points.len());
        assert!(!l.triangles[0].points.is_empty());

        // The next left hand redraws its entity in place; a world without a new hand leaves
        // both as they are; the entity is made once.
        two.set_hand(&hand_at(-0.5, HandSide::Left));
        two.set_world(2, block);
        two.set_world(2, block);
        assert_eq!(ids(&two).len(), 5);
        assert_eq!(x0(&two.update().entities[4]), Some(-0.5));
        assert_eq!(x0(&two.update().entities[3]), Some(0.0));
    }

    #[test]
    fn z_up_puts_handblocks_up_on_foxgloves_z() {
        assert_eq!(z_up([0.0, 1.0, 0.0]), [0.0, 0.0, 1.0]);
        assert_eq!(z_up([1.0, 0.0, 0.0]), [1.0, 0.0, 0.0]);
        assert_eq!(z_up([0.0, 0.0, 1.0]), [0.0, -1.0, 0.0]);
        // The rotation does to a block's axes what z_up does to points.
        let q = DQuat::from_array(z_up_rotation([0.0, 0.0, 0.0, 1.0]));
        let up = q * DVec3::Y;
        assert!((up - DVec3::Z).length() < 1e-12, "{up}");
        // A block turned about handblocks' up turns about Foxglove's up.
        let turn = DQuat::from_rotation_y(0.7);
        let q = DQuat::from_array(z_up_rotation(turn.to_array()));
        let x = q * DVec3::X;
        let expect = DVec3::from_array(z_up((turn * DVec3::X).to_array()));
        assert!((x - expect).length() < 1e-12, "{x} {expect}");
    }
}
