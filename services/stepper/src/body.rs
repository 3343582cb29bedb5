//! One block's state: what docs/model.md "Conventions" says the stepper keeps per block (pose, v,
//! floor contact set, mode), plus the per-step scratch the rules pass between stages.

use std::sync::Arc;

use glam::{DQuat, DVec3};

use common::BlockMode;

use crate::block_set::BlockSet;
use crate::geometry::Polyhedron;
use crate::tracked::GripPath;

/// A set of vertex indices (a block has at most 256 hull vertices: the scene loader's limit).
/// A fixed bit set, so updating a contact set never allocates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct VertexSet([u64; 4]);

impl VertexSet {
    pub const EMPTY: VertexSet = VertexSet([0; 4]);

    #[inline]
    pub fn insert(&mut self, i: usize) {
        self.0[i / 64] |= 1 << (i % 64);
    }
    #[inline]
    pub fn contains(&self, i: usize) -> bool {
        self.0[i / 64] & (1 << (i % 64)) != 0
    }
    pub fn is_empty(&self) -> bool {
        self.0 == [0; 4]
    }
    pub fn len(&self) -> usize {
        self.0.iter().map(|w| w.count_ones() as usize).sum()
    }
    /// True when some member of `self` is not in `other`.
    pub fn has_new_vs(&self, other: &VertexSet) -> bool {
        self.0.iter().zip(other.0.iter()).any(|(a, b)| a & !b != 0)
    }
    pub fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        (0..256).filter(move |&i| self.contains(i))
    }
}

/// How the block moved in this step (docs/model.md "Order of one step").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Moved {
    #[default]
    No,
    /// R4, R5 or R6 moved it.
    Hand,
    /// R10 translated it with a hand-moved block.
    Carried,
    /// R7 moved it (after R12).
    Free,
    /// R9 rotated it (set in the floor stage).
    Tipped,
    /// R14 turned it: it tipped over its supporters, or rode on a tipping block as its load.
    /// The floor stage applies only R8 to it (R14 already was its R9).
    Stacked,
}

/// What the hand does to a block this step (R3's verdict, applied in stage 2).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum HandAction {
    #[default]
    None,
    /// R4: one contact at C (relative to G, world orientation), check point now at B.
    Push { c: DVec3, b: DVec3 },
    /// R6: translate by the mean T of the non-leaving contacts.
    Translate(DVec3),
    /// R5.
    Grasp,
}

/// A block of the world, laid out by what a step reads of it. A rain of 4096 blocks is ~2 MB
/// of blocks, past the L2 cache, so each line of a block that a step reads is fetched from
/// memory, once a pass: the fields every pass reads share the first line, the box and the
/// flags that stand in for colder fields the second, and a block that falls through the air
/// has its whole step in free motion's pass (`World::step`), reading and writing those two
/// lines only (callgrind's cache simulation of the rain: 2.76M -> 1.32M last-level read
/// misses over 120 steps with the last two of these, `README`'s stepper memory paragraph).
/// `repr(C)` keeps the order written; `align(64)` starts every block on a line.
#[derive(Debug, Clone)]
#[repr(C, align(64))]
pub struct Block {
    // ---- line 0: every pass ----
    /// Position of G. Private: it changes only through the methods that keep the step's
    /// start (`translate`, `rotate_about`, `lift`, `set_position`, and free motion's
    /// `translate_unrecorded`), so that the start is written only when a block moves.
    pos: DVec3,
    /// The inertia v: G's displacement per step (docs/model.md "Conventions").
    pub v: DVec3,
    /// Shared by every block of the same shape (`World::new`): a field of 4096 equal cubes
    /// holds one hull, which stays in the cache, instead of 4096 copies of it (~1 KB each
    /// with parry's) that a step's queries fetched from memory one block at a time.
    pub poly: Arc<Polyhedron>,
    pub mode: BlockMode,
    pub moved: Moved,
    /// Set when R3 ends a grasp this step (R13).
    pub released: bool,
    /// R14 decided this block this step (held or tipped): stages 3 and 4 leave it alone.
    pub judged: bool,
    /// Its pose or mode changed in the previous step (or the hand moved it this step): R14
    /// judges again the resting and supported blocks it touches ("a block whose supporter
    /// moved is judged again in the next step").
    pub stirred: bool,

