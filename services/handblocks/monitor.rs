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
//! carries (the topic table's field lists: each field's name, type, offset and size), walked
//! once by `recording::walk` for the text and for the JSON, so every topic prints without code
//! of its own; a topic's inlet is the run-time one (`AnyInlet`), whichever the topic.

use std::fmt;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use common::bus::{AnyInlet, Bus, BusConfig, BusError, RunningSession, Wakeable};
use common::topic::{Field, Meaning};
use common::{Stamp, Topic};
use recording::{Group, MessageVisitor, Value, Values};

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

/// One topic's inlet, whatever its topic: the next sample as a recording's bytes.
type Tap = AnyInlet;

/// The next sample of `tap`: its message (CDR header and bytes) into `out`, its stamp, and
/// when it was taken (CLOCK_MONOTONIC, before it was copied out).
fn take(tap: &Tap, out: &mut Vec<u8>) -> Result<Option<(Stamp, u64)>, BusError> {
    Ok(tap.receive()?.map(|s| {
        let taken = common::monotonic_ns();
        recording::encode_view(&s.view(), out);
        (*s.stamp(), taken)
    }))
}

/// Samples a second of every recorded topic over `window`, read through one inlet each (as
/// `ros2 topic hz` reads: a reader for the look's length). In topic order.
fn measure_rates(bus: &Bus, window: Duration) -> Result<Vec<(Topic, f64)>, MonitorError> {
    // An inlet of every recorded topic (a short look at all of them: `topics -v`).
    let taps = Topic::RECORDED
        .into_iter()
        .map(|t| bus.any_inlet(t))
        .collect::<Result<Vec<_>, _>>()?;
    let mut counts = vec![0u64; taps.len()];
    let mut message = Vec::new();
    let started = Instant::now();
    let until = started + window;
    loop {
        for (tap, n) in taps.iter().zip(counts.iter_mut()) {
            while take(tap, &mut message)?.is_some() {
                *n += 1;
            }
        }
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() || common::shutdown::requested() {
            break;
        }
        common::bus::wait_each(
            taps.iter().map(|t| t as &dyn Wakeable),
            None,
            left.min(Duration::from_millis(50)),
        )?;
    }
    let secs = started.elapsed().as_secs_f64().max(1e-3);
    Ok(taps
        .iter()
        .zip(counts)
        .map(|(t, n)| (t.topic(), n as f64 / secs))
        .collect())
}

/// The running session, and an inlet of `topic` on its bus.
fn tap(topic: &str, session: Option<&str>) -> Result<(RunningSession, Bus, Tap), MonitorError> {
    let topic = Topic::from_channel(topic)
        .filter(|t| t.is_recorded())
        .ok_or_else(|| MonitorError::NoTopic(topic.to_string()))?;
    let running = pick(session)?;
    if running.bus.lossless {
        return Err(MonitorError::Lossless(running.bus.id.clone()));
    }
    let bus = Bus::open(&running.bus, "monitor")?;
    let tap = bus.any_inlet(topic)?;
    Ok((running, bus, tap))
}

