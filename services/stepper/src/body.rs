//! One block's state: what docs/model.md "Conventions" says the stepper keeps per block (pose, v,
//! floor contact set, mode), plus the per-step scratch the rules pass between stages.

use std::sync::Arc;

use glam::{DQuat, DVec3};

use common::BlockMode;

use crate::block_set::BlockSet;
use crate::geometry::Polyhedron;

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

/// A block of the world: first what a step's passes read of every active block, then what only
/// some steps read.
#[derive(Debug, Clone)]
pub struct Block {
    /// Position of G.
    pub pos: DVec3,
    /// The box of `rel` (world axes, relative to G): the broad phase's exact "cannot meet"
    /// test before a GJK query (`interference::boxes_apart`).
    pub rel_lo: DVec3,
    pub rel_hi: DVec3,
    /// Unit quaternion, body to world.
    pub rot: DQuat,
    /// The rotation `rel` was computed for.
    pub rel_rot: DQuat,
    /// The inertia v: G's displacement per step (docs/model.md "Conventions").
    pub v: DVec3,
    pub mode: BlockMode,
    pub mode_before: BlockMode,
    pub moved: Moved,
    /// Set when R3 ends a grasp this step (R13).
    pub released: bool,
    /// R14 decided this block this step (held or tipped): stages 3 and 4 leave it alone.
    pub judged: bool,
    /// Its pose or mode changed in the previous step (or the hand moved it this step): R14
    /// judges again the resting and supported blocks it touches ("a block whose supporter
    /// moved is judged again in the next step").
    pub stirred: bool,
    /// Floor contact vertices after the last step (R8).
    pub floor: VertexSet,
    pub start_pos: DVec3,
    pub start_rot: DQuat,
    /// R7's d before R12 cut it (R9's Gm on the landing step).
    pub intended: DVec3,
    /// Shared by every block of the same shape (`World::new`): a field of 4096 equal cubes
    /// holds one hull, which stays in the cache, instead of 4096 copies of it (~1 KB each
    /// with parry's) that a step's queries fetched from memory one block at a time.
    pub poly: Arc<Polyhedron>,
    /// Vertices in world orientation relative to G, for `rel_rot`.
    pub rel: Vec<DVec3>,
    pub action: HandAction,

    // ---- read by some steps only ----
    pub name: String,
    /// R14: the blocks this block tipped over as the root of a tipping load (bit j: block j),
    /// kept while it still rests on them. Its weight rests on their edge, not on them as a
    /// load: they do not count it in their G_L.
    pub tipped_over: BlockSet,
    /// R13: the last `throw_window` grasped displacements (ring buffer) and how many are valid.
    pub grasp_history: Vec<DVec3>,
    pub grasp_history_len: usize,
    pub grasp_history_next: usize,
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
            rel_rot: DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
            rel_lo: DVec3::ZERO,
            rel_hi: DVec3::ZERO,
            start_pos: pos,
            start_rot: rot,
            mode_before: BlockMode::Free,
            moved: Moved::No,
            intended: DVec3::ZERO,
            action: HandAction::None,
            released: false,
            judged: false,
            stirred: true,
            // Sized for its world by `World::new` (an empty set holds no index).
            tipped_over: BlockSet::default(),
            grasp_history: vec![DVec3::ZERO; window.max(1)],
            grasp_history_len: 0,
            grasp_history_next: 0,
        };
        b.refresh_rel();
        b
    }

    /// Recomputes the rotated vertices if the rotation changed since the last call.
    pub fn refresh_rel(&mut self) {
        if self.rel_rot != self.rot || self.rel.len() != self.poly.vertices.len() {
            crate::geometry::rotate_vertices(&self.poly, self.rot, &mut self.rel);
            self.rel_rot = self.rot;
            let (lo, hi) = self.rel.iter().fold(
                (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), v| (lo.min(*v), hi.max(*v)),
            );
            (self.rel_lo, self.rel_hi) = (lo, hi);
        }
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
        self.pos += d;
    }

    /// Rotates the block by `q` about the point G + `pivot_rel` (world orientation).
    pub fn rotate_about(&mut self, q: DQuat, pivot_rel: DVec3) {
        // G' = C + q (G - C), with C = G + pivot_rel: G' - G = pivot_rel - q pivot_rel.
        self.pos += pivot_rel - q * pivot_rel;
        self.rot = (q * self.rot).normalize();
        self.refresh_rel();
    }
}
