//! The command line: every subcommand, its options and their help, as clap parses them. What
//! each subcommand does is its own module's; this file only says what can be asked.

use std::path::PathBuf;
use std::time::Duration;

use clap::{Parser, Subcommand};

/// The version and the commit it was built from (build.rs).
pub const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("HANDBLOCKS_COMMIT"),
    ")"
);

/// The session `handblocks` and `handblocks launch` run (found from any folder: `locate`).
pub const DEFAULT_SESSION: &str = "config/sessions/live.toml";

/// `launch --help`'s closing text: the report's terms and where the documents are.
const LAUNCH_AFTER_HELP: &str = concat!(
    "The latency table (microseconds), per stage:\n",
    "  hop          a sample's publish (by the stage before) to its receive here: the bus and the wake-up\n",
    "  process      receive to this stage's publish: its own work\n",
    "  origin->out  the sample's origin (when its source sample entered the pipeline) to this\n",
    "               stage's publish: the age of what it sends (at the stepper: origin -> world)\n",
    "  origin->px   the renderer only: origin to the frame's GPU work complete (origin -> photon)\n",
    "  received     per topic, the fewest samples any reader received; dropped = never read\n",
    "\n",
    "Besides the session's [budget] keys, every session is judged on what users assume: the source\n",
    "delivers a sample at least every `source_silence_ms` (default 1000), and the renderer draws at\n",
    "least (1 - `frame_rate_margin`) x frame_hz frames per second (default margin 0.25; frame_hz, or\n",
    "the world's rate when that is lower).\n",
    "\n",
    "Supervision, [supervise] in the session file (absent: restart = \"never\"):\n",
    "  restart = \"never\" | \"on-failure\"   a process that exits or is killed mid-session fails the\n",
    "               session at once, or is started again while the others keep running\n",
    "  max_restarts = 3 (0 to 1000)      restarts allowed per process; one more fails the session\n",
    "  backoff_ms = 100 (0 to 60000)     the wait before a process's first restart, doubled for each\n",
    "  backoff_max_ms = 2000             further one of the same process, up to this\n",
    "The report lists each restart (when, the exit, the downtime, samples lost); a restarted recorder\n",
    "writes the next segment beside the recording (live.mcap, then live.1.mcap, ...).\n",
    "The design: docs/design.md; the model: docs/model.md."
);