    // ---- line 1: the box (read by every query that meets this block), stage 6's flags ----
    /// The box of `rel` (world axes, relative to G): the broad phase's exact "cannot meet"
    /// test before a GJK query (`interference::boxes_apart`).
    pub rel_lo: DVec3,
    pub rel_hi: DVec3,
    pub mode_before: BlockMode,
    /// Whether `rel_lo` and `rel_hi` bound the block: false only when the rotation holds a NaN
    /// (its rotated vertices bound nothing), and then the stages that read the box take their
    /// slow, exact path instead.
    pub box_exact: bool,
    /// Whether `action` is not `HandAction::None`: stage 0 and stage 6 read this flag, not the
    /// action (on a later line), which only the hand's stages need.
    acted: bool,
    /// Whether the rotation changed this step: `start_rot` holds the one it started with.
    /// Stage 0 clears it rather than copying the rotation, and stage 6 compares rotations only
    /// when it is set.
    turned: bool,
    /// Whether `floor` holds a vertex: free motion and the floor stage read this, and a block
    /// in the air never has its contact set's line fetched.
    on_floor: bool,
    /// Whether free motion kept R7's d in `intended` this step: only when R12 cut it or R14
    /// slid it. Otherwise d is the displacement it took (v with inertia, g_step without), and
    /// the floor stage works it out from those (`Block::free_d`) without the line 3 write.
    pub intended_kept: bool,
    /// Whether `start_pos` holds where the block started this step: set by the first move of
    /// the step (stage 0 clears it rather than copying the position, as for `turned`).
    shifted: bool,

    // ---- line 2: the start of a block that moved, the rotation ----
    // A falling block's step does not read this line: free motion tells stage 6 where the
    // block started (`translate_unrecorded`), and stage 6 publishes the rotation only when it
    // changed (`rotated`).
    /// Where G was at the step's start; meaningful while `shifted` is set.
    start_pos: DVec3,
    /// Unit quaternion, body to world. Private: it changes only through
    /// [`Block::set_rotation`] (and [`Block::rotate_about`]), which rotate `rel` and its box
    /// with it, so `rel`, `rel_lo` and `rel_hi` are always those of this rotation and no stage
    /// has to check (the check read two quaternions a block in every pass that used the box).
    rot: DQuat,
    /// (Fills line 2: read by R13's grasps only.)
    pub grasp_history_next: usize,

    // ---- line 3: the floor stage's contact set, and R7's d ----
    /// Floor contact vertices after the last step (R8). Private: written with
    /// [`Block::set_floor`], which keeps `on_floor`.
    floor: VertexSet,
    /// R7's d before R12 cut it (R9's Gm on the landing step), when `intended_kept`.
    /// Meaningful only in a step that free motion moved the block (`Moved::Free`), which
    /// writes it: stage 0 leaves it.
    pub intended: DVec3,

    // ---- read by some steps only ----
    /// The rotation at the step's start; meaningful while `turned` is set.
    start_rot: DQuat,
    /// Vertices in world orientation relative to G, for `rot`.
    pub rel: Vec<DVec3>,
    action: HandAction,
    pub name: String,
    /// R14: the blocks this block tipped over as the root of a tipping load (bit j: block j),
    /// kept while it still rests on them. Its weight rests on their edge, not on them as a
    /// load: they do not count it in their G_L.
    pub tipped_over: BlockSet,
    /// R13: the last `throw_window` grasped displacements (ring buffer) and how many are valid.
    pub grasp_history: Vec<DVec3>,
    pub grasp_history_len: usize,
    /// T3 (tracked hands only): G along the current grasp, for the fitted throw. Empty (no
    /// memory) under the paper's rules; sized by `World::new`.
    pub grip: GripPath,
    /// The hands that grasp it (bit k: hand slot k, `crate::HAND_SLOTS`); 0 unless grasped.
    /// A one-hand world's grasp is always slot 0's.
    pub held_by: u8,
    /// In a two-hand world, the hands acting on it this step (stage 1, for the events that
    /// name them); 0 otherwise.
    pub acting_hands: u8,
    /// The hands that held it when R13 let it go (its release event names them).
    pub released_by: u8,
}

