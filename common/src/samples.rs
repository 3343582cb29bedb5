//! The sample type of every topic: fixed `#[repr(C)]` layouts that travel zero-copy.
//!
//! Each type has a stable `type_name`: processes that disagree on a layout fail to connect
//! (`IncompatibleTypes`) instead of reading garbage. Geometry is f64 in metres, world frame,
//! y up; rotations are unit quaternions `[x, y, z, w]`.

use iceoryx2::prelude::ZeroCopySend;

use crate::stamp::Stamp;

/// Most sensors a CyberGlove reports (the 22-sensor model).
pub const MAX_GLOVE_SENSORS: usize = 22;
/// Fingers a hand sample can carry (a scene's bare `fingers` hand may use fewer).
pub const MAX_FINGERS: usize = 5;
/// Check points per finger, ordered knuckle to tip (docs/model.md, "Hand input per step").
pub const MAX_FINGER_POINTS: usize = 5;
/// Vertices of the palm polyhedron.
pub const MAX_PALM_VERTICES: usize = 16;
/// Blocks a scene may hold, end to end: the block world (`simulate`, the benchmarks), a live
/// session's `world` topic (its samples are sized from the scene: a [`WorldHeader`] and one
/// [`BlockState`] per block), the renderer and a recording.
pub const MAX_SCENE_BLOCKS: usize = 4096;
/// Joints of an OpenXR hand (XR_EXT_hand_tracking order).
pub const OPENXR_JOINTS: usize = 26;
/// The joints' names, in that order (`XrHandJointEXT` without its prefix).
pub const OPENXR_JOINT_NAMES: [&str; OPENXR_JOINTS] = [
    "palm",
    "wrist",
    "thumb_metacarpal",
    "thumb_proximal",
    "thumb_distal",
    "thumb_tip",
    "index_metacarpal",
    "index_proximal",
    "index_intermediate",
    "index_distal",
    "index_tip",
    "middle_metacarpal",
    "middle_proximal",
    "middle_intermediate",
    "middle_distal",
    "middle_tip",
    "ring_metacarpal",
    "ring_proximal",
    "ring_intermediate",
    "ring_distal",
    "ring_tip",
    "little_metacarpal",
    "little_proximal",
    "little_intermediate",
    "little_distal",
    "little_tip",
];

/// A rigid pose: position in metres and rotation as a unit quaternion `[x, y, z, w]`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("handblocks::Pose")]
pub struct Pose {
    pub position: [f64; 3],
    pub rotation: [f64; 4],
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        position: [0.0; 3],
        rotation: [0.0, 0.0, 0.0, 1.0],
    };

    /// True when every component is finite (no NaN or infinity).
    pub fn is_finite(&self) -> bool {
        self.position
            .iter()
            .chain(self.rotation.iter())
            .all(|v| v.is_finite())
    }
}

impl Default for Pose {
    fn default() -> Self {
        Pose::IDENTITY
    }
}

/// The farthest a hand's joint may be from the origin, metres: a room, generously. Farther is
/// a unit or frame mistake (millimetres given as metres), not a hand.
pub const MAX_JOINT_DISTANCE_M: f64 = 100.0;
/// The norms a joint's quaternion may have. The hand model normalises what it uses, so a
/// rotation is taken as given near 1; far from it (a zero-filled joint) it is no rotation.
pub const JOINT_ROTATION_NORMS: std::ops::RangeInclusive<f64> = 0.5..=2.0;

/// Why a pose is no joint of a hand ([`first_joint_fault`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JointFault {
    /// A position or rotation value is NaN or infinite.
    NonFinite,
    /// Farther than [`MAX_JOINT_DISTANCE_M`] from the origin.
    TooFar { metres: f64 },
    /// A quaternion whose norm is outside [`JOINT_ROTATION_NORMS`].
    NoRotation { norm: f64 },
}

impl Pose {
    /// Why this pose cannot be a hand's joint, if it cannot: the one check every source of
    /// `joints` makes (a headset's page, an external program, a replayed recording), so that
    /// no source lets through what another would refuse.
    pub fn joint_fault(&self) -> Option<JointFault> {
        if !self.is_finite() {
            return Some(JointFault::NonFinite);
        }
        let metres = self.position.iter().map(|v| v * v).sum::<f64>().sqrt();
        if metres > MAX_JOINT_DISTANCE_M {
            return Some(JointFault::TooFar { metres });
        }
        let norm = self.rotation.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !JOINT_ROTATION_NORMS.contains(&norm) {
            return Some(JointFault::NoRotation { norm });
        }
        None
    }
}

/// The first of `poses` that cannot be a hand's joint ([`Pose::joint_fault`]): its index
/// among them and why.
pub fn first_joint_fault<'a>(
    poses: impl IntoIterator<Item = &'a Pose>,
) -> Option<(usize, JointFault)> {
    poses
        .into_iter()
        .enumerate()
        .find_map(|(i, p)| p.joint_fault().map(|f| (i, f)))
}

