//! The worlds the render loop keeps for the preview while the session runs: copies into
//! recycled slots, thinned evenly when full, and the hands' points each one frames.

use common::{BlockState, HandSample, WorldHeader, WorldView};
use glam::DVec3;

use super::{FrameFacts, MAX_STATES};

/// A world as the preview keeps it until the session ends: the header, the blocks, the hand
/// it answers (and a two-hand session's newest left hand), the hand's events so far and the
/// facts of the moment.
pub(super) struct KeptState {
    pub(super) header: WorldHeader,
    pub(super) blocks: Vec<BlockState>,
    pub(super) hand: HandSample,
    pub(super) left: Option<HandSample>,
    pub(super) hand_events: u64,
    pub(super) facts: FrameFacts,
}

/// The worlds kept for the preview, at most [`MAX_STATES`]: when full, every other one goes
/// and the rate halves (the whole session, more sparsely). Dropped states are reused, so the
/// render loop allocates only while the store first fills.
#[derive(Default)]
pub(super) struct StateStore {
    pub(super) kept: Vec<KeptState>,
    spare: Vec<KeptState>,
    keep_every: u32,
    offered: u64,
}

impl StateStore {
    /// Whether the next offered state is kept (and counts it).
    pub(super) fn wants_next(&mut self) -> bool {
        if self.keep_every == 0 {
            self.keep_every = 1;
        }
        let n = self.offered;
        self.offered += 1;
        if !n.is_multiple_of(u64::from(self.keep_every)) {
            return false;
        }
        if self.kept.len() == MAX_STATES {
            // Keep the 1st, 3rd, ...; the 2nd, 4th, ... become spares (from the back, so that
            // the indices still to visit do not move).
            for i in (0..self.kept.len()).rev().filter(|i| i % 2 == 1) {
                let s = self.kept.remove(i);
                self.spare.push(s);
            }
            self.keep_every *= 2;
            return n.is_multiple_of(u64::from(self.keep_every));
        }
        true
    }

    /// A state to fill: a spare one, or a new one.
    pub(super) fn slot(&mut self) -> KeptState {
        self.spare.pop().unwrap_or_else(KeptState::placeholder)
    }
}

impl KeptState {
    pub(super) fn placeholder() -> KeptState {
        KeptState {
            header: WorldHeader::default(),
            blocks: Vec::new(),
            hand: HandSample::default(),
            left: None,
            hand_events: 0,
            facts: FrameFacts::default(),
        }
    }

    pub(super) fn view(&self) -> WorldView<'_> {
        WorldView {
            header: &self.header,
            blocks: &self.blocks,
        }
    }

    /// The points of the hands as drawn (finger points, palm; and a two-hand session's left
    /// hand, as tracked), finite ones only.
    pub(super) fn hand_points(&self) -> impl Iterator<Item = DVec3> + '_ {
        let right = drawn_finger_points(&self.header, &self.hand)
            .chain(self.hand.palm().iter().map(|p| DVec3::from_array(*p)));
        let left = self
            .left
            .iter()
            .flat_map(|l| tracked_points(l).chain(l.palm().iter().map(|p| DVec3::from_array(*p))));
        right.chain(left).filter(|p| p.is_finite())
    }
}

/// The finger points a frame draws: the world's (the fingers as the stepper placed them, out
/// of the blocks) when it carries them, else the hand's.
fn drawn_finger_points<'a>(
    world: &'a common::WorldHeader,
    hand: &'a HandSample,
) -> impl Iterator<Item = DVec3> + 'a {
    let (count, counts, points) = crate::draw_list::drawn_fingers(world, hand);
    points
        .iter()
        .zip(counts)
        .take(count as usize)
        .flat_map(|(finger, n)| finger.iter().take(*n as usize))
        .map(|p| DVec3::from_array(*p))
}

/// A hand's own check points, as tracked (a two-hand session's left hand: the world's drawn
/// points are the right hand's).
fn tracked_points(hand: &HandSample) -> impl Iterator<Item = DVec3> + '_ {
    (0..(hand.finger_count as usize).min(common::MAX_FINGERS))
        .flat_map(|f| hand.finger(f).iter())
        .map(|p| DVec3::from_array(*p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_render_loop_keeps_at_most_max_states_worlds_reusing_dropped_ones() {
        let mut store = StateStore::default();
        let mut fresh = 0;
        for i in 0..5000 {
            if store.wants_next() {
                if store.spare.is_empty() {
                    fresh += 1;
                }
                let mut s = store.slot();
                s.facts.time_s = i as f64;
                store.kept.push(s);
            }
            assert!(store.kept.len() <= MAX_STATES);
        }
        assert!(store.kept.len() > MAX_STATES / 2, "{}", store.kept.len());
        assert!(fresh <= MAX_STATES + 1, "{fresh} states made");
        // In time order, evenly spaced from the start.
        let t: Vec<f64> = store.kept.iter().map(|s| s.facts.time_s).collect();
        assert_eq!(t[0], 0.0);
        let step = t[1] - t[0];
        assert!(t.windows(2).all(|w| w[1] - w[0] == step), "{t:?}");
        assert_eq!(step, f64::from(store.keep_every));
    }

    /// A two-hand session's left hand is part of what the preview frames; without one, the
    /// points are the right hand's alone.
    #[test]
    fn the_left_hand_is_framed_too() {
        let w = common::WorldSample::with_blocks(1);
        let mut right = HandSample {
            finger_count: 1,
            ..Default::default()
        };
        right.finger_point_count[0] = 2;
        right.finger_points[0][..2].copy_from_slice(&[[0.0, 0.2, 0.0], [0.0, 0.2, 0.04]]);
        let mut left = HandSample {
            finger_count: 1,
            palm_vertex_count: 1,
            side: common::HandSide::Left.code(),
            ..Default::default()
        };
        left.finger_point_count[0] = 1;
        left.finger_points[0][0] = [-0.3, 0.25, 0.0];
        left.palm_vertices[0] = [-0.32, 0.25, 0.0];
        let mut state = KeptState::placeholder();
        state.header = w.header;
        state.blocks = w.blocks.clone();
        state.hand = right;
        let one: Vec<DVec3> = state.hand_points().collect();
        assert_eq!(one, [DVec3::new(0.0, 0.2, 0.0), DVec3::new(0.0, 0.2, 0.04)]);
        state.left = Some(left);
        let two: Vec<DVec3> = state.hand_points().collect();
        assert_eq!(two[..2], one[..]);
        assert_eq!(
            two[2..],
            [DVec3::new(-0.3, 0.25, 0.0), DVec3::new(-0.32, 0.25, 0.0)]
        );
    }
}
