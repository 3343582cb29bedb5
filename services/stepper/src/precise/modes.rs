//! A mode per block, derived from the engine's state after each step, so that the `world`
//! sample, the renderer and `simulate --json` read the same as under the paper model:
//! - `grasped`: touched by the hand at two or more points whose outward contact normals are
//!   further apart than R3's grasp_angle (release_angle once grasped): the paper's own test,
//!   on the engine's contact normals instead of pseudo-normals;
//! - `pushed`: touched by the hand otherwise;
//! - `carried`: touching a grasped block, not the hand;
//! - `resting` / `supported`: touching the floor / only blocks, and still (below 5 mm/s and
//!   0.05 rad/s, or asleep);
//! - `tipping`: touching something and turning faster than that;
//! - `free`: anything else (in flight, or sliding).
//!
//! Events are the mode changes (as the paper model's), `release` when a grasp ends, and
//! `impact` when a block that touched nothing starts touching the floor or a block.
//!
//! A body that slept through a step is not looked at (`[precise] sleep`): asleep, it has no
//! velocity and its contacts are not updated, and whatever would change them wakes it first
//! (rapier wakes a sleeping body when a contact with it starts, when a collider touching it
//! moves, is switched off or removed; bodies in contact sleep and wake as one island), so its
//! mode, contacts and events stay what they were when it was last judged. A body is judged in
//! the step it falls asleep (its last contacts, `still` now that it sleeps) and again from the
//! step it wakes; the rest of a settled field costs nothing here.
//!
//! The contacts are read in one of two ways that give the same counts. While few blocks are
//! judged, each asks the narrow phase for its own pairs (a walk through the contact graph: a
//! chain of dependent cache misses per block). While most are, one pass over every contact
//! pair in storage order counts each block's touching points against the floor and whether it
//! touches a block or the hand (independent loads the processor overlaps: at 1024 falling
//! blocks the walks were ~0.8 ms of the wrapper's 1.5 ms a step). What depends on the order of
//! a block's own pairs (the hand's normals, kept up to 24, and the first block touched, which
//! `carried` reads) is taken from the block's own walk: for a block touching the hand, and for
//! one touching a block while some block may be grasped.

use common::BlockMode;
use glam::DVec3;

use super::{PreciseWorld, KIND_BLOCK, KIND_FLOOR, KIND_HAND, KIND_MASK, TOUCH_EPS};
use crate::world::EventKind;

const STILL_SPEED: f64 = 0.005;
const STILL_TURN: f64 = 0.05;
/// Hand contact normals kept per block for R3's angle (more add nothing to the largest angle
/// in practice; a hand model has at most 5 x 4 segments and a palm).
const MAX_HAND_NORMALS: usize = 24;

/// What a block touches after the step (its hand normals apart, in a scratch array: they are
/// read once, and a copy per block cost more than the reading).
#[derive(Clone, Copy)]
pub(super) struct Touches {
    floor_points: usize,
    blocks: bool,
    hand_count: usize,
    /// A touched block's index (the first one), for `carried`.
    first_block: Option<usize>,
}

/// One block's counts from the pass over every contact pair: touching points against the
/// floor, and whether it touches a block or the hand.
#[derive(Clone, Copy, Default)]
pub(super) struct Swept {
    floor_points: u32,
    block: bool,
    hand: bool,
}