/// `glove`: one reading of the data glove, calibrated to radians.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("handblocks::GloveSample")]
pub struct GloveSample {
    pub stamp: Stamp,
    /// 18 or 22 (CyberGlove models).
    pub sensor_count: u32,
    /// Which hand wears the glove ([`HandSide::code`]): 0 the right, 1 the left. A scene of
    /// two scripted hands sends a glove and a tracker for each (the right's first); a device
    /// glove, and a recording made before two hands, hold 0 here, the right.
    pub side: u32,
    /// Joint angles in radians, in the CyberGlove's sensor order.
    pub angles: [f64; MAX_GLOVE_SENSORS],
}

impl Default for GloveSample {
    fn default() -> Self {
        GloveSample {
            stamp: Stamp::default(),
            sensor_count: 22,
            side: 0,
            angles: [0.0; 22],
        }
    }
}

/// `tracker`: one wrist pose from the 6-DoF tracker, already in the world frame, metres.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("handblocks::TrackerSample")]
pub struct TrackerSample {
    pub stamp: Stamp,
    pub station: u32,
    /// Which hand the tracker is on ([`HandSide::code`]), as [`GloveSample::side`].
    pub side: u32,
    pub wrist: Pose,
}

/// `joints`: one hand from a hand tracker (e.g. OpenXR), 26 joints in OpenXR order.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("handblocks::JointsSample")]
pub struct JointsSample {
    pub stamp: Stamp,
    /// 1 when the hand is tracked; 0 when lost (the poses are then the last known ones).
    pub tracked: u32,
    /// Which hand ([`HandSide::code`]): 0 the right, 1 the left. A source of two hands sends
    /// both in every frame, the right first, with the same source time (a lost one marked
    /// `tracked = 0`); a recording made before two hands holds 0 here, the right.
    pub side: u32,
    pub wrist: Pose,
    pub joints: [Pose; OPENXR_JOINTS],
}

/// How long a hand tracker's hand that lost tracking keeps its grasp, in its source time: a
/// lost hand holds its last pose (and so whatever it holds) through a gap up to this long,
/// then lets go (it has no fingers or palm until it is tracked again). Tracking drops of tens
/// of milliseconds are common on headsets, and SDKs that drop a held object on a shorter loss
/// are a known complaint (MRTK #10391); 100 ms is still short enough that a hand that really
/// left does not seem to hold a block in mid-air.
pub const TRACKING_HOLD_NS: u64 = 100_000_000;

impl Default for JointsSample {
    fn default() -> Self {
        JointsSample {
            stamp: Stamp::default(),
            tracked: 0,
            side: 0,
            wrist: Pose::IDENTITY,
            joints: [Pose::IDENTITY; OPENXR_JOINTS],
        }
    }
}

/// Which of a person's hands a sample, a trace's track or a rule's count is about. A headset
/// tracks both; a glove and its tracker are one (the right, unless a session says otherwise).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum HandSide {
    Left,
    Right,
}

impl HandSide {
    pub const BOTH: [HandSide; 2] = [HandSide::Left, HandSide::Right];

    /// `"left"` or `"right"`: as events, reports and options name it.
    pub fn name(self) -> &'static str {
        match self {
            HandSide::Left => "left",
            HandSide::Right => "right",
        }
    }

    /// The side's code in a `joints` sample ([`JointsSample::side`]): 0 the right, 1 the left.
    pub fn code(self) -> u32 {
        match self {
            HandSide::Right => 0,
            HandSide::Left => 1,
        }
    }

    /// [`HandSide::code`]'s inverse: 1 is the left; anything else the right (a sample's side
    /// is outside input: an unknown code is read as the one hand a one-hand source has).
    pub fn from_code(code: u32) -> HandSide {
        if code == 1 {
            HandSide::Left
        } else {
            HandSide::Right
        }
    }

    /// `"left"` or `"right"` (any case); None for anything else.
    pub fn parse(text: &str) -> Option<HandSide> {
        match text.to_ascii_lowercase().as_str() {
            "left" => Some(HandSide::Left),
            "right" => Some(HandSide::Right),
            _ => None,
        }
    }
}

/// Which hands of a source drive a world: one of them (the other unused), or both (a headset
/// tracks two; docs/model.md "Two hands").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HandsUsed {
    One(HandSide),
    Both,
}

impl Default for HandsUsed {
    /// The right hand alone: a glove and its tracker are one hand, the right.
    fn default() -> Self {
        HandsUsed::One(HandSide::Right)
    }
}

