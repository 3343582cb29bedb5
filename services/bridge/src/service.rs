//! The bridge process: one loop that sleeps on its inlets and on the samples its zenoh link
//! took in (one descriptor more in the same `ppoll`), and on each wake-up
//! 1. sends out: every sample of the topics it reads goes, as a recording's bytes, to the link
//!    (if the topic is sent) and to the Foxglove view (if a client wants it);
//! 2. takes in: every sample the link queued is checked, its stamps moved onto this machine's
//!    clock, and published on this session's bus under its own seq (so a link's losses are
//!    gaps every reader counts), and shown in the view;
//! 3. reports its latencies like any stage: hop (publish -> here: across the link for what it
//!    takes in, by the clock estimate), its own processing, and origin -> out.
//!
//! When it stops it leaves `bridge.json` in the session folder (what it sent and took in, what
//! it dropped and why, the clock estimate and how it was made); the launcher puts it in the
//! session report under `bridge`.

use std::collections::BTreeMap;
use std::os::unix::io::RawFd;
use std::path::PathBuf;
use std::time::Duration;

use common::bus::{
    wait_each, AnyInlet, Bus, BusError, Outlet, Stamped, WaitStrategy, Waiter, Wakeable,
};
use common::config::session::{LinkRole, Source};
use common::config::Session;
use common::latency::{LatencyRecorder, Metric, Reporter};
use common::node::{self, Counters, Pass, Task};
use common::topic::{SliceTopicSpec, TopicSpec, TopicVisitor};
use common::{monotonic_ns, Stage, Stamp, Topic, TopicCounter};

use crate::clock::ClockOffset;
use crate::link::{Link, LinkError};
use crate::refusals;
use crate::viewer::{Viewer, ViewerError};

