//! Waiting for a sample: sleeping on inlets' events, polling, and the adaptive waiter.

use super::*;

/// Something a process can sleep on: an inlet's wake-up listener or its stage's doorbell; and
/// poll: whether a sample waits in it.
pub trait Wakeable {
    fn wake_source(&self) -> WakeSource<'_>;
    /// True when a sample is there to receive (a poll that takes nothing).
    fn has_samples(&self) -> bool;
}

/// What an inlet sleeps on ([`crate::topic::WakesBy`]).
pub enum WakeSource<'a> {
    /// iceoryx2's event listener: a descriptor, slept on in `ppoll` with any others.
    Listener(&'a Listener<ipc::Service>),
    /// The doorbell of the stage that opened the inlet: one futex word for all its inlets.
    Doorbell(&'a Doorbell),
}

impl WakeSource<'_> {
    fn listener(&self) -> Option<&Listener<ipc::Service>> {
        match self {
            WakeSource::Listener(l) => Some(l),
            WakeSource::Doorbell(_) => None,
        }
    }
}

impl<P: TopicLayout> Wakeable for Inlet<P>
where
    P::Payload: PayloadKind,
{
    fn wake_source(&self) -> WakeSource<'_> {
        Inlet::wake_source(self)
    }
    fn has_samples(&self) -> bool {
        Inlet::has_samples(self)
    }
}

/// Waits by a [`WaitStrategy`]; for `Adaptive`, learns the inlets' period (the median-like
/// running estimate of the time between arrivals) and how late this machine wakes from a timed
/// sleep, so that the poll window opens before the sample is due even when a wake-up takes
/// 100 us. Allocates nothing.
#[derive(Debug, Clone)]
pub struct Waiter {
    strategy: WaitStrategy,
    last_arrival_ns: Option<u64>,
    /// Estimated time between arrivals (0 until two arrivals).
    period_ns: u64,
    /// How late a timed sleep returns, estimated (starts at 100 us).
    wake_late_ns: u64,
    /// Whether the last wait ended in the poll window (a sample found by polling).
    polled: bool,
    /// Arrivals found in the poll window, and all arrivals: how often the prediction held.
    pub in_window: u64,
    pub arrivals: u64,
    /// The last adaptive wait's window (open, close; 0, 0 without one) and when it returned.
    window_ns: (u64, u64),
    returned_ns: u64,
    /// Per-arrival records, when asked for (`Waiter::trace_to`): preallocated, kept while
    /// there is room.
    trace: Option<Vec<WaitRecord>>,
}

/// One arrival as an adaptive wait saw it (`Waiter::trace_to`): where the sample's publish
/// fell against the window the waiter predicted, and how the wait ended. What shows why a
/// prediction misses, sample by sample (docs/design.md, "Waiting for a sample").
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WaitRecord {
    /// The sample's publish (the sender's stamp), ns on CLOCK_MONOTONIC.
    pub publish_ns: u64,
    /// The window the wait polled in (0, 0: none yet, no period known).
    pub open_ns: u64,
    pub close_ns: u64,
    /// When the wait returned.
    pub returned_ns: u64,
    /// Found by polling in the window (else woken by its event, or already there).
    pub polled: bool,
}

/// Where an arrival fell against its adaptive wait's window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitOutcome {
    /// No window yet (no period known).
    NoWindow,
    /// Found by polling in the window.
    Polled,
    /// Published before the window opened (the wait slept through it).
    Early,
    /// Published inside the window but not seen by polling (the sender could not run).
    Inside,
    /// Published after the window closed.
    Late,
}

impl WaitRecord {
    pub fn outcome(&self) -> WaitOutcome {
        if self.open_ns == 0 {
            WaitOutcome::NoWindow
        } else if self.polled {
            WaitOutcome::Polled
        } else if self.publish_ns < self.open_ns {
            WaitOutcome::Early
        } else if self.publish_ns <= self.close_ns {
            WaitOutcome::Inside
        } else {
            WaitOutcome::Late
        }
    }