impl Block {
    pub fn new(
        name: String,
        poly: impl Into<Arc<Polyhedron>>,
        pos: DVec3,
        rot: DQuat,
        v: DVec3,
        window: usize,
    ) -> Block {
        let poly = poly.into();
        let n = poly.vertices.len();
        let mut b = Block {
            name,
            poly,
            pos,
            rot,
            v,
            mode: BlockMode::Free,
            floor: VertexSet::EMPTY,
            rel: Vec::with_capacity(n),
            rel_lo: DVec3::ZERO,
            box_exact: false,
            rel_hi: DVec3::ZERO,
            start_pos: pos,
            start_rot: rot,
            mode_before: BlockMode::Free,
            moved: Moved::No,
            intended: DVec3::ZERO,
            action: HandAction::None,
            acted: false,
            turned: false,
            on_floor: false,
            intended_kept: false,
            shifted: false,
            released: false,
            judged: false,
            stirred: true,
            // Sized for its world by `World::new` (an empty set holds no index).
            tipped_over: BlockSet::default(),
            grasp_history: vec![DVec3::ZERO; window.max(1)],
            grasp_history_len: 0,
            grasp_history_next: 0,
            grip: GripPath::default(),
            held_by: 0,
            acting_hands: 0,
            released_by: 0,
        };
        b.rotate_rel();
        b
    }

    /// Whether hand slot `slot` grasps it.
    #[inline]
    pub fn grasped_by(&self, slot: usize) -> bool {
        self.mode == BlockMode::Grasped && self.held_by & (1 << slot) != 0
    }

    /// The rotation, body to world.
    #[inline]
    pub fn rot(&self) -> DQuat {
        self.rot
    }

    /// The position of G.
    #[inline]
    pub fn pos(&self) -> DVec3 {
        self.pos
    }

    /// Where G was at the step's start.
    #[inline]
    pub fn start_pos(&self) -> DVec3 {
        if self.shifted {
            self.start_pos
        } else {
            self.pos
        }
    }

    /// Every move of G goes through here first: the step's first keeps where it started.
    #[inline]
    fn keep_start(&mut self) {
        if !self.shifted {
            self.start_pos = self.pos;
            self.shifted = true;
        }
    }

    /// Whether G is not where it started the step (stage 6's "moved": R14 judges again what
    /// touches it). A position holding a NaN never equals itself, as when this compared the
    /// position with a copy taken at the step's start.
    #[inline]
    pub fn shifted_this_step(&self) -> bool {
        if self.shifted {
            self.pos != self.start_pos
        } else {
            self.pos.is_nan()
        }
    }

    /// Whether the rotation was set this step (it may be the one it started with): stage 6
    /// publishes it only then.
    #[inline]
    pub fn rotated(&self) -> bool {
        self.turned
    }

    /// Puts G at `pos` (rotation unchanged).
    #[inline]
    pub fn set_position(&mut self, pos: DVec3) {
        self.keep_start();
        self.pos = pos;
    }

    /// Raises G by `dy` (R8's lift).
    #[inline]
    pub fn lift(&mut self, dy: f64) {
        self.keep_start();
        self.pos.y += dy;
    }

    /// Free motion's move of G by `d`, without keeping the start: returns where the block
    /// started the step, and the caller either ends the block's step with it (stage 6 is told
    /// it: a block free motion leaves flying, `World::step`) or hands it to
    /// [`Block::record_start`] before anything else reads or moves the block. So a falling
    /// block's step never writes the line the start is on.
    #[inline]
    pub fn translate_unrecorded(&mut self, d: DVec3) -> DVec3 {
        let start = self.start_pos();
        self.pos += d;
        start
    }