impl PreciseWorld {
    /// Block `i`'s contacts from its own pairs, in the contact graph's order; the normals of
    /// its hand contacts into `normals` (the first `hand_count`).
    fn touches(&self, i: usize, normals: &mut [DVec3; MAX_HAND_NORMALS]) -> Touches {
        let me = self.blocks[i].collider;
        let mut t = Touches {
            floor_points: 0,
            blocks: false,
            hand_count: 0,
            first_block: None,
        };
        for pair in self.physics.narrow_phase.contact_pairs_with(me) {
            let other = if pair.collider1 == me {
                pair.collider2
            } else {
                pair.collider1
            };
            let Some(oc) = self.physics.colliders.get(other) else {
                continue;
            };
            if !oc.is_enabled() {
                continue;
            }
            let kind = oc.user_data & KIND_MASK;
            for m in pair.manifolds() {
                let touching = m.points.iter().filter(|p| p.dist <= TOUCH_EPS).count();
                if touching == 0 {
                    continue;
                }
                match kind {
                    KIND_FLOOR => t.floor_points += touching,
                    KIND_BLOCK => {
                        t.blocks = true;
                        if t.first_block.is_none() {
                            t.first_block = Some((oc.user_data & !KIND_MASK) as usize);
                        }
                    }
                    KIND_HAND => {
                        // The block's outward normal: the manifold's normal points from
                        // collider1 to collider2.
                        let n = if pair.collider1 == me {
                            m.data.normal
                        } else {
                            -m.data.normal
                        };
                        if t.hand_count < MAX_HAND_NORMALS && n.length_squared() > 0.5 {
                            normals[t.hand_count] = n;
                            t.hand_count += 1;
                        }
                    }
                    _ => {}
                }
            }
        }
        t
    }

    /// One pass over every contact pair: each block's [`Swept`] counts into `self.swept`.
    /// Returns whether any block touches the hand. The same pairs as the blocks' own walks
    /// (each pair is an edge of both its colliders), the same test per manifold; a pair's
    /// colliders are looked up only when one of its points touches.
    fn sweep_contacts(&mut self) -> bool {
        let n = self.blocks.len();
        let swept = &mut self.swept;
        swept.clear();
        swept.resize(n, Swept::default());
        let colliders = &self.physics.colliders;
        let mut any_hand = false;
        for pair in self.physics.narrow_phase.contact_pairs() {
            let touching = |m: &&rapier3d_f64::geometry::ContactManifold| {
                m.points.iter().filter(|p| p.dist <= TOUCH_EPS).count()
            };
            if pair.manifolds().iter().all(|m| touching(&m) == 0) {
                continue;
            }
            let (Some(c1), Some(c2)) =
                (colliders.get(pair.collider1), colliders.get(pair.collider2))
            else {
                continue;
            };
            for (me, other) in [(c1, c2), (c2, c1)] {
                if me.user_data & KIND_MASK != KIND_BLOCK || !other.is_enabled() {
                    continue;
                }
                let Some(e) = swept.get_mut((me.user_data & !KIND_MASK) as usize) else {
                    continue;
                };
                let points: usize = pair.manifolds().iter().map(|m| touching(&m)).sum();
                match other.user_data & KIND_MASK {
                    KIND_FLOOR => e.floor_points += points as u32,
                    KIND_BLOCK => e.block = true,
                    KIND_HAND => {
                        e.hand = true;
                        any_hand = true;
                    }
                    _ => {}
                }
            }
        }
        any_hand
    }

    /// The blocks to judge this step, in index order (events come out by block index): those
    /// awake after this step or the previous one. Without sleeping, every block.
    fn blocks_to_judge(&mut self, judge: &mut Vec<usize>) {
        let n = self.blocks.len();
        judge.clear();
        if !self.settings.sleep || self.judge_all {
            judge.extend(0..n);
            return;
        }
        let step = self.steps;
        let mut now = std::mem::take(&mut self.awake_now);
        now.clear();
        now.extend(
            self.physics
                .islands
                .active_bodies()
                .filter_map(|h| self.block_of_body.get(h.into_raw_parts().0 as usize))
                .filter(|&&i| (i as usize) < n)
                .map(|&i| i as usize),
        );
        for &i in now.iter().chain(&self.awake_before) {
            // judged_at marks the ones already listed (a block awake both times).
            if let Some(b) = self.blocks.get_mut(i) {
                if b.judged_at != step {
                    b.judged_at = step;
                    judge.push(i);
                }
            }
        }
        if judge.len() == n {
            judge.clear();
            judge.extend(0..n);
        } else {
            judge.sort_unstable();
        }
        self.awake_now = std::mem::replace(&mut self.awake_before, now);
    }

