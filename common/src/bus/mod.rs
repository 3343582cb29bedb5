//! The bus: iceoryx2 publish-subscribe services, each paired with an event service of the same
//! name, under a prefix and root path of the session's own.
//!
//! * [`BusConfig`] isolates one session (or one test) from every other: its own file prefix in
//!   /dev/shm and its own root directory for iceoryx2's bookkeeping, removed by
//!   [`BusConfig::remove_resources`] when the session ends.
//! * [`Bus`] is one process's node. [`Bus::outlet`] gives an [`Outlet`] (publisher + notifier)
//!   that stamps `seq` and `publish_ns` and counts what it sent; [`Bus::inlet`] gives an
//!   [`Inlet`] (subscriber + listener) that counts what it received and the sequence gaps.
//!   Both are typed by a topic's marker ([`crate::topics`]), which fixes their sample type: a
//!   port cannot be opened with another topic's samples.
//! * Service limits (subscribers, publishers, buffer depth) are fixed when a service is
//!   created, so [`Bus::create_services`] creates every topic of the table
//!   ([`crate::topic`]) with its sizing before any process attaches; every later open must
//!   agree.
//!
//! * [`Bus::any_inlet`] gives an [`AnyInlet`]: an inlet of a topic chosen at run time (a
//!   variant per topic of the table), whose samples are received as bytes
//!   ([`crate::topic::SampleView`]), for the readers of many topics or of one named by the
//!   user (the recorder, the bridge, `handblocks echo`, Python).
//!
//! By concept: `folder` (a session's /dev/shm prefix and private folder, and sweeping what a
//! dead session left), this module (the node, the services, opening ports), `ports` (what an
//! outlet and an inlet do per sample), `any` (the run-time inlet) and `wait` (sleeping on
//! inlets, polling, the adaptive waiter).

use std::cell::Cell;
use std::fmt;
use std::path::{Path as StdPath, PathBuf};
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;

pub use crate::config::session::WaitStrategy;
use crate::output::open_restart_file;
use crate::samples::{TopicCounter, MAX_SCENE_BLOCKS};
pub use crate::stamp::Stamped;
use crate::stamp::{monotonic_ns, Stamp};
use crate::topic::{SliceTopicSpec, Stage, Topic, TopicLayout, TopicSpec, TopicVisitor};

mod any;
mod doorbell;
mod folder;
mod ports;
pub mod semaphore;
mod wait;

pub use any::{AnyInlet, AnySample};
pub use doorbell::Doorbell;
use folder::*;
pub use folder::{BusConfig, RunningSession};
use ports::*;
pub use ports::{Inlet, Outlet, PayloadKind, PubSubBuilder, PubSubService};
use wait::*;
pub use wait::{
    take_wake_ups, wait_any, wait_any_or, wait_each, wait_fd, wake_fd, WaitOutcome, WaitRecord,
    Waiter, Wake, WakeSource, Wakeable, MAX_WAIT,
};

/// A sample read from an [`Inlet`] of topic `P`: of a fixed-size topic, `payload()` is the
/// sample; of a slice topic, `user_header()` is its header and `payload()` its elements.
pub type Received<P> =
    Sample<ipc::Service, <P as TopicLayout>::Payload, <P as TopicLayout>::Header>;

/// Most processes that attach to one topic (a recorder, a monitor and the `iox2` tool included).
const MAX_SUBSCRIBERS: usize = 4;
const MAX_NODES: usize = 16;
/// How long a session folder must be untouched before a launcher may judge it abandoned.
const ABANDONED_AFTER: Duration = Duration::from_secs(10);
/// Blocks a world sample holds when a session does not say ([`BusConfig::world_blocks`]).
pub const DEFAULT_WORLD_BLOCKS: usize = 128;
/// Bytes of unread samples one subscriber of a slice topic may hold: its buffer depth is this
/// over the sample size (at most the table's depth, at least [`MIN_SLICE_BUFFER`]). iceoryx2
/// zeroes a publisher's whole data segment when it creates it, and that segment holds every
/// subscriber's buffer, so a 4096-block world at the table's 1024 samples per subscriber would
/// pin 1 GiB of /dev/shm; at 16 MiB it pins about 64 MiB (a 128-block world keeps all 1024).
pub const SLICE_BUFFER_BYTES: usize = 16 << 20;
/// The shallowest buffer a slice topic gets: 64 samples, half a second at 120 Hz.
pub const MIN_SLICE_BUFFER: usize = 64;

