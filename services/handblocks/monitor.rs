//! Looking at a running session from outside, as `ros2 topic` does: `handblocks sessions` (what
//! runs on this machine), `handblocks topics` (its topics, with publishers, readers, rate and
//! type), `handblocks echo TOPIC` (its samples, field by field) and `handblocks hz TOPIC` (its
//! rate). None of them waits in silence: a topic nobody publishes is said at once (`--wait`
//! waits for a publisher, saying so), and `hz --seconds` ends on time with or without samples.
//!
//! A session's launcher leaves a card in the session's folder (`BusConfig::write_card`): its
//! bus id, its world size and whether it is lossless. `echo` and `hz` open that bus as one
//! more reader of one topic. A live session's publishers overwrite a reader's oldest unread
//! sample rather than wait for it, so a slow terminal costs the pipeline nothing; a lossless
//! session (a speed-0 replay) would wait for every reader, so it is refused.
//!
//! Samples are printed from the very bytes a recording holds, by the schema every recording
//! carries (`recording::fields`: each field's name, type, offset and size), so every topic
//! prints without code of its own.

use std::fmt;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use common::bus::{Bus, BusConfig, BusError, Inlet, RunningSession, Wakeable};
use common::topic::{SliceTopicSpec, TopicSpec, TopicVisitor};
use common::{BlockMode, Stamp, Topic};

/// Why a look at a running session failed.
#[derive(Debug)]
pub enum MonitorError {
    /// No session runs, or none with the id asked for, or several and none chosen.
    NoSession(String),
    /// The topic named is not one.
    NoTopic(String),
    /// A speed-0 replay would wait for this reader.
    Lossless(String),
    /// No sample of the topic came within a second (and `--wait` was not given): the topic,
    /// the session's id, its publishers attached, and the topics that do send.
    NoPublisher {
        topic: &'static str,
        session: String,
        publishers: usize,
        sending: Vec<&'static str>,
    },
    /// The bus could not be opened or read.
    Bus(BusError),
}