/// Why the bridge process stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error("{0}")]
    Bus(#[from] BusError),
    /// The zenoh link could not be opened.
    #[error("{0}")]
    Link(#[source] LinkError),
    /// The Foxglove view could not be started.
    #[error("{0}")]
    Viewer(#[source] ViewerError),
    /// A shared world's link (`[shared]`) could not be opened or joined.
    #[error(transparent)]
    Shared(#[from] crate::shared::SharedError),
}
/// While samples wait for the first clock estimate, the loop looks again this often.
const CLOCK_WAIT: Duration = Duration::from_millis(5);

/// What the bridge counts besides its ports' counters (the `bridge.json` it leaves).
#[derive(Default)]
struct Counts {
    sent: BTreeMap<&'static str, u64>,
    taken_in: BTreeMap<&'static str, u64>,
    /// Messages from the link that are not samples of their topic (with the first reason),
    /// and by name: topic and kind (`hand counts: finger_point_count`, `world length`, ...).
    malformed: u64,
    first_malformed: Option<String>,
    malformed_by_name: BTreeMap<String, u64>,
    /// Sends the link refused (with the first reason).
    send_errors: u64,
    first_send_error: Option<String>,
}

/// What a sample read from the bus goes to.
struct Out {
    link: Option<Link>,
    viewer: Option<Viewer>,
    message: Vec<u8>,
    counts: Counts,
}

impl Out {
    /// Sends `self.message` (a sample of `topic` received at `received_ns`) to the link and the
    /// view, and records the bridge's own time and the sample's age.
    fn send(&mut self, r: &mut LatencyRecorder, topic: Topic, received_ns: u64, stamp: &Stamp) {
        r.hop(stamp, received_ns);
        if let Some(link) = &self.link {
            match link.put(topic, &self.message) {
                Ok(true) => *self.counts.sent.entry(topic.name()).or_default() += 1,
                Ok(false) => {}
                Err(e) => {
                    self.counts.send_errors += 1;
                    if self.counts.first_send_error.is_none() {
                        eprintln!("handblocks bridge: sending {} failed: {e}", topic.name());
                        self.counts.first_send_error = Some(e);
                    }
                }
            }
        }
        if let Some(v) = &mut self.viewer {
            v.observe(topic, &self.message, received_ns);
        }
        let done = monotonic_ns();
        r.record(Metric::Process, done.saturating_sub(received_ns));
        r.record(Metric::Origin, done.saturating_sub(stamp.origin_ns));
    }
}

/// Sends out every sample waiting in `inlet` (one of the topics the bridge reads,
/// whichever): its message made from the sample's bytes in the publisher's memory, into the
/// one buffer `out` keeps.
fn drain(inlet: &AnyInlet, out: &mut Out, r: &mut LatencyRecorder) -> Result<(), BusError> {
    while let Some(s) = inlet.receive()? {
        let received = monotonic_ns();
        let view = s.view();
        recording::encode_view(&view, &mut out.message);
        out.send(r, view.topic(), received, s.stamp());
    }
    Ok(())
}

/// One topic the bridge publishes on the bus, taken in from the link.
trait Output {
    fn topic(&self) -> Topic;
    /// Publishes `message` (from the other machine) with its origin moved onto our clock by
    /// `offset_ns` (theirs minus ours), under its own seq; returns the stamp it went with.
    fn forward(&mut self, message: &[u8], offset_ns: i64) -> Result<Stamp, String>;
    fn counter(&self) -> TopicCounter;
}

impl<P: TopicSpec> Output for Outlet<P> {
    fn topic(&self) -> Topic {
        P::TOPIC
    }
    fn forward(&mut self, message: &[u8], offset_ns: i64) -> Result<Stamp, String> {
        let mut sample: P::Sample =
            recording::decode_sample(P::TOPIC, message).map_err(|e| e.to_string())?;
        let stamp = sample.stamp_mut();
        let seq = stamp.seq;
        stamp.origin_ns = ClockOffset::to_ours(offset_ns, stamp.origin_ns);
        self.publish_as(&sample, seq).map_err(|e| e.to_string())
    }
    fn counter(&self) -> TopicCounter {
        Outlet::counter(self)
    }
}

/// A slice topic's outlet and the element count this session's scene gives it.
struct SliceOutput<P: SliceTopicSpec> {
    outlet: Outlet<P>,
    elements: usize,
}

impl<P: SliceTopicSpec> Output for SliceOutput<P> {
    fn topic(&self) -> Topic {
        P::TOPIC
    }
    fn forward(&mut self, message: &[u8], offset_ns: i64) -> Result<Stamp, String> {
        let (header, body): (P::Header, &[u8]) =
            recording::decode_slice(P::TOPIC, message).map_err(|e| e.to_string())?;
        let size = std::mem::size_of::<P::Element>();
        let n = body.len() / size;
        if n != self.elements {
            return Err(format!(
                "a {} sample of {n} elements; this session's scene gives {}: both halves of a \
                 session must name the same scene",
                P::TOPIC.name(),
                self.elements
            ));
        }
        let seq = header.stamp().seq;
        self.outlet
            .publish_with_as(
                seq,
                n,
                |h| {
                    *h = header;
                    let st = h.stamp_mut();
                    st.origin_ns = ClockOffset::to_ours(offset_ns, st.origin_ns);
                },
                // SAFETY: `body` holds exactly `n` elements (checked above); every element
                // type is plain old data (any bit pattern valid), read unaligned.
                |i| unsafe {
                    std::ptr::read_unaligned(body[i * size..].as_ptr() as *const P::Element)
                },
            )
            .map_err(|e| e.to_string())
    }
    fn counter(&self) -> TopicCounter {
        self.outlet.counter()
    }
}

/// Opens an outlet on each topic of `outputs`.
struct OpenOutputs<'b> {
    bus: &'b Bus,
    outputs: Vec<Topic>,
    world_elements: usize,
    opened: Vec<Box<dyn Output>>,
}

impl TopicVisitor for OpenOutputs<'_> {
    type Error = BusError;
    fn visit<P: TopicSpec>(&mut self) -> Result<(), BusError> {
        if self.outputs.contains(&P::TOPIC) {
            self.opened.push(Box::new(self.bus.outlet::<P>()?));
        }
        Ok(())
    }
    fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), BusError> {
        if self.outputs.contains(&P::TOPIC) {
            self.opened.push(Box::new(SliceOutput {
                outlet: self.bus.slice_outlet::<P>()?,
                elements: self.world_elements,
            }));
        }
        Ok(())
    }
}