    /// A record back from a [`WaitRecord::csv`] line (times relative to the window's
    /// opening, as written); `None` for a line that is not one.
    pub fn from_csv(line: &str) -> Option<WaitRecord> {
        let f: Vec<i128> = line
            .split(',')
            .map(|x| x.parse().ok())
            .collect::<Option<_>>()?;
        let [publish_ns, publish, close, returned, polled] = f[..] else {
            return None;
        };
        let open = publish_ns - publish;
        let at = |t: i128| u64::try_from(open + t).ok();
        Some(WaitRecord {
            publish_ns: u64::try_from(publish_ns).ok()?,
            open_ns: if close == 0 { 0 } else { at(0)? },
            close_ns: if close == 0 { 0 } else { at(close)? },
            returned_ns: at(returned)?,
            polled: polled == 1,
        })
    }

    /// The record as a CSV line (the header is [`WaitRecord::CSV_HEADER`]), times relative
    /// to the window's opening (the publish's, where there is no window).
    pub fn csv(&self) -> String {
        let base = if self.open_ns > 0 {
            self.open_ns
        } else {
            self.publish_ns
        } as i128;
        let rel = |t: u64| t as i128 - base;
        format!(
            "{},{},{},{},{}",
            self.publish_ns,
            rel(self.publish_ns),
            if self.open_ns > 0 {
                rel(self.close_ns)
            } else {
                0
            },
            rel(self.returned_ns),
            u8::from(self.polled)
        )
    }

    pub const CSV_HEADER: &'static str =
        "publish_ns,publish_after_open_ns,close_after_open_ns,returned_after_open_ns,polled";
}

/// The poll window's half-width beyond the predicted wake lateness.
const POLL_MARGIN_NS: u64 = 50_000;

