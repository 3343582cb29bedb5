//! Both drivers read at once, each on its own thread, delivering to one consumer.
//!
//! The glove (about 100 Hz) and the tracker (120 Hz shared among stations) are independent
//! serial lines: reading them in turn on one thread would make each wait out the other's read
//! slice. So each driver blocks on its own line in its own thread and hands each sample, the
//! moment it is stamped, to the consumer (the acquisition loop that publishes) over a bounded,
//! preallocated channel. If the consumer stalls, samples are dropped and counted rather than
//! queued: a stale hand pose is worth nothing.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use common::{GloveSample, TrackerSample};

use super::{DeviceError, Glove, LinkStats, ReadOutcome, Tracker};

/// What the reader threads deliver.
#[derive(Debug, Clone)]
pub enum DeviceEvent {
    Glove(GloveSample),
    Tracker(TrackerSample),
    /// A device problem the driver is already handling (reconnecting): to be logged.
    Error(DeviceError),
}

/// The two reader threads and the channel they deliver to.
pub struct DeviceReaders {
    rx: Receiver<DeviceEvent>,
    stop: Arc<AtomicBool>,
    dropped: Arc<AtomicU64>,
    glove: Option<JoinHandle<LinkStats>>,
    tracker: Option<JoinHandle<LinkStats>>,
}

/// Final counters of both drivers, and the samples the consumer was too slow to take.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReaderStats {
    pub glove: LinkStats,
    pub tracker: LinkStats,
    pub dropped: u64,
}

const CAPACITY: usize = 64;

/// What a reader thread needs of a driver.
trait Driver: Send + 'static {
    type Sample: Copy + Default + Send;
    fn read_into(&mut self, s: &mut Self::Sample) -> Result<ReadOutcome, DeviceError>;
    fn event(s: Self::Sample) -> DeviceEvent;
    fn counters(&self) -> LinkStats;
}

impl Driver for Glove {
    type Sample = GloveSample;
    fn read_into(&mut self, s: &mut GloveSample) -> Result<ReadOutcome, DeviceError> {
        self.read(s)
    }
    fn event(s: GloveSample) -> DeviceEvent {
        DeviceEvent::Glove(s)
    }
    fn counters(&self) -> LinkStats {
        self.stats()
    }
}

impl Driver for Tracker {
    type Sample = TrackerSample;
    fn read_into(&mut self, s: &mut TrackerSample) -> Result<ReadOutcome, DeviceError> {
        self.read(s)
    }
    fn event(s: TrackerSample) -> DeviceEvent {
        DeviceEvent::Tracker(s)
    }
    fn counters(&self) -> LinkStats {
        self.stats()
    }
}

fn reader<D: Driver>(
    name: &str,
    mut driver: D,
    tx: SyncSender<DeviceEvent>,
    stop: Arc<AtomicBool>,
    dropped: Arc<AtomicU64>,
) -> std::io::Result<JoinHandle<LinkStats>> {
    std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            let mut sample = D::Sample::default();
            while !stop.load(Ordering::Relaxed) {
                let event = match driver.read_into(&mut sample) {
                    Ok(ReadOutcome::Sample) => D::event(sample),
                    Ok(ReadOutcome::Pending) => continue,
                    Err(e) => DeviceEvent::Error(e),
                };
                match tx.try_send(event) {
                    Ok(()) => {}
                    Err(TrySendError::Full(_)) => {
                        dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(TrySendError::Disconnected(_)) => break,
                }
            }
            driver.counters()
        })
}

impl DeviceReaders {
    /// Starts a reader thread per driver (either may be absent, e.g. a tracker-only setup).
    pub fn spawn(glove: Option<Glove>, tracker: Option<Tracker>) -> std::io::Result<DeviceReaders> {
        let (tx, rx) = sync_channel(CAPACITY);
        let stop = Arc::new(AtomicBool::new(false));
        let dropped = Arc::new(AtomicU64::new(0));
        let glove = match glove {
            Some(g) => Some(reader(
                "glove",
                g,
                tx.clone(),
                stop.clone(),
                dropped.clone(),
            )?),
            None => None,
        };
        let tracker = match tracker {
            Some(t) => Some(reader("tracker", t, tx, stop.clone(), dropped.clone())?),
            None => None,
        };
        Ok(DeviceReaders {
            rx,
            stop,
            dropped,
            glove,
            tracker,
        })
    }

    /// The next event, waiting at most `timeout` (so the caller can check for shutdown).
    pub fn recv_timeout(&self, timeout: Duration) -> Option<DeviceEvent> {
        match self.rx.recv_timeout(timeout) {
            Ok(ev) => Some(ev),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => {
                // Both readers are gone (they only end on stop): wait as asked, do not spin.
                std::thread::sleep(timeout);
                None
            }
        }
    }

    /// Samples dropped so far because the consumer fell behind.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Stops both threads (each within one read slice), closing the devices.
    pub fn stop(mut self) -> ReaderStats {
        self.stop_inner()
    }

    /// Stops both threads, then hands `deliver` every event they had sent and nobody took:
    /// the records read as the session stopped are published too, so a driver's sample count
    /// is what was published (but for samples the consumer fell behind on, `dropped`).
    pub fn stop_delivering(mut self, mut deliver: impl FnMut(DeviceEvent)) -> ReaderStats {
        // The readers use try_send: they never block on the channel, so they end without it
        // being drained, and what they sent stays in it for `deliver`.
        let stats = self.join_readers();
        while let Ok(ev) = self.rx.try_recv() {
            deliver(ev);
        }
        stats
    }

    fn stop_inner(&mut self) -> ReaderStats {
        // Unblock a reader waiting on a full channel: it uses try_send, so none does; drain
        // anyway so the threads see an open channel until they notice the flag.
        while self.rx.try_recv().is_ok() {}
        self.join_readers()
    }

    /// Tells both threads to stop and waits for them: their final counters.
    fn join_readers(&mut self) -> ReaderStats {
        self.stop.store(true, Ordering::Relaxed);
        let join =
            |h: Option<JoinHandle<LinkStats>>| h.and_then(|h| h.join().ok()).unwrap_or_default();
        let glove = join(self.glove.take());
        let tracker = join(self.tracker.take());
        ReaderStats {
            glove,
            tracker,
            dropped: self.dropped(),
        }
    }
}

impl Drop for DeviceReaders {
    fn drop(&mut self) {
        if self.glove.is_some() || self.tracker.is_some() {
            self.stop_inner();
        }
    }
}
