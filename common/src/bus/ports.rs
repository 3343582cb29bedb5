//! The ports: outlets that stamp, send and count, inlets that receive and count gaps, and
//! what a restarted or lossless session adds to them.

use super::*;
use iceoryx2::port::ReceiveError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;

/// What iceoryx2 does differently for a fixed-size payload and for a slice of elements, and
/// one generic port needs: opening the service and receiving (iceoryx2 has an impl of each per
/// kind). Implemented, as iceoryx2's own `IceoryxSend` is, for every plain sample type and for
/// every slice of them, so a topic's payload has it whichever its kind.
pub trait PayloadKind: IceoryxSend + fmt::Debug + 'static {
    /// Opens or creates the service `builder` describes.
    fn open_or_create<H: fmt::Debug + ZeroCopySend>(
        builder: PubSubBuilder<Self, H>,
    ) -> Result<PubSubService<Self, H>, PublishSubscribeOpenOrCreateError>;
    /// The next unread sample, or None.
    fn receive<H: fmt::Debug + ZeroCopySend>(
        subscriber: &Subscriber<ipc::Service, Self, H>,
    ) -> Result<Option<Sample<ipc::Service, Self, H>>, ReceiveError>;
    /// A received sample's payload.
    fn payload<H: fmt::Debug + ZeroCopySend>(sample: &Sample<ipc::Service, Self, H>) -> &Self;
}

impl<T: ZeroCopySend + fmt::Debug + 'static> PayloadKind for T {
    fn open_or_create<H: fmt::Debug + ZeroCopySend>(
        builder: PubSubBuilder<T, H>,
    ) -> Result<PubSubService<T, H>, PublishSubscribeOpenOrCreateError> {
        builder.open_or_create()
    }
    fn receive<H: fmt::Debug + ZeroCopySend>(
        subscriber: &Subscriber<ipc::Service, T, H>,
    ) -> Result<Option<Sample<ipc::Service, T, H>>, ReceiveError> {
        subscriber.receive()
    }
    fn payload<H: fmt::Debug + ZeroCopySend>(sample: &Sample<ipc::Service, T, H>) -> &T {
        sample.payload()
    }
}

impl<T: ZeroCopySend + fmt::Debug + 'static> PayloadKind for [T] {
    fn open_or_create<H: fmt::Debug + ZeroCopySend>(
        builder: PubSubBuilder<[T], H>,
    ) -> Result<PubSubService<[T], H>, PublishSubscribeOpenOrCreateError> {
        builder.open_or_create()
    }
    fn receive<H: fmt::Debug + ZeroCopySend>(
        subscriber: &Subscriber<ipc::Service, [T], H>,
    ) -> Result<Option<Sample<ipc::Service, [T], H>>, ReceiveError> {
        subscriber.receive()
    }
    fn payload<H: fmt::Debug + ZeroCopySend>(sample: &Sample<ipc::Service, [T], H>) -> &[T] {
        sample.payload()
    }
}

/// iceoryx2's description of a publish-subscribe service, before it is opened.
pub type PubSubBuilder<Payload, Header> =
    iceoryx2::service::builder::publish_subscribe::Builder<Payload, Header, ipc::Service>;
/// iceoryx2's handle of an open publish-subscribe service, which makes its ports.
pub type PubSubService<Payload, Header> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, Payload, Header>;

/// A publisher with its notifier, of any topic ([`TopicLayout`]: a fixed-size sample, or a
/// header and a slice of elements): stamps `seq` and `publish_ns`, sends, wakes the readers,
/// and counts what it sent. One type for both kinds, as iceoryx2's `Publisher` is; how a
/// sample is written is the kind's: [`Outlet::publish`] for a fixed-size topic,
/// [`Outlet::publish_with`] for a slice topic.
pub struct Outlet<P: TopicLayout> {
    publisher: Publisher<ipc::Service, P::Payload, P::Header>,
    notifier: Notifier<ipc::Service>,
    /// The doorbells of the stages that read this topic and sleep on one
    /// ([`crate::topic::WakesBy::Doorbell`]), rung after each send.
    doorbells: Vec<Doorbell>,
    /// The most elements a sample holds (1 for a fixed-size topic).
    capacity: usize,
    next_seq: u64,
    /// Seqs this topic's source never sent ([`Outlet::skip_to`]).
    skipped: u64,
    /// A supervised process's next seq (and skipped), kept where its restart finds it.
    kept: Option<SeqStore>,
    /// On a lossless bus, until every reader is connected ([`ConnectGate`]).
    gate: Option<ConnectGate>,
}