impl fmt::Display for MonitorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MonitorError::NoSession(why) => f.write_str(why),
            MonitorError::NoTopic(name) => write!(
                f,
                "{name:?} is not a topic; one of: {}",
                Topic::RECORDED
                    .iter()
                    .map(|t| t.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            MonitorError::Lossless(id) => write!(
                f,
                "session {id} is a lossless replay (speed 0): its publishers wait for every \
                 reader, so a look from here would slow it; replay at a speed above 0 to watch it"
            ),
            MonitorError::NoPublisher {
                topic,
                session,
                publishers,
                sending,
            } => write!(
                f,
                "session {session}: {}; it sends {}. `handblocks topics -v --session {session}` \
                 lists its topics with their rates; --wait waits for {topic}",
                if *publishers == 0 {
                    format!("nobody publishes {topic}")
                } else {
                    format!(
                        "nothing sends {topic} (its publisher sent no sample in {} s: a replay \
                         of a trace without it, or a source that does not make it)",
                        FIRST_SAMPLE_WITHIN.as_secs()
                    )
                },
                if sending.is_empty() {
                    "nothing".to_string()
                } else {
                    sending.join(", ")
                }
            ),
            MonitorError::Bus(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for MonitorError {}

impl From<BusError> for MonitorError {
    fn from(e: BusError) -> Self {
        MonitorError::Bus(e)
    }
}

fn age(started_unix_s: u64) -> String {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let s = now.saturating_sub(started_unix_s);
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {} s", s / 60, s % 60),
        _ => format!("{} h {} min", s / 3600, s % 3600 / 60),
    }
}

/// `handblocks sessions`: one block per running session.
pub fn sessions(json: bool) -> ExitCode {
    let running = BusConfig::running();
    if json {
        let list: Vec<serde_json::Value> = running
            .iter()
            .map(|s| {
                serde_json::json!({
                    "id": s.bus.id,
                    "session": s.session_file,
                    "source": s.source,
                    "started_unix_s": s.started_unix_s,
                    "launcher_pid": s.launcher_pid,
                    "lossless": s.bus.lossless,
                    "processes": s.processes().iter().map(|(name, pid)| {
                        serde_json::json!({"name": name, "pid": pid})
                    }).collect::<Vec<_>>(),
                })
            })
            .collect();
        println!("{}", serde_json::Value::Array(list));
        return ExitCode::SUCCESS;
    }
    if running.is_empty() {
        println!(
            "no session runs on this machine (for this user); start one with `handblocks launch`"
        );
        return ExitCode::SUCCESS;
    }
    for s in &running {
        println!(
            "{}  running {}  {}  (launcher pid {})",
            s.bus.id,
            age(s.started_unix_s),
            s.session_file,
            s.launcher_pid
        );
        let processes = s.processes();
        let names: Vec<String> = processes
            .iter()
            .map(|(name, pid)| format!("{name} ({pid})"))
            .collect();
        println!("    processes: {}", names.join(", "));
    }
    println!("look at one: handblocks echo TOPIC | handblocks hz TOPIC  [--session ID]");
    ExitCode::SUCCESS
}

/// The session `--session ID` names, or the only one running.
fn pick(id: Option<&str>) -> Result<RunningSession, MonitorError> {
    RunningSession::find(id)
        .map_err(|why| MonitorError::NoSession(why.replace("by its id", "with --session ID")))
}

/// One topic's inlet, whatever its sample type: the next sample as a recording's bytes.
trait Tap {
    fn wakeable(&self) -> &dyn Wakeable;
    /// The next sample's message (CDR header and bytes) into `out`, its stamp, and when it
    /// was taken (CLOCK_MONOTONIC, before it was copied out).
    fn next(&self, out: &mut Vec<u8>) -> Result<Option<(Stamp, u64)>, BusError>;
}

impl<P: TopicSpec> Tap for Inlet<P> {
    fn wakeable(&self) -> &dyn Wakeable {
        self
    }
    fn next(&self, out: &mut Vec<u8>) -> Result<Option<(Stamp, u64)>, BusError> {
        use common::bus::Stamped as _;
        Ok(self.receive()?.map(|s| {
            let taken = common::monotonic_ns();
            recording::encode_sample(s.payload(), out);
            (*s.payload().stamp(), taken)
        }))
    }
}

struct SliceTap<P: SliceTopicSpec>(Inlet<P>);

impl<P: SliceTopicSpec> Tap for SliceTap<P> {
    fn wakeable(&self) -> &dyn Wakeable {
        &self.0
    }
    fn next(&self, out: &mut Vec<u8>) -> Result<Option<(Stamp, u64)>, BusError> {
        use common::bus::Stamped as _;
        Ok(self.0.receive()?.map(|s| {
            let taken = common::monotonic_ns();
            recording::encode_slice(P::TOPIC, s.user_header(), s.payload(), out);
            (*s.user_header().stamp(), taken)
        }))
    }
}

/// Opens the inlet of one topic.
struct OpenTap<'b> {
    bus: &'b Bus,
    topic: Topic,
    tap: Option<Box<dyn Tap>>,
}

impl TopicVisitor for OpenTap<'_> {
    type Error = BusError;
    fn visit<P: TopicSpec>(&mut self) -> Result<(), BusError> {
        if P::TOPIC == self.topic {
            self.tap = Some(Box::new(self.bus.inlet::<P>()?));
        }
        Ok(())
    }
    fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), BusError> {
        if P::TOPIC == self.topic {
            self.tap = Some(Box::new(SliceTap(self.bus.inlet::<P>()?)));
        }
        Ok(())
    }
}

/// Opens an inlet of every recorded topic (a short look at all of them: `topics -v`).
struct OpenAll<'b> {
    bus: &'b Bus,
    taps: Vec<(Topic, Box<dyn Tap>)>,
}