/// Runs until asked to stop.
pub fn run(session: &Session, bus: &Bus) -> Result<(), BridgeError> {
    let settings = &session.bridge;
    // A shared world's link is this process's one job (the loader refuses [remote] and
    // [viewer] beside it).
    if let Some(shared) = &settings.shared {
        return crate::shared::run(session, bus, shared);
    }
    let remote_fed = matches!(session.source, Source::Remote);
    let inputs = session.bridge_inputs();
    let outputs = settings.outputs();
    let link = match &settings.link {
        Some(l) => {
            refusals::install();
            let link = Link::open(l).map_err(BridgeError::Link)?;
            eprintln!("handblocks bridge: the link: {}", link.protection);
            eprintln!(
                "handblocks bridge: {} {} (key {}): sending {}, taking in {}",
                match l.role {
                    LinkRole::Listen => "listening on",
                    LinkRole::Connect => "connecting to",
                },
                l.endpoint,
                l.key,
                names(&l.publish),
                names(&l.subscribe),
            );
            Some(link)
        }
        None => None,
    };
    let viewer = match &settings.foxglove {
        Some((host, port)) => {
            // A remote-fed view shows what the link brings; a local one what the bus carries.
            let served = if remote_fed {
                outputs.clone()
            } else {
                inputs.clone()
            };
            let v = Viewer::start_capped(
                host,
                *port,
                &session.scene,
                &served,
                settings.foxglove_clients,
            )
            .map_err(BridgeError::Viewer)?;
            eprintln!(
                "handblocks bridge: Foxglove view on ws://{host}:{} (in Foxglove or \
                 Lichtblick: Open connection -> Foxglove WebSocket, then import \
                 config/foxglove/handblocks-layout.json; the 3D panel on /scene and /tf, z-up; \
                 topics {} as they carry samples)",
                v.port,
                served
                    .iter()
                    .map(|t| t.channel())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            Some(v)
        }
        None => None,
    };
    // An inlet on each topic it reads, in table order.
    let ins = Topic::ALL
        .into_iter()
        .filter(|t| inputs.contains(t))
        .map(|t| bus.any_inlet(t))
        .collect::<Result<Vec<_>, _>>()?;
    let mut outputs = OpenOutputs {
        bus,
        outputs,
        world_elements: session.scene.blocks.len(),
        opened: Vec::new(),
    };
    Topic::visit_each(&mut outputs)?;
    let outs = outputs.opened;
    // A session that expects a viewer: the launcher starts the source once this stage
    // reports (its latency publisher, made in `node::run`), as it does once every local reader
    // is attached; so wait here until the viewer takes every topic sent (issue 40).
    if let (Some(l), Some(k)) = (&settings.link, &link) {
        if l.wait_for_viewer_s > 0 {
            eprintln!(
                "handblocks bridge: waiting up to {} s for a viewer to take {} on {}                  ([remote] wait_for_viewer_s) before the source starts",
                l.wait_for_viewer_s,
                names(&l.publish),
                l.endpoint
            );
            match k.wait_for_viewer(Duration::from_secs(l.wait_for_viewer_s)) {
                Some(waited) => eprintln!(
                    "handblocks bridge: a viewer attached after {:.1} s: the source starts",
                    waited.as_secs_f64()
                ),
                None if common::shutdown::requested() => {}
                None => eprintln!(
                    "handblocks bridge: no viewer attached within {} s: the source starts \
                     without one (a viewer that attaches later misses what went before)",
                    l.wait_for_viewer_s
                ),
            }
        }
    }
    let wake_fd = link
        .as_ref()
        .filter(|_| !outs.is_empty())
        .map(|l| l.wake_fd());
    let mut bridge = BridgeStage {
        session,
        summary_file: bus.session_folder().join("bridge.json"),
        ins,
        outs,
        out: Out {
            link,
            viewer,
            message: Vec::new(),
            counts: Counts::default(),
        },
        wake_fd,
        remote_fed,
    };
    // It sleeps on its inlets and its link at once, not by the session's wait strategy.
    Ok(node::run(
        Stage::Bridge,
        bus,
        WaitStrategy::Event,
        &mut bridge,
    )?)
}

/// The bridge stage: its inlets and outlets, the link and the view.
struct BridgeStage<'s> {
    session: &'s Session,
    /// `bridge.json` in the session folder.
    summary_file: PathBuf,
    /// One per topic it reads, in table order.
    ins: Vec<AnyInlet>,
    outs: Vec<Box<dyn Output>>,
    out: Out,
    /// The link's descriptor that says samples were taken in (when any topic is).
    wake_fd: Option<RawFd>,
    remote_fed: bool,
}