#[derive(Parser)]
#[command(
    name = "handblocks",
    version = VERSION,
    about = "A hand grasps, pushes, carries and throws virtual blocks at interactive rate.",
    long_about = "A hand grasps, pushes, carries and throws virtual blocks at interactive rate.\n\n\
        A session runs as independent processes (acquisition, kinematics, stepper, renderer, \
        recorder) exchanging zero-copy samples over iceoryx2; the launcher measures every \
        stage's latency and judges it against the session's [budget].\n\n\
        Start with:  ./run                        (set-up, build, the live session: the scripted hand)\n\
        \x20            handblocks launch --help     (options, the report and its terms)\n\
        \x20            handblocks list              (the scenes and sessions)\n\n\
        The design: docs/design.md; the model's rules: docs/model.md (in the repository)."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run a session: start its processes, measure latency, judge the budget.
    ///
    /// After the session it prints what the world came to (each block's final pose and mode,
    /// the events, as `simulate` does), the latency table, and the budget's verdict. A headless
    /// session also writes an animated preview (out/SESSION-preview.png; --no-preview: none).
    /// A replay session ends when its trace does (unless [source] loop = true).
    ///
    /// Exit status: 0 when the session ran within its [budget], 1 when it ran but violated the
    /// budget or a process failed, 2 when it could not run (bad config, no processes).
    #[command(after_help = LAUNCH_AFTER_HELP)]
    Launch(LaunchArgs),
    /// List a recording's topics: messages, sequence gaps, time span and rate of each.
    ///
    /// Reads an MCAP file the recorder wrote (`[recorder] file` in a session). A file cut off
    /// by a crash is read up to its last complete chunk and the damage is named with its byte
    /// offset. The file also opens in the standard MCAP tools (`mcap info FILE`, Foxglove).
    /// Exit status: 0 for an intact recording, 1 when it is damaged (what could be read is
    /// listed), 2 when it cannot be read at all.
    Inspect {
        /// The recording (.mcap).
        recording: PathBuf,
        /// Print {"file", "complete", "damage", "foreign_messages", "scene_messages", "refused_messages",
        /// "topics": [{"topic", "messages", "gaps", "seconds", "rate_hz", "schema", "bytes"}]}.
        #[arg(long)]
        json: bool,
        // A line per sample instead of the table: `--samples TOPIC` or `--world-hashes`.
        #[command(flatten)]
        samples: Option<InspectLines>,
    },
    /// Run a scene's block world alone, in one process, deterministically.
    ///
    /// The scene's [hand] keyframes drive the hand, sampled once per step: `grip`/`angles` keys
    /// through the hand model, `fingers` keys as bare check points. Two runs print identical
    /// bytes. Exit status 2 when the scene is refused (the message names file, key and range).
    Simulate {
        /// The scene file (docs/design.md, "Effects"; the rules: docs/model.md).
        scene: PathBuf,
        /// Steps to run, 0 to 10,000,000 (default: the hand's last key plus 3 s).
        #[arg(long, value_name = "N", value_parser = parse_steps, allow_negative_numbers = true)]
        frames: Option<u64>,
        /// Override the scene's [world] model.
        #[arg(long, value_parser = ["paper", "precise"])]
        model: Option<String>,
        /// Drive the hand from a trace instead of the scene's [hand]: one of our MCAP recordings
        /// (its glove + tracker or joints topics) or a CARL file (OpenXR joints), through the
        /// hand model and the stepper's own timeline, exactly as a live replay would.
        #[arg(long, value_name = "TRACE")]
        hand: Option<PathBuf>,
        /// Move the traced hand by X,Y,Z metres (real traces hold the hand ~1 m above the floor).
        #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
        hand_offset: Option<[f64; 3]>,
        /// Which hands of the trace drive the world: a CARL file tracks both (default: right).
        /// `both`: the two hands in one world (docs/model.md "Two hands"); events then name
        /// the hand ("hand": "left" or "right").
        #[arg(long, value_name = "SIDE", value_parser = ["left", "right", "both"], requires = "hand")]
        hands: Option<String>,
        /// Print {"frames", "blocks": [{"name", "position", "rotation", "mode"}], "events"}.
        #[arg(long, conflicts_with = "world_hashes")]
        json: bool,
        /// Print `STEP HASH` after every step instead of the report (as `inspect FILE
        /// --world-hashes` prints a recording's): `--hand` a shared world's host recording
        /// steps its world again from the hands it recorded, to compare line by line.
        #[arg(long)]
        world_hashes: bool,
        /// Override a key of the scene file, checked as the file's own keys are, e.g.
        /// --set world.hands=tracked (docs/model.md T1-T3 for tracked hands), --set
        /// tracked.grip_margin=0.03, --set effects.stacking=supported. Repeatable.
        #[arg(long = "set", value_name = "KEY=VALUE", value_parser = parse_override)]
        overrides: Vec<common::config::session::Override>,
    },
    /// Replay a recording or a CARL trace in place of the devices (as `ros2 bag play`).
    ///
    /// FILE is one of our MCAP recordings (its glove + tracker or joints topics) or a CARL
    /// file (OpenXR joints). The scene is the one the recording was made on, or, for a CARL
    /// trace, the one the configuration's session for that trace uses (--scene to choose).
    /// The pipeline makes the hand and the world anew from the trace; the session ends when
    /// the trace does (--loop: never). A shared world host's recording holds no source
    /// samples: its hands (every participant's, as its stepper took them) go straight to the
    /// stepper, which steps the host's worlds again, bit for bit (`inspect --world-hashes`). Everything else is `launch`'s: the report, the
    /// preview (out/replay-NAME-preview.png), --record, --set.
    ///
    /// Example: handblocks replay ../shared/data/carl/example_push_0.carl --speed 0.5
    Replay(ReplayArgs),
    /// Print a topic's samples on a running session, field by field (as `ros2 topic echo`).
    ///
    /// TOPIC is glove, tracker, joints, hand, world, frame or peer_hand (or /world, ...). The
    /// session is the only one running, or --session ID (`handblocks sessions` lists them). A
    /// topic nobody publishes in the session is said at once (`handblocks topics -v` lists who
    /// publishes what); --wait waits for a publisher instead. Ends with the session, after --count
    /// samples, or on Ctrl-C.
    ///
    /// Example: handblocks echo hand -n 1
    Echo {
        /// The topic.
        topic: String,
        /// The session's bus id (default: the only one running).
        #[arg(long, value_name = "ID")]
        session: Option<String>,
        /// Stop after this many samples (1 or more; default: until Ctrl-C).
        #[arg(long, short = 'n', value_name = "N", value_parser = parse_count, allow_negative_numbers = true)]
        count: Option<u64>,
        /// Wait for a publisher when nobody publishes the topic yet (default: say so and stop).
        #[arg(long)]
        wait: bool,
    },
    /// Print a topic's rate on a running session once a second (as `ros2 topic hz`).
    ///
    /// The rate is over the last --window samples' publish times (the publisher's clock, so
    /// this terminal's own delays do not show). A topic nobody publishes is said at once
    /// (--wait waits for a publisher instead). Ends with the session, after --seconds (on
    /// time, samples or none), or on Ctrl-C.
    ///
    /// Example: handblocks hz world --seconds 3
    Hz {
        /// The topic.
        topic: String,
        /// The session's bus id (default: the only one running).
        #[arg(long, value_name = "ID")]
        session: Option<String>,
        /// Samples the rate is taken over.
        #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(2..=100_000))]
        window: u64,
        /// Stop after this many seconds.
        #[arg(long, value_name = "SECONDS", value_parser = parse_seconds, allow_negative_numbers = true)]
        seconds: Option<Duration>,
        /// Wait for a publisher when nobody publishes the topic yet (default: say so and stop).
        #[arg(long)]
        wait: bool,
    },
    /// A running session's topics (as `ros2 topic list`); -v adds each one's publishers,
    /// readers, rate and sample type.
    ///
    /// The rate is measured over --window seconds from the counts the session's publishers
    /// keep, so looking adds no reader. Example: handblocks topics -v
    Topics {
        /// The session's bus id (default: the only one running).
        #[arg(long, value_name = "ID")]
        session: Option<String>,
        /// Publishers, readers, rate and type of every topic.
        #[arg(long, short = 'v')]
        verbose: bool,
        /// Print [{"topic", "type", "publishers", "readers", "rate_hz", "window_s"}].
        #[arg(long)]
        json: bool,
        /// Seconds the rates are measured over (-v and --json).
        #[arg(long, value_name = "SECONDS", default_value = "1", value_parser = parse_seconds, allow_negative_numbers = true)]
        window: Duration,
    },
    /// The sessions running on this machine: bus id, age, session file, processes.
    Sessions {
        /// Print [{"id", "session", "source", "started_unix_s", "launcher_pid", "lossless",
        /// "processes": [{"name", "pid"}]}].
        #[arg(long)]
        json: bool,
    },
    /// Benchmarks, each reported against a peer measured in the same run.
    Bench {
        #[command(subcommand)]
        which: BenchKind,
    },
    /// Emulate a CyberGlove or a FASTRAK on a pseudo-terminal, or a headset in a browser.
    ///
    /// glove, tracker: the device appears at --link (a symbolic link to the pty), which a
    /// session's [source.glove] or [source.tracker] `port` names exactly as it would name
    /// /dev/ttyUSB0. See config/devices/emulated-session.toml. Ctrl-C stops it.
    ///
    /// headset URL --trace FILE: plays a trace's hand through a webxr session's page in
    /// headless Chromium (see `handblocks emulate headset --help`).
    #[command(subcommand)]
    Emulate(EmulateDevice),
    /// The publishing half of the latency benchmark's peer (started by `bench latency`).
    #[command(hide = true)]
    BenchPeer {
        #[arg(long)]
        bus: String,
        #[arg(long)]
        rate: f64,
        #[arg(long)]
        count: u64,
    },
    /// The writing half of `bench latency transport` (started by it, one run each).
    #[command(hide = true)]
    BenchTransportPeer {
        #[arg(long)]
        transport: String,
        #[arg(long)]
        endpoint: String,
        #[arg(long)]
        bytes: usize,
        #[arg(long)]
        rate: f64,
        #[arg(long)]
        count: u64,
    },
    /// List the scenes and sessions under config/ (or DIR), each with its first comment line.
    List {
        /// Where to look.
        #[arg(default_value = "config")]
        dir: PathBuf,
    },
    /// The configuration files' keys: `config keys [--markdown|--json]` (docs/config.md).
    Config {
        #[command(subcommand)]
        what: crate::config_keys::ConfigCommand,
    },
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    ///
    /// For bash: handblocks completions bash > ~/.local/share/bash-completion/completions/handblocks
    Completions {
        /// bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
    },
    /// Run one process of a session (the launcher starts each one this way).
    #[command(hide = true)]
    Service {
        /// acquisition, kinematics, stepper, renderer or recorder.
        name: String,
        /// The session file.
        #[arg(long)]
        session: PathBuf,
        /// The session's bus id, as the launcher chose it.
        #[arg(long)]
        bus: String,
        /// The renderer only: write PNG frames here.
        #[arg(long, value_name = "DIR")]
        frames_dir: Option<PathBuf>,
        /// The recorder only: the file, in place of the session's `[recorder] file`.
        #[arg(long, value_name = "FILE")]
        record: Option<PathBuf>,
        /// The renderer only: write the animated preview here.
        #[arg(long, value_name = "FILE")]
        preview: Option<PathBuf>,
        /// The stepper only: write the world's outcome into this folder when stopping.
        #[arg(long, value_name = "DIR")]
        outcome_dir: Option<PathBuf>,
        /// The session's --set overrides, as the launcher got them.
        #[arg(long = "set", value_name = "KEY=VALUE", value_parser = parse_override)]
        overrides: Vec<common::config::session::Override>,
        /// Which restart of this process this is ([supervise]): 0 for its first start.
        #[arg(long, default_value_t = 0)]
        restart: u32,
    },
}