impl Waiter {
    pub fn new(strategy: WaitStrategy) -> Waiter {
        // A timed sleep's deadline is exact to the timer slack: ask for 1 ns instead of 50 us.
        // SAFETY: prctl with PR_SET_TIMERSLACK and an integer argument only changes this
        // thread's timer slack.
        if strategy == WaitStrategy::Adaptive {
            unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) };
        }
        Waiter {
            strategy,
            last_arrival_ns: None,
            period_ns: 0,
            wake_late_ns: 100_000,
            polled: false,
            in_window: 0,
            arrivals: 0,
            window_ns: (0, 0),
            returned_ns: 0,
            trace: None,
        }
    }

    /// Keeps a [`WaitRecord`] per arrival, up to `capacity` (allocated here, once), for
    /// [`Waiter::trace`].
    pub fn keep_trace(&mut self, capacity: usize) {
        self.trace = Some(Vec::with_capacity(capacity));
    }

    /// The records kept (empty unless [`Waiter::keep_trace`] was called).
    pub fn trace(&self) -> &[WaitRecord] {
        self.trace.as_deref().unwrap_or(&[])
    }

    /// The environment variable that asks every adaptive stage for its per-arrival trace: a
    /// folder, where each writes `wait-STAGE.csv` as it stops.
    pub const TRACE_ENV: &'static str = "HANDBLOCKS_WAIT_TRACE";

    /// A waiter as a stage makes it: with a trace when `HANDBLOCKS_WAIT_TRACE` names a folder
    /// and the strategy is adaptive (the first 65,536 arrivals: ~9 minutes at 120 Hz).
    pub fn for_stage(strategy: WaitStrategy) -> Waiter {
        let mut w = Waiter::new(strategy);
        if strategy == WaitStrategy::Adaptive && std::env::var_os(Self::TRACE_ENV).is_some() {
            w.keep_trace(1 << 16);
        }
        w
    }

    /// How an adaptive stage's waits went, in a line, and its trace written as
    /// `$HANDBLOCKS_WAIT_TRACE/wait-STAGE.csv` when one was kept. Where each publish fell
    /// against its window: before it opened (the wait slept through it: the period or the
    /// wake-up was mispredicted), inside it but not found by polling (the sender could not run
    /// while this stage polled: they share a CPU), or after it closed.
    pub fn finish(&self, stage: &str) -> String {
        let count = |o: WaitOutcome| self.trace().iter().filter(|r| r.outcome() == o).count();
        let (early, missed, late) = (
            count(WaitOutcome::Early),
            count(WaitOutcome::Inside),
            count(WaitOutcome::Late),
        );
        let mut line = format!(
            "handblocks {stage}: adaptive wait: {} of {} arrivals found in the poll window",
            self.in_window, self.arrivals
        );
        if let (Some(trace), Some(dir)) = (&self.trace, std::env::var_os(Self::TRACE_ENV)) {
            let path = std::path::Path::new(&dir).join(format!("wait-{stage}.csv"));
            let mut text = String::from(WaitRecord::CSV_HEADER);
            for r in trace {
                text.push('\n');
                text.push_str(&r.csv());
            }
            text.push('\n');
            line += &format!(
                "; of the others, published before the window {early}, inside it but not seen \
                 by polling {missed}, after it {late}"
            );
            match std::fs::write(&path, text) {
                Ok(()) => line += &format!("; trace: {}", path.display()),
                Err(e) => line += &format!("; trace not written to {}: {e}", path.display()),
            }
        }
        line
    }

    pub fn strategy(&self) -> WaitStrategy {
        self.strategy
    }

    /// Returns when any of `inlets` may have a sample, or after `timeout`.
    pub fn wait(&mut self, inlets: &[&dyn Wakeable], timeout: Duration) -> Result<(), BusError> {
        self.polled = false;
        self.window_ns = (0, 0);
        let r = self.wait_by_strategy(inlets, timeout);
        if self.trace.is_some() {
            self.returned_ns = monotonic_ns();
        }
        r
    }

    fn wait_by_strategy(
        &mut self,
        inlets: &[&dyn Wakeable],
        timeout: Duration,
    ) -> Result<(), BusError> {
        let any = || inlets.iter().any(|i| i.has_samples());
        match self.strategy {
            WaitStrategy::Event => wait_any(inlets, timeout),
            WaitStrategy::Spin => {
                let end = monotonic_ns() + timeout.as_nanos() as u64;
                while !any() && monotonic_ns() < end {
                    poll_pause();
                }
                self.drain_wakeups(inlets);
                Ok(())
            }
            WaitStrategy::Adaptive => {
                if any() {
                    return Ok(());
                }
                let now = monotonic_ns();
                let end = now + timeout.as_nanos() as u64;
                if let (Some(last), true) = (self.last_arrival_ns, self.period_ns > 0) {
                    let due = last + self.period_ns;
                    let open = due.saturating_sub(self.wake_late_ns + POLL_MARGIN_NS);
                    let close = due + self.wake_late_ns + POLL_MARGIN_NS;
                    self.window_ns = (open, close);
                    // Sleep until the window opens, or a sample wakes us first. A wake-up
                    // with nothing to read (the notification of a sample already taken by
                    // polling arrives after it) sleeps again: polling from there would spin
                    // away the period.
                    let mut now = now;
                    while now < open.min(end) {
                        wait_any(inlets, Duration::from_nanos(open.min(end) - now))?;
                        if any() {
                            return Ok(());
                        }
                        let woke = monotonic_ns();
                        if woke >= open {
                            // Woken by the deadline: learn how late (a running mean).
                            self.wake_late_ns = (3 * self.wake_late_ns + (woke - open)) / 4;
                        }
                        now = woke;
                    }
                    let close = close.min(end);
                    while !any() && monotonic_ns() < close {
                        poll_pause();
                    }
                    if any() {
                        self.polled = true;
                        self.drain_wakeups(inlets);
                        return Ok(());
                    }
                }
                let left = end.saturating_sub(monotonic_ns());
                wait_any(inlets, Duration::from_nanos(left))
            }
        }
    }

    /// Tells the waiter the first sample after a wait was published at `now_ns` (its stamp's
    /// `publish_ns`: the receive time would carry this wake-up's lateness into the next
    /// prediction): the period estimate follows the time between arrivals, ignoring bursts and
    /// gaps (a stall is not a new period).
    pub fn arrived(&mut self, now_ns: u64) {
        self.arrivals += 1;
        self.in_window += u64::from(self.polled);
        if let Some(trace) = self.trace.as_mut().filter(|t| t.len() < t.capacity()) {
            trace.push(WaitRecord {
                publish_ns: now_ns,
                open_ns: self.window_ns.0,
                close_ns: self.window_ns.1,
                returned_ns: self.returned_ns,
                polled: self.polled,
            });
        }
        if let Some(last) = self.last_arrival_ns {
            let gap = now_ns.saturating_sub(last);
            if self.period_ns == 0 {
                self.period_ns = gap;
            } else if gap > self.period_ns / 2 && gap < 2 * self.period_ns {
                self.period_ns = (7 * self.period_ns + gap) / 8;
            }
        }
        self.last_arrival_ns = Some(now_ns);
    }

    fn drain_wakeups(&self, inlets: &[&dyn Wakeable]) {
        for inlet in inlets {
            take_wake_ups(*inlet);
        }
    }
}