/// Why an operation on the bus failed: iceoryx2's typed error (downcast it, e.g. to
/// `iceoryx2::service::publish_subscribe::PublishSubscribeOpenError`, to tell its cases apart),
/// an I/O error, or our own words where we refused.
pub type BusCause = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Something went wrong on the bus; each variant says which operation and which topic, and
/// keeps what failed underneath as its [`std::error::Error::source`].
#[derive(Debug)]
pub enum BusError {
    /// The session's prefix or root path is not usable by iceoryx2.
    Config(BusCause),
    /// This process's node could not be created.
    Node(BusCause),
    /// A service could not be created or opened (e.g. another build with a different sample
    /// layout is attached: `IncompatibleTypes`).
    Service {
        topic: &'static str,
        source: BusCause,
    },
    /// A publisher, subscriber, notifier or listener could not be created.
    Port {
        topic: &'static str,
        source: BusCause,
    },
    /// A sample could not be loaned or sent.
    Send {
        topic: &'static str,
        source: BusCause,
    },
    /// A sample could not be received.
    Receive {
        topic: &'static str,
        source: BusCause,
    },
    /// Waiting for samples failed.
    Wait(BusCause),
}

impl BusError {
    fn config(reason: impl Into<BusCause>) -> BusError {
        BusError::Config(reason.into())
    }
    fn service(topic: Topic, e: impl Into<BusCause>) -> BusError {
        BusError::Service {
            topic: topic.name(),
            source: e.into(),
        }
    }
    fn port(topic: Topic, e: impl Into<BusCause>) -> BusError {
        BusError::Port {
            topic: topic.name(),
            source: e.into(),
        }
    }
    fn send(topic: Topic, e: impl Into<BusCause>) -> BusError {
        BusError::Send {
            topic: topic.name(),
            source: e.into(),
        }
    }
    fn receive(topic: Topic, e: impl Into<BusCause>) -> BusError {
        BusError::Receive {
            topic: topic.name(),
            source: e.into(),
        }
    }
}

impl fmt::Display for BusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BusError::Config(r) => write!(f, "bus configuration: {r}"),
            BusError::Node(r) => write!(f, "cannot create the iceoryx2 node: {r}"),
            BusError::Service { topic, source } => write!(
                f,
                "cannot open the `{topic}` service: {source} (a process of another build may be attached; stop it or use another session id)"
            ),
            BusError::Port { topic, source } => {
                write!(f, "cannot attach to the `{topic}` service: {source}")
            }
            BusError::Send { topic, source } => write!(f, "cannot send on `{topic}`: {source}"),
            BusError::Receive { topic, source } => {
                write!(f, "cannot receive on `{topic}`: {source}")
            }
            BusError::Wait(r) => write!(f, "waiting for samples failed (ppoll): {r}"),
        }
    }
}

impl std::error::Error for BusError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            BusError::Config(e) | BusError::Node(e) | BusError::Wait(e) => Some(e.as_ref()),
            BusError::Service { source, .. }
            | BusError::Port { source, .. }
            | BusError::Send { source, .. }
            | BusError::Receive { source, .. } => Some(source.as_ref()),
        }
    }
}