impl HandsUsed {
    /// `"left"`, `"right"` or `"both"` (any case); None for anything else.
    pub fn parse(text: &str) -> Option<HandsUsed> {
        match text.to_ascii_lowercase().as_str() {
            "both" => Some(HandsUsed::Both),
            other => HandSide::parse(other).map(HandsUsed::One),
        }
    }

    /// `"left"`, `"right"` or `"both"`.
    pub fn name(self) -> &'static str {
        match self {
            HandsUsed::One(side) => side.name(),
            HandsUsed::Both => "both",
        }
    }
}

/// `hand`: the hand as the block world sees it (docs/model.md R1-R2): check points per finger
/// (knuckle to tip), finger radii, the palm polyhedron and the wrist pose, all in the world frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("handblocks::HandSample")]
pub struct HandSample {
    pub stamp: Stamp,
    pub wrist: Pose,
    /// 1 when the hand is tracked; 0 when lost (it then holds its last pose).
    pub tracked: u32,
    pub finger_count: u32,
    pub finger_point_count: [u32; MAX_FINGERS],
    /// 0 for a hand of bare check points (no palm).
    pub palm_vertex_count: u32,
    pub finger_points: [[[f64; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
    pub finger_radius: [f64; MAX_FINGERS],
    pub palm_vertices: [[f64; 3]; MAX_PALM_VERTICES],
    /// Which hand ([`HandSide::code`]): 0 the right (or a one-hand session's only hand), 1
    /// the left of a two-hand session (docs/model.md "Two hands"). Last, so that a hand
    /// recorded before it had this field reads as the right ([`HandSample::LEGACY_SIZE`]).
    pub side: u32,
    /// Whose hand, in a shared session (docs/sessions.md "Shared sessions"): the participant's
    /// number, 0 to [`MAX_PARTICIPANTS`] - 1, given by the host that orders the participants'
    /// hands; 0 in any other session (where it was padding, so a recording made before it
    /// reads as participant 0).
    pub participant: u32,
}

/// The most people one shared world holds: each brings up to two hands, so a world has
/// `2 * MAX_PARTICIPANTS` hand slots ([`HandSample::slot`]).
pub const MAX_PARTICIPANTS: usize = 4;

/// Hand slots of a world: each participant's right (or only) hand and left hand.
pub const HAND_SLOTS: usize = 2 * MAX_PARTICIPANTS;

/// `peer_hand`: another participant's hand in a shared world, as a participant's bridge took
/// it from the host (docs/sessions.md "Shared sessions"), for this machine's renderer and
/// recorder. A topic of its own, not `hand`: the `hand` topic on a participant's bus is its
/// own kinematics' stream, whose seqs every reader counts gaps in; a second publisher there
/// would break that count. `stamp` is this machine's (the bridge's seq; `origin_ns` when the
/// hand arrived here); `hand` is the other participant's hand as the host's frame held it
/// (its participant's number in the host's numbering, its side; its stamp the host's frame's).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Default)]
#[type_name("handblocks::PeerHandSample")]
pub struct PeerHandSample {
    pub stamp: Stamp,
    /// This machine's own participant number in the shared world (its own hands, on `hand`,
    /// are participant 0 on its own bus, whatever the host numbered them).
    pub own_participant: u32,
    pub _reserved: u32,
    pub hand: HandSample,
}

/// How far from the scene's origin a hand's check points and wrist may be, in x, y and z:
/// 1000 km. A scene lies within 100 km of its origin (the loader's range); a sample beyond
/// this is a device's or a file's garbage, and its coordinates (a joint at 1e20 m in a trace)
/// overflowed the broad phase's cell arithmetic and hung the step.
pub const HAND_RANGE_M: f64 = 1e6;

/// The thickest finger a sample may give (its colliders' radius under the precise model): a
/// metre, twenty times a hand model's largest (`config/hands`: up to 5 cm). Beyond it, or
/// negative, or NaN, the sample is garbage.
pub const MAX_FINGER_RADIUS_M: f64 = 1.0;

impl HandSample {
    /// The size of a `hand` sample before it had `side`: a recording made then holds hands of
    /// this size, which read as the right hand (the fields after it zero).
    pub const LEGACY_SIZE: usize = std::mem::offset_of!(HandSample, side);

    /// The world's hand slot of this hand: `2 * participant` for the right (or a one-hand
    /// source's only) hand, one more for the left; None for a participant number out of range
    /// (outside input: the stepper refuses such a hand and counts it).
    pub fn slot(&self) -> Option<usize> {
        let participant = usize::try_from(self.participant)
            .ok()
            .filter(|&p| p < MAX_PARTICIPANTS)?;
        Some(2 * participant + usize::from(HandSide::from_code(self.side) == HandSide::Left))
    }

    /// Why the models cannot use a hand sample (None: they can): counts out of range, a used value
    /// not finite (a device glitch), a point (check point, wrist, palm vertex) beyond
    /// [`HAND_RANGE_M`], or a finger radius outside 0..=[`MAX_FINGER_RADIUS_M`]. The stepper refuses
    /// such a sample where it enters, names the first and counts them; the hand holds its last
    /// good pose.
    pub fn unusable_because(&self) -> Option<&'static str> {
        let h = self;
        let far = |p: &[f64; 3]| p.iter().any(|c| c.abs() > HAND_RANGE_M);
        if h.finger_count as usize > MAX_FINGERS {
            return Some("more fingers than a hand sample holds");
        }
        if !h.wrist.is_finite() {
            return Some("its wrist pose is not finite");
        }
        if far(&h.wrist.position) {
            return Some("its wrist is farther than 1000 km from the origin");
        }
        for f in 0..h.finger_count as usize {
            let n = h.finger_point_count[f] as usize;
            if n > MAX_FINGER_POINTS {
                return Some("more points on a finger than a hand sample holds");
            }
            let points = &h.finger_points[f][..n];
            if !points.iter().flatten().all(|v| v.is_finite()) {
                return Some("a check point is not finite");
            }
            if points.iter().any(far) {
                return Some("a check point is farther than 1000 km from the origin");
            }
            let r = h.finger_radius[f];
            if !(0.0..=MAX_FINGER_RADIUS_M).contains(&r) {
                return Some("a finger's radius is not between 0 and 1 m");
            }
        }
        if h.palm_vertex_count as usize > MAX_PALM_VERTICES {
            return Some("more palm vertices than a hand sample holds");
        }
        let palm = &h.palm_vertices[..h.palm_vertex_count as usize];
        if !palm.iter().flatten().all(|v| v.is_finite()) {
            return Some("a palm vertex is not finite");
        }
        if palm.iter().any(far) {
            return Some("a palm vertex is farther than 1000 km from the origin");
        }
        None
    }
}

impl Default for HandSample {
    fn default() -> Self {
        HandSample {
            stamp: Stamp::default(),
            wrist: Pose::IDENTITY,
            tracked: 0,
            finger_count: 0,
            finger_point_count: [0; MAX_FINGERS],
            palm_vertex_count: 0,
            finger_points: [[[0.0; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
            finger_radius: [0.0; MAX_FINGERS],
            palm_vertices: [[0.0; 3]; MAX_PALM_VERTICES],
            side: 0,
            participant: 0,
        }
    }
}

impl HandSample {
    /// The check points of finger `f`, knuckle to tip: never more than the arrays hold, and
    /// none for a finger past them, whatever the counts say (a sample from outside may say
    /// anything; [`HandSample::check_counts`] refuses it where it comes in).
    pub fn finger(&self, f: usize) -> &[[f64; 3]] {
        match (self.finger_points.get(f), self.finger_point_count.get(f)) {
            (Some(points), Some(&n)) => &points[..(n as usize).min(MAX_FINGER_POINTS)],
            _ => &[],
        }
    }
    /// The palm polyhedron's vertices (empty for a bare check-point hand), never more than the
    /// array holds.
    pub fn palm(&self) -> &[[f64; 3]] {
        &self.palm_vertices[..(self.palm_vertex_count as usize).min(MAX_PALM_VERTICES)]
    }

    /// Every count field within the arrays it counts: the one check where outside bytes
    /// become a hand sample (the zenoh link, a recording read back, Python), so that nothing
    /// downstream indexes past an array on a sample a stranger wrote.
    pub fn check_counts(&self) -> Result<(), CountError> {
        check_finger_counts(self.finger_count, &self.finger_point_count)?;
        CountError::check(
            "palm_vertex_count",
            None,
            self.palm_vertex_count,
            MAX_PALM_VERTICES,
        )
    }
}

/// A count field of a sample that its array cannot hold (a sample from outside: the link, a
/// file). It names the field, so a peer's author knows what they wrote wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CountError {
    /// The field, as the layout names it (`finger_point_count`).
    pub field: &'static str,
    /// Which element of an array field (`finger_point_count[2]`).
    pub index: Option<usize>,
    pub value: i64,
    /// The most the field allows.
    pub max: i64,
}

impl CountError {
    fn check(
        field: &'static str,
        index: Option<usize>,
        value: u32,
        max: usize,
    ) -> Result<(), CountError> {
        if value as usize > max {
            return Err(CountError {
                field,
                index,
                value: i64::from(value),
                max: max as i64,
            });
        }
        Ok(())
    }
}

impl std::fmt::Display for CountError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.index {
            Some(i) => write!(f, "{}[{i}]", self.field)?,
            None => f.write_str(self.field)?,
        }
        write!(f, " is {}; at most {} fit", self.value, self.max)
    }
}

impl std::error::Error for CountError {}

/// A sample type whose count fields say how much of its arrays is used: every topic's sample
/// (the topic table requires it), so that each place where outside bytes become a sample (the
/// zenoh link, a recording read back, Python) checks them once, here, and a topic added later
/// cannot forget to. `slice_len` is the elements that came with a slice topic's header (the
/// blocks after a world header); a fixed-size sample ignores it.
pub trait Counted {
    fn check_counts(&self, slice_len: usize) -> Result<(), CountError>;
}

impl Counted for HandSample {
    fn check_counts(&self, _: usize) -> Result<(), CountError> {
        HandSample::check_counts(self)
    }
}

impl Counted for PeerHandSample {
    fn check_counts(&self, _: usize) -> Result<(), CountError> {
        self.hand.check_counts()
    }
}

impl Counted for WorldHeader {
    fn check_counts(&self, slice_len: usize) -> Result<(), CountError> {
        WorldHeader::check_counts(self, slice_len)
    }
}

impl Counted for GloveSample {
    fn check_counts(&self, _: usize) -> Result<(), CountError> {
        CountError::check("sensor_count", None, self.sensor_count, MAX_GLOVE_SENSORS)
    }
}

impl Counted for LatencySample {
    fn check_counts(&self, _: usize) -> Result<(), CountError> {
        for (i, h) in self.histograms.iter().enumerate() {
            if h.len as usize > HISTOGRAM_BYTES {
                return Err(CountError {
                    field: "histograms.len",
                    index: Some(i),
                    value: i64::from(h.len),
                    max: HISTOGRAM_BYTES as i64,
                });
            }
        }
        Ok(())
    }
}

/// Samples without count fields: any bit pattern of their size is one.
macro_rules! uncounted {
    ($($t:ty),*) => {$(
        impl Counted for $t {
            fn check_counts(&self, _: usize) -> Result<(), CountError> {
                Ok(())
            }
        }
    )*};
}
uncounted!(TrackerSample, JointsSample, FrameSample);

/// `finger_count` and each `finger_point_count[f]` within their arrays.
fn check_finger_counts(fingers: u32, points: &[u32; MAX_FINGERS]) -> Result<(), CountError> {
    CountError::check("finger_count", None, fingers, MAX_FINGERS)?;
    for (f, &n) in points.iter().enumerate() {
        CountError::check("finger_point_count", Some(f), n, MAX_FINGER_POINTS)?;
    }
    Ok(())
}

/// What a block is doing (docs/model.md, "Per block the stepper keeps ... a mode").
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BlockMode {
    #[default]
    Free = 0,
    Resting = 1,
    Tipping = 2,
    Pushed = 3,
    Grasped = 4,
    Carried = 5,
    Supported = 6,
}

impl BlockMode {
    pub const ALL: [BlockMode; 7] = [
        BlockMode::Free,
        BlockMode::Resting,
        BlockMode::Tipping,
        BlockMode::Pushed,
        BlockMode::Grasped,
        BlockMode::Carried,
        BlockMode::Supported,
    ];

    pub fn from_u32(v: u32) -> Option<BlockMode> {
        BlockMode::ALL.get(v as usize).copied()
    }

    pub const fn name(self) -> &'static str {
        match self {
            BlockMode::Free => "free",
            BlockMode::Resting => "resting",
            BlockMode::Tipping => "tipping",
            BlockMode::Pushed => "pushed",
            BlockMode::Grasped => "grasped",
            BlockMode::Carried => "carried",
            BlockMode::Supported => "supported",
        }
    }
}

/// One block in a world sample.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("handblocks::BlockState")]
pub struct BlockState {
    /// Centre of gravity and orientation.
    pub pose: Pose,
    /// A [`BlockMode`] as u32.
    pub mode: u32,
    /// The hands that grasp it: bit 0 the right hand (or a one-hand session's only hand), bit
    /// 1 the left (docs/model.md "Two hands"); 0 when it is not grasped (and in a recording
    /// made before two hands, where this was padding).
    pub held_by: u32,
}

impl BlockState {
    pub fn mode(&self) -> BlockMode {
        BlockMode::from_u32(self.mode).unwrap_or_default()
    }
}

/// `world`: the block world after the steps one hand sample brought (docs/model.md
/// conventions). On the bus this header travels as the sample's user header and the blocks as
/// its slice payload, one [`BlockState`] per block of the scene, so a sample is as large as its
/// scene needs (a 16-block scene sends 1.3 KiB, a 4096-block one 256 KiB) and every reader
/// reads the stepper's memory in place ([`WorldView`]).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("handblocks::WorldHeader")]
pub struct WorldHeader {
    pub stamp: Stamp,
    /// Fixed steps taken since the world began.
    pub step: u64,
    /// The `hand` sample this state answers (its seq).
    pub hand_seq: u64,
    /// Blocks that follow the header (the slice's length).
    pub block_count: u32,
    /// Index of the grasped block, or -1.
    pub grasped_block: i32,
    /// Check points as drawn: moved to the grasped block's surface where they ended inside it
    /// (docs/model.md R5), otherwise the hand's own. Same layout as the hand sample's.
    pub finger_count: u32,
    pub finger_point_count: [u32; MAX_FINGERS],
    pub finger_points: [[[f64; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
}

impl Default for WorldHeader {
    fn default() -> Self {
        WorldHeader {
            stamp: Stamp::default(),
            step: 0,
            hand_seq: 0,
            block_count: 0,
            grasped_block: -1,
            finger_count: 0,
            finger_point_count: [0; MAX_FINGERS],
            finger_points: [[[0.0; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
        }
    }
}

impl WorldHeader {
    /// The check points of drawn finger `f`, as [`HandSample::finger`] clamps them.
    pub fn finger(&self, f: usize) -> &[[f64; 3]] {
        match (self.finger_points.get(f), self.finger_point_count.get(f)) {
            (Some(points), Some(&n)) => &points[..(n as usize).min(MAX_FINGER_POINTS)],
            _ => &[],
        }
    }

    /// Every count field within what it counts (`block_count` within the scene's blocks,
    /// `grasped_block` -1 or one of them), as [`HandSample::check_counts`] for a world.
    pub fn check_counts(&self, blocks: usize) -> Result<(), CountError> {
        check_finger_counts(self.finger_count, &self.finger_point_count)?;
        CountError::check(
            "block_count",
            None,
            self.block_count,
            blocks.min(MAX_SCENE_BLOCKS),
        )?;
        if self.grasped_block < -1 || self.grasped_block >= self.block_count as i32 {
            return Err(CountError {
                field: "grasped_block",
                index: None,
                value: i64::from(self.grasped_block),
                max: i64::from(self.block_count) - 1,
            });
        }
        Ok(())
    }
}

/// A world sample read in place: the header and the blocks of a received sample (or of a
/// [`WorldSample`]). Nothing is copied to make one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldView<'a> {
    pub header: &'a WorldHeader,
    pub blocks: &'a [BlockState],
}

impl<'a> WorldView<'a> {
    /// The blocks the header counts (never more than the slice holds).
    pub fn blocks(&self) -> &'a [BlockState] {
        &self.blocks[..(self.header.block_count as usize).min(self.blocks.len())]
    }
}

impl std::ops::Deref for WorldView<'_> {
    type Target = WorldHeader;
    fn deref(&self) -> &WorldHeader {
        self.header
    }
}

/// A world sample held by value: the header and its blocks (what `simulate`, a recording read
/// back and the tests hold). The header's fields read through it (`world.step`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WorldSample {
    pub header: WorldHeader,
    pub blocks: Vec<BlockState>,
}

impl WorldSample {
    /// A sample of `n` default blocks, `block_count` set.
    pub fn with_blocks(n: usize) -> WorldSample {
        WorldSample {
            header: WorldHeader {
                block_count: n as u32,
                ..WorldHeader::default()
            },
            blocks: vec![BlockState::default(); n],
        }
    }

    /// The blocks the header counts.
    pub fn blocks(&self) -> &[BlockState] {
        self.view().blocks()
    }

    pub fn view(&self) -> WorldView<'_> {
        WorldView {
            header: &self.header,
            blocks: &self.blocks,
        }
    }
}

impl std::ops::Deref for WorldSample {
    type Target = WorldHeader;
    fn deref(&self) -> &WorldHeader {
        &self.header
    }
}

impl std::ops::DerefMut for WorldSample {
    fn deref_mut(&mut self) -> &mut WorldHeader {
        &mut self.header
    }
}

/// `frame`: statistics of one rendered frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("handblocks::FrameSample")]
pub struct FrameSample {
    pub stamp: Stamp,
    /// The world sample drawn (its seq).
    pub world_seq: u64,
    /// CPU + GPU time to produce the frame.
    pub render_ns: u64,
    /// Origin of the drawn data to the frame's GPU work complete.
    pub origin_to_photon_ns: u64,
    /// World samples that arrived since the last frame but were superseded by a newer one.
    pub skipped_worlds: u64,
}

/// Bytes one encoded latency histogram may take on the wire.
pub const HISTOGRAM_BYTES: usize = 16 * 1024;
/// Histograms per latency sample: hop, process, origin, photon.
pub const METRICS: usize = 5;
/// Topic counters per latency sample.
pub const MAX_TOPIC_COUNTERS: usize = 8;

/// One histogram, encoded with hdrhistogram's V2 format.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("handblocks::EncodedHistogram")]
pub struct EncodedHistogram {
    pub len: u32,
    pub _reserved: u32,
    pub bytes: [u8; HISTOGRAM_BYTES],
}

impl Default for EncodedHistogram {
    fn default() -> Self {
        EncodedHistogram {
            len: 0,
            _reserved: 0,
            bytes: [0; HISTOGRAM_BYTES],
        }
    }
}

/// What a stage counted on one topic: as publisher, samples sent; as subscriber, samples
/// received and sequence gaps (samples that never arrived).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("handblocks::TopicCounter")]
pub struct TopicCounter {
    /// A [`crate::Topic`] as u32; `u32::MAX` marks an unused slot.
    pub topic: u32,
    /// 0 = publisher, 1 = subscriber.
    pub role: u32,
    pub count: u64,
    pub gaps: u64,
    /// Last seq seen or sent (u64::MAX before the first).
    pub last_seq: u64,
}

/// What a device driver counted over a session (the acquisition process's final report
/// carries one per device; `device` 0 marks an empty slot).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("handblocks::DeviceCounters")]
pub struct DeviceCounters {
    /// A [`DeviceKind`]: 0: none, 1: the glove, 2: the tracker, 3: a headset's page (webxr: samples = hands
    /// frames published, rejected_records = messages refused, other_station_records = frames
    /// of a page that was not driving the hand, link_losses = sockets lost, reconnects = pages
    /// that drove the hand after the first, device_errors = tracking gaps longer than the hold),
    /// 4: an external source's program (samples = joints published, rejected_records = samples
    /// refused by the range checks or for their order).
    pub device: u32,
    pub _reserved: u32,
    /// Valid records turned into samples.
    pub samples: u64,
    /// Bytes skipped looking for the start of a record (noise, the rest of a cut record).
    pub garbage_bytes: u64,
    /// Record candidates refused: malformed, out of range or not finite.
    pub rejected_records: u64,
    /// Records of other tracker stations (skipped, not an error).
    pub other_station_records: u64,
    /// Times the link was lost (I/O error or silence).
    pub link_losses: u64,
    /// Reconnections after a loss.
    pub reconnects: u64,
    /// Error records the device sent (the CyberGlove's `e` replies).
    pub device_errors: u64,
}

/// The devices a stage counts, as [`DeviceCounters::device`] numbers them (0: an empty slot).
/// Which stage counts which is a column of the stage table ([`crate::Stage::devices`]).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DeviceKind {
    /// A CyberGlove on a serial port.
    Glove = 1,
    /// A FASTRAK on a serial port.
    Tracker = 2,
    /// A headset's page (the webxr stage).
    Headset = 3,
    /// An external source's program.
    External = 4,
}

impl DeviceKind {
    pub const ALL: [DeviceKind; 4] = [
        DeviceKind::Glove,
        DeviceKind::Tracker,
        DeviceKind::Headset,
        DeviceKind::External,
    ];