/// Between two looks at the inlets while polling: gives the CPU to any other thread that is
/// ready to run on it, else returns at once (~1 us). A bare spin starved the sender whenever
/// it shared the poller's CPU (the launcher puts a session's pipeline on one CPU on a 2-CPU
/// machine): per-arrival traces (`HANDBLOCKS_WAIT_TRACE`) showed the scripted source's
/// 120 Hz publishes spread over 7.6-9.0 ms apart while two stages polled windows up to 1 ms
/// wide, 2 of 480 samples found by polling, and `spin` took origin -> world to 5.6 ms.
#[inline]
fn poll_pause() {
    // SAFETY: sched_yield takes no arguments and only reschedules this thread.
    unsafe { libc::sched_yield() };
}

/// Sleeps until one of `fds` is readable or `timeout` passes, to the nanosecond (`ppoll`;
/// iceoryx2's own timed waits round to milliseconds). A signal ends it early, as a wake-up.
fn poll_readable(fds: &mut [libc::pollfd], timeout: Duration) -> Result<(), BusError> {
    let ts = libc::timespec {
        tv_sec: timeout.as_secs().min(i32::MAX as u64) as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: `fds` is a valid slice of initialised pollfd entries; `ts` outlives the call; a
    // null signal mask keeps the current one.
    let r = unsafe {
        libc::ppoll(
            fds.as_mut_ptr(),
            fds.len() as libc::nfds_t,
            &ts,
            std::ptr::null(),
        )
    };
    if r < 0 {
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(BusError::Wait(e.into()));
        }
    }
    Ok(())
}

/// Most inlets one [`wait_any`] call can watch.
pub const MAX_WAIT: usize = 8;

/// Sleeps until any of `inlets` may have a sample, or `timeout` passes, and consumes their
/// wake-ups. Unlike iceoryx2's WaitSet it allocates nothing per wake-up (it polls the
/// listeners' descriptors on the stack), so it can sit on the per-sample path.
pub fn wait_any(inlets: &[&dyn Wakeable], timeout: Duration) -> Result<(), BusError> {
    wait_any_or(inlets, None, timeout)
}

/// [`wait_any`], also woken when `other` (a descriptor of the caller's: an eventfd another
/// thread writes, say) is readable; reading it is the caller's. The bridge sleeps so on its
/// inlets and on the samples its zenoh callback queued, in one thread, without polling.
pub fn wait_any_or(
    inlets: &[&dyn Wakeable],
    other: Option<std::os::fd::RawFd>,
    timeout: Duration,
) -> Result<(), BusError> {
    wait_each(inlets.iter().copied(), other, timeout)
}