// What `handblocks launch` was given (the bare `handblocks` is `launch` with the defaults but
// the live session file). A plain comment: a doc comment here would replace the subcommand's
// own help, which the `Launch` variant above holds.
/// What `inspect` prints instead of its table, one line per sample: one of these at most, and
/// neither with `--json`.
#[derive(clap::Args, Debug, Clone)]
#[group(multiple = false)]
pub struct InspectLines {
    /// Print every sample of TOPIC instead (glove, tracker, joints, hand, world, frame,
    /// peer_hand): one JSON object a line, field by field as the recording's schema names them.
    #[arg(long, value_name = "TOPIC", conflicts_with = "json")]
    pub samples: Option<String>,
    /// Print `STEP HASH` for each world sample instead, in recording order (HASH: 16 hex
    /// digits of the step, the grasp and every block's pose bit for bit, mode and hands; not
    /// the stamps), so that two participants' recordings of a shared session can be compared
    /// line by line (`diff`): the first differing line is the first step they disagree on.
    #[arg(long, conflicts_with = "json")]
    pub world_hashes: bool,
}

#[derive(clap::Args, Default)]
pub struct LaunchArgs {
    /// The session file (which scene, which source, renderer, recorder, budget), or a scene
    /// file (run with the default settings: the scripted hand, headless).
    #[arg(default_value = "config/sessions/live.toml")]
    pub session: PathBuf,
    /// Override a key of the session file, e.g. --set renderer.mode=off, --set
    /// budget.max_dropped=0, --set source.file=my.carl (a path given here starts at the
    /// current folder, as on any command line; in the file, at the file's folder), or of its
    /// scene with `scene.`, e.g. --set
    /// scene.world.hands=tracked (docs/model.md T1-T3 for a tracked hand). Checked as the
    /// files' keys are. Repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE", value_parser = parse_override)]
    pub overrides: Vec<common::config::session::Override>,
    /// No animated preview (a headless session writes one by default).
    #[arg(long)]
    pub no_preview: bool,
    /// Replace what is at the recording's path (--record or [recorder] file, and its restart
    /// segments), --report's path and --frames-dir's frame_*.png: the file or link itself is
    /// removed (never a link's target) and the session writes its own, private (0600). Without
    /// it, any of these that exists is refused before anything starts.
    #[arg(long)]
    pub force: bool,
    /// Stop after this many seconds (default: run until Ctrl-C or SIGTERM).
    #[arg(long, value_name = "SECONDS", value_parser = parse_seconds, allow_negative_numbers = true)]
    pub duration: Option<Duration>,
    /// Also write the report as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// The session's bus id (iceoryx2 prefix `hb_<ID>_`); default: a fresh one.
    #[arg(long, value_name = "ID")]
    pub bus_id: Option<String>,
    /// No progress lines while running.
    #[arg(long)]
    pub quiet: bool,
    /// Write rendered frames as PNG into DIR (every `[renderer] frames_every`-th frame).
    #[arg(long, value_name = "DIR")]
    pub frames_dir: Option<PathBuf>,
    /// Record every topic to this MCAP file (overrides the session's `[recorder] file`);
    /// list it with `handblocks inspect FILE`, replay it with `[source] kind = "replay"`.
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
    #[command(flatten)]
    pub world: WorldPrint,
}