    /// The device's name for reports (and its refusals file's).
    pub const fn name(self) -> &'static str {
        match self {
            DeviceKind::Glove => "glove",
            DeviceKind::Tracker => "tracker",
            DeviceKind::Headset => "headset",
            DeviceKind::External => "external",
        }
    }

    /// True for a device whose stage writes its refusals by kind (a page's or a program's
    /// messages are refused for many reasons; a serial device's records for one).
    pub const fn writes_refusals_by_kind(self) -> bool {
        matches!(self, DeviceKind::Headset | DeviceKind::External)
    }

    pub fn from_u32(v: u32) -> Option<DeviceKind> {
        DeviceKind::ALL.into_iter().find(|d| *d as u32 == v)
    }

    /// Empty counters of this device, to count into.
    pub fn counters(self) -> DeviceCounters {
        DeviceCounters {
            device: self as u32,
            ..DeviceCounters::default()
        }
    }
}

impl DeviceCounters {
    /// The device, or `None` for an empty slot (or a number no version of ours wrote).
    pub fn kind(&self) -> Option<DeviceKind> {
        DeviceKind::from_u32(self.device)
    }

    /// The device's name for reports.
    pub fn name(&self) -> Option<&'static str> {
        self.kind().map(DeviceKind::name)
    }
}