/// A sample loaned from an outlet, written and not yet sent.
type Loaned<P> = iceoryx2::sample_mut::SampleMut<
    ipc::Service,
    <P as TopicLayout>::Payload,
    <P as TopicLayout>::Header,
>;

impl<P: TopicLayout> Outlet<P> {
    /// An outlet on `publisher`: a supervised one goes on from the seq its dead incarnation
    /// kept (`kept`).
    pub(super) fn new(
        publisher: Publisher<ipc::Service, P::Payload, P::Header>,
        notifier: Notifier<ipc::Service>,
        doorbells: Vec<Doorbell>,
        capacity: usize,
        kept: Option<SeqStore>,
        gate: Option<ConnectGate>,
    ) -> Outlet<P> {
        Outlet {
            publisher,
            notifier,
            doorbells,
            capacity,
            next_seq: kept.as_ref().map_or(0, |k| k.load(0)),
            skipped: kept.as_ref().map_or(0, |k| k.load(1)),
            kept,
            gate,
        }
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

    /// The stamp's `seq` and `publish_ns` of the sample about to go.
    fn stamp_next(&self, stamp: &mut Stamp) -> Stamp {
        stamp.seq = self.next_seq;
        stamp.publish_ns = monotonic_ns();
        *stamp
    }

    /// Sends a written and stamped sample and wakes the readers; what every kind shares.
    fn send(&mut self, sample: Loaned<P>, sent: Stamp) -> Result<Stamp, BusError> {
        // Kept before the send: a process killed between the two skips a seq (a gap its
        // readers count) rather than sending one seq twice.
        if let Some(kept) = &self.kept {
            kept.store(0, self.next_seq + 1);
        }
        sample.send().map_err(|e| BusError::send(P::TOPIC, e))?;
        self.notifier
            .notify()
            .map_err(|e| BusError::send(P::TOPIC, e))?;
        for doorbell in &self.doorbells {
            doorbell.ring();
        }
        self.next_seq += 1;
        Ok(sent)
    }
}

impl<P: TopicSpec> Outlet<P> {
    /// Sends `value` with the next seq and `publish_ns` = now; returns the stamp it went with.
    /// `value`'s `source_time_ns` and `origin_ns` travel as given.
    pub fn publish(&mut self, value: &P::Sample) -> Result<Stamp, BusError> {
        ConnectGate::pass(&mut self.gate)?;
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| BusError::send(P::TOPIC, e))?;
        let mut sample = sample.write_payload(*value);
        let sent = self.stamp_next(sample.payload_mut().stamp_mut());
        self.send(sample, sent)
    }

    /// Sends `value` as [`Outlet::publish`] does, under seq `seq` if no later seq has gone
    /// out (the seqs skipped count as this outlet's gaps), else under the next: the bridge
    /// forwards another machine's samples with their own seqs, so what the link lost shows as
    /// gaps here and in every reader.
    pub fn publish_as(&mut self, value: &P::Sample, seq: u64) -> Result<Stamp, BusError> {
        self.skip_to(seq);
        self.publish(value)
    }
}

impl<P: SliceTopicSpec> Outlet<P> {
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
        if len > self.capacity {
            return Err(BusError::Send {
                topic: P::TOPIC.name(),
                source: format!(
                    "a sample of {len} elements; this session's samples hold at most {}",
                    self.capacity
                )
                .into(),
            });
        }
        ConnectGate::pass(&mut self.gate)?;
        let mut sample = self
            .publisher
            .loan_slice_uninit(len)
            .map_err(|e| BusError::send(P::TOPIC, e))?;
        write_header(sample.user_header_mut());
        let mut sample = sample.write_from_fn(element);
        let sent = self.stamp_next(sample.user_header_mut().stamp_mut());
        self.send(sample, sent)
    }

    /// Sends a copy of `header` and `elements` (for tests and tools; a stage writes in place
    /// with [`Outlet::publish_with`]).
    pub fn publish_copy(
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
        self.skip_to(seq);
        self.publish_with(len, write_header, element)
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
    topic: Topic,
    root: PathBuf,
    /// Samples that may go before every reader is connected.
    free: u64,
    sent: u64,
    /// The topic's subscribers now.
    subscribers: Box<dyn Fn() -> usize>,
}