/// How much of what the world came to a session prints at its end. By default a summary:
/// the blocks counted by mode (each block only in a scene of at most
/// `world_summary::BLOCKS_LISTED` blocks), the events counted by kind, and the grasps, releases and
/// topples: a thousand blocks' poses and their events would bury the verdict.
#[derive(clap::Args, Default, Clone, Copy)]
pub struct WorldPrint {
    /// Print every block's final pose and mode (as `simulate` prints them).
    #[arg(long)]
    pub blocks: bool,
    /// Print every event with its step (as `simulate` prints them).
    #[arg(long)]
    pub events: bool,
}

/// What `handblocks replay` was given.
#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The trace: a recording (.mcap) or a CARL file (.carl).
    pub file: PathBuf,
    /// 1 = recorded timing, 0.5 = half speed, 0 = as fast as the pipeline takes it (losing
    /// nothing).
    #[arg(long, default_value_t = 1.0, value_parser = parse_speed, allow_negative_numbers = true)]
    pub speed: f64,
    /// Play it again and again until stopped.
    #[arg(long = "loop")]
    pub looped: bool,
    /// Play only these source topics (glove, tracker, joints; comma-separated or repeated).
    #[arg(long, value_name = "TOPIC")]
    pub topics: Vec<String>,
    /// Which hands of a CARL trace play: right, left, or both in one world (docs/model.md
    /// "Two hands"); a recording plays the hands it holds.
    #[arg(long, value_name = "SIDE", default_value = "right", value_parser = ["right", "left", "both"])]
    pub hands: String,
    /// The scene (a file, or a name of `handblocks list`); default: see above.
    #[arg(long, value_name = "SCENE")]
    pub scene: Option<PathBuf>,
    /// Move the traced hand by X,Y,Z metres (default: the CARL sessions' own offset for a
    /// CARL trace, none for a recording).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub offset: Option<[f64; 3]>,
    /// Stop after this many seconds (default: when the trace ends).
    #[arg(long, value_name = "SECONDS", value_parser = parse_seconds, allow_negative_numbers = true)]
    pub duration: Option<Duration>,
    /// Record the replayed session to this MCAP file.
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
    /// Override a key of the replay's session, as `launch --set` (e.g. renderer.mode=off).
    #[arg(long = "set", value_name = "KEY=VALUE", value_parser = parse_override)]
    pub overrides: Vec<common::config::session::Override>,
    /// No animated preview.
    #[arg(long)]
    pub no_preview: bool,
    /// Replace what is at --record's and --report's paths.
    #[arg(long)]
    pub force: bool,
    /// Also write the report as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// No progress lines while running.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub world: WorldPrint,
}