impl TopicVisitor for OpenAll<'_> {
    type Error = BusError;
    fn visit<P: TopicSpec>(&mut self) -> Result<(), BusError> {
        if P::TOPIC.is_recorded() {
            self.taps.push((P::TOPIC, Box::new(self.bus.inlet::<P>()?)));
        }
        Ok(())
    }
    fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), BusError> {
        if P::TOPIC.is_recorded() {
            self.taps
                .push((P::TOPIC, Box::new(SliceTap(self.bus.inlet::<P>()?))));
        }
        Ok(())
    }
}

/// Samples a second of every recorded topic over `window`, read through one inlet each (as
/// `ros2 topic hz` reads: a reader for the look's length). In topic order.
fn measure_rates(bus: &Bus, window: Duration) -> Result<Vec<(Topic, f64)>, MonitorError> {
    let mut open = OpenAll {
        bus,
        taps: Vec::new(),
    };
    Topic::visit_each(&mut open)?;
    let mut counts = vec![0u64; open.taps.len()];
    let mut message = Vec::new();
    let started = Instant::now();
    let until = started + window;
    loop {
        for ((_, tap), n) in open.taps.iter().zip(counts.iter_mut()) {
            while tap.next(&mut message)?.is_some() {
                *n += 1;
            }
        }
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() || common::shutdown::requested() {
            break;
        }
        common::bus::wait_each(
            open.taps.iter().map(|(_, t)| t.wakeable()),
            None,
            left.min(Duration::from_millis(50)),
        )?;
    }
    let secs = started.elapsed().as_secs_f64().max(1e-3);
    Ok(open
        .taps
        .iter()
        .zip(counts)
        .map(|((t, _), n)| (*t, n as f64 / secs))
        .collect())
}

/// The running session, and an inlet of `topic` on its bus.
fn tap(
    topic: &str,
    session: Option<&str>,
) -> Result<(RunningSession, Bus, Box<dyn Tap>), MonitorError> {
    let topic = Topic::from_channel(topic)
        .filter(|t| t.is_recorded())
        .ok_or_else(|| MonitorError::NoTopic(topic.to_string()))?;
    let running = pick(session)?;
    if running.bus.lossless {
        return Err(MonitorError::Lossless(running.bus.id.clone()));
    }
    let bus = Bus::open(&running.bus, "monitor")?;
    let mut open = OpenTap {
        bus: &bus,
        topic,
        tap: None,
    };
    Topic::visit_each(&mut open)?;
    let tap = open
        .tap
        .ok_or_else(|| MonitorError::NoTopic(topic.name().to_string()))?;
    Ok((running, bus, tap))
}

/// Waits for the next sample of `tap` until the session ends (its launcher gone) or
/// `until` passes.
fn next_sample(
    tap: &dyn Tap,
    running: &RunningSession,
    message: &mut Vec<u8>,
    until: Option<Instant>,
) -> Result<Option<(Stamp, u64)>, MonitorError> {
    loop {
        if let Some(taken) = tap.next(message)? {
            return Ok(Some(taken));
        }
        if common::shutdown::requested() || !running_still(running) {
            return Ok(None);
        }
        let mut wait = Duration::from_millis(200);
        if let Some(until) = until {
            let left = until.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            wait = wait.min(left);
        }
        common::bus::wait_each(std::iter::once(tap.wakeable()), None, wait)?;
    }
}

fn running_still(running: &RunningSession) -> bool {
    running.is_running()
}

/// How long `echo` and `hz` wait for a first sample before they say the topic is silent: a
/// topic of an interactive session sends many a second, so a second without one is a topic
/// nothing sends (a replay of a trace without it, a source that does not make it).
const FIRST_SAMPLE_WITHIN: Duration = Duration::from_secs(1);

