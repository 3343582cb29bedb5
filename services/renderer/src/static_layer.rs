//! The static layer: the resting blocks, drawn once into an image (colour and depth) that each
//! frame starts from, so that a frame draws only what changed since.
//!
//! Why: on a software rasteriser (llvmpipe, the only "GPU" of a machine without one) a frame
//! costs per triangle, and a field of 1024 cubes costs ~30 ms a frame whatever the pixels,
//! although in the field-1024 session a hand pushes a few of them and the rest lie still. The
//! stepper's rule "resting blocks that nothing touches cost nothing" then holds for the
//! renderer too: a frame copies the layer's image (two texture copies) and draws the moving
//! blocks, the hand and their shadows on it.
//!
//! The layer is exact: every frame is drawn in two layers whether the image is reused or not
//! (floor, the layer's solids and their shadows; then the other solids, their shadows, the
//! hand, the grid lines), so a frame from a reused image has the bytes of the same frame drawn
//! from scratch (a test compares them). The camera is fixed for a renderer's life (its eyes
//! are set when it is built), so an image stays valid until one of its blocks changes.
//!
//! When the image is redrawn: a block of the layer changed (moved, turned, another mode, or
//! the hand grasps it), or enough blocks rest outside it that drawing them every frame costs
//! more than redrawing once (at least [`MIN_OUTSIDE`], and more than half of the live
//! blocks). Blocks within [`NEAR_HAND`] of the hand's check points stay out of it: they are
//! the ones the hand touches next, and each one the hand touched inside the layer would cost a
//! redraw (a hand sweeping a field touches a new block every few frames; with the margin the
//! layer is redrawn once per `NEAR_HAND` the hand travels). A redraw costs one whole frame's drawing, so a scene where blocks keep coming to
//! rest and being disturbed gains less. The floor is in the layer whatever the blocks do: its
//! shading alone was 8.8 ms of a 640 x 480 stereo frame on llvmpipe, a copy of the image ~3.

use common::samples::{MAX_FINGERS, MAX_FINGER_POINTS};
use common::{BlockMode, BlockState, HandSample, WorldView};
use glam::DVec3;

/// The fewest blocks resting outside the layer that make it worth redrawing for them.
pub const MIN_OUTSIDE: usize = 8;

/// Blocks whose centre is this close to the box of the hand's check points (m) are drawn live.
pub const NEAR_HAND: f64 = 0.25;

/// What a frame does with the layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LayerFrame {
    /// No layer (turned off): every block is live, drawn on a cleared image.
    Off,
    /// Draw the layer's image again (its blocks changed), then start the frame from it.
    Redraw,
    /// Start the frame from the image drawn before.
    Reuse,
}

/// Which blocks are in the layer, and the state each was drawn in.
#[derive(Debug)]
pub struct StaticLayer {
    member: Vec<bool>,
    drawn: Vec<BlockState>,
    members: usize,
    /// Whether an image of the members exists (false until the first redraw).
    drawn_once: bool,
}