/// `latency`: a stage's cumulative histograms and topic counters, published about once a
/// second and once more, marked final, when the stage stops.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("handblocks::LatencySample")]
pub struct LatencySample {
    pub stamp: Stamp,
    /// A [`crate::Stage`] as u32.
    pub stage: u32,
    /// 1 on the stage's last report.
    pub final_report: u32,
    /// A source only: the longest stretch without a sample it sent so far (from its start, and
    /// the current one included), ns.
    pub silence_ns: u64,
    /// When this process first published what it makes (CLOCK_MONOTONIC ns; 0: not yet): the
    /// launcher takes a restarted process's downtime up to it.
    pub first_output_ns: u64,
    /// When it last did (CLOCK_MONOTONIC ns; 0: not yet): with `first_output_ns`, the span in
    /// which it made anything, over which the launcher judges a rate (a viewer started before
    /// its session had no worlds to draw then).
    pub last_output_ns: u64,
    pub counters: [TopicCounter; MAX_TOPIC_COUNTERS],
    /// The acquisition process with devices only: what each driver counted (issue 16: the
    /// drivers counted rejected and garbage records, and no report showed them).
    pub devices: [DeviceCounters; 2],
    /// Indexed by [`crate::latency::Metric`].
    pub histograms: [EncodedHistogram; METRICS],
}