/// The first sample of `tap` within [`FIRST_SAMPLE_WITHIN`] (or `until`, if sooner); when none
/// comes, says why at once (no publisher, or a publisher that sends nothing, and the topics
/// that do send), and refuses unless asked to wait (then says it waits, and goes on).
#[allow(clippy::too_many_arguments)]
fn first_sample_or_say_why(
    tool: &str,
    bus: &Bus,
    running: &RunningSession,
    topic: Topic,
    tap: &dyn Tap,
    message: &mut Vec<u8>,
    wait: bool,
    until: Option<Instant>,
) -> Result<Option<(Stamp, u64)>, MonitorError> {
    let first_by = Instant::now() + FIRST_SAMPLE_WITHIN;
    let soon = until.map_or(first_by, |u| u.min(first_by));
    if let Some(sample) = next_sample(tap, running, message, Some(soon))? {
        return Ok(Some(sample));
    }
    if common::shutdown::requested()
        || !running_still(running)
        || until.is_some_and(|u| Instant::now() >= u)
    {
        return Ok(None);
    }
    let publishers = bus.create_services()?.publishers(topic);
    let sending: Vec<&'static str> = measure_rates(bus, Duration::from_millis(300))?
        .into_iter()
        .filter(|(t, rate)| *t != topic && *rate > 0.0)
        .map(|(t, _)| t.name())
        .collect();
    if !wait {
        return Err(MonitorError::NoPublisher {
            topic: topic.name(),
            session: running.bus.id.clone(),
            publishers,
            sending,
        });
    }
    eprintln!(
        "handblocks {tool}: {} in session {}: {}; waiting (--wait; Ctrl-C stops)",
        topic.name(),
        running.bus.id,
        if publishers == 0 {
            "nobody publishes it yet".to_string()
        } else {
            format!("no sample in {} s", FIRST_SAMPLE_WITHIN.as_secs())
        }
    );
    next_sample(tap, running, message, until)
}

/// A look's bus and inlet, handed back with its first sample (its stamp, when it was taken).
type KeptLook = (Bus, Box<dyn Tap>, Option<(Stamp, u64)>);

/// [`first_sample_or_say_why`] for a look that owns its bus and inlet: handed back with the
/// first sample, or let go of (nothing of the look left) when the topic is refused.
#[allow(clippy::too_many_arguments)]
fn first_or_let_go(
    tool: &str,
    running: &RunningSession,
    bus: Bus,
    tap: Box<dyn Tap>,
    topic: Topic,
    message: &mut Vec<u8>,
    wait: bool,
    until: Option<Instant>,
) -> Result<KeptLook, MonitorError> {
    match first_sample_or_say_why(
        tool,
        &bus,
        running,
        topic,
        tap.as_ref(),
        message,
        wait,
        until,
    ) {
        Ok(first) => Ok((bus, tap, first)),
        Err(e) => {
            let _ = let_go(tool, running, bus, tap, Ok(()));
            Err(e)
        }
    }
}

/// Lets go of the session's bus and says how the look ended. When the session has ended
/// (its launcher stopped it, or is gone), one line says so, an error its bus gave as it went
/// is part of that end rather than a failure, and whatever this tool's node left of the
/// session is removed ([`RunningSession::tidy_after_reader`]): a look leaves nothing in
/// /dev/shm. Ctrl-C, `-n` and `--seconds` end it while the session runs, and the tool's
/// node removes its own files as it goes.
fn let_go(
    tool: &str,
    running: &RunningSession,
    bus: Bus,
    tap: Box<dyn Tap>,
    outcome: Result<(), MonitorError>,
) -> Result<ExitCode, MonitorError> {
    drop(tap);
    drop(bus);
    if running.is_running() {
        return outcome.map(|()| ExitCode::SUCCESS);
    }
    running.tidy_after_reader();
    eprintln!(
        "handblocks {tool}: session {} ended (`handblocks sessions` lists those that run)",
        running.bus.id
    );
    Ok(ExitCode::SUCCESS)
}