    /// Derives the mode of every block that may have changed (see the module documentation:
    /// not a body that slept through the step) and this step's events.
    pub(super) fn settle_modes(&mut self) {
        let step = self.steps;
        let mut judge = std::mem::take(&mut self.judge);
        self.blocks_to_judge(&mut judge);
        let mut touches = std::mem::take(&mut self.touches);
        let mut modes = std::mem::take(&mut self.modes);
        touches.clear();
        modes.clear();
        let n = self.blocks.len();
        // Most blocks judged: one pass over the pairs (see the module documentation).
        let swept = !self.judge_all && judge.len() * 2 >= n;
        // Carried needs a grasped block: one touching the hand now, or one asleep grasped.
        let grasp_possible = swept && (self.sweep_contacts() || self.grasped > 0);
        let mut normals = [DVec3::ZERO; MAX_HAND_NORMALS];
        // The block's own walk where the order of its pairs matters: the hand's normals, and
        // the first block touched while a block may be grasped.
        let own_walk = |e: &Swept| e.hand || (e.block && grasp_possible);
        for &i in &judge {
            let t = match self.swept.get(i).filter(|_| swept) {
                Some(e) if !own_walk(e) => Touches {
                    floor_points: e.floor_points as usize,
                    blocks: e.block,
                    hand_count: 0,
                    first_block: None,
                },
                _ => self.touches(i, &mut normals),
            };
            let before = self.blocks[i].mode;
            let threshold = if before == BlockMode::Grasped {
                self.release_angle
            } else {
                self.grasp_angle
            };
            let normals = &normals[..t.hand_count];
            let mut widest: f64 = 0.0;
            for (a, na) in normals.iter().enumerate() {
                for nb in &normals[a + 1..] {
                    widest = widest.max(na.angle_between(*nb));
                }
            }
            let mode = if t.hand_count >= 2 && widest > threshold {
                BlockMode::Grasped
            } else if t.hand_count >= 1 {
                BlockMode::Pushed
            } else if t.floor_points > 0 || t.blocks {
                let body = &self.physics.bodies[self.blocks[i].body];
                let still = body.is_sleeping()
                    || (body.linvel().length() < STILL_SPEED
                        && body.angvel().length() < STILL_TURN);
                if still {
                    if t.floor_points > 0 {
                        BlockMode::Resting
                    } else {
                        BlockMode::Supported
                    }
                } else if body.angvel().length() >= STILL_TURN {
                    BlockMode::Tipping
                } else {
                    BlockMode::Free
                }
            } else {
                BlockMode::Free
            };
            let b = &mut self.blocks[i];
            b.judged_at = step;
            b.judged = mode;
            touches.push(t);
            modes.push(mode);
        }
        // Carried: on a grasped block, and not held by the hand itself. A block not judged
        // this step keeps its mode, and grasped is never turned into carried.
        for k in 0..judge.len() {
            if matches!(modes[k], BlockMode::Grasped | BlockMode::Pushed) {
                continue;
            }
            if let Some(j) = touches[k].first_block {
                let grasped = self.blocks.get(j).is_some_and(|o| {
                    let m = if o.judged_at == step {
                        o.judged
                    } else {
                        o.mode
                    };
                    m == BlockMode::Grasped
                });
                if grasped && touches[k].floor_points == 0 {
                    modes[k] = BlockMode::Carried;
                }
            }
        }
        for (k, &i) in judge.iter().enumerate() {
            let before = self.blocks[i].mode;
            let now = modes[k];
            let touching = touches[k].floor_points > 0 || touches[k].blocks;
            if touching && !self.blocks[i].touching {
                self.emit(EventKind::Impact, i);
            }
            if before == BlockMode::Grasped && now != BlockMode::Grasped {
                self.emit(EventKind::Release, i);
                self.grasped = self.grasped.saturating_sub(1);
            }
            if before != BlockMode::Grasped && now == BlockMode::Grasped {
                self.grasped += 1;
            }
            if before != now {
                if let Some(k) = EventKind::on_entering(now) {
                    self.emit(k, i);
                }
            }
            let b = &mut self.blocks[i];
            b.mode = now;
            b.touching = touching;
            b.floor_contacts = touches[k].floor_points;
        }
        self.touches = touches;
        self.modes = modes;
        self.judge = judge;
    }
}
