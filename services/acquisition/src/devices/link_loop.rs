//! The read loop both drivers share: keep the link, pace the polls, notice silence, and get the
//! link back when it goes.
//!
//! The CyberGlove and the FASTRAK differ in their bytes (the parser, the handshake, what a
//! record turns into) but not in how they sit on a serial port: a `read` call reconnects with
//! backoff while the link is down, hands out a buffered record if there is one, reports
//! silence, polls when the device does not stream, and otherwise waits for bytes until the end
//! of its time slice. That part lives here once, so a fix to the link policy (a timing, a
//! counter, a state transition) reaches both devices; each driver implements [`Protocol`] with
//! only what is its own.

use std::time::{Duration, Instant};

use super::serial::{sleep_toward, Backoff, Link, LinkSettings, LinkState, LinkStats};
use super::{DeviceError, ReadOutcome};

/// A poll whose answer has not come for this long is taken as lost and sent again (the next
/// period permitting), so one dropped command byte does not stall a polled device for good.
const POLL_OVERDUE: Duration = Duration::from_millis(100);

/// A parser's byte buffer, as the loop sees it: it reads into the free space and forgets the
/// bytes of a lost link, and it compares garbage counts to tell a silent device from one that
/// talks at the wrong baud rate. A parser gives its window and its counters; the rest is the
/// same for every parser.
pub(super) trait RecordBuffer {
    /// The parser's byte window and its counters, at once.
    fn window(&mut self) -> (&mut RecordBytes, &mut LinkStats);
    fn stats(&self) -> &LinkStats;

    /// The free tail of the buffer, to read into; then [`RecordBuffer::commit`].
    fn space(&mut self) -> &mut [u8] {
        let (bytes, stats) = self.window();
        bytes.space(&mut stats.garbage_bytes)
    }

    fn commit(&mut self, n: usize) {
        self.window().0.commit(n)
    }

    /// Forgets buffered bytes: after a loss they are the remains of another connection.
    fn clear(&mut self) {
        self.window().0.clear()
    }

    /// Bytes skipped so far that made no record.
    fn garbage_bytes(&self) -> u64 {
        self.stats().garbage_bytes
    }
}

/// The largest window a parser uses (the FASTRAK's; the glove's records are shorter).
pub(super) const MAX_WINDOW: usize = 1024;

/// A parser's byte window: what was read from the link waits here until it makes a record.
/// Fixed-size, so the sample path never allocates; a window that fills without a record (only
/// noise does that) drops its older half, counted as garbage.
#[derive(Debug, Clone)]
pub(super) struct RecordBytes {
    buf: [u8; MAX_WINDOW],
    /// How much of `buf` the parser uses: a few of its records' worth.
    capacity: usize,
    len: usize,
}

impl RecordBytes {
    /// A window of `capacity` bytes (at most [`MAX_WINDOW`]).
    pub fn new(capacity: usize) -> RecordBytes {
        RecordBytes {
            buf: [0; MAX_WINDOW],
            capacity: capacity.clamp(2, MAX_WINDOW),
            len: 0,
        }
    }

    /// The bytes waiting, oldest first.
    pub fn filled(&self) -> &[u8] {
        &self.buf[..self.len]
    }

    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// The free tail, to read into; then [`RecordBytes::commit`]. A full window first drops
    /// its older half and adds it to `garbage`.
    pub fn space(&mut self, garbage: &mut u64) -> &mut [u8] {
        if self.len == self.capacity {
            let half = self.capacity / 2;
            self.buf.copy_within(half..self.capacity, 0);
            self.len -= half;
            *garbage += half as u64;
        }
        &mut self.buf[self.len..self.capacity]
    }

    pub fn commit(&mut self, n: usize) {
        self.len = (self.len + n).min(self.capacity);
    }

    /// Appends what fits of `bytes` (for tests and emulators); returns how many did.
    pub fn push(&mut self, bytes: &[u8], garbage: &mut u64) -> usize {
        let space = self.space(garbage);
        let n = bytes.len().min(space.len());
        space[..n].copy_from_slice(&bytes[..n]);
        self.commit(n);
        n
    }

    /// Forgets the first `n` bytes (a record taken, or bytes that can start none).
    pub fn consume(&mut self, n: usize) {
        let n = n.min(self.len);
        self.buf.copy_within(n..self.len, 0);
        self.len -= n;
    }
}

