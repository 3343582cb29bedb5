//! The other participants' hands in a shared world, as the headset's page is sent them
//! (docs/sessions.md "Shared sessions"): the participant's bridge publishes each hand the
//! host sent it on `peer_hand`; this keeps the newest of each hand slot, forgets a hand that
//! has been silent for [`FORGET_AFTER_NS`] (its participant left, or its link is down: a
//! frozen hand would say they are still there), and tells when the page's message changed.
//! Fixed-size, so the stage keeps them without allocating.

use common::{HandSample, HAND_SLOTS, MAX_FINGERS};
use webxr_wire::page::{self, PEER_HAND_POINTS};

/// A hand not heard from for this long is no longer drawn: 2 s, many times the host's
/// sending interval for a hand that moves (`PEER_HZ`, 30 a second), and long enough that a
/// hand held still (the host sends a slot only when it changed) flickers only after a long
/// stillness, when a drawn ghost would mislead more.
pub const FORGET_AFTER_NS: u64 = 2_000_000_000;

#[derive(Clone, Copy)]
struct Kept {
    points: [[f32; 3]; PEER_HAND_POINTS],
    count: usize,
    heard_ns: u64,
}

/// The newest hand of each slot (participant and side), and whether the page has it.
pub struct Peers {
    slots: [Option<Kept>; HAND_SLOTS],
    /// The kept hands differ from the last message made ([`Peers::encode`]).
    changed: bool,
}

impl Default for Peers {
    fn default() -> Self {
        Peers {
            slots: [None; HAND_SLOTS],
            changed: false,
        }
    }
}

impl Peers {
    /// Keeps `hand` as its slot's newest, heard at `now_ns`. An untracked hand is forgotten
    /// (its points are where it was lost, not where it is); a hand out of the slots' range
    /// is passed over (the bridge checked it; nothing else publishes here).
    pub fn take(&mut self, hand: &HandSample, now_ns: u64) {
        let Some(slot) = hand.slot().and_then(|k| self.slots.get_mut(k)) else {
            return;
        };
        if hand.tracked == 0 {
            self.changed |= slot.take().is_some();
            return;
        }
        let mut kept = Kept {
            points: [[0.0; 3]; PEER_HAND_POINTS],
            count: 0,
            heard_ns: now_ns,
        };
        for f in 0..(hand.finger_count as usize).min(MAX_FINGERS) {
            for p in hand.finger(f) {
                if kept.count < PEER_HAND_POINTS {
                    kept.points[kept.count] = p.map(|v| v as f32);
                    kept.count += 1;
                }
            }
        }
        *slot = Some(kept);
        self.changed = true;
    }

    /// Forgets the hands silent for [`FORGET_AFTER_NS`] at `now_ns`.
    pub fn forget_silent(&mut self, now_ns: u64) {
        for slot in &mut self.slots {
            if slot.is_some_and(|k| now_ns.saturating_sub(k.heard_ns) > FORGET_AFTER_NS) {
                *slot = None;
                self.changed = true;
            }
        }
    }

    /// Hands kept now.
    pub fn count(&self) -> usize {
        self.slots.iter().flatten().count()
    }

    /// The page's peers message of the kept hands into `out`, when they changed since the
    /// last one: true when it wrote one.
    pub fn encode(&mut self, out: &mut Vec<u8>) -> bool {
        if !self.changed {
            return false;
        }
        self.changed = false;
        let hands = self.slots.iter().enumerate().filter_map(|(k, s)| {
            s.as_ref()
                .map(|kept| ((k / 2) as u32, (k % 2) as u16, &kept.points[..kept.count]))
        });
        page::encode_peers(hands, out);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hand(participant: u32, side: u32, x: f64) -> HandSample {
        let mut h = HandSample {
            tracked: 1,
            finger_count: 2,
            participant,
            side,
            ..HandSample::default()
        };
        h.finger_point_count[0] = 3;
        h.finger_point_count[1] = 2;
        for f in 0..2 {
            for p in 0..3 {
                h.finger_points[f][p] = [x, f as f64, p as f64];
            }
        }
        h
    }

    #[test]
    fn the_newest_of_each_slot_is_sent_once_and_a_silent_or_lost_hand_is_forgotten() {
        let mut peers = Peers::default();
        let mut out = Vec::new();
        assert!(!peers.encode(&mut out), "nothing to send before a hand");
        peers.take(&hand(1, 0, 0.5), 1_000);
        peers.take(&hand(2, 1, 0.25), 1_000);
        peers.take(&hand(1, 0, 0.75), 2_000);
        assert!(peers.encode(&mut out));
        let sent = page::decode_peers(&out).unwrap();
        assert_eq!(sent.len(), 2, "one per slot, the newest");
        assert_eq!((sent[0].participant, sent[0].side), (1, 0));
        assert_eq!(
            sent[0].points.len(),
            5,
            "3 + 2 points, none past the counts"
        );
        assert_eq!(sent[0].points[0], [0.75, 0.0, 0.0]);
        assert_eq!(sent[0].points[4], [0.75, 1.0, 1.0]);
        assert_eq!((sent[1].participant, sent[1].side), (2, 1));
        assert!(!peers.encode(&mut out), "unchanged: not sent again");

        // Participant 2's left hand goes silent; participant 1's keeps coming.
        let later = 2_000 + FORGET_AFTER_NS;
        peers.take(&hand(1, 0, 0.8), later);
        peers.forget_silent(later + 500);
        assert!(peers.encode(&mut out));
        let sent = page::decode_peers(&out).unwrap();
        assert_eq!(sent.len(), 1);
        assert_eq!(sent[0].participant, 1);

        // A lost hand is forgotten at once; a slot out of range is passed over.
        let mut lost = hand(1, 0, 0.9);
        lost.tracked = 0;
        peers.take(&lost, later + 600);
        peers.take(&hand(9, 0, 0.1), later + 600);
        assert_eq!(peers.count(), 0);
        assert!(peers.encode(&mut out));
        assert_eq!(page::decode_peers(&out).unwrap(), vec![]);
    }
}