/// `handblocks echo TOPIC`: each sample, field by field, `---` between them.
pub fn echo(
    topic: &str,
    session: Option<&str>,
    count: Option<u64>,
    wait: bool,
) -> Result<ExitCode, MonitorError> {
    common::shutdown::install_signal_handlers();
    RunningSession::quiet_bus_log();
    let (running, bus, tap) = tap(topic, session)?;
    let topic = Topic::from_channel(topic).unwrap_or(Topic::World);
    eprintln!(
        "handblocks echo: {} of session {} (Ctrl-C stops)",
        topic.channel(),
        running.bus.id
    );
    let mut message = Vec::new();
    let mut text = String::new();
    let mut printed = 0;
    let (bus, tap, first) =
        first_or_let_go("echo", &running, bus, tap, topic, &mut message, wait, None)?;
    let mut have = first.is_some();
    let mut print_each = || -> Result<(), MonitorError> {
        while count.is_none_or(|n| printed < n) {
            if !have && next_sample(tap.as_ref(), &running, &mut message, None)?.is_none() {
                break;
            }
            have = false;
            text.clear();
            describe(topic, &message, &mut text);
            println!("{text}---");
            printed += 1;
        }
        Ok(())
    };
    let outcome = print_each();
    let_go("echo", &running, bus, tap, outcome)
}

/// `handblocks hz TOPIC`: once a second, the rate over the last `window` samples, as
/// `ros2 topic hz` prints it, from the samples' publish times.
pub fn hz(
    topic: &str,
    session: Option<&str>,
    window: usize,
    seconds: Option<f64>,
    wait: bool,
) -> Result<ExitCode, MonitorError> {
    common::shutdown::install_signal_handlers();
    RunningSession::quiet_bus_log();
    let (running, bus, tap) = tap(topic, session)?;
    let name = Topic::from_channel(topic).map_or("?", |t| t.channel());
    let topic = Topic::from_channel(topic).unwrap_or(Topic::World);
    eprintln!(
        "handblocks hz: {name} of session {} (Ctrl-C stops)",
        running.bus.id
    );
    let window = window.max(2);
    let mut times: std::collections::VecDeque<u64> =
        std::collections::VecDeque::with_capacity(window);
    let mut message = Vec::new();
    let started = Instant::now();
    // --seconds ends the look on time, samples or none (the wait below has this deadline).
    let until = seconds.map(|s| started + Duration::from_secs_f64(s.clamp(0.0, 1e9)));
    let mut last_print = Instant::now();
    let mut total = 0u64;
    // Each sample's hop, publish -> taken here (a tool's, not a stage's: kept to the end).
    let mut hops = common::latency::new_histogram();
    let (bus, tap, mut first) =
        first_or_let_go("hz", &running, bus, tap, topic, &mut message, wait, until)?;
    let outcome = loop {
        if seconds.is_some_and(|s| started.elapsed().as_secs_f64() >= s) {
            break Ok(());
        }
        let next = match first.take() {
            Some(sample) => Ok(Some(sample)),
            None => next_sample(tap.as_ref(), &running, &mut message, until),
        };
        let (stamp, taken) = match next {
            Ok(Some(sample)) => sample,
            Ok(None) => break Ok(()),
            Err(e) => break Err(e),
        };
        total += 1;
        let _ = hops.record(taken.saturating_sub(stamp.publish_ns).max(1));
        if times.len() == window {
            times.pop_front();
        }
        times.push_back(stamp.publish_ns);
        if last_print.elapsed() >= Duration::from_secs(1) && times.len() >= 2 {
            last_print = Instant::now();
            let gaps: Vec<f64> = times
                .iter()
                .zip(times.iter().skip(1))
                .map(|(a, b)| b.saturating_sub(*a) as f64 / 1e9)
                .collect();
            let mean = gaps.iter().sum::<f64>() / gaps.len() as f64;
            let var = gaps.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / gaps.len() as f64;
            let min = gaps.iter().copied().fold(f64::INFINITY, f64::min);
            let max = gaps.iter().copied().fold(0.0, f64::max);
            println!(
                "average rate: {:.3}\n\tmin: {:.4}s max: {:.4}s std dev: {:.5}s window: {}",
                if mean > 0.0 { 1.0 / mean } else { 0.0 },
                min,
                max,
                var.sqrt(),
                times.len()
            );
        }
    };
    eprintln!("handblocks hz: {total} samples");
    if total > 0 {
        let us = |q: f64| hops.value_at_quantile(q) as f64 / 1e3;
        eprintln!(
            "handblocks hz: publish -> taken here: p50 {:.1} us, p90 {:.1} us, p99 {:.1} us, \
             max {:.1} us",
            us(0.5),
            us(0.9),
            us(0.99),
            hops.max() as f64 / 1e3
        );
    }
    let_go("hz", &running, bus, tap, outcome)
}