/// What a driver keeps about its link besides the protocol: whether it is up, when to retry
/// or poll, when the last record came, and the counters that survive reconnections.
pub(super) struct LinkUpkeep {
    pub state: LinkState,
    pub backoff: Backoff,
    /// When the last sample was taken (or the link came up): silence is measured from here.
    pub last_record: Instant,
    /// The parser's garbage count at `last_record`, so a silence report can say how many
    /// bytes arrived meanwhile that made no record.
    pub garbage_at_last_record: u64,
    /// When the next poll may be sent (polled mode).
    pub next_poll: Instant,
    /// When the unanswered poll was sent; None once it was answered.
    pub poll_sent: Option<Instant>,
    /// The driver's own counters; the parser keeps the byte-level ones.
    pub stats: LinkStats,
    /// Whether the link was ever up: the first connection of a session is not a reconnect.
    pub ever_up: bool,
}

impl LinkUpkeep {
    /// Down, with the first connection attempt due now: `new` does not touch the port, the
    /// first `read` connects.
    pub fn new(backoff: Backoff) -> LinkUpkeep {
        let now = Instant::now();
        LinkUpkeep {
            state: LinkState::Down { retry_at: now },
            ever_up: false,
            backoff,
            last_record: now,
            garbage_at_last_record: 0,
            next_poll: now,
            poll_sent: None,
            stats: LinkStats::default(),
        }
    }

    /// Whether the driver currently has its link (false while reconnecting).
    pub fn connected(&self) -> bool {
        matches!(self.state, LinkState::Up(_))
    }

    /// The link is (back) up: a fresh connection gets the full silence timeout and polls at
    /// once, and the next loss starts its backoff from the shortest delay again.
    pub fn up(&mut self, link: Link, garbage_now: u64) {
        let now = Instant::now();
        self.state = LinkState::Up(link);
        self.ever_up = true;
        self.backoff.reset();
        self.last_record = now;
        self.garbage_at_last_record = garbage_now;
        self.next_poll = now;
        self.poll_sent = None;
    }

    /// The link is gone: the first reconnection attempt follows after the shortest backoff
    /// (a glitch heals fast); failures then back off further. The buffered bytes go too, so
    /// half a record of the old connection cannot join one of the next.
    pub fn down(&mut self, buffer: &mut impl RecordBuffer) {
        self.state = LinkState::Down {
            retry_at: Instant::now() + self.backoff.first,
        };
        self.stats.link_losses += 1;
        buffer.clear();
    }

    /// Sends `bytes` if the link is up, ignoring a failure: for a driver that is going away
    /// and leaves its device quiet for the next program that opens it.
    pub fn send_if_up(&mut self, bytes: &[u8]) {
        if let LinkState::Up(link) = &mut self.state {
            let _ = link.write_all(bytes);
        }
    }

    /// A sample was taken: it counts, it ends the silence, and it answers the poll.
    pub fn record_seen(&mut self, garbage_now: u64) {
        self.stats.samples += 1;
        self.last_record = Instant::now();
        self.garbage_at_last_record = garbage_now;
        self.poll_sent = None;
    }
}

/// What a driver tells the shared loop about its device.
pub(super) trait Protocol {
    /// What `read` fills in.
    type Sample;
    type Buffer: RecordBuffer;
    /// The device's name in errors ("glove", "tracker").
    const DEVICE: &'static str;
    /// The command that asks for one sample in polled mode.
    const POLL_COMMAND: &'static [u8];

    /// The poll rate in polled mode; None when the device streams on its own.
    fn poll_rate_hz(&self) -> Option<f64>;
    /// The port, its timeouts and its backoff.
    fn link(&self) -> &LinkSettings;
    /// Opens the port and runs the handshake; does not touch the upkeep's state.
    fn connect(&mut self) -> Result<Link, DeviceError>;
    /// Takes buffered records until one makes a sample, written into `out` (true), or the
    /// buffer holds no complete record (false). Does not touch the upkeep's timing: the loop
    /// calls [`LinkUpkeep::record_seen`] after a sample.
    fn take_sample(&mut self, out: &mut Self::Sample) -> bool;
    /// What the device itself said went wrong since the last sample, for a silence report;
    /// taking it leaves None.
    fn take_reported(&mut self) -> Option<&'static str>;
    /// The upkeep and the parser's buffer at once, so the loop can read from the link into
    /// the buffer.
    fn parts(&mut self) -> (&mut LinkUpkeep, &mut Self::Buffer);
}

/// Opens the port for a handshake: stops whatever the device may still be sending (`stop`,
/// a stream left running by an earlier session would bury the answer), throws away what it
/// sent, and empties the parser's buffer.
pub(super) fn open_quiet(
    device: &'static str,
    settings: &LinkSettings,
    stop: &[u8],
    buffer: &mut impl RecordBuffer,
) -> Result<Link, DeviceError> {
    let mut link = Link::open(device, &settings.port, settings.baud)?;
    link.write_all(stop)?;
    link.drain(Duration::from_millis(30), Duration::from_millis(300))?;
    buffer.clear();
    Ok(link)
}