impl Task for BridgeStage<'_> {
    type Error = BusError;

    fn wait(&mut self, _: &mut Waiter, _: Duration) -> Result<(), BusError> {
        let waiting_for_clock = self
            .out
            .link
            .as_ref()
            .is_some_and(|l| l.clock.offset_ns().is_none() && !l.incoming.is_empty());
        let timeout = if waiting_for_clock {
            CLOCK_WAIT
        } else {
            node::IDLE_WAIT
        };
        if self.ins.is_empty() && (self.wake_fd.is_none() || waiting_for_clock) {
            std::thread::sleep(timeout);
            return Ok(());
        }
        let wakeables = self.ins.iter().map(|i| i as &dyn Wakeable);
        wait_each(wakeables, self.wake_fd, timeout)
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        for i in &self.ins {
            drain(i, &mut self.out, pass.recorder)?;
        }
        take_in(
            &mut self.out,
            pass.recorder,
            &mut self.outs,
            self.remote_fed,
        );
        Ok(())
    }

    fn counters(&self) -> Counters {
        self.ins
            .iter()
            .map(AnyInlet::counter)
            .chain(self.outs.iter().map(|o| o.counter()))
            .collect()
    }

    fn stop(&mut self, _: &mut Reporter) -> Result<(), BusError> {
        let summary = summary(self.session, &self.out);
        if let Err(e) = std::fs::write(&self.summary_file, summary.to_string()) {
            eprintln!(
                "handblocks bridge: cannot write {}: {e}",
                self.summary_file.display()
            );
        }
        if let Some(v) = self.out.viewer.take() {
            v.stop();
        }
        if let Some(l) = self.out.link.take() {
            l.close();
        }
        Ok(())
    }
}