fn parse_speed(s: &str) -> Result<f64, String> {
    s.parse::<f64>()
        .ok()
        .filter(|v| (0.0..=1000.0).contains(v))
        .ok_or_else(|| format!("{s:?}: allowed 0 (as fast as the pipeline takes it) to 1000"))
}

/// The parts of `bench latency`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LatencyPart {
    /// The live session's hops and origin -> world against a bare hop.
    Pipeline,
    /// One hop over each transport at each payload size.
    Transport,
    /// The scripted hand at 1 kHz for 60 s, every topic recorded: drops, gaps, latency.
    Load,
    /// transport, then pipeline, then load, into one latency.json.
    All,
}

#[derive(Subcommand)]
pub enum BenchKind {
    /// Latency: `pipeline` (default), per-hop and origin -> world latency of the whole process
    /// set against a bare two-process iceoryx2 hop measured in the same run; `load`, the
    /// scripted hand at 1 kHz for 60 s with every topic recorded (drops, gaps, recording
    /// completeness and each stage's latency under that load); `transport`, one
    /// hop between two processes over iceoryx2 (woken by its datagram or its semaphore event,
    /// and polled), a bare futex and eventfd wake-up (the floor), a Unix socket, TCP and
    /// zenoh, at 64 B to 4 MiB, 120 Hz and flat out, the median of --runs sweeps, with .hgrm
    /// files and a plot.
    Latency {
        /// What to measure.
        #[arg(value_enum, default_value = "pipeline")]
        part: LatencyPart,
        /// `transport`: 1 s paced runs and short flat-out ones (under a minute); `load`: 5 s;
        /// `all`: both, and a 2 s pipeline.
        #[arg(long)]
        quick: bool,
        /// `pipeline` and `load`: the session to measure (`load` makes its source the
        /// scripted hand at 1 kHz).
        #[arg(long, default_value = "config/sessions/live.toml")]
        session: PathBuf,
        /// `pipeline` only: seconds for the peer, and again for the session.
        #[arg(long, default_value = "10", value_parser = parse_seconds)]
        seconds: Duration,
        /// `transport` and `pipeline`: whole runs, one after another; each figure published is
        /// the median of the runs', with their spread.
        #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=20))]
        runs: u64,
        /// `transport` only: the transports to measure, comma-separated (default: all):
        /// iceoryx2, iceoryx2-doorbell, iceoryx2-semaphore, iceoryx2-poll, futex, eventfd, uds, tcp, zenoh.
        #[arg(long, value_name = "LIST", value_delimiter = ',', value_parser = parse_transport)]
        transports: Vec<handblocks_bench::transport::Transport>,
        /// Where the parts' files go (pipeline.json, transport.json, load.json, .md, .png,
        /// hgrm/), and latency.json: {"transport": [...], "pipeline": [...], "load": {...}}
        /// with every part run into this folder.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// What accuracy costs in time: the paper model and the precise one (rapier3d) against
    /// exact answers at several settings each, timed in the same run.
    Accuracy {
        /// Where accuracy.json, accuracy.md and accuracy.png go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// A reduced sweep (under a minute on 2 cores).
        #[arg(long)]
        quick: bool,
        /// Whole runs, each measuring everything from the start: every published ratio is the
        /// median of the runs' medians, with the run-to-run spread beside it.
        #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=20))]
        runs: u64,
    },
    /// Every hard case (config/scenes/hard/) under the paper model, R11 only (stacks) and the
    /// precise one, with drift, sink, penetration, decision, time to rest and a state hash.
    Stability {
        /// Where stability.json, stability.md and stability.png go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Leave out the slowest precise runs (under a minute on 2 cores).
        #[arg(long)]
        quick: bool,
    },
    /// How well a tracked hand holds and throws (issue 41): scripted throws with a known
    /// release velocity, degraded as trackers deliver hands (rate, noise, latency, gaps) at
    /// named levels, scored for the world's `hands = "tracked"` and `"paper"` rules and four
    /// SDK throw rules (release speed and direction error, false drops, flickers, release
    /// timing); and the CARL recordings under --traces replayed under both rules.
    Hands {
        /// Where hands.json, hands.md and hands.png go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// The CARL recordings (a relative path not found here is also looked for beside the
        /// repository this binary was built from).
        #[arg(long, value_name = "DIR", default_value = "../shared/data/carl")]
        traces: PathBuf,
        /// Scripted throws per level.
        #[arg(long, value_name = "N", default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=100_000))]
        throws: u64,
        /// At most 100 throws per level (a few seconds).
        #[arg(long)]
        quick: bool,
    },
    /// How far each engine is from a real block: real tosses of a 10.5 cm cube tracked at
    /// 148 Hz, each simulated from its first tracked state by the paper model, the precise model
    /// (rapier3d), MuJoCo and PyBullet (at the source's nominal contact values, at values
    /// fitted to a quarter of the tosses, and at each engine's own), and scored against the rest
    /// of its track: position error in cube edges (in flight and after the first impact),
    /// rotation error, final position, same face, and each engine's own time per simulated
    /// second (MuJoCo and PyBullet from Python, their loops timed apart from the bench's I/O).
    Tosses {
        /// Where tosses.json, tosses.md and tosses.png go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// A folder of toss CSVs in the format of ../shared/data/tosses/README.md (a relative
        /// path not found here is also looked for beside the repository this binary was built
        /// from).
        #[arg(long, value_name = "DIR", default_value = "../shared/data/tosses")]
        tosses: PathBuf,
        /// Fit every engine's contact values again (friction x restitution, then contact
        /// stiffness, a grid scored on every fourth toss) and write config/tosses-fit.toml,
        /// which every run reads.
        #[arg(long)]
        fit: bool,
        /// The first 40 tosses only (a minute).
        #[arg(long)]
        quick: bool,
        /// A Python that imports mujoco and pybullet, for the outside engines. Without it the
        /// bench makes its own venv under target/toss-engines (once, from the package index);
        /// where it cannot, the run goes on without them and its page says so.
        #[arg(long, value_name = "PATH")]
        python: Option<PathBuf>,
        /// Whole runs of every engine (each 3 interleaved rounds): a published time is the
        /// median of the runs' medians, with the run-to-run spread beside it.
        #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=20))]
        runs: u64,
    },
    /// A shared world under a bad network (issue 45): a host and two participants on this
    /// machine (the scripted hand; a CARL recording, looped), each behind its own UDP proxy
    /// that delays and drops zenoh's QUIC datagrams, at 0/0, 20/1, 50/1, 100/1 and 100/5 (ms
    /// each way / % loss). Per participant: hand -> world p50/p99 beside the injected round
    /// trip, world-hash divergences from the host's recording, worlds lost, hands sent, taken,
    /// lost and refused; per condition, the host's bridge CPU per participant and bytes a second.
    Shared {
        /// Where shared.json, shared.md and shared.png go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Two conditions (0/0 and 20/1), 10 s each.
        #[arg(long)]
        quick: bool,
        /// Seconds each condition runs (the host runs 4 s longer).
        #[arg(long, value_name = "S", default_value_t = 30.0, value_parser = parse_bench_seconds)]
        seconds: f64,
        /// The CARL recordings: the second participant replays example_lift_0.carl from here
        /// (the scripted hand where it is missing; a relative path not found here is also
        /// looked for beside the repository this binary was built from).
        #[arg(long, value_name = "DIR", default_value = "../shared/data/carl")]
        traces: PathBuf,
    },
    /// What a step costs as the world grows (16 to 4096 blocks: falling, resting, a hand
    /// sweeping a field) under both models, and what each `[effects]` effect costs on and off.
    ///
    /// Scaling: every step timed on its own, p50/p99, blocks active, the fitted exponent of
    /// time against N, the paper model's time as a ratio to the precise model's. Ablation: per
    /// effect, the same scene with it on and off, 5 interleaved runs a side, with the noise of
    /// the machine beside the difference. Sizes over the world's block limit are listed as
    /// not run.
    Stepper {
        /// Where stepper.json, stepper.md and stepper.png go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// 16 and 64 blocks only, 2 timed runs (well under a minute on 2 cores).
        #[arg(long)]
        quick: bool,
        /// Whole runs of the scaling part, each from the start: every published ratio is the
        /// median of the runs' medians, with the run-to-run spread beside it.
        #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=20))]
        runs: u64,
    },
}

fn parse_bench_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (2.0..=3600.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: give seconds from 2 to 3600")),
    }
}

fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("{s:?}: give three numbers, X,Y,Z (metres)"));
    }
    let mut v = [0.0; 3];
    for (slot, p) in v.iter_mut().zip(&parts) {
        *slot = p
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite() && x.abs() <= 1e5)
            .ok_or_else(|| format!("{p:?} is not a number of metres within 100 km"))?;
    }
    Ok(v)
}

/// Session keys whose values are paths. In a file they start at the file's folder; given with
/// --set they start where the user stands, as every other path on a command line does, so
/// `--set source.file=my.carl` is the my.carl of the current folder (issue 43).
const PATH_KEYS: [&str; 10] = [
    "scene",
    "hand_model",
    "source.file",
    "source.certificate_dir",
    "source.key_dir",
    "source.peer_certificate",
    "source.glove.calibration",
    "recorder.file",
    "remote.key_dir",
    "remote.peer_certificate",
];

fn parse_override(s: &str) -> Result<common::config::session::Override, String> {
    let mut o = common::config::session::Override::parse(s)?;
    if PATH_KEYS.contains(&o.key.as_str()) {
        if let toml::Value::String(p) = &o.value {
            let path = std::path::Path::new(p);
            if path.is_relative() {
                let abs = std::path::absolute(path)
                    .map_err(|e| format!("{}: {p}: cannot make it absolute: {e}", o.key))?;
                o.value = toml::Value::String(abs.display().to_string());
            }
        }
    }
    Ok(o)
}