/// Reads what arrives within 20 ms, or until `deadline` if sooner, into the buffer: one step
/// of a handshake waiting for its answer.
pub(super) fn receive_until(
    link: &mut Link,
    buffer: &mut impl RecordBuffer,
    deadline: Instant,
) -> Result<(), DeviceError> {
    let timeout = deadline
        .saturating_duration_since(Instant::now())
        .min(Duration::from_millis(20));
    let got = link.read_some(buffer.space(), timeout)?;
    buffer.commit(got);
    Ok(())
}

/// Connects now (the port and the handshake), failing with the reason: for `open`, which
/// must not return a driver that is not there.
pub(super) fn connect_now<P: Protocol>(driver: &mut P) -> Result<(), DeviceError> {
    let link = driver.connect()?;
    let (upkeep, buffer) = driver.parts();
    upkeep.up(link, buffer.garbage_bytes());
    Ok(())
}

/// Waits up to the driver's read slice for the next sample and writes it into `out`; never
/// allocates on the sample path.
///
/// `Err` reports a problem the driver is already handling (the link is being re-established
/// with backoff): the caller logs it and calls again.
pub(super) fn read<P: Protocol>(
    driver: &mut P,
    out: &mut P::Sample,
) -> Result<ReadOutcome, DeviceError> {
    let read_slice = driver.link().read_slice;
    let slice_end = Instant::now() + read_slice;
    if let LinkState::Down { retry_at } = driver.parts().0.state {
        if Instant::now() < retry_at {
            sleep_toward(retry_at, read_slice);
            return Ok(ReadOutcome::Pending);
        }
        match driver.connect() {
            Ok(link) => {
                let (upkeep, buffer) = driver.parts();
                if upkeep.ever_up {
                    upkeep.stats.reconnects += 1;
                }
                upkeep.up(link, buffer.garbage_bytes());
            }
            Err(cause) => {
                let upkeep = driver.parts().0;
                let (retry_in, attempt) = upkeep.backoff.next_delay();
                upkeep.state = LinkState::Down {
                    retry_at: Instant::now() + retry_in,
                };
                return Err(DeviceError::Reconnecting {
                    device: P::DEVICE,
                    port: driver.link().port.clone(),
                    attempt,
                    retry_in,
                    cause: Box::new(cause),
                });
            }
        }
    }
    let silence_timeout = driver.link().silence_timeout;
    let poll_rate_hz = driver.poll_rate_hz();
    loop {
        // A record may already be buffered.
        if driver.take_sample(out) {
            let (upkeep, buffer) = driver.parts();
            upkeep.record_seen(buffer.garbage_bytes());
            return Ok(ReadOutcome::Sample);
        }
        let now = Instant::now();
        let (upkeep, buffer) = driver.parts();
        if now.duration_since(upkeep.last_record) > silence_timeout {
            let waited = now.duration_since(upkeep.last_record);
            let garbage_bytes = buffer.garbage_bytes() - upkeep.garbage_at_last_record;
            let err = DeviceError::Silent {
                device: P::DEVICE,
                port: driver.link().port.clone(),
                waited,
                garbage_bytes,
                reported: driver.take_reported(),
            };
            let (upkeep, buffer) = driver.parts();
            upkeep.down(buffer);
            return Err(err);
        }
        if now >= slice_end {
            return Ok(ReadOutcome::Pending);
        }
        let LinkState::Up(link) = &mut upkeep.state else {
            return Ok(ReadOutcome::Pending);
        };
        let mut wait_until = slice_end;
        if let Some(rate_hz) = poll_rate_hz {
            // Ask again when the period is up, or when an answer is overdue (a lost poll).
            let overdue = upkeep
                .poll_sent
                .is_some_and(|t| now.duration_since(t) > POLL_OVERDUE);
            if upkeep.poll_sent.is_none() || overdue {
                if now >= upkeep.next_poll {
                    if let Err(e) = link.write_all(P::POLL_COMMAND) {
                        upkeep.down(buffer);
                        return Err(e);
                    }
                    upkeep.poll_sent = Some(now);
                    let period = Duration::from_secs_f64(1.0 / rate_hz);
                    upkeep.next_poll = (upkeep.next_poll + period).max(now);
                } else {
                    wait_until = wait_until.min(upkeep.next_poll);
                }
            }
        }
        let timeout = wait_until.saturating_duration_since(now);
        match link.read_some(buffer.space(), timeout) {
            Ok(n) => buffer.commit(n),
            Err(e) => {
                upkeep.down(buffer);
                return Err(e);
            }
        }
    }
}
