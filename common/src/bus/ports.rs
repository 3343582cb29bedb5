//! The ports: outlets that stamp, send and count, inlets that receive and count gaps, and
//! what a restarted or lossless session adds to them.

use super::*;

/// A publisher with its notifier: stamps `seq` and `publish_ns`, sends, wakes the readers.
pub struct Outlet<P: TopicSpec> {
    pub(super) publisher: Publisher<ipc::Service, P::Sample, ()>,
    pub(super) notifier: Notifier<ipc::Service>,
    pub(super) next_seq: u64,
    /// Seqs this topic's source never sent ([`Outlet::skip_to`]).
    pub(super) skipped: u64,
    /// A supervised process's next seq (and skipped), kept where its restart finds it.
    pub(super) kept: Option<SeqStore>,
    /// On a lossless bus, until every reader is connected ([`ConnectGate`]).
    pub(super) gate: Option<ConnectGate>,
}

impl<P: TopicSpec> Outlet<P> {
    /// Sends `value` with the next seq and `publish_ns` = now; returns the stamp it went with.
    /// `value`'s `source_time_ns` and `origin_ns` travel as given.
    pub fn publish(&mut self, value: &P::Sample) -> Result<Stamp, BusError> {
        let send_err = |e: String| BusError::Send {
            topic: P::TOPIC.name(),
            reason: e,
        };
        ConnectGate::pass(&mut self.gate)?;
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| send_err(format!("{e:?}")))?;
        let mut sample = sample.write_payload(*value);
        let stamp = sample.payload_mut().stamp_mut();
        stamp.seq = self.next_seq;
        stamp.publish_ns = monotonic_ns();
        let sent = *stamp;
        // Kept before the send: a process killed between the two skips a seq (a gap its
        // readers count) rather than sending one seq twice.
        if let Some(kept) = &self.kept {
            kept.store(0, self.next_seq + 1);
        }
        sample.send().map_err(|e| send_err(format!("{e:?}")))?;
        self.notifier
            .notify()
            .map_err(|e| send_err(format!("{e:?}")))?;
        self.next_seq += 1;
        Ok(sent)
    }

    /// Sends `value` as [`Outlet::publish`] does, under seq `seq` if no later seq has gone
    /// out (the seqs skipped count as this outlet's gaps), else under the next: the bridge
    /// forwards another machine's samples with their own seqs, so what the link lost shows as
    /// gaps here and in every reader.
    pub fn publish_as(&mut self, value: &P::Sample, seq: u64) -> Result<Stamp, BusError> {
        self.skip_to(seq);
        self.publish(value)
    }

    pub fn topic(&self) -> Topic {
        P::TOPIC
    }

    /// This outlet's counter for the latency report.
    pub fn counter(&self) -> TopicCounter {
        sent_counter(P::TOPIC, self.next_seq, self.skipped)
    }

    /// A restarted source's next sample gets seq `seq` (its deadline grid's index, where the
    /// dead one would have got to): the seqs between were never sent, samples lost while it
    /// was down, which every reader counts as a gap. Its counter says how many it skipped
    /// (`gaps` of a publisher's counter). A seq already used is not used again.
    pub fn skip_to(&mut self, seq: u64) {
        if seq <= self.next_seq {
            return;
        }
        self.skipped += seq - self.next_seq;
        self.next_seq = seq;
        if let Some(kept) = &self.kept {
            kept.store(1, self.skipped);
            kept.store(0, self.next_seq);
        }
    }
}

/// What names the files with which inlets on a lossless bus say they are connected.
pub(super) const CONNECTED_MARK: &str = "connected.";

/// Issue 28: a lossless publisher must not fill the buffer of a reader that is not yet
/// connected to it. iceoryx2 connects a subscriber to a publisher that appeared after it only
/// when the subscriber next receives; until then its buffer fills, and once full, a send with
/// back-pressure does not wait for it but skips it ("to prevent a deadlock on sender side").
/// A speed-0 replay sends its first thousand samples in tens of milliseconds: a reader that
/// was descheduled just then (the recorder, niced beside a renderer compiling its shaders)
/// lost 33 glove and 32 tracker samples. So on a lossless bus each inlet marks itself
/// connected when its first sample arrives (a file in the session's folder), and each outlet
/// sends at most half its readers' buffer until there are as many marks of its topic as the
/// topic has subscribers. It costs a branch per sample after that, and nothing on a bus that
/// is not lossless.
pub(super) struct ConnectGate {
    pub(super) topic: Topic,
    pub(super) root: PathBuf,
    /// Samples that may go before every reader is connected.
    pub(super) free: u64,
    pub(super) sent: u64,
    /// The topic's subscribers now.
    pub(super) subscribers: Box<dyn Fn() -> usize>,
}