    /// Keeps `start`, from [`Block::translate_unrecorded`], as where the block started.
    #[inline]
    pub fn record_start(&mut self, start: DVec3) {
        if !self.shifted {
            self.start_pos = start;
            self.shifted = true;
        }
    }

    /// Turns the block to `rot` (a unit quaternion), its rotated vertices and their box with it.
    pub fn set_rotation(&mut self, rot: DQuat) {
        if !self.turned {
            self.start_rot = self.rot;
            self.turned = true;
        }
        // An equal rotation (a zero's sign aside) has `rel` already: the same bits.
        let same = rot == self.rot;
        self.rot = rot;
        if !same {
            self.rotate_rel();
        }
    }

    /// Whether the rotation is not the one the step started with (stage 6's "turned": R14
    /// judges again what touches it). A rotation holding a NaN never equals itself, as when
    /// this compared the rotation with a copy taken at the step's start.
    #[inline]
    pub fn turned_this_step(&self) -> bool {
        if self.turned {
            self.rot != self.start_rot
        } else {
            !self.box_exact
        }
    }

    /// R7's d of this step, for a block free motion moved (`Moved::Free`): kept when R12 cut
    /// it or R14 slid it, else the displacement taken, which is d bit for bit (`inertia` and
    /// `g_step`: the scene's, as free motion used them).
    #[inline]
    pub fn free_d(&self, inertia: bool, g_step: DVec3) -> DVec3 {
        if self.intended_kept {
            self.intended
        } else if inertia {
            self.v
        } else {
            DVec3::ZERO + g_step
        }
    }

    /// Floor contact vertices after the last step (R8).
    #[inline]
    pub fn floor(&self) -> &VertexSet {
        &self.floor
    }

    /// Whether a vertex is in floor contact (`floor()` is not empty), read off line 1.
    #[inline]
    pub fn on_floor(&self) -> bool {
        self.on_floor
    }

    /// The floor stage's contact set (R8).
    #[inline]
    pub fn set_floor(&mut self, set: VertexSet) {
        self.on_floor = !set.is_empty();
        self.floor = set;
    }

    /// The hand's action on the block this step (stage 1's decision).
    #[inline]
    pub fn action(&self) -> HandAction {
        self.action
    }

    /// Whether the hand acts on it this step (`action()` is not `None`), read off line 1.
    #[inline]
    pub fn acted(&self) -> bool {
        self.acted
    }

    /// Stage 1 decided the hand's action on it.
    #[inline]
    pub fn set_action(&mut self, action: HandAction) {
        self.acted = action != HandAction::None;
        self.action = action;
    }

    /// Stage 0: the block starts the step where it is, with nothing done to it yet. Done by the
    /// last step's stage 6 in its pass (and by `World::new` before the first step), not by a
    /// pass of its own: a pass over the active set is a pass over memory (in a rain of 4096
    /// blocks, ~27,000 cache misses a step, callgrind). Writes lines 0 and 1 only: the action
    /// only when there was one; the start position and rotation not at all (`shifted` and
    /// `turned` say they are the ones now); `intended` not at all (free motion writes it
    /// before anything reads it).
    #[inline]
    pub fn begin_step(&mut self) {
        self.shifted = false;
        self.turned = false;
        self.mode_before = self.mode;
        self.moved = Moved::No;
        if self.acted {
            self.set_action(HandAction::None);
        }
        self.released = false;
    }