/// One process's attachment to the session's bus.
pub struct Bus {
    node: Node<ipc::Service>,
    /// Elements a slice topic's sample holds at most ([`BusConfig::world_blocks`]).
    slice_capacity: usize,
    /// [`BusConfig::lossless`].
    lossless: bool,
    /// The session's folder ([`BusConfig::root`]).
    root: PathBuf,
    /// This node's name, which names its outlets' seq files.
    node_name: String,
    /// Set by [`Bus::supervised`]: this process may be restarted by the launcher.
    supervised: Option<Supervised>,
    /// Set by [`Bus::for_stage`]: this node is a stage of the graph, and may open only the
    /// ports the topic table grants it.
    stage: Option<Stage>,
    /// Set by [`Bus::for_stage`] for a stage woken by its doorbell
    /// ([`crate::topic::WakesBy::Doorbell`]): every inlet it opens sleeps on it.
    doorbell: Option<std::sync::Arc<Doorbell>>,
}

/// What a stage the launcher may restart does differently ([`Bus::supervised`]).
#[derive(Debug, Clone, Copy)]
struct Supervised {
    /// 0 for the first start, n for the n-th restart.
    restart: u32,
}

impl Bus {
    /// Creates this process's node, named e.g. after its stage.
    pub fn open(config: &BusConfig, node_name: &str) -> Result<Bus, BusError> {
        // Twice: another session that ends may remove this user's (empty) folder between the
        // two creations.
        let dirs = || -> Result<(), BusError> {
            if let Some(base) = config.root.parent() {
                make_private_dir(base)?;
            }
            make_private_dir(&config.root)
        };
        dirs().or_else(|_| dirs())?;
        make_shm_private(&config.prefix)?;
        let iox = config.iceoryx()?;
        let name = NodeName::new(node_name).map_err(|e| BusError::Node(e.into()))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&iox)
            // Processes handle SIGINT/SIGTERM themselves (crate::shutdown), so that a stage can
            // finish its final report before it exits.
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| BusError::Node(e.into()))?;
        // The node made the prefix's management segment (world-writable): make it private.
        make_shm_private(&config.prefix)?;
        Ok(Bus {
            node,
            slice_capacity: config.world_blocks,
            lossless: config.lossless,
            root: config.root.clone(),
            node_name: node_name.to_string(),
            supervised: None,
            stage: None,
            doorbell: None,
        })
    }

    /// The node of stage `stage` (a process of the graph, named after it): it may open an
    /// outlet only on a topic whose row names it a publisher, an inlet only on one whose row
    /// names it a reader; any other port is an error ([`BusError::Port`]) that says so. Tools
    /// and tests open a free-named node ([`Bus::open`]), which the table does not restrict.
    pub fn for_stage(config: &BusConfig, stage: Stage) -> Result<Bus, BusError> {
        let mut bus = Bus::open(config, stage.name())?;
        bus.stage = Some(stage);
        if stage.wakes_by() == crate::topic::WakesBy::Doorbell {
            let doorbell = bus.open_doorbell(stage).map_err(BusError::config)?;
            bus.doorbell = Some(std::sync::Arc::new(doorbell));
        }
        Ok(bus)
    }

    /// Refuses a port the topic table does not grant this stage: an outlet when `publish`,
    /// else an inlet.
    fn granted(&self, topic: Topic, publish: bool) -> Result<(), BusError> {
        let Some(stage) = self.stage else {
            return Ok(());
        };
        let (stages, what) = if publish {
            (topic.publishers(), "publisher")
        } else {
            (topic.readers(), "reader")
        };
        if stages.contains(&stage) {
            return Ok(());
        }
        Err(BusError::port(
            topic,
            format!(
                "the topic table (common/src/topic.rs) does not name the {} stage a {what} of \
                 `{}`: add it to the topic's row, or open the port from a stage the row names",
                stage.name(),
                topic.name()
            ),
        ))
    }

    /// Issue 16, supervision: this process is a stage the launcher restarts when it dies
    /// (`[supervise] restart = "on-failure"`); `restart` is 0 for its first start, n for its
    /// n-th restart. Then
    /// * every outlet keeps its next `seq` in a file of the session's folder, mapped into
    ///   memory (a store per sample, no system call), so a restarted publisher goes on from
    ///   where the dead one stopped: seq stays monotonic for every reader;
    /// * on a restart, every inlet counts gaps from its first sample, not from seq 0: the
    ///   samples before it were the dead process's to count (the launcher adds the two
    ///   incarnations' counts and attributes the samples between them to the restart).
    pub fn supervised(mut self, restart: u32) -> Bus {
        self.supervised = Some(Supervised { restart });
        self
    }

    /// The n-th restart this process is (0: its first start, or not supervised).
    pub fn restart(&self) -> u32 {
        self.supervised.map_or(0, |s| s.restart)
    }

    /// True when the launcher may restart this process ([`Bus::supervised`]).
    pub fn is_supervised(&self) -> bool {
        self.supervised.is_some()
    }

    /// The session's folder: private to this user, removed when the session ends. What a
    /// restarted stage needs of its dead incarnation lives here.
    pub fn session_folder(&self) -> &StdPath {
        &self.root
    }

    /// The session's epoch for `name` (a source's timeline): CLOCK_MONOTONIC when it first
    /// asked, kept in the session folder, so that a restarted source goes on on the same
    /// timeline (its deadlines, its source times). Returns the epoch and whether it was kept
    /// from an earlier incarnation. Unsupervised, it is simply now.
    pub fn session_epoch_ns(&self, name: &str) -> (u64, bool) {
        let now = monotonic_ns();
        if self.supervised.is_none() {
            return (now, false);
        }
        let path = self.root.join(format!("epoch.{name}"));
        if let Some(kept) = std::fs::read_to_string(&path)
            .ok()
            .and_then(|t| t.trim().parse::<u64>().ok())
        {
            return (kept, true);
        }
        // Written whole by rename, so a process killed while writing leaves no half number.
        let tmp = self.root.join(format!("epoch.{name}.tmp"));
        if std::fs::write(&tmp, now.to_string())
            .and_then(|()| std::fs::rename(&tmp, &path))
            .is_err()
        {
            eprintln!(
                "handblocks: cannot keep the epoch of {name} in {}: a restart of it will start \
                 its timeline anew",
                self.root.display()
            );
        }
        (now, false)
    }

    /// Removes what processes of this session that died (SIGKILL, a crash) left on the bus:
    /// their nodes, their ports in every service, their shared memory (iceoryx2's dead-node
    /// cleanup). The dead processes must have been reaped. Returns the nodes removed and those
    /// that could not be.
    pub fn cleanup_dead_nodes(&self) -> (u64, u64) {
        let state = self.node.try_cleanup_dead_nodes();
        (state.cleanups, state.failed_cleanups)
    }

    /// Where this node keeps `topic`'s next seq, when it is supervised.
    /// This stage's inlets sleep on iceoryx2's event, not on its doorbell, whatever the stage
    /// table says (`[pipeline] wake = "event"`). Before any inlet is opened.
    pub fn woken_by_events(mut self) -> Bus {
        self.doorbell = None;
        self
    }

    /// `stage`'s doorbell, in the session's folder (made when it is not there yet).
    fn open_doorbell(&self, stage: Stage) -> Result<Doorbell, String> {
        let path = self.root.join(format!("doorbell.{}", stage.name()));
        Doorbell::open(&path)
            .map_err(|e| format!("cannot open the doorbell {}: {e}", path.display()))
    }

    /// The doorbells an outlet of `topic` rings: those of its readers woken by one.
    fn doorbells(&self, topic: Topic) -> Result<Vec<Doorbell>, BusError> {
        topic
            .readers()
            .iter()
            .filter(|s| s.wakes_by() == crate::topic::WakesBy::Doorbell)
            .map(|&s| self.open_doorbell(s).map_err(|e| BusError::port(topic, e)))
            .collect()
    }

    fn seq_store(&self, topic: Topic) -> Result<Option<SeqStore>, BusError> {
        if self.supervised.is_none() {
            return Ok(None);
        }
        let path = self
            .root
            .join(format!("seq.{}.{}", self.node_name, topic.name()));
        SeqStore::open(&path).map(Some).map_err(|e| {
            BusError::port(
                topic,
                format!("cannot keep its seq in {}: {e}", path.display()),
            )
        })
    }

    /// A fresh count of received samples of `topic`: on a restart, gaps count from the first
    /// sample; on a lossless bus, the first sample marks the inlet connected ([`ConnectGate`]).
    fn seq_count(&self, topic: Topic) -> SeqCount {
        let connected_mark = self.is_lossless(topic).then(|| {
            static INLETS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
            let n = INLETS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            self.root.join(format!(
                "{CONNECTED_MARK}{}.{}.{}.{n}",
                topic.name(),
                self.node_name,
                std::process::id()
            ))
        });
        SeqCount::new(self.restart() > 0, connected_mark)
    }

    /// On a lossless bus, what an outlet of `topic` waits for before it may fill a reader's
    /// buffer ([`ConnectGate`]); None elsewhere.
    fn connect_gate(
        &self,
        topic: Topic,
        buffer: usize,
        subscribers: impl Fn() -> usize + 'static,
    ) -> Option<ConnectGate> {
        self.is_lossless(topic)
            .then(|| ConnectGate::new(topic, self.root.clone(), buffer, subscribers))
    }

    /// True when `topic` waits for its slowest reader on this bus ([`BusConfig::lossless`]).
    fn is_lossless(&self, topic: Topic) -> bool {
        self.lossless && topic != Topic::Latency
    }

    /// The most elements a sample of a slice topic carries on this bus.
    pub fn slice_capacity(&self) -> usize {
        self.slice_capacity
    }

    /// Creates every topic of the session with its fixed sizing. The launcher calls this once
    /// before it starts any process, and keeps the returned handles until the session ends.
    pub fn create_services(&self) -> Result<Services, BusError> {
        /// Creates each topic's service with its sample type, in table order.
        struct Create<'b> {
            bus: &'b Bus,
            pubsub: Vec<Box<dyn AttachedPorts>>,
        }
        impl Create<'_> {
            fn create<P: TopicLayout>(&mut self) -> Result<(), BusError>
            where
                P::Payload: PayloadKind,
            {
                let service = self.bus.pubsub::<P>()?;
                self.pubsub.push(Box::new(service));
                Ok(())
            }
        }
        impl TopicVisitor for Create<'_> {
            type Error = BusError;
            fn visit<P: TopicSpec>(&mut self) -> Result<(), BusError> {
                self.create::<P>()
            }
            fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), BusError> {
                self.create::<P>()
            }
        }
        let mut create = Create {
            bus: self,
            pubsub: Vec::with_capacity(Topic::ALL.len()),
        };
        Topic::visit_each(&mut create)?;
        Ok(Services {
            pubsub: create.pubsub,
            _events: Topic::ALL
                .iter()
                .map(|t| self.event(*t))
                .collect::<Result<_, _>>()?,
        })
    }

    /// The subscriber buffer depth of `topic` on this bus: the table's depth, or for a slice
    /// topic, less when its samples are large ([`SLICE_BUFFER_BYTES`]).
    pub fn buffer(&self, topic: Topic) -> usize {
        let depth = topic.subscriber_buffer();
        let Some(element) = topic.element_size() else {
            return depth;
        };
        let sample = topic.sample_size() + self.slice_capacity * element;
        (SLICE_BUFFER_BYTES / sample.max(1)).clamp(MIN_SLICE_BUFFER.min(depth), depth)
    }

    /// The subscriber buffer depth of slice topic `P` on this bus ([`Bus::buffer`]).
    pub fn slice_buffer<P: SliceTopicSpec>(&self) -> usize {
        self.buffer(P::TOPIC)
    }

    /// Opens (or creates) topic `P`'s service, with its payload and header types and its
    /// row's sizing ([`Bus::buffer`]).
    fn pubsub<P: TopicLayout>(&self) -> Result<PubSub<P>, BusError>
    where
        P::Payload: PayloadKind,
    {
        let topic = P::TOPIC;
        let name = service_name(topic)?;
        let builder = self
            .node
            .service_builder(&name)
            .publish_subscribe::<P::Payload>()
            .user_header::<P::Header>()
            .max_publishers(topic.max_publishers())
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(self.buffer(topic))
            .subscriber_max_borrowed_samples(4)
            .history_size(0)
            // A slow reader loses its oldest unread sample instead of stalling the publisher,
            // but on a lossless bus (a speed-0 replay).
            .enable_safe_overflow(!self.is_lossless(topic));
        P::Payload::open_or_create(builder).map_err(|e| BusError::service(topic, e))
    }

    /// The wake-up side of topic `topic`'s outlets.
    fn notifier(&self, topic: Topic) -> Result<Notifier<ipc::Service>, BusError> {
        self.event(topic)?
            .notifier_builder()
            .create()
            .map_err(|e| BusError::port(topic, e))
    }

    /// What an inlet of topic `topic` sleeps on.
    fn listener(&self, topic: Topic) -> Result<Listener<ipc::Service>, BusError> {
        self.event(topic)?
            .listener_builder()
            .create()
            .map_err(|e| BusError::port(topic, e))
    }

    fn event(&self, topic: Topic) -> Result<EventService, BusError> {
        let name = service_name(topic)?;
        self.node
            .service_builder(&name)
            .event()
            .max_listeners(8)
            .max_notifiers(8)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| BusError::service(topic, e))
    }

    /// A publisher on topic `P` (a marker of [`crate::topics`]) with its notifier. The outlet
    /// sends `P`'s sample type and nothing else:
    ///
    /// ```no_run
    /// # use common::{bus::Bus, topics, GloveSample};
    /// # fn f(bus: &Bus) -> Result<(), common::bus::BusError> {
    /// let mut glove = bus.outlet::<topics::Glove>()?;
    /// glove.publish(&GloveSample::default())?;
    /// # Ok(()) }
    /// ```
    ///
    /// A hand sample on the glove topic does not compile:
    ///
    /// ```compile_fail
    /// # use common::{bus::Bus, topics, HandSample};
    /// # fn f(bus: &Bus) -> Result<(), common::bus::BusError> {
    /// let mut glove = bus.outlet::<topics::Glove>()?;
    /// glove.publish(&HandSample::default())?;
    /// # Ok(()) }
    /// ```
    pub fn outlet<P: TopicSpec>(&self) -> Result<Outlet<P>, BusError> {
        self.granted(P::TOPIC, true)?;
        let service = self.pubsub::<P>()?;
        let publisher = service
            .publisher_builder()
            .max_loaned_samples(2)
            .create()
            .map_err(|e| BusError::port(P::TOPIC, e))?;
        self.outlet_on(service, publisher, 1)
    }

    /// A publisher on slice topic `P` (the `world` topic) with its notifier; each sample it
    /// sends holds 0 to [`Bus::slice_capacity`] elements, written in place
    /// ([`Outlet::publish_with`]). (Only a slice publisher is told the longest slice it sends,
    /// so its constructor is its own; the outlet is the same type.)
    pub fn slice_outlet<P: SliceTopicSpec>(&self) -> Result<Outlet<P>, BusError> {
        self.granted(P::TOPIC, true)?;
        let service = self.pubsub::<P>()?;
        let publisher = service
            .publisher_builder()
            .initial_max_slice_len(self.slice_capacity)
            .max_loaned_samples(2)
            .create()
            .map_err(|e| BusError::port(P::TOPIC, e))?;
        self.outlet_on(service, publisher, self.slice_capacity)
    }

    /// The outlet of `publisher`, with its notifier, kept seq and connect gate.
    fn outlet_on<P: TopicLayout>(
        &self,
        service: PubSub<P>,
        publisher: Publisher<ipc::Service, P::Payload, P::Header>,
        capacity: usize,
    ) -> Result<Outlet<P>, BusError> {
        let topic = P::TOPIC;
        let notifier = self.notifier(topic)?;
        let doorbells = self.doorbells(topic)?;
        let kept = self.seq_store(topic)?;
        let gate = self.connect_gate(topic, self.buffer(topic), move || {
            service.dynamic_config().number_of_subscribers()
        });
        Ok(Outlet::new(
            publisher, notifier, doorbells, capacity, kept, gate,
        ))
    }

    /// A subscriber on topic `P` (a marker of [`crate::topics`], fixed-size or slice) with its
    /// listener; it receives `P`'s sample type:
    ///
    /// ```compile_fail
    /// # use common::{bus::Bus, topics, HandSample};
    /// # fn f(bus: &Bus) -> Result<(), common::bus::BusError> {
    /// let glove = bus.inlet::<topics::Glove>()?;
    /// let hand: Option<HandSample> = glove.receive()?.map(|s| *s.payload());
    /// # Ok(()) }
    /// ```
    pub fn inlet<P: TopicLayout>(&self) -> Result<Inlet<P>, BusError>
    where
        P::Payload: PayloadKind,
    {
        let topic = P::TOPIC;
        self.granted(topic, false)?;
        let subscriber = self
            .pubsub::<P>()?
            .subscriber_builder()
            .buffer_size(self.buffer(topic))
            .create()
            .map_err(|e| BusError::port(topic, e))?;
        let wake = match &self.doorbell {
            Some(doorbell) => InletWake::Doorbell(doorbell.clone()),
            None => InletWake::Listener(Box::new(self.listener(topic)?)),
        };
        Ok(Inlet::new(subscriber, wake, self.seq_count(topic)))
    }
}