/// One topic of a running session, as `handblocks topics` reports it.
#[derive(Debug, Clone)]
pub struct TopicInfo {
    pub topic: Topic,
    /// Its sample type (the recordings' schema name).
    pub type_name: &'static str,
    pub publishers: usize,
    /// Readers (subscribers) attached now.
    pub readers: usize,
    /// Samples a second over the window, read through an inlet of this look's own (None: not
    /// measured, or a lossless replay, which would wait for that reader).
    pub rate_hz: Option<f64>,
}

/// `handblocks topics`: a running session's topics, as `ros2 topic list` (`-v`: with their
/// publishers, readers, rate over `window_s` and type; `--json` all of it).
pub fn topics(
    session: Option<&str>,
    verbose: bool,
    json: bool,
    window_s: f64,
) -> Result<ExitCode, MonitorError> {
    RunningSession::quiet_bus_log();
    let running = pick(session)?;
    let bus = Bus::open(&running.bus, "monitor")?;
    // Counted before the look opens its own inlets, so that they are not among the readers.
    let services = bus.create_services()?;
    let attached: Vec<(usize, usize)> = Topic::RECORDED
        .iter()
        .map(|&t| (services.publishers(t), services.subscribers(t)))
        .collect();
    drop(services);
    let window = Duration::from_secs_f64(window_s.clamp(0.05, 60.0));
    // A lossless replay's publishers would wait for these readers: no rates there.
    let rates = if (verbose || json) && !running.bus.lossless {
        Some(measure_rates(&bus, window)?)
    } else {
        None
    };
    let elapsed = window.as_secs_f64();
    let infos: Vec<TopicInfo> = Topic::RECORDED
        .iter()
        .zip(&attached)
        .map(|(&t, &(publishers, readers))| TopicInfo {
            topic: t,
            type_name: recording::sample_type(t).0,
            publishers,
            readers,
            rate_hz: rates
                .as_ref()
                .and_then(|r| r.iter().find(|(x, _)| *x == t).map(|(_, hz)| *hz)),
        })
        .collect();
    drop(bus);
    if !running.is_running() {
        running.tidy_after_reader();
    }
    if json {
        let list: Vec<serde_json::Value> = infos
            .iter()
            .map(|i| {
                serde_json::json!({"topic": i.topic.channel(), "type": i.type_name,
                    "publishers": i.publishers, "readers": i.readers,
                    "rate_hz": i.rate_hz, "window_s": elapsed})
            })
            .collect();
        println!("{}", serde_json::Value::Array(list));
    } else if verbose {
        println!(
            "session {} ({}), rates over {:.1} s:",
            running.bus.id, running.session_file, elapsed
        );
        println!(
            "{:<10} {:<30} {:>10} {:>8} {:>10}",
            "topic", "type", "publishers", "readers", "rate (Hz)"
        );
        for i in &infos {
            println!(
                "{:<10} {:<30} {:>10} {:>8} {:>10}",
                i.topic.channel(),
                i.type_name,
                i.publishers,
                i.readers,
                i.rate_hz.map_or("-".to_string(), |r| format!("{r:.1}"))
            );
        }
        if rates.is_none() {
            println!(
                "(no rates: session {} is a lossless replay, whose publishers would wait for \
                 this look's readers)",
                running.bus.id
            );
        }
    } else {
        for i in infos.iter().filter(|i| i.publishers > 0 || i.readers > 0) {
            println!("{}", i.topic.channel());
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// A sample's fields, one per line (`name: value`), nested types indented, from its message
/// (the CDR header, then the bytes) by its schema's field list.
pub fn describe(topic: Topic, message: &[u8], out: &mut String) {
    let body = message.get(recording::CDR_LE_HEADER.len()..).unwrap_or(&[]);
    let (name, size) = recording::sample_type(topic);
    describe_struct(name, body, 0, out);
    if topic.element_size().is_some() {
        let count = body
            .get(size..size + 4)
            .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
        let at = recording::slice_elements_offset(topic);
        let element = topic.element_size().unwrap_or(0);
        out.push_str("blocks:\n");
        for i in 0..count {
            let Some(bytes) = body.get(at + i * element..at + (i + 1) * element) else {
                break;
            };
            out.push_str(&format!("- # [{i}]\n"));
            describe_struct("handblocks/BlockState", bytes, 1, out);
        }
    }
}

/// A sample's fields as JSON (`inspect --samples`), from its message by its schema's field
/// list, as [`describe`] prints them: nested messages as objects, arrays as lists, a slice
/// topic's elements under `blocks`. Numbers print in Rust's shortest round-trip form, so a
/// reader that parses them gets the recorded doubles exactly.
pub fn to_json(topic: Topic, message: &[u8]) -> serde_json::Value {
    let body = message.get(recording::CDR_LE_HEADER.len()..).unwrap_or(&[]);
    let (name, size) = recording::sample_type(topic);
    let mut value = struct_json(name, body);
    if let (Some(element), serde_json::Value::Object(map)) = (topic.element_size(), &mut value) {
        let count = body
            .get(size..size + 4)
            .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
        let at = recording::slice_elements_offset(topic);
        let blocks: Vec<serde_json::Value> = (0..count)
            .map_while(|i| body.get(at + i * element..at + (i + 1) * element))
            .map(|bytes| struct_json("handblocks/BlockState", bytes))
            .collect();
        map.insert("blocks".into(), blocks.into());
    }
    value
}

fn struct_json(name: &str, bytes: &[u8]) -> serde_json::Value {
    let mut map = serde_json::Map::new();
    for f in recording::fields(name)
        .into_iter()
        .flatten()
        .filter(|f| f.name != "reserved")
    {
        let (base, count, listed) = match f.ty.split_once('[') {
            Some((b, n)) => (
                b,
                n.trim_end_matches(']').parse::<usize>().unwrap_or(1),
                true,
            ),
            None => (f.ty, 1, false),
        };
        let Some(field) = bytes.get(f.offset..f.offset + f.size) else {
            continue;
        };
        let each = f.size / count.max(1);
        let values: Vec<serde_json::Value> = field
            .chunks_exact(each.max(1))
            .map(|c| {
                if recording::fields(base).is_some() {
                    struct_json(base, c)
                } else {
                    scalar_json(base, c)
                }
            })
            .collect();
        let value = if listed {
            values.into()
        } else {
            values.into_iter().next().unwrap_or_default()
        };
        map.insert(f.name.to_string(), value);
    }
    map.into()
}

fn scalar_json(ty: &str, b: &[u8]) -> serde_json::Value {
    let mut a = [0u8; 8];
    a[..b.len().min(8)].copy_from_slice(&b[..b.len().min(8)]);
    let w = [a[0], a[1], a[2], a[3]];
    match ty {
        "float64" => f64::from_le_bytes(a).into(),
        "uint64" => u64::from_le_bytes(a).into(),
        "int64" => i64::from_le_bytes(a).into(),
        "uint32" => u32::from_le_bytes(w).into(),
        "int32" => i32::from_le_bytes(w).into(),
        _ => b.iter().map(|x| u64::from(*x)).collect::<Vec<_>>().into(),
    }
}

fn describe_struct(name: &str, bytes: &[u8], depth: usize, out: &mut String) {
    let Some(fields) = recording::fields(name) else {
        return;
    };
    let pad = "  ".repeat(depth);
    for f in fields.iter().filter(|f| f.name != "reserved") {
        let (base, count) = match f.ty.split_once('[') {
            Some((b, n)) => (b, n.trim_end_matches(']').parse::<usize>().unwrap_or(1)),
            None => (f.ty, 1),
        };
        let Some(field) = bytes.get(f.offset..f.offset + f.size) else {
            continue;
        };
        if recording::fields(base).is_some() {
            let each = f.size / count.max(1);
            for i in 0..count {
                if count > 1 {
                    out.push_str(&format!("{pad}{}[{i}]:\n", f.name));
                } else {
                    out.push_str(&format!("{pad}{}:\n", f.name));
                }
                describe_struct(base, &field[i * each..(i + 1) * each], depth + 1, out);
            }
            continue;
        }
        let each = f.size / count.max(1);
        let values: Vec<String> = field
            .chunks_exact(each.max(1))
            .map(|c| scalar(base, c))
            .collect();
        let value = if count > 1 {
            format!("[{}]", values.join(", "))
        } else {
            values.into_iter().next().unwrap_or_default()
        };
        if f.name == "mode" {
            let mode = u32::from_le_bytes(field[..4].try_into().unwrap_or([0; 4]));
            let name = BlockMode::from_u32(mode).map_or("?", |m| m.name());
            out.push_str(&format!("{pad}mode: {value} ({name})\n"));
        } else {
            out.push_str(&format!("{pad}{}: {value}\n", f.name));
        }
    }
}

fn scalar(ty: &str, b: &[u8]) -> String {
    let arr = |n: usize| -> [u8; 8] {
        let mut a = [0u8; 8];
        a[..n.min(b.len())].copy_from_slice(&b[..n.min(b.len())]);
        a
    };
    match ty {
        "float64" => format!("{}", f64::from_le_bytes(arr(8))),
        "uint64" => format!("{}", u64::from_le_bytes(arr(8))),
        "int64" => format!("{}", i64::from_le_bytes(arr(8))),
        "uint32" => format!(
            "{}",
            u32::from_le_bytes(arr(4)[..4].try_into().unwrap_or([0; 4]))
        ),
        "int32" => format!(
            "{}",
            i32::from_le_bytes(arr(4)[..4].try_into().unwrap_or([0; 4]))
        ),
        _ => format!("{b:02x?}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_world_prints_its_fields_and_each_block_with_its_mode() {
        let mut header = common::WorldHeader::default();
        header.stamp.seq = 7;
        header.block_count = 2;
        let mut block = common::BlockState::default();
        block.pose.position = [0.5, 0.25, -1.0];
        block.mode = BlockMode::Grasped as u32;
        let mut message = Vec::new();
        recording::encode_slice(Topic::World, &header, &[block, block], &mut message);
        let mut text = String::new();
        describe(Topic::World, &message, &mut text);
        assert!(text.contains("stamp:\n  seq: 7\n"), "{text}");
        assert!(text.contains("block_count: 2\n"), "{text}");
        assert_eq!(text.matches("mode: 4 (grasped)").count(), 2, "{text}");
        assert!(text.contains("position: [0.5, 0.25, -1]"), "{text}");
    }
}