    /// `rel` and its box for the current rotation.
    fn rotate_rel(&mut self) {
        crate::geometry::rotate_vertices(&self.poly, self.rot, &mut self.rel);
        let (lo, hi) = self.rel.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), v| (lo.min(*v), hi.max(*v)),
        );
        (self.rel_lo, self.rel_hi) = (lo, hi);
        self.box_exact = !self.rot.is_nan();
    }

    /// The lowest vertex's height above the floor, relative to G (min of rel.y).
    pub fn lowest_rel_y(&self) -> f64 {
        self.rel.iter().fold(f64::INFINITY, |m, v| m.min(v.y))
    }

    /// Records one grasped step's displacement (R13's throw window).
    pub fn push_grasp_displacement(&mut self, d: DVec3) {
        let k = self.grasp_history.len();
        self.grasp_history[self.grasp_history_next] = d;
        self.grasp_history_next = (self.grasp_history_next + 1) % k;
        self.grasp_history_len = (self.grasp_history_len + 1).min(k);
    }

    /// R13: the mean displacement over the last grasped steps (the last one when k = 1).
    pub fn throw_displacement(&self) -> DVec3 {
        if self.grasp_history_len == 0 {
            return DVec3::ZERO;
        }
        let k = self.grasp_history.len();
        let mut sum = DVec3::ZERO;
        for j in 0..self.grasp_history_len {
            sum += self.grasp_history[(self.grasp_history_next + k - 1 - j) % k];
        }
        sum / self.grasp_history_len as f64
    }

    /// Translates the block (rotation unchanged).
    #[inline]
    pub fn translate(&mut self, d: DVec3) {
        self.keep_start();
        self.pos += d;
    }

    /// Rotates the block by `q` about the point G + `pivot_rel` (world orientation).
    pub fn rotate_about(&mut self, q: DQuat, pivot_rel: DVec3) {
        // G' = C + q (G - C), with C = G + pivot_rel: G' - G = pivot_rel - q pivot_rel.
        self.keep_start();
        self.pos += pivot_rel - q * pivot_rel;
        self.set_rotation((q * self.rot).normalize());
    }
}

#[cfg(test)]
mod tests {
    use std::mem::{align_of, offset_of, size_of};

    use super::*;

    /// The cache lines of a block are what `Block`'s comment says they are: a falling block's
    /// step reads lines 0 and 1 in every pass, 2 in stage 6, 3 where free motion writes R7's
    /// d; everything else lies after them. A field added in the wrong place fails here, not as a
    /// slower rain nobody measures.
    #[test]
    fn the_fields_every_pass_reads_share_the_first_cache_lines() {
        assert_eq!(align_of::<Block>(), 64);
        let line = |offset: usize, size: usize| {
            let first = offset / 64;
            assert_eq!(
                first,
                (offset + size - 1) / 64,
                "a field straddles two lines"
            );
            first
        };
        macro_rules! line_of {
            ($field:ident, $t:ty) => {
                line(offset_of!(Block, $field), size_of::<$t>())
            };
        }
        for l in [
            line_of!(pos, DVec3),
            line_of!(v, DVec3),
            line_of!(poly, Arc<Polyhedron>),
            line_of!(mode, BlockMode),
            line_of!(moved, Moved),
            line_of!(released, bool),
            line_of!(judged, bool),
            line_of!(stirred, bool),
        ] {
            assert_eq!(l, 0);
        }
        for l in [
            line_of!(rel_lo, DVec3),
            line_of!(rel_hi, DVec3),
            line_of!(mode_before, BlockMode),
            line_of!(box_exact, bool),
            line_of!(acted, bool),
            line_of!(turned, bool),
            line_of!(on_floor, bool),
            line_of!(intended_kept, bool),
            line_of!(shifted, bool),
        ] {
            assert_eq!(l, 1);
        }
        assert_eq!(line_of!(start_pos, DVec3), 2);
        assert_eq!(line_of!(rot, DQuat), 2);
        assert_eq!(line_of!(floor, VertexSet), 3);
        assert_eq!(line_of!(intended, DVec3), 3);
        for cold in [
            offset_of!(Block, start_rot),
            offset_of!(Block, rel),
            offset_of!(Block, action),
            offset_of!(Block, name),
            offset_of!(Block, tipped_over),
            offset_of!(Block, grasp_history),
        ] {
            assert!(
                cold >= offset_of!(Block, intended) + size_of::<DVec3>(),
                "a field read by some steps only among the hot ones"
            );
        }
    }

