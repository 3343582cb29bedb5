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

use common::BlockMode;
use glam::DVec3;

use super::{PreciseWorld, KIND_BLOCK, KIND_FLOOR, KIND_HAND, KIND_MASK, TOUCH_EPS};
use crate::world::EventKind;

const STILL_SPEED: f64 = 0.005;
const STILL_TURN: f64 = 0.05;
/// Hand contact normals kept per block for R3's angle (more add nothing to the largest angle
/// in practice; a hand model has at most 5 x 4 segments and a palm).
const MAX_HAND_NORMALS: usize = 24;

#[derive(Clone, Copy)]
pub(super) struct Touches {
    floor_points: usize,
    blocks: bool,
    hand_normals: [DVec3; MAX_HAND_NORMALS],
    hand_count: usize,
    /// A touched block's index (the first one), for `carried`.
    first_block: Option<usize>,
}

impl PreciseWorld {
    fn touches(&self, i: usize) -> Touches {
        let me = self.blocks[i].collider;
        let mut t = Touches {
            floor_points: 0,
            blocks: false,
            hand_normals: [DVec3::ZERO; MAX_HAND_NORMALS],
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
                            t.hand_normals[t.hand_count] = n;
                            t.hand_count += 1;
                        }
                    }
                    _ => {}
                }
            }
        }
        t
    }

    /// Derives every block's mode and this step's events.
    pub(super) fn settle_modes(&mut self) {
        let n = self.blocks.len();
        let mut touches = std::mem::take(&mut self.touches);
        let mut modes = std::mem::take(&mut self.modes);
        touches.clear();
        modes.clear();
        for i in 0..n {
            let t = self.touches(i);
            let before = self.blocks[i].mode;
            let threshold = if before == BlockMode::Grasped {
                self.release_angle
            } else {
                self.grasp_angle
            };
            let normals = &t.hand_normals[..t.hand_count];
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
            touches.push(t);
            modes.push(mode);
        }
        // Carried: on a grasped block, and not held by the hand itself.
        for i in 0..n {
            if matches!(modes[i], BlockMode::Grasped | BlockMode::Pushed) {
                continue;
            }
            if let Some(j) = touches[i].first_block {
                if modes.get(j) == Some(&BlockMode::Grasped) && touches[i].floor_points == 0 {
                    modes[i] = BlockMode::Carried;
                }
            }
        }
        for i in 0..n {
            let before = self.blocks[i].mode;
            let now = modes[i];
            let touching = touches[i].floor_points > 0 || touches[i].blocks;
            if touching && !self.blocks[i].touching {
                self.emit(EventKind::Impact, i);
            }
            if before == BlockMode::Grasped && now != BlockMode::Grasped {
                self.emit(EventKind::Release, i);
            }
            if before != now {
                if let Some(k) = EventKind::on_entering(now) {
                    self.emit(k, i);
                }
            }
            let b = &mut self.blocks[i];
            b.mode = now;
            b.touching = touching;
            b.floor_contacts = touches[i].floor_points;
        }
        self.touches = touches;
        self.modes = modes;
    }
}