/// [`wait_any_or`] over inlets a caller holds in its own structures (trait objects, say):
/// `inlets` is walked twice, to poll and to consume the wake-ups, so no list is built; the
/// first [`MAX_WAIT`] are watched.
pub fn wait_each<'a>(
    inlets: impl Iterator<Item = &'a dyn Wakeable> + Clone,
    other: Option<std::os::fd::RawFd>,
    timeout: Duration,
) -> Result<(), BusError> {
    use iceoryx2::prelude::FileDescriptorBased;
    // Inlets of a stage woken by its doorbell share it: with no other descriptor to watch,
    // the stage sleeps on the doorbell alone.
    let doorbell = inlets.clone().find_map(|i| match i.wake_source() {
        WakeSource::Doorbell(d) => Some(d),
        WakeSource::Listener(_) => None,
    });
    let listeners = inlets
        .clone()
        .filter(|i| i.wake_source().listener().is_some())
        .count();
    if let (Some(doorbell), 0, None) = (doorbell, listeners, other) {
        doorbell.wait_unless(|| inlets.clone().any(|i| i.has_samples()), timeout);
        return Ok(());
    }
    let mut fds = [libc::pollfd {
        fd: -1,
        events: 0,
        revents: 0,
    }; MAX_WAIT + 1];
    let mut n = 0;
    for inlet in inlets.clone() {
        if let (Some(listener), true) = (inlet.wake_source().listener(), n < MAX_WAIT) {
            // SAFETY: the descriptor stays owned by the listener, which outlives this call; we
            // only poll it.
            fds[n].fd = unsafe { listener.file_descriptor().native_handle() };
            fds[n].events = libc::POLLIN;
            n += 1;
        }
    }
    let mut watched = n;
    if let Some(fd) = other {
        fds[n].fd = fd;
        fds[n].events = libc::POLLIN;
        watched += 1;
    }
    // A doorbell cannot join a `ppoll`: a stage that mixes one with descriptors (none of the
    // table's does) looks at its doorbell's inlets every millisecond.
    let timeout = if doorbell.is_some() && !inlets.clone().any(|i| i.has_samples()) {
        timeout.min(Duration::from_millis(1))
    } else if doorbell.is_some() {
        Duration::ZERO
    } else {
        timeout
    };
    poll_readable(&mut fds[..watched], timeout)?;
    for inlet in inlets {
        take_wake_ups(inlet);
    }
    Ok(())
}

/// The descriptor that becomes readable when `inlet` is woken, for a caller that must sleep
/// on it without holding something else (Python's reader sleeps with the interpreter's lock
/// released, so its other threads run): [`wait_fd`], then [`take_wake_ups`]. The listener
/// owns it; it is valid while the inlet is.
///
/// None for an inlet of a stage woken by its doorbell, which has no descriptor (sleep on it
/// with [`Inlet::wait`] or [`wait_any`]).
pub fn wake_fd(inlet: &dyn Wakeable) -> Option<std::os::fd::RawFd> {
    use iceoryx2::prelude::FileDescriptorBased;
    // SAFETY: the descriptor stays owned by the listener; the caller only polls it.
    inlet
        .wake_source()
        .listener()
        .map(|l| unsafe { l.file_descriptor().native_handle() })
}

/// Sleeps until `fd` (a [`wake_fd`]) is readable, or `timeout` passes, to the nanosecond.
pub fn wait_fd(fd: std::os::fd::RawFd, timeout: Duration) -> Result<(), BusError> {
    let mut fds = [libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    }];
    poll_readable(&mut fds, timeout)
}

/// Takes the wake-ups `inlet` has had, so that its descriptor sleeps again.
pub fn take_wake_ups(inlet: &dyn Wakeable) {
    if let Some(listener) = inlet.wake_source().listener() {
        let _ = listener.try_wait(|_| {});
    }
}

/// Sleeps on `listener` until a sample may have arrived, or `timeout` passes, to the
/// nanosecond; consumes the wake-ups.
pub(super) fn wait_on(
    listener: &Listener<ipc::Service>,
    timeout: Duration,
) -> Result<(), BusError> {
    use iceoryx2::prelude::FileDescriptorBased;
    // SAFETY: the descriptor is owned by the listener, which outlives the call.
    let fd = unsafe { listener.file_descriptor().native_handle() };
    let mut fds = [libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    }];
    poll_readable(&mut fds, timeout)?;
    let _ = listener.try_wait(|_| {});
    Ok(())
}