/// Waits for the next sample of `tap` until the session ends (its launcher gone) or
/// `until` passes.
fn next_sample(
    tap: &Tap,
    running: &RunningSession,
    message: &mut Vec<u8>,
    until: Option<Instant>,
) -> Result<Option<(Stamp, u64)>, MonitorError> {
    loop {
        if let Some(taken) = take(tap, message)? {
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
        common::bus::wait_each(std::iter::once(tap as &dyn Wakeable), None, wait)?;
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
    tap: &Tap,
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
type KeptLook = (Bus, Tap, Option<(Stamp, u64)>);

/// [`first_sample_or_say_why`] for a look that owns its bus and inlet: handed back with the
/// first sample, or let go of (nothing of the look left) when the topic is refused.
#[allow(clippy::too_many_arguments)]
fn first_or_let_go(
    tool: &str,
    running: &RunningSession,
    bus: Bus,
    tap: Tap,
    topic: Topic,
    message: &mut Vec<u8>,
    wait: bool,
    until: Option<Instant>,
) -> Result<KeptLook, MonitorError> {
    match first_sample_or_say_why(tool, &bus, running, topic, &tap, message, wait, until) {
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
    tap: Tap,
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
            if !have && next_sample(&tap, &running, &mut message, None)?.is_none() {
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
            None => next_sample(&tap, &running, &mut message, until),
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
/// (the CDR header, then the bytes) by its schema's field list ([`recording::walk`]).
pub fn describe(topic: Topic, message: &[u8], out: &mut String) {
    recording::walk(topic, message, &mut Text { out, depth: 0 });
}

/// A sample's fields as JSON (`inspect --samples`), from its message by its schema's field
/// list ([`recording::walk`]), as [`describe`] prints them: nested messages as objects, arrays
/// as lists, a slice topic's elements under their name (`blocks`). Numbers print in Rust's
/// shortest round-trip form, so a reader that parses them gets the recorded doubles exactly.
pub fn to_json(topic: Topic, message: &[u8]) -> serde_json::Value {
    let mut json = Json {
        open: vec![Open::Object(serde_json::Map::new())],
    };
    recording::walk(topic, message, &mut json);
    match json.open.pop() {
        Some(Open::Object(map)) => map.into(),
        _ => serde_json::Value::Null,
    }
}

/// [`describe`]'s visitor: a line per field of numbers, `name:` (or `name[i]:`) above each
/// nested message's fields, `- # [i]` above each element's.
struct Text<'o> {
    out: &'o mut String,
    depth: usize,
}

impl Text<'_> {
    fn pad(&mut self) {
        for _ in 0..self.depth {
            self.out.push_str("  ");
        }
    }
}

impl MessageVisitor for Text<'_> {
    fn values(&mut self, field: &Field, values: Values<'_>) {
        let first = values.clone().next();
        let shown: Vec<String> = values.map(|v| v.to_string()).collect();
        let value = if field.count() > 1 {
            format!("[{}]", shown.join(", "))
        } else {
            shown.into_iter().next().unwrap_or_default()
        };
        self.pad();
        self.out.push_str(&format!("{}: {value}", field.name));
        // An enumeration's value with its name (`mode: 4 (grasped)`).
        if let Meaning::Names(names) = field.meaning {
            let name = first
                .and_then(Value::as_index)
                .and_then(|v| names.get(usize::try_from(v).ok()?))
                .unwrap_or(&"?");
            self.out.push_str(&format!(" ({name})"));
        }
        self.out.push('\n');
    }

    fn begin(&mut self, group: Group<'_>) {
        if let Group::Elements { name, .. } = group {
            self.pad();
            self.out.push_str(&format!("{name}:\n"));
        }
    }

    fn item(&mut self, group: Group<'_>, index: usize) {
        self.pad();
        match group {
            Group::Field(f) if f.count() > 1 => {
                self.out.push_str(&format!("{}[{index}]:\n", f.name));
            }
            Group::Field(f) => self.out.push_str(&format!("{}:\n", f.name)),
            Group::Elements { .. } => self.out.push_str(&format!("- # [{index}]\n")),
        }
        self.depth += 1;
    }

    fn end_item(&mut self, _: Group<'_>) {
        self.depth = self.depth.saturating_sub(1);
    }
}

/// What [`to_json`]'s visitor is filling: the object of the message being walked, or the
/// list of an array field's (or the elements') messages.
enum Open {
    Object(serde_json::Map<String, serde_json::Value>),
    List(Vec<serde_json::Value>),
}

/// [`to_json`]'s visitor: an object per message, a list per array.
struct Json {
    open: Vec<Open>,
}

impl Json {
    /// Puts `value` where the walk is: into the list being filled, or under `name` into the
    /// object.
    fn put(&mut self, name: &str, value: serde_json::Value) {
        match self.open.last_mut() {
            Some(Open::List(list)) => list.push(value),
            Some(Open::Object(map)) => {
                map.insert(name.to_string(), value);
            }
            None => {}
        }
    }
}

impl MessageVisitor for Json {
    fn values(&mut self, field: &Field, values: Values<'_>) {
        let mut values = values.map(|v| match v {
            Value::F64(v) => serde_json::Value::from(v),
            Value::U64(v) => v.into(),
            Value::I64(v) => v.into(),
            Value::U32(v) => v.into(),
            Value::I32(v) => v.into(),
            Value::U8(v) => v.into(),
        });
        let value = if field.dims.is_empty() {
            values.next().unwrap_or_default()
        } else {
            values.collect::<Vec<_>>().into()
        };
        self.put(field.name, value);
    }

    fn begin(&mut self, group: Group<'_>) {
        if group.is_list() {
            self.open.push(Open::List(Vec::new()));
        }
    }

    fn item(&mut self, _: Group<'_>, _: usize) {
        self.open.push(Open::Object(serde_json::Map::new()));
    }

    fn end_item(&mut self, group: Group<'_>) {
        if let Some(Open::Object(map)) = self.open.pop() {
            self.put(group.name(), map.into());
        }
    }

    fn end(&mut self, group: Group<'_>) {
        if group.is_list() {
            if let Some(Open::List(list)) = self.open.pop() {
                self.put(group.name(), list.into());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::BlockMode;

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