/// The box of the hand's finite check points grown by [`NEAR_HAND`] (empty: no points, or no
/// hand).
fn near_hand_box(hand: Option<&HandSample>) -> (DVec3, DVec3) {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let Some(hand) = hand else {
        return (lo, hi);
    };
    for f in 0..(hand.finger_count as usize).min(MAX_FINGERS) {
        for p in
            &hand.finger_points[f][..(hand.finger_point_count[f] as usize).min(MAX_FINGER_POINTS)]
        {
            let p = DVec3::from_array(*p);
            if p.is_finite() {
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
    }
    (lo - NEAR_HAND, hi + NEAR_HAND)
}

/// A block the layer may hold: resting, not grasped, near neither hand (each hand's box, as
/// [`near_hand_box`] makes it), with a pose the draw list draws.
fn may_hold(b: &BlockState, i: usize, grasped: i32, near_hands: &[(DVec3, DVec3); 2]) -> bool {
    if b.mode() != BlockMode::Resting || grasped == i as i32 || !b.pose.is_finite() {
        return false;
    }
    let p = DVec3::from_array(b.pose.position);
    !near_hands
        .iter()
        .any(|near| p.cmpge(near.0).all() && p.cmple(near.1).all())
}

impl StaticLayer {
    /// A layer for a scene of `blocks` blocks, empty.
    pub fn new(blocks: usize) -> StaticLayer {
        StaticLayer {
            member: vec![false; blocks],
            drawn: vec![BlockState::default(); blocks],
            members: 0,
            drawn_once: false,
        }
    }

    /// Which blocks (by scene index) the layer holds.
    pub fn members(&self) -> &[bool] {
        &self.member
    }

    /// How many blocks it holds.
    pub fn len(&self) -> usize {
        self.members
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.members == 0
    }

    /// Forgets the image: the next frame redraws it (or draws without it).
    pub fn clear(&mut self) {
        self.member.fill(false);
        self.members = 0;
        self.drawn_once = false;
    }

    /// Decides what this frame does with the layer, and updates its members when it redraws.
    /// One pass over the world's block states; allocates nothing.
    pub fn update(&mut self, world: WorldView<'_>, hand: &HandSample) -> LayerFrame {
        self.update_hands(world, hand, None)
    }

    /// [`Self::update`] with a two-hand session's `left` hand too: the blocks near either
    /// hand stay live.
    pub fn update_hands(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
        left: Option<&HandSample>,
    ) -> LayerFrame {
        let states = world.blocks();
        let grasped = world.grasped_block;
        let near = [near_hand_box(Some(hand)), near_hand_box(left)];
        let mut changed = !self.drawn_once;
        let (mut outside, mut live) = (0usize, 0usize);
        for (i, member) in self.member.iter().enumerate() {
            let Some(b) = states.get(i) else {
                // A world with fewer blocks than the layer's: its missing members changed.
                changed |= *member;
                continue;
            };
            if *member {
                changed |= *b != self.drawn[i] || grasped == i as i32;
            } else {
                live += 1;
                outside += may_hold(b, i, grasped, &near) as usize;
            }
            if changed {
                break;
            }
        }
        let worth_joining = outside >= MIN_OUTSIDE && 2 * outside > live;
        if !changed && !worth_joining {
            return LayerFrame::Reuse;
        }
        self.members = 0;
        for (i, member) in self.member.iter_mut().enumerate() {
            *member = states
                .get(i)
                .is_some_and(|b| may_hold(b, i, grasped, &near));
            if *member {
                self.drawn[i] = states[i];
                self.members += 1;
            }
        }
        self.drawn_once = true;
        LayerFrame::Redraw
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::{Pose, WorldSample};

    fn world(modes: &[BlockMode]) -> WorldSample {
        let mut w = WorldSample::default();
        w.header.grasped_block = -1;
        for (i, m) in modes.iter().enumerate() {
            w.blocks.push(BlockState {
                pose: Pose {
                    position: [i as f64 * 0.1, 0.02, 0.0],
                    rotation: [0.0, 0.0, 0.0, 1.0],
                },
                mode: *m as u32,
                held_by: 0,
            });
        }
        w.header.block_count = modes.len() as u32;
        w
    }

    #[test]
    fn resting_blocks_are_drawn_once_and_reused_until_one_of_them_changes() {
        let no_hand = HandSample::default();
        let mut modes = vec![BlockMode::Resting; 20];
        modes[3] = BlockMode::Pushed;
        let mut w = world(&modes);
        let mut layer = StaticLayer::new(20);
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Redraw);
        assert_eq!(layer.len(), 19);
        assert!(!layer.members()[3]);
        // The pushed block moves: the layer's image still holds.
        w.blocks[3].pose.position[0] += 0.01;
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Reuse);
        // A block of the layer moves: redrawn, and it leaves the layer if it no longer rests.
        w.blocks[7].pose.position[0] += 0.01;
        w.blocks[7].mode = BlockMode::Pushed as u32;
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Redraw);
        assert!(!layer.members()[7] && layer.len() == 18);
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Reuse);
        // Grasping a block of the layer takes it out too.
        w.header.grasped_block = 0;
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Redraw);
        assert!(!layer.members()[0]);
    }

    #[test]
    fn blocks_that_come_to_rest_join_when_they_outnumber_the_live_ones() {
        let no_hand = HandSample::default();
        let mut w = world(&[BlockMode::Free; 20]);
        let mut layer = StaticLayer::new(20);
        // The floor alone is drawn once.
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Redraw);
        assert!(layer.is_empty());
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Reuse);
        for b in w.blocks.iter_mut().take(MIN_OUTSIDE - 1) {
            b.mode = BlockMode::Resting as u32;
        }
        // 7 of 20 at rest: not worth a redraw yet.
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Reuse);
        for b in w.blocks.iter_mut().take(11) {
            b.mode = BlockMode::Resting as u32;
        }
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Redraw);
        assert_eq!(layer.len(), 11);
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Reuse);
    }

    #[test]
    fn a_world_with_fewer_blocks_or_a_bad_pose_leaves_nothing_stale() {
        let no_hand = HandSample::default();
        let mut w = world(&[BlockMode::Resting; 10]);
        let mut layer = StaticLayer::new(12);
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Redraw);
        assert_eq!(layer.len(), 10);
        w.blocks.truncate(5);
        w.header.block_count = 5;
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Redraw);
        assert_eq!(layer.len(), 5);
        w.blocks[1].pose.position[1] = f64::NAN;
        assert_eq!(layer.update(w.view(), &no_hand), LayerFrame::Redraw);
        assert!(!layer.members()[1]);
    }

    /// A two-hand session's left hand keeps the blocks near it live too.
    #[test]
    fn blocks_near_the_left_hand_stay_live_too() {
        let w = world(&[BlockMode::Resting; 20]);
        let point_at = |x: f64| {
            let mut h = HandSample {
                finger_count: 1,
                ..HandSample::default()
            };
            h.finger_point_count[0] = 1;
            h.finger_points[0][0] = [x, 0.02, 0.0];
            h
        };
        let (right, mut left) = (point_at(0.0), point_at(1.5));
        left.side = 1;
        let mut one = StaticLayer::new(20);
        assert_eq!(one.update(w.view(), &right), LayerFrame::Redraw);
        let mut two = StaticLayer::new(20);
        assert_eq!(two.update_hands(w.view(), &right, None), LayerFrame::Redraw);
        assert_eq!(two.members(), one.members(), "no left hand: as one hand");
        two.clear();
        assert_eq!(
            two.update_hands(w.view(), &right, Some(&left)),
            LayerFrame::Redraw
        );
        // Near the right (x = 0 .. 0.2) and near the left (x = 1.3 .. 1.7): live.
        let live: Vec<usize> = (0..20).filter(|&i| !two.members()[i]).collect();
        assert_eq!(live, [0, 1, 2, 13, 14, 15, 16, 17]);
    }

    /// Blocks near the hand's check points are live, and the layer is not redrawn as the hand
    /// nears the next ones, only when it touches one of the layer's or leaves enough behind.
    #[test]
    fn blocks_near_the_hand_stay_live() {
        // 20 resting blocks 0.1 m apart along x; a fingertip at x = 0.
        let mut w = world(&[BlockMode::Resting; 20]);
        let mut hand = HandSample {
            finger_count: 1,
            ..HandSample::default()
        };
        hand.finger_point_count[0] = 1;
        hand.finger_points[0][0] = [0.0, 0.02, 0.0];
        let mut layer = StaticLayer::new(20);
        assert_eq!(layer.update(w.view(), &hand), LayerFrame::Redraw);
        // x = 0.0, 0.1, 0.2 are within 0.25 m.
        assert_eq!(&layer.members()[..4], &[false, false, false, true]);
        // The hand moves 0.1 m and pushes block 1: nothing of the layer changed.
        hand.finger_points[0][0][0] = 0.1;
        w.blocks[1].mode = BlockMode::Pushed as u32;
        w.blocks[1].pose.position[0] += 0.01;
        assert_eq!(layer.update(w.view(), &hand), LayerFrame::Reuse);
        // It reaches block 3, of the layer: redrawn, and the blocks now near it leave.
        hand.finger_points[0][0][0] = 0.3;
        w.blocks[3].mode = BlockMode::Pushed as u32;
        assert_eq!(layer.update(w.view(), &hand), LayerFrame::Redraw);
        assert_eq!(
            &layer.members()[..7],
            &[true, false, false, false, false, false, true]
        );
    }
}