/// Publishes what the link queued, once the other clock is known (until then it waits in the
/// queue: a sample's stamps cannot be placed on our timeline without it).
fn take_in(out: &mut Out, r: &mut LatencyRecorder, outs: &mut [Box<dyn Output>], remote_fed: bool) {
    // Nothing taken in: no wake-ups to clear (a session that only sends pays no read(2) per
    // sample here).
    let Some(link) = out.link.as_ref().filter(|_| !outs.is_empty()) else {
        return;
    };
    link.clear_wake();
    let Some(offset) = link.clock.offset_ns() else {
        return;
    };
    while let Ok(item) = link.incoming.try_recv() {
        let bytes = item.bytes.to_bytes();
        let Some(output) = outs.iter_mut().find(|o| o.topic() == item.topic) else {
            continue;
        };
        let sent = recording::message_stamp(&bytes);
        match output.forward(&bytes, offset) {
            Ok(stamp) => {
                if let Some(theirs) = sent {
                    // The hop across the link: their publish, on our clock, to our receipt.
                    r.record(
                        Metric::Hop,
                        item.arrived_ns
                            .saturating_sub(ClockOffset::to_ours(offset, theirs.publish_ns)),
                    );
                }
                if remote_fed {
                    r.delivered_after_waiting(stamp.publish_ns);
                }
                r.output(item.arrived_ns, &stamp);
                *out.counts.taken_in.entry(item.topic.name()).or_default() += 1;
                if let Some(v) = &mut out.viewer {
                    v.observe(item.topic, &bytes, item.arrived_ns);
                }
            }
            Err(why) => {
                out.counts.malformed += 1;
                *out.counts
                    .malformed_by_name
                    .entry(format!("{} {}", item.topic.name(), malformed_kind(&why)))
                    .or_default() += 1;
                if out.counts.first_malformed.is_none() {
                    eprintln!(
                        "handblocks bridge: dropped a {} sample from the link: {why}",
                        item.topic.name()
                    );
                    out.counts.first_malformed = Some(why);
                }
            }
        }
    }
}

/// The kind of a refused message, for its name in `bridge.json`: which count overran its
/// array, or what else was wrong (its length, another scene).
fn malformed_kind(why: &str) -> String {
    if let Some(rest) = why.split_once("sample whose ").map(|(_, r)| r) {
        let field = rest.split(' ').next().unwrap_or(rest);
        let field = field.split('[').next().unwrap_or(field);
        return format!("counts: {field}");
    }
    if why.contains("this session's scene gives") {
        return "of another scene".into();
    }
    if why.contains("bytes") {
        return "length".into();
    }
    "other".into()
}

fn names(topics: &[Topic]) -> String {
    if topics.is_empty() {
        return "nothing".into();
    }
    topics
        .iter()
        .map(|t| t.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// `bridge.json`: what the bridge did, for the session report.
fn summary(session: &Session, out: &Out) -> serde_json::Value {
    use serde_json::json;
    let mut refused = refusals::counts();
    let unsigned = out.link.as_ref().map_or(0, |k| k.clock.unsigned_answers());
    if unsigned > 0 {
        refused.insert(
            "clock answers not signed by the trusted authority (an impostor)".into(),
            unsigned,
        );
    }
    let link = session.bridge.link.as_ref().map(|l| {
        let clock = out.link.as_ref().and_then(|k| {
            k.clock.offset_ns().map(|offset| {
                json!({
                    "offset_ns": offset,
                    "uncertainty_ns": k.clock.uncertainty_ns(),
                    "exchanges": k.clock.exchanges(),
                    "method": "round trips to the sender's clock over the link (a zenoh query \
                               on KEY/clock/TOPIC): offset = their clock - the midpoint of ours, \
                               from the shortest round trip of the last 64; uncertainty is half \
                               that round trip",
                })
            })
        });
        json!({
            "endpoint": l.endpoint,
            "role": l.role.name(),
            "key": l.key,
            "publish": l.publish.iter().map(|t| t.name()).collect::<Vec<_>>(),
            "subscribe": l.subscribe.iter().map(|t| t.name()).collect::<Vec<_>>(),
            "peers_at_end": out.link.as_ref().map_or(0, |k| k.peers()),
            "sent": out.counts.sent,
            "taken_in": out.counts.taken_in,
            "queue_full": out.link.as_ref().map_or(0, |k| k.queue_full.load(std::sync::atomic::Ordering::Relaxed)),
            "malformed": out.counts.malformed,
            "first_malformed": out.counts.first_malformed,
            "malformed_by_name": out.counts.malformed_by_name,
            "protection": out.link.as_ref().map(|k| k.protection.clone()),
            "refused": refused,
            "send_errors": out.counts.send_errors,
            "first_send_error": out.counts.first_send_error,
            "clock": clock,
        })
    });
    json!({
        "link": link,
        "foxglove": out.viewer.as_ref().map(|v| json!({"port": v.port})),
    })
}