impl ConnectGate {
    /// Lets the next sample go: at once while it fits in the readers' buffers, else once
    /// every reader is connected (then the gate is gone), or when the process is asked to
    /// stop.
    fn pass(gate: &mut Option<ConnectGate>) -> Result<(), BusError> {
        let Some(g) = gate else { return Ok(()) };
        if g.sent < g.free {
            g.sent += 1;
            return Ok(());
        }
        let started = std::time::Instant::now();
        let mut said = Duration::ZERO;
        loop {
            let readers = (g.subscribers)();
            let connected = g.connected();
            if connected >= readers || crate::shutdown::requested() {
                break;
            }
            // Waiting this long means a reader does not run: say so, every 5 s.
            if started.elapsed() >= said + Duration::from_secs(5) {
                said = started.elapsed();
                eprintln!(
                    "handblocks: the {} topic waits {:.0} s for {} of its {readers} readers to                      take their first sample (a lossless session sends nothing a reader could                      miss)",
                    g.topic.name(),
                    said.as_secs_f64(),
                    readers - connected
                );
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        *gate = None;
        Ok(())
    }

    /// Inlets of this topic that have marked themselves connected.
    pub(super) fn connected(&self) -> usize {
        let prefix = format!("{CONNECTED_MARK}{}.", self.topic.name());
        std::fs::read_dir(&self.root).map_or(0, |entries| {
            entries
                .flatten()
                .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
                .count()
        })
    }
}

/// A publisher's counter: samples sent, seqs skipped (never sent), the last seq.
fn sent_counter(topic: Topic, next_seq: u64, skipped: u64) -> TopicCounter {
    TopicCounter {
        topic: topic as u32,
        role: 0,
        count: next_seq - skipped,
        gaps: skipped,
        last_seq: next_seq.wrapping_sub(1),
    }
}

/// What a subscriber counted: samples received and the gaps in `seq`. Cells, so that an inlet
/// can be read while its listener is attached to a WaitSet.
#[derive(Default)]
pub(super) struct SeqCount {
    pub(super) received: Cell<u64>,
    pub(super) gaps: Cell<u64>,
    pub(super) last_seq: Cell<Option<u64>>,
    /// A restarted reader: the samples before its first were its dead incarnation's to count.
    pub(super) from_first: bool,
    /// On a lossless bus: the file this inlet creates on its first sample ([`ConnectGate`]);
    /// taken (None) once created.
    pub(super) connected_mark: Cell<Option<PathBuf>>,
}

impl SeqCount {
    pub(super) fn saw(&self, seq: u64) {
        // A seq that jumps ahead means samples were lost (overwritten unread, or never sent to
        // us); a seq that goes back means the publisher restarted.
        let missed = match self.last_seq.get() {
            Some(last) if seq > last + 1 => seq - last - 1,
            Some(_) => 0,
            None if self.from_first => 0,
            None => seq,
        };
        self.gaps.set(self.gaps.get() + missed);
        self.last_seq.set(Some(seq));
        self.received.set(self.received.get() + 1);
    }

    /// After a sample was seen: on the first, says so to a lossless publisher's
    /// [`ConnectGate`] (once; one compare per sample after that).
    fn mark_connected(&self, topic: Topic) -> Result<(), BusError> {
        if self.received.get() != 1 {
            return Ok(());
        }
        let Some(path) = self.connected_mark.take() else {
            return Ok(());
        };
        open_restart_file(&path)
            .map(drop)
            .map_err(|e| BusError::Receive {
                topic: topic.name(),
                reason: format!(
                    "cannot tell the publisher this reader is connected ({}): {e}",
                    path.display()
                ),
            })
    }

    fn counter(&self, topic: Topic) -> TopicCounter {
        TopicCounter {
            topic: topic as u32,
            role: 1,
            count: self.received.get(),
            gaps: self.gaps.get(),
            last_seq: self.last_seq.get().unwrap_or(u64::MAX),
        }
    }
}

/// Two u64 in a file of the session's folder, mapped into this process's memory: an outlet's
/// next seq and the seqs it skipped, which outlive the process (the page cache keeps them when
/// the process is killed) for its restart to read. A store is a plain memory write: no system
/// call, no lock.
pub(super) struct SeqStore {
    pub(super) words: std::ptr::NonNull<std::sync::atomic::AtomicU64>,
}

/// The bytes a [`SeqStore`] maps.
const SEQ_STORE_BYTES: usize = 16;

impl SeqStore {
    pub(super) fn open(path: &StdPath) -> std::io::Result<SeqStore> {
        use std::os::unix::io::AsRawFd;
        let file = open_restart_file(path)?;
        if file.metadata()?.len() < SEQ_STORE_BYTES as u64 {
            file.set_len(SEQ_STORE_BYTES as u64)?;
        }
        // SAFETY: maps the 16 bytes of a file we opened read-write and sized to at least 16;
        // the mapping is page-aligned, so it holds two aligned AtomicU64, and it stays valid
        // until `drop` unmaps it (closing the file does not end a mapping).
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                SEQ_STORE_BYTES,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if p == libc::MAP_FAILED {
            return Err(std::io::Error::last_os_error());
        }
        std::ptr::NonNull::new(p.cast())
            .map(|words| SeqStore { words })
            .ok_or_else(|| std::io::Error::other("mmap returned null"))
    }

    /// Word `i` (0: next seq, 1: skipped).
    fn word(&self, i: usize) -> &std::sync::atomic::AtomicU64 {
        // SAFETY: `words` points at two AtomicU64 in our live mapping (see `open`); i < 2.
        unsafe { &*self.words.as_ptr().add(i.min(1)) }
    }

    pub(super) fn load(&self, i: usize) -> u64 {
        self.word(i).load(std::sync::atomic::Ordering::Relaxed)
    }

    pub(super) fn store(&self, i: usize, v: u64) {
        self.word(i).store(v, std::sync::atomic::Ordering::Relaxed)
    }
}

impl Drop for SeqStore {
    fn drop(&mut self) {
        // SAFETY: unmaps the bytes `open` mapped, once; nothing refers to them after.
        unsafe { libc::munmap(self.words.as_ptr().cast(), SEQ_STORE_BYTES) };
    }
}

/// A subscriber with its listener: counts what arrives and the gaps in `seq`.
pub struct Inlet<P: TopicSpec> {
    pub(super) subscriber: Subscriber<ipc::Service, P::Sample, ()>,
    pub(super) listener: Listener<ipc::Service>,
    pub(super) seqs: SeqCount,
}

impl<P: TopicSpec> Inlet<P> {
    /// The next unread sample, zero-copy (it reads the publisher's memory), or None.
    pub fn receive(&self) -> Result<Option<Received<P::Sample>>, BusError> {
        let sample = self.subscriber.receive().map_err(|e| BusError::Receive {
            topic: P::TOPIC.name(),
            reason: format!("{e:?}"),
        })?;
        if let Some(s) = &sample {
            self.seqs.saw(s.payload().stamp().seq);
            self.seqs.mark_connected(P::TOPIC)?;
        }
        Ok(sample)
    }

    /// Sleeps until a sample may have arrived, or `timeout` passes, to the nanosecond;
    /// consumes the wake-ups.
    pub fn wait(&self, timeout: Duration) -> Result<(), BusError> {
        wait_on(&self.listener, timeout)
    }

    pub fn received(&self) -> u64 {
        self.seqs.received.get()
    }

    pub fn topic(&self) -> Topic {
        P::TOPIC
    }

    /// This inlet's counter for the latency report.
    pub fn counter(&self) -> TopicCounter {
        self.seqs.counter(P::TOPIC)
    }
}

/// A publisher of a slice topic with its notifier: each sample is a header and 0 to
/// `capacity` elements, written straight into shared memory by [`SliceOutlet::publish_with`].
pub struct SliceOutlet<P: SliceTopicSpec> {
    pub(super) publisher: Publisher<ipc::Service, [P::Element], P::Header>,
    pub(super) notifier: Notifier<ipc::Service>,
    pub(super) capacity: usize,
    pub(super) next_seq: u64,
    /// As [`Outlet`]'s.
    pub(super) skipped: u64,
    pub(super) kept: Option<SeqStore>,
    pub(super) gate: Option<ConnectGate>,
}

impl<P: SliceTopicSpec> SliceOutlet<P> {
    /// Sends one sample of `len` elements: `write_header` fills the header (its stamp's
    /// `source_time_ns` and `origin_ns` travel as written; `seq` and `publish_ns` are set
    /// here), `element(i)` gives element `i`, written in place. Nothing is copied and nothing
    /// allocated. Returns the stamp the sample went with.
    pub fn publish_with(
        &mut self,
        len: usize,
        write_header: impl FnOnce(&mut P::Header),
        element: impl FnMut(usize) -> P::Element,
    ) -> Result<Stamp, BusError> {
        let send_err = |e: String| BusError::Send {
            topic: P::TOPIC.name(),
            reason: e,
        };
        if len > self.capacity {
            return Err(send_err(format!(
                "a sample of {len} elements; this session's samples hold at most {}",
                self.capacity
            )));
        }
        ConnectGate::pass(&mut self.gate)?;
        let mut sample = self
            .publisher
            .loan_slice_uninit(len)
            .map_err(|e| send_err(format!("{e:?}")))?;
        write_header(sample.user_header_mut());
        let mut sample = sample.write_from_fn(element);
        let stamp = sample.user_header_mut().stamp_mut();
        stamp.seq = self.next_seq;
        stamp.publish_ns = monotonic_ns();
        let sent = *stamp;
        // Kept before the send: a process killed between the two skips a seq (a gap its
        // readers count) rather than sending one seq twice.
        if let Some(kept) = &self.kept {
            kept.store(0, self.next_seq + 1);
        }
        sample.send().map_err(|e| send_err(format!("{e:?}")))?;
        self.notifier
            .notify()
            .map_err(|e| send_err(format!("{e:?}")))?;
        self.next_seq += 1;
        Ok(sent)
    }

    /// Sends a copy of `header` and `elements` (for tests and tools; a stage writes in place
    /// with [`SliceOutlet::publish_with`]).
    pub fn publish(
        &mut self,
        header: &P::Header,
        elements: &[P::Element],
    ) -> Result<Stamp, BusError> {
        self.publish_with(elements.len(), |h| *h = *header, |i| elements[i])
    }

    /// The most elements a sample holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// As [`Outlet::publish_as`]: `publish_with` under seq `seq` unless a later one went out.
    pub fn publish_with_as(
        &mut self,
        seq: u64,
        len: usize,
        write_header: impl FnOnce(&mut P::Header),
        element: impl FnMut(usize) -> P::Element,
    ) -> Result<Stamp, BusError> {
        if seq > self.next_seq {
            self.skipped += seq - self.next_seq;
            self.next_seq = seq;
        }
        self.publish_with(len, write_header, element)
    }

    /// This outlet's counter for the latency report.
    pub fn counter(&self) -> TopicCounter {
        sent_counter(P::TOPIC, self.next_seq, self.skipped)
    }
}

/// A subscriber of a slice topic with its listener; counts like an [`Inlet`].
pub struct SliceInlet<P: SliceTopicSpec> {
    pub(super) subscriber: Subscriber<ipc::Service, [P::Element], P::Header>,
    pub(super) listener: Listener<ipc::Service>,
    pub(super) seqs: SeqCount,
}

impl<P: SliceTopicSpec> SliceInlet<P> {
    /// The next unread sample, zero-copy, or None: `user_header()` is its header, `payload()`
    /// its elements.
    pub fn receive(&self) -> Result<Option<ReceivedSlice<P>>, BusError> {
        let sample = self.subscriber.receive().map_err(|e| BusError::Receive {
            topic: P::TOPIC.name(),
            reason: format!("{e:?}"),
        })?;
        if let Some(s) = &sample {
            self.seqs.saw(s.user_header().stamp().seq);
            self.seqs.mark_connected(P::TOPIC)?;
        }
        Ok(sample)
    }

    /// Sleeps until a sample may have arrived, or `timeout` passes; consumes the wake-ups.
    pub fn wait(&self, timeout: Duration) -> Result<(), BusError> {
        wait_on(&self.listener, timeout)
    }

    pub fn received(&self) -> u64 {
        self.seqs.received.get()
    }

    pub fn topic(&self) -> Topic {
        P::TOPIC
    }

    /// This inlet's counter for the latency report.
    pub fn counter(&self) -> TopicCounter {
        self.seqs.counter(P::TOPIC)
    }
}