impl ConnectGate {
    /// The gate of an outlet of `topic` whose readers each buffer `buffer` samples; the marks
    /// are counted in the session's folder `root`.
    pub(super) fn new(
        topic: Topic,
        root: PathBuf,
        buffer: usize,
        subscribers: impl Fn() -> usize + 'static,
    ) -> ConnectGate {
        ConnectGate {
            topic,
            root,
            free: (buffer as u64 / 2).max(1),
            sent: 0,
            subscribers: Box::new(subscribers),
        }
    }

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
    fn connected(&self) -> usize {
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
    received: Cell<u64>,
    gaps: Cell<u64>,
    last_seq: Cell<Option<u64>>,
    /// A restarted reader: the samples before its first were its dead incarnation's to count.
    from_first: bool,
    /// On a lossless bus: the file this inlet creates on its first sample ([`ConnectGate`]);
    /// taken (None) once created.
    connected_mark: Cell<Option<PathBuf>>,
}

impl SeqCount {
    /// A fresh count: `from_first` for a restarted reader, `connected_mark` on a lossless bus.
    pub(super) fn new(from_first: bool, connected_mark: Option<PathBuf>) -> SeqCount {
        SeqCount {
            from_first,
            connected_mark: Cell::new(connected_mark),
            ..SeqCount::default()
        }
    }

    fn saw(&self, seq: u64) {
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
                source: format!(
                    "cannot tell the publisher this reader is connected ({}): {e}",
                    path.display()
                )
                .into(),
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
    words: std::ptr::NonNull<std::sync::atomic::AtomicU64>,
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

/// A subscriber with what wakes it (iceoryx2's listener, or its stage's doorbell), of any
/// topic: counts what arrives and the gaps in `seq`.
pub struct Inlet<P: TopicLayout> {
    subscriber: Subscriber<ipc::Service, P::Payload, P::Header>,
    wake: InletWake,
    seqs: SeqCount,
}

/// What an inlet sleeps on: iceoryx2's event listener (a descriptor), or the doorbell of the
/// stage that opened it, shared by its inlets ([`crate::topic::WakesBy`]).
pub(super) enum InletWake {
    /// Boxed: a listener is about 1.4 KB, the doorbell's handle a pointer.
    Listener(Box<Listener<ipc::Service>>),
    Doorbell(std::sync::Arc<Doorbell>),
}

impl<P: TopicLayout> Inlet<P>
where
    P::Payload: PayloadKind,
{
    pub(super) fn new(
        subscriber: Subscriber<ipc::Service, P::Payload, P::Header>,
        wake: InletWake,
        seqs: SeqCount,
    ) -> Inlet<P> {
        Inlet {
            subscriber,
            wake,
            seqs,
        }
    }

    /// The next unread sample, zero-copy (it reads the publisher's memory), or None. Of a
    /// fixed-size topic, `payload()` is the sample; of a slice topic, `user_header()` is its
    /// header and `payload()` its elements.
    pub fn receive(&self) -> Result<Option<Received<P>>, BusError> {
        let sample =
            P::Payload::receive(&self.subscriber).map_err(|e| BusError::receive(P::TOPIC, e))?;
        if let Some(s) = &sample {
            self.seqs
                .saw(P::stamp(P::Payload::payload(s), s.user_header()).seq);
            self.seqs.mark_connected(P::TOPIC)?;
        }
        Ok(sample)
    }

    /// Sleeps until a sample may have arrived, or `timeout` passes, to the nanosecond;
    /// consumes the wake-ups.
    pub fn wait(&self, timeout: Duration) -> Result<(), BusError> {
        match &self.wake {
            InletWake::Listener(listener) => wait_on(listener, timeout),
            InletWake::Doorbell(doorbell) => {
                doorbell.wait_unless(|| self.has_samples(), timeout);
                Ok(())
            }
        }
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

    /// What [`Wakeable`] sleeps on.
    pub(super) fn wake_source(&self) -> WakeSource<'_> {
        match &self.wake {
            InletWake::Listener(listener) => WakeSource::Listener(listener),
            InletWake::Doorbell(doorbell) => WakeSource::Doorbell(doorbell),
        }
    }

    /// True when a sample waits (an error counts as one: the receive will say what it is).
    pub(super) fn has_samples(&self) -> bool {
        self.subscriber.has_samples().unwrap_or(true)
    }
}
