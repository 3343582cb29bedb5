//! Which glove reading goes with a tracker sample.
//!
//! Kinematics makes one hand per tracker sample with "the newest glove reading" (docs/design.md).
//! Newest *at the tracker's source time*, not newest received: when kinematics falls behind
//! (a descheduled process, a replay as fast as it is consumed) several gloves may be waiting,
//! and pairing a tracker with a glove from its future would make the hand depend on timing.
//! Pairing by source time makes the hand a function of the samples alone, which is what lets a
//! replay reproduce a live run bit for bit.

use common::GloveSample;

/// Glove readings kept to pair with trackers that arrive late (a second of a 120 Hz glove).
pub const GLOVE_HISTORY: usize = 128;

/// The most recent glove readings, in arrival order, in a fixed ring (no allocation).
pub struct GloveHistory {
    ring: [GloveSample; GLOVE_HISTORY],
    len: usize,
    next: usize,
}

impl Default for GloveHistory {
    fn default() -> Self {
        GloveHistory {
            ring: [GloveSample::default(); GLOVE_HISTORY],
            len: 0,
            next: 0,
        }
    }
}

impl GloveHistory {
    pub fn push(&mut self, glove: &GloveSample) {
        self.ring[self.next] = *glove;
        self.next = (self.next + 1) % GLOVE_HISTORY;
        self.len = (self.len + 1).min(GLOVE_HISTORY);
    }

    /// The glove to pair with a tracker sample of `source_time_ns`: the newest reading at or
    /// before it; if every reading held is later, the oldest held; `None` before any glove.
    pub fn at(&self, source_time_ns: u64) -> Option<&GloveSample> {
        let mut oldest = None;
        for back in 1..=self.len {
            let g = &self.ring[(self.next + GLOVE_HISTORY - back) % GLOVE_HISTORY];
            if g.stamp.source_time_ns <= source_time_ns {
                return Some(g);
            }
            oldest = Some(g);
        }
        oldest
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glove(t: u64) -> GloveSample {
        let mut g = GloveSample::default();
        g.stamp.source_time_ns = t;
        g
    }

    #[test]
    fn a_tracker_takes_the_newest_glove_at_or_before_its_time() {
        let mut h = GloveHistory::default();
        assert!(h.at(5).is_none());
        for t in [10, 20, 30, 40] {
            h.push(&glove(t));
        }
        assert_eq!(h.at(30).unwrap().stamp.source_time_ns, 30);
        assert_eq!(h.at(35).unwrap().stamp.source_time_ns, 30);
        assert_eq!(h.at(99).unwrap().stamp.source_time_ns, 40);
        // Every glove is later: the oldest held.
        assert_eq!(h.at(1).unwrap().stamp.source_time_ns, 10);
        for t in 0..(2 * GLOVE_HISTORY as u64) {
            h.push(&glove(100 + t));
        }
        assert_eq!(
            h.at(50).unwrap().stamp.source_time_ns,
            100 + GLOVE_HISTORY as u64
        );
    }
}