/// A wake-up another thread can give a stage sleeping in [`wait_each`] (its `other`
/// descriptor): an eventfd, readable once [`Wake::wake`] was called. For work that arrives off
/// the bus (a network library's callback, an async server's task), handed over through a queue.
#[derive(Debug)]
pub struct Wake {
    fd: std::os::fd::OwnedFd,
}

impl Wake {
    pub fn new() -> std::io::Result<Wake> {
        use std::os::fd::FromRawFd;
        // SAFETY: plain syscall; the descriptor is owned by the returned OwnedFd.
        let fd = unsafe { libc::eventfd(0, libc::EFD_NONBLOCK | libc::EFD_CLOEXEC) };
        if fd < 0 {
            return Err(std::io::Error::last_os_error());
        }
        // SAFETY: `fd` is a fresh descriptor nobody else owns.
        Ok(Wake {
            fd: unsafe { std::os::fd::OwnedFd::from_raw_fd(fd) },
        })
    }

    /// The descriptor to sleep on (readable after a wake-up).
    pub fn fd(&self) -> std::os::fd::RawFd {
        use std::os::fd::AsRawFd;
        self.fd.as_raw_fd()
    }

    /// Wakes the sleeper (from any thread; never blocks).
    pub fn wake(&self) {
        let one: u64 = 1;
        // SAFETY: writes 8 bytes from a live u64 to an eventfd; a full counter (EAGAIN) is
        // fine: the sleeper is awake already.
        unsafe {
            libc::write(self.fd(), &one as *const u64 as *const libc::c_void, 8);
        }
    }

    /// Consumes the wake-ups given so far (the work itself is taken from its queue).
    pub fn clear(&self) {
        let mut n: u64 = 0;
        // SAFETY: reads 8 bytes into a live u64 from a non-blocking eventfd.
        unsafe {
            libc::read(self.fd(), &mut n as *mut u64 as *mut libc::c_void, 8);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The period follows the time between publications and ignores a stall or a burst.
    #[test]
    fn the_adaptive_waiter_learns_the_period_and_ignores_stalls() {
        let mut w = Waiter::new(WaitStrategy::Event);
        let period = 8_333_333u64;
        for k in 0..20u64 {
            // 20 us of jitter either way.
            let jitter = if k % 2 == 0 { 20_000 } else { 0 };
            w.arrived(k * period + jitter);
        }
        assert!(
            (w.period_ns as i64 - period as i64).abs() < 30_000,
            "{}",
            w.period_ns
        );
        let before = w.period_ns;
        w.arrived(20 * period + 50 * period); // a stall
        w.arrived(70 * period + 1000); // a burst right after
        assert_eq!(w.period_ns, before);
        assert_eq!(w.arrivals, 22);
        assert_eq!(w.in_window, 0, "nothing was polled");
    }

    /// A trace keeps one record per arrival, up to its capacity, with the window the wait
    /// polled in, and reads back as CSV relative to the window's opening.
    #[test]
    fn a_kept_trace_records_each_arrival_against_its_window() {
        let mut w = Waiter::new(WaitStrategy::Adaptive);
        w.keep_trace(2);
        for (k, polled) in [(0u64, false), (1, true), (2, false)] {
            w.window_ns = (1_000 + k * 10_000, 1_500 + k * 10_000);
            w.returned_ns = 1_300 + k * 10_000;
            w.polled = polled;
            w.arrived(1_200 + k * 10_000);
        }
        assert_eq!(w.arrivals, 3);
        assert_eq!(w.in_window, 1);
        let t = w.trace();
        assert_eq!(t.len(), 2, "capacity 2: the third is counted, not kept");
        assert_eq!(
            t[1],
            WaitRecord {
                publish_ns: 11_200,
                open_ns: 11_000,
                close_ns: 11_500,
                returned_ns: 11_300,
                polled: true
            }
        );
        assert_eq!(t[1].csv(), "11200,200,500,300,1");
        assert_eq!(WaitRecord::from_csv(&t[1].csv()), Some(t[1]));
        assert_eq!(
            WaitRecord::CSV_HEADER.split(',').count(),
            t[0].csv().split(',').count()
        );
    }
}