    /// The flags that stand in for their fields agree with them through every writer:
    /// `on_floor` with the contact set, `acted` with the action, `turned_this_step` with a
    /// comparison of the rotation against the step's start (NaN included).
    #[test]
    fn the_flags_agree_with_what_they_stand_for() {
        let poly =
            Polyhedron::from_spec(&common::config::scene::ShapeSpec::Box { size: [0.04; 3] })
                .unwrap();
        let mut b = Block::new(
            String::new(),
            poly,
            DVec3::ONE,
            DQuat::IDENTITY,
            DVec3::ZERO,
            1,
        );
        b.begin_step();
        assert!(!b.on_floor() && !b.acted() && !b.turned_this_step());
        let mut set = VertexSet::EMPTY;
        set.insert(3);
        b.set_floor(set);
        assert!(b.on_floor());
        b.set_floor(VertexSet::EMPTY);
        assert!(!b.on_floor());
        b.set_action(HandAction::Grasp);
        assert!(b.acted() && b.action() == HandAction::Grasp);
        b.begin_step();
        assert!(!b.acted() && b.action() == HandAction::None);
        // Turned and back: the same rotation as at the start, not turned.
        let q = DQuat::from_rotation_y(0.3);
        b.set_rotation(q);
        assert!(b.turned_this_step());
        b.set_rotation(DQuat::IDENTITY);
        assert!(!b.turned_this_step());
        b.set_rotation(q);
        b.begin_step();
        assert!(!b.turned_this_step() && b.rot() == q);
        // The box follows the rotation.
        let (lo, hi) = (b.rel_lo, b.rel_hi);
        b.set_rotation(DQuat::IDENTITY);
        assert!(b.rel_lo != lo || b.rel_hi != hi);
        assert!((b.rel_hi - DVec3::splat(0.02)).length() < 1e-12);
        // A rotation holding a NaN never equals itself: turned every step, no exact box.
        b.set_rotation(DQuat::from_xyzw(f64::NAN, 0.0, 0.0, 1.0));
        b.begin_step();
        assert!(b.turned_this_step() && !b.box_exact);
    }

    /// `shifted_this_step` agrees with comparing the position against a copy taken at the
    /// step's start, through every writer (a move and back, a zero move, NaN), and the start
    /// free motion hands over (`translate_unrecorded`) is that copy, recorded or not.
    #[test]
    fn the_start_position_is_the_one_the_step_began_with() {
        let poly =
            Polyhedron::from_spec(&common::config::scene::ShapeSpec::Box { size: [0.04; 3] })
                .unwrap();
        let start = DVec3::new(1.0, 0.5, -2.0);
        let mut b = Block::new(String::new(), poly, start, DQuat::IDENTITY, DVec3::ZERO, 1);
        b.begin_step();
        assert!(!b.shifted_this_step() && b.start_pos() == start);
        b.translate(DVec3::ZERO);
        assert!(!b.shifted_this_step());
        b.translate(DVec3::X);
        b.lift(0.25);
        assert!(b.shifted_this_step() && b.start_pos() == start);
        b.set_position(start);
        assert!(!b.shifted_this_step(), "moved and back: where it started");
        b.rotate_about(DQuat::from_rotation_y(0.5), DVec3::X);
        assert!(b.shifted_this_step() && b.start_pos() == start);
        let now = b.pos();
        b.begin_step();
        assert!(!b.shifted_this_step() && b.start_pos() == now);
        // Free motion's move: the start handed over, then recorded (or not, the step ending).
        let from = b.translate_unrecorded(DVec3::Y);
        assert_eq!(from, now);
        b.record_start(from);
        assert!(b.shifted_this_step() && b.start_pos() == now);
        b.translate(DVec3::Z);
        assert_eq!(
            b.translate_unrecorded(DVec3::Y),
            now,
            "an earlier move kept the start"
        );
        // A position holding a NaN never equals itself: shifted every step.
        b.set_position(DVec3::new(f64::NAN, 0.0, 0.0));
        b.begin_step();
        assert!(b.shifted_this_step());
    }
}