/// `simulate --frames`: the steps to run. The bound is what a run can finish: ten million
/// steps of 120 Hz are 23 hours of world time.
fn parse_steps(s: &str) -> Result<u64, String> {
    s.parse::<u64>()
        .ok()
        .filter(|n| *n <= 10_000_000)
        .ok_or_else(|| format!("{s}: allowed: a whole number of steps, 0 to 10000000"))
}

/// `echo -n`: how many samples to print before stopping.
fn parse_count(s: &str) -> Result<u64, String> {
    s.parse::<u64>().ok().filter(|n| *n >= 1).ok_or_else(|| {
        format!("{s}: allowed: a whole number of samples, 1 or more (leave -n out to print until Ctrl-C)")
    })
}

fn parse_transport(s: &str) -> Result<handblocks_bench::transport::Transport, String> {
    handblocks_bench::transport::Transport::from_name(s).ok_or_else(|| {
        let names: Vec<&str> = handblocks_bench::transport::Transport::ALL
            .iter()
            .map(|t| t.name())
            .collect();
        format!("{s:?} is not a transport (allowed: {})", names.join(", "))
    })
}

fn parse_seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if !(v.is_finite() && v > 0.0 && v <= 86_400.0 * 365.0) {
        return Err(format!(
            "{s}: allowed: more than 0 and at most a year of seconds"
        ));
    }
    Ok(Duration::from_secs_f64(v))
}

