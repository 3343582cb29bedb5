//! The other machine's clock, as an offset from ours: how a sample's stamps (CLOCK_MONOTONIC
//! of the machine that made them) are moved onto this machine's timeline, so that hop and
//! origin latencies stay meaningful across hosts.
//!
//! How it is estimated (Cristian's algorithm, as NTP does per exchange): the receiving bridge
//! asks the sending bridge for its clock at our `t0`, it answers with its clock `r`, and the
//! answer arrives at our `t1`. If the way there and the way back take equally long, the other
//! clock read `r` at our `(t0 + t1) / 2`, so `offset = r - (t0 + t1) / 2`, true to within half
//! the round trip. Of the recent exchanges the one with the shortest round trip is used: it
//! waited least in queues, so its bound is the tightest. On one machine (two network
//! namespaces share one CLOCK_MONOTONIC) the true offset is 0, which is how the tests check it.
//!
//! Why not zenoh's timestamps: they are wall-clock (an HLC over the system time), which NTP
//! slews and steps; our stamps are monotonic by design (DESIGN.md, "Stamps and latency").

/// Exchanges kept: at one a second, the best of the last minute (monotonic clocks drift by a
/// few parts per million, so an older best would be off by tens of microseconds).
const WINDOW: usize = 64;

/// One exchange: our send and receive times and the other clock's answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Exchange {
    pub sent_ns: u64,
    pub their_ns: u64,
    pub received_ns: u64,
}

impl Exchange {
    pub fn round_trip_ns(&self) -> u64 {
        self.received_ns.saturating_sub(self.sent_ns)
    }

    /// Their clock minus ours at the exchange's midpoint.
    pub fn offset_ns(&self) -> i64 {
        let mid = self.sent_ns as i128 + self.round_trip_ns() as i128 / 2;
        (self.their_ns as i128 - mid).clamp(i64::MIN as i128, i64::MAX as i128) as i64
    }
}

/// The estimate: the best exchange of the last [`WINDOW`].
#[derive(Debug, Clone)]
pub struct ClockOffset {
    recent: [Option<Exchange>; WINDOW],
    next: usize,
    exchanges: u64,
    best: Option<Exchange>,
}

impl Default for ClockOffset {
    fn default() -> Self {
        ClockOffset {
            recent: [None; WINDOW],
            next: 0,
            exchanges: 0,
            best: None,
        }
    }
}

impl ClockOffset {
    /// Takes one exchange; one whose answer came before it was asked (clocks are monotonic, so
    /// only damage does that) is ignored.
    pub fn add(&mut self, e: Exchange) {
        if e.received_ns < e.sent_ns {
            return;
        }
        self.recent[self.next] = Some(e);
        self.next = (self.next + 1) % WINDOW;
        self.exchanges += 1;
        self.best = self
            .recent
            .iter()
            .flatten()
            .min_by_key(|e| e.round_trip_ns())
            .copied();
    }

    /// Their clock minus ours, once an exchange has been made.
    pub fn offset_ns(&self) -> Option<i64> {
        self.best.map(|e| e.offset_ns())
    }

    /// How far the offset may be off: half the best exchange's round trip.
    pub fn uncertainty_ns(&self) -> Option<u64> {
        self.best.map(|e| e.round_trip_ns() / 2)
    }

    pub fn exchanges(&self) -> u64 {
        self.exchanges
    }

    /// The time `their_ns` of the other clock on ours (saturating at 0).
    pub fn to_ours(offset_ns: i64, their_ns: u64) -> u64 {
        (their_ns as i128 - offset_ns as i128).clamp(0, u64::MAX as i128) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A clock 5 s ahead of ours, answered over asymmetric round trips: the estimate is the
    /// shortest round trip's, within half of it of the truth.
    #[test]
    fn the_shortest_round_trip_gives_the_offset() {
        let truth: i64 = 5_000_000_000;
        let mut c = ClockOffset::default();
        assert_eq!(c.offset_ns(), None);
        // (send, there, back) in ns of our clock.
        for (i, (there, back)) in [(300_000, 50_000), (20_000, 20_000), (90_000, 400_000)]
            .into_iter()
            .enumerate()
        {
            let t0 = 1_000_000_000 * (i as u64 + 1);
            c.add(Exchange {
                sent_ns: t0,
                their_ns: (t0 + there) as i64 as u64 + truth as u64,
                received_ns: t0 + there + back,
            });
        }
        assert_eq!(c.exchanges(), 3);
        assert_eq!(
            c.offset_ns(),
            Some(truth),
            "the symmetric exchange is exact"
        );
        assert_eq!(c.uncertainty_ns(), Some(20_000));
        assert_eq!(ClockOffset::to_ours(truth, 7_000_000_000), 2_000_000_000);
    }

    /// An answer before the question is damage, not an exchange; old exchanges leave the window.
    #[test]
    fn damage_is_ignored_and_the_window_moves_on() {
        let mut c = ClockOffset::default();
        c.add(Exchange {
            sent_ns: 10,
            their_ns: 0,
            received_ns: 5,
        });
        assert_eq!(c.offset_ns(), None);
        c.add(Exchange {
            sent_ns: 0,
            their_ns: 1_000,
            received_ns: 10,
        });
        assert_eq!(c.offset_ns(), Some(995));
        for k in 0..WINDOW as u64 {
            let t0 = 1_000_000 + k * 1_000;
            c.add(Exchange {
                sent_ns: t0,
                their_ns: t0 + 50 - 7,
                received_ns: t0 + 100,
            });
        }
        assert_eq!(
            c.offset_ns(),
            Some(-7),
            "the 10 ns exchange left the window"
        );
    }
}