impl Default for LatencySample {
    fn default() -> Self {
        LatencySample {
            stamp: Stamp::default(),
            stage: 0,
            final_report: 0,
            silence_ns: 0,
            first_output_ns: 0,
            last_output_ns: 0,
            counters: [TopicCounter {
                topic: u32::MAX,
                ..Default::default()
            }; MAX_TOPIC_COUNTERS],
            devices: [DeviceCounters::default(); 2],
            histograms: [EncodedHistogram::default(); METRICS],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_joint_is_finite_within_a_room_and_a_rotation() {
        let at = |position, rotation| Pose { position, rotation };
        let q = [0.0, 0.0, 0.0, 1.0];
        assert_eq!(Pose::IDENTITY.joint_fault(), None);
        assert_eq!(
            at([99.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.9]).joint_fault(),
            None
        );
        assert_eq!(
            at([0.0, f64::NAN, 0.0], q).joint_fault(),
            Some(JointFault::NonFinite)
        );
        assert_eq!(
            at([0.0, 1e3, 0.0], q).joint_fault(),
            Some(JointFault::TooFar { metres: 1e3 })
        );
        assert_eq!(
            at([0.0; 3], [0.0; 4]).joint_fault(),
            Some(JointFault::NoRotation { norm: 0.0 })
        );
        let hand = [
            Pose::IDENTITY,
            at([0.0; 3], [0.0; 4]),
            at([1e3, 0.0, 0.0], q),
        ];
        assert_eq!(
            first_joint_fault(&hand),
            Some((1, JointFault::NoRotation { norm: 0.0 }))
        );
        assert_eq!(first_joint_fault(&hand[..1]), None);
    }

    /// Issue 40: a hand from the zenoh link with `finger_point_count[0] = 6` (or a palm of 17
    /// vertices) panicked `finger`/`palm` in every viewer. They clamp to the arrays now, and
    /// `check_counts` names the field where such a sample comes in.
    #[test]
    fn counts_past_the_arrays_are_clamped_and_named() {
        let mut h = HandSample {
            finger_count: 1,
            ..HandSample::default()
        };
        h.finger_point_count[0] = 6;
        h.palm_vertex_count = 17;
        assert_eq!(h.finger(0).len(), MAX_FINGER_POINTS);
        assert_eq!(h.finger(MAX_FINGERS + 3).len(), 0);
        assert_eq!(h.palm().len(), MAX_PALM_VERTICES);
        let e = h.check_counts().unwrap_err();
        assert_eq!(e.to_string(), "finger_point_count[0] is 6; at most 5 fit");
        h.finger_point_count[0] = 5;
        let e = h.check_counts().unwrap_err();
        assert_eq!(e.to_string(), "palm_vertex_count is 17; at most 16 fit");
        h.palm_vertex_count = 16;
        assert!(h.check_counts().is_ok());
        h.finger_count = u32::MAX;
        assert_eq!(h.check_counts().unwrap_err().field, "finger_count");
    }

    #[test]
    fn a_worlds_counts_are_checked_against_the_blocks_that_came_with_it() {
        let mut w = WorldSample::with_blocks(3);
        assert!(w.header.check_counts(3).is_ok());
        assert_eq!(w.header.check_counts(2).unwrap_err().field, "block_count");
        w.header.grasped_block = 3;
        assert_eq!(
            w.header.check_counts(3).unwrap_err().to_string(),
            "grasped_block is 3; at most 2 fit"
        );
        w.header.grasped_block = -2;
        assert_eq!(w.header.check_counts(3).unwrap_err().field, "grasped_block");
        w.header.grasped_block = 2;
        w.header.finger_point_count[4] = 9;
        assert_eq!(w.header.check_counts(3).unwrap_err().index, Some(4));
        assert_eq!(w.header.finger(4).len(), MAX_FINGER_POINTS);
    }

    #[test]
    fn a_glove_and_a_latency_sample_check_their_lengths() {
        let g = GloveSample {
            sensor_count: 23,
            ..GloveSample::default()
        };
        assert_eq!(
            Counted::check_counts(&g, 0).unwrap_err().field,
            "sensor_count"
        );
        let mut l = LatencySample::default();
        assert!(Counted::check_counts(&l, 0).is_ok());
        l.histograms[2].len = HISTOGRAM_BYTES as u32 + 1;
        assert_eq!(Counted::check_counts(&l, 0).unwrap_err().index, Some(2));
    }
}