/// `handblocks emulate DEVICE`: each device with only the options it takes.
#[derive(Subcommand)]
pub enum EmulateDevice {
    /// A CyberGlove on a pseudo-terminal at --link.
    Glove {
        #[command(flatten)]
        serial: EmulatedSerial,
        /// Glove sensors (18 or 22).
        #[arg(long, default_value = "22", value_parser = clap::value_parser!(u8).range(18..=22))]
        sensors: u8,
    },
    /// A FASTRAK on a pseudo-terminal at --link.
    Tracker {
        #[command(flatten)]
        serial: EmulatedSerial,
    },
    /// A headset in headless Chromium, playing a trace's hand through a webxr session's page.
    ///
    /// Opens the page (the URL the session printed) with IWER (Meta's WebXR emulation
    /// runtime: an emulated Quest with hand tracking) as its XR runtime, enters VR, and plays
    /// the trace's hand (a CARL file, or one of our recordings' joints) through the page's
    /// WebXR calls, one trace sample per XR frame in the sample's own time. Needs Chromium and
    /// Node.js with playwright-core and iwer (tests/run installs them:
    /// scripts/webxr-tools.sh). Prints what the page measured.
    Headset {
        // url, --trace and --link are checked by `emulate` itself, whose messages say what each
        // is for and give an example; clap's would only name them.
        /// The page's URL, as the session printed it (with its token).
        url: Option<String>,
        /// The hand to play (a CARL file, or a recording with `joints`); needed unless
        /// --spectator.
        #[arg(long, value_name = "FILE")]
        trace: Option<PathBuf>,
        /// Which of the page's hands plays the trace: right or left (the trace's hand, a CARL
        /// file's right), or both (a CARL file's right and left hands, or a two-hand
        /// recording's; both of a sample in one XR frame).
        #[arg(long, visible_alias = "hands", default_value = "right", value_parser = ["right", "left", "both"])]
        hand: String,
        /// A screenshot of the page when done (PNG).
        #[arg(long, value_name = "PNG")]
        screenshot: Option<PathBuf>,
        /// Open the page as a spectator (no XR, no trace), wait for a drawn world, screenshot.
        #[arg(long)]
        spectator: bool,
    },
}

/// What an emulated serial device (glove or tracker) takes.
#[derive(clap::Args)]
pub struct EmulatedSerial {
    /// Where the device appears: a symbolic link to its pty, in an existing folder (needed).
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
    /// Records per second (glove default 100, tracker default 120).
    #[arg(long, value_name = "HZ")]
    pub rate: Option<f64>,
    /// A fault to inject, KIND@RECORD[:ARG]: garbage@100, truncate@200:5, corrupt@300:7,
    /// silence@400:1500 (ms, or `forever`), unplug@500:1000. Repeatable.
    #[arg(long = "fault", value_name = "SPEC")]
    pub faults: Vec<String>,
}