fn service_name(topic: Topic) -> Result<ServiceName, BusError> {
    ServiceName::new(topic.name()).map_err(BusError::config)
}

/// A topic's publish-subscribe service (iceoryx2's port factory), its payload and header
/// types those of the topic's marker.
type PubSub<P> = PubSubService<<P as TopicLayout>::Payload, <P as TopicLayout>::Header>;
type EventService = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

/// The attachment counts of one publish-subscribe service, whatever its sample type.
trait AttachedPorts {
    fn subscribers(&self) -> usize;
    fn publishers(&self) -> usize;
}

impl<Payload, Header> AttachedPorts for PubSubService<Payload, Header>
where
    Payload: ?Sized + fmt::Debug + IceoryxSend + 'static,
    Header: fmt::Debug + ZeroCopySend + 'static,
{
    fn subscribers(&self) -> usize {
        self.dynamic_config().number_of_subscribers()
    }
    fn publishers(&self) -> usize {
        self.dynamic_config().number_of_publishers()
    }
}

/// Every service of a session, created once by the launcher; it also reads how many ports are
/// attached, to start the source only when every reader is there.
pub struct Services {
    /// The publish-subscribe services, indexed by `Topic as usize`.
    pubsub: Vec<Box<dyn AttachedPorts>>,
    /// Held so the event services keep the sizing they were created with.
    _events: Vec<EventService>,
}

impl Services {
    /// Subscribers attached to `topic` now.
    pub fn subscribers(&self, topic: Topic) -> usize {
        self.pubsub[topic as usize].subscribers()
    }

    /// Publishers attached to `topic` now.
    pub fn publishers(&self, topic: Topic) -> usize {
        self.pubsub[topic as usize].publishers()
    }
}
