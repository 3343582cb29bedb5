//! Session files: which scene, which source feeds the pipeline, renderer and recorder settings,
//! and the interactive-rate budget (docs/design.md, "Sessions").

use std::path::{Path, PathBuf};

use super::catalog::{FileKind, Spec};
use super::devices::{self, GloveConfig, TrackerConfig};
use super::hand::HandModelSpec;
use super::reader::{parse_file, Reader};
pub use super::remote::{BridgeSettings, LinkRole, RemoteLink};
use super::scene::{HandKey, HandPoseSpec, HandScript, Scene};
use super::ConfigError;

/// A whole session file, with its scene loaded.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    pub file: PathBuf,
    /// The scene file, resolved against the session file's folder.
    pub scene_file: PathBuf,
    pub scene: Scene,
    pub source: Source,
    pub renderer: RendererSettings,
    pub recorder: RecorderSettings,
    pub budget: Budget,
    /// The hand model (`hand_model = "../hand.toml"`); the built-in adult hand when absent.
    pub hand_model: HandModelSpec,
    /// `[pipeline]`: how the pipeline's stages wait for their next sample.
    pub wait: WaitStrategy,
    /// `[pipeline] wake`: what wakes a stage that sleeps for its next sample.
    pub wake: WakeUp,
    /// `[supervise]`: what the launcher does when a process dies mid-session.
    pub supervise: Supervise,
    /// `[remote]`, `[source] kind = "remote"` and `[viewer]`: what the bridge process forwards
    /// beyond this machine's shared memory (issue 17); off unless a key asks for it.
    pub bridge: BridgeSettings,
}

/// `[supervise] restart`: what the launcher does when a process exits mid-session without
/// being asked to (a crash, SIGKILL, the OOM killer).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RestartPolicy {
    /// The session fails at once, naming the process (a test or a benchmark wants to know).
    #[default]
    Never,
    /// The process is started again (after the back-off), the others go on; past
    /// `max_restarts` restarts of one process the session fails as with `never`.
    OnFailure,
}

impl RestartPolicy {
    pub fn name(self) -> &'static str {
        match self {
            RestartPolicy::Never => "never",
            RestartPolicy::OnFailure => "on-failure",
        }
    }
}

/// `[supervise]`: restarting a process that died. Absent, `never`: a session file says when it
/// wants restarts (the live session does), so a benchmark or test never hides a crash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Supervise {
    pub restart: RestartPolicy,
    /// Restarts allowed per process over the session; one more fails it.
    pub max_restarts: u32,
    /// The wait before a process's first restart, milliseconds; each further restart of the
    /// same process waits twice as long as the one before, up to `backoff_max_ms`, so that a
    /// process that dies at once on start does not spin.
    pub backoff_ms: u64,
    pub backoff_max_ms: u64,
}

impl Default for Supervise {
    fn default() -> Self {
        Supervise {
            restart: RestartPolicy::Never,
            max_restarts: 3,
            backoff_ms: 100,
            backoff_max_ms: 2000,
        }
    }
}

impl Supervise {
    /// The wait before restart number `n` (1 for the first) of one process.
    pub fn backoff(&self, n: u32) -> std::time::Duration {
        let doubled = self
            .backoff_ms
            .saturating_mul(1u64 << n.saturating_sub(1).min(20));
        std::time::Duration::from_millis(doubled.min(self.backoff_max_ms.max(self.backoff_ms)))
    }
}

/// `[source]`: what feeds the pipeline.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// The scene's `[hand]` keyframes, sampled at `rate_hz`.
    Scripted { rate_hz: f64 },
    /// A CyberGlove and a FASTRAK on serial ports, with their settings read and checked at
    /// load ([`super::devices`]), so a wrong key fails the session before anything starts.
    /// Boxed: the settings are large beside the other sources' few numbers.
    Devices {
        glove: Box<GloveConfig>,
        tracker: Box<TrackerConfig>,
    },
    /// A recorded hand (one of our MCAP recordings or a CARL trace); `speed` 0 = as fast as the pipeline consumes;
    /// `offset` moves the recorded hand, metres (real traces hold it ~1 m above the floor).
    /// The session ends when the trace does, unless `looped` (`loop = true`): then it plays
    /// again, its source times continuing, until stopped.
    Replay {
        file: PathBuf,
        speed: f64,
        offset: [f64; 3],
        looped: bool,
        /// `topics`: the trace's source topics to play (glove, tracker, joints); empty: all
        /// it holds (as `ros2 bag play --topics`).
        topics: Vec<crate::topic::Topic>,
        /// `hands`: which hands of a CARL trace to play, `"right"` (default), `"left"` or
        /// `"both"` (docs/model.md "Two hands"); one of our recordings plays the hands it holds.
        hands: crate::HandsUsed,
    },
    /// Another machine's session, over zenoh: the bridge publishes what it takes in
    /// (`session.bridge.link`), and this session renders and records it (a viewer).
    Remote,
    /// A headset's browser (WebXR hand input): the webxr process serves the page and its
    /// socket and publishes the hand it sends ([`WebxrSource`]).
    Webxr(WebxrSource),
    /// A program of the user's that publishes OpenXR hand joints (Python's
    /// `handblocks.Source`): the launcher starts `command` as the session's source, and the
    /// session ends when it closes its source or exits.
    External {
        /// `command`: the program and its arguments, run from the folder `handblocks launch`
        /// runs in, with `HANDBLOCKS_BUS` (this session's bus id) in its environment.
        command: Vec<String>,
    },
    /// A flat right hand held still, a glove and a tracker sample at each of `rate_hz`'s
    /// deadlines (the null source, `services/null`): for tests and for measuring a pipeline
    /// whose hand never moves.
    Null { rate_hz: f64 },
    /// The host of a shared world: its hands are the participants', each from their own
    /// machine, ordered on this machine's clock by the bridge (`[shared]`,
    /// [`super::shared`]).
    Shared,
}

/// `[source] kind = "webxr"`: where the page is served and which hand drives the model.
#[derive(Debug, Clone, PartialEq)]
pub struct WebxrSource {
    /// `listen`: the address the page and its socket are served on, an address and port or an
    /// address alone (port 8443). Default: with `tls`, `0.0.0.0:8443` (every interface, so a
    /// headset on the network reaches it); without, `127.0.0.1:8443` (this machine only: plain
    /// HTTP would carry the token and the hands across the network in clear, so that needs
    /// saying, as `listen = "0.0.0.0"`, and the process warns of it).
    pub listen: std::net::SocketAddr,
    /// `tls`: HTTPS and WSS with a certificate kept in `certificate_dir` (WebXR needs a secure
    /// context); false: plain HTTP, for `http://localhost` through `adb reverse` and for tests.
    pub tls: bool,
    /// `certificate_dir`: where the certificate made on first use is kept for the next
    /// (default `$XDG_DATA_HOME/handblocks/webxr`, or `~/.local/share/handblocks/webxr`).
    pub certificate_dir: Option<PathBuf>,
    /// `hand`: the hands that drive the model: `"right"` (default) or `"left"`, published as
    /// a one-hand source's only hand (side 0), or `"both"`, each frame's right then left hand
    /// (docs/model.md "Two hands", docs/webxr.md).
    pub hand: crate::HandsUsed,
    /// `offset`: moves the tracked hand, metres (a standing user's hands are ~1 m above the
    /// floor; the blocks of most scenes are on it).
    pub offset: [f64; 3],
    /// `token`: the page's token (at least 16 characters of `A-Za-z0-9-_`); default: a new
    /// random one each session, so nobody else on the network drives the hand.
    pub token: Option<String>,
}

impl Source {
    /// Every `[source] kind`, as a session names it; each is a column value of exactly one
    /// row of the stage table ([`crate::Stage::selected_by`]), the stage it starts.
    pub const KINDS: [&'static str; 8] = [
        "scripted", "devices", "replay", "remote", "webxr", "external", "null", "shared",
    ];

    pub fn kind(&self) -> &'static str {
        match self {
            Source::Scripted { .. } => "scripted",
            Source::Devices { .. } => "devices",
            Source::Replay { .. } => "replay",
            Source::Remote => "remote",
            Source::Webxr(_) => "webxr",
            Source::External { .. } => "external",
            Source::Null { .. } => "null",
            Source::Shared => "shared",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RenderMode {
    Window,
    Headless,
    Off,
}

/// `[renderer]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RendererSettings {
    pub mode: RenderMode,
    /// Per eye.
    pub width: u32,
    pub height: u32,
    /// "side-by-side", "anaglyph" (red-cyan) or "separate" (one image per eye).
    pub output: String,
    /// Distance between the eyes, millimetres (adults: 50-75, mean 63).
    pub ipd_mm: f64,
    /// The screen plane both eyes' frusta share (zero disparity), metres from the eyes.
    pub screen_distance_m: f64,
    pub screen_width_m: f64,
    /// Where the eyes' midpoint is and what it looks at, world frame.
    pub eye: [f64; 3],
    pub target: [f64; 3],
    /// Neither `eye` nor `target` given: the renderer frames the scene itself (its blocks, the
    /// hand's reach, what the hand throws), looking from `eye` towards `target`'s direction.
    pub auto_camera: bool,
    pub shadows: bool,
    /// With `launch --frames-dir`, write every Nth frame.
    pub frames_every: u32,
    /// Run the renderer (and the recorder) on CPUs of their own, apart from the pipeline's,
    /// when the machine has at least two. A software rasteriser otherwise delays the stepper's
    /// wake-ups by milliseconds however low its priority.
    pub own_cpus: bool,
}

impl Default for RendererSettings {
    fn default() -> Self {
        RendererSettings {
            mode: RenderMode::Headless,
            width: 640,
            height: 480,
            output: "side-by-side".into(),
            ipd_mm: 63.0,
            screen_distance_m: 0.6,
            screen_width_m: 0.52,
            eye: [0.0, 0.75, 1.1],
            target: [0.0, 0.05, 0.0],
            auto_camera: true,
            shadows: true,
            frames_every: 1,
            own_cpus: true,
        }
    }
}

/// How a stage waits for its next sample (`[pipeline] wait`); [`crate::bus::Waiter`] waits
/// by it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WaitStrategy {
    /// Sleep on the inlets' events until one wakes the process (~65 us on a 2-vCPU VM).
    #[default]
    Event,
    /// Poll the inlets always: the ~2 us hop, for a core per stage (each look gives the CPU
    /// to any other thread ready on it: a stage sharing its CPU does not starve its sender).
    Spin,
    /// Sleep on the event until shortly before the next sample is due (the source's period
    /// and the last arrival are known), poll for a bounded window around it, then sleep on the
    /// event again (polling as `Spin` does).
    Adaptive,
}

impl WaitStrategy {
    /// Its name as the session key `[pipeline] wait` gives it.
    pub fn name(self) -> &'static str {
        match self {
            WaitStrategy::Event => "event",
            WaitStrategy::Spin => "spin",
            WaitStrategy::Adaptive => "adaptive",
        }
    }
}

/// What wakes a sleeping stage when a sample comes (`[pipeline] wake`, issue 46).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WakeUp {
    /// The stages the stage table marks (kinematics, the stepper) sleep on a doorbell of
    /// their own, a futex word every publisher of what they read rings
    /// ([`crate::bus::Doorbell`]); the others on iceoryx2's event.
    #[default]
    Doorbell,
    /// Every stage sleeps on iceoryx2's event (a Unix datagram per inlet, slept on in
    /// `ppoll`): the wake-up before issue 46, kept to measure against.
    Event,
}

impl WakeUp {
    /// Its name as the session key `[pipeline] wake` gives it.
    pub fn name(self) -> &'static str {
        match self {
            WakeUp::Doorbell => "doorbell",
            WakeUp::Event => "event",
        }
    }
}

/// `[recorder]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RecorderSettings {
    /// None: the recorder runs (it counts what flows) but writes no file.
    pub file: Option<PathBuf>,
    /// `flush_ms`: a chunk of the recording is handed to the operating system once it is this
    /// old (or `chunk_kib` big): a crash of the recorder loses at most this much of each
    /// topic. Smaller chunks compress less well and cost a write each.
    pub flush_ms: u64,
    /// `chunk_kib`: ... or once it holds this many KiB uncompressed.
    pub chunk_kib: u64,
    /// `scene_hz`: how often the `/scene` channel (the 3D panel's drawing of the world and
    /// the hand, so the file opens in Foxglove's 3D panel) is written, at most; 0: never.
    pub scene_hz: u64,
}

impl RecorderSettings {
    pub const DEFAULT_FLUSH_MS: u64 = 500;
    pub const DEFAULT_CHUNK_KIB: u64 = 1024;
    pub const DEFAULT_SCENE_HZ: u64 = 30;

    /// No file, the default chunking.
    pub fn off() -> RecorderSettings {
        RecorderSettings {
            file: None,
            flush_ms: Self::DEFAULT_FLUSH_MS,
            chunk_kib: Self::DEFAULT_CHUNK_KIB,
            scene_hz: Self::DEFAULT_SCENE_HZ,
        }
    }
}

/// Where a recorder restarted for the `n`-th time writes (`[supervise]`): segment `n` beside
/// the recording, `live.mcap` -> `live.1.mcap`, `live.2.mcap`, ... (segment 0 is the file
/// itself). The dead recorder's file is left as it was (everything up to its last closed
/// chunk reads back); each segment is a whole recording of its own, so `inspect` and a replay
/// take any one of them.
pub fn recording_segment(file: &Path, n: u32) -> PathBuf {
    if n == 0 {
        return file.to_path_buf();
    }
    let stem = file
        .file_stem()
        .map_or_else(|| "recording".into(), |s| s.to_string_lossy().into_owned());
    let name = match file.extension() {
        Some(ext) => format!("{stem}.{n}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{n}"),
    };
    file.with_file_name(name)
}

/// `[budget]`: the interactive-rate budget; exceeding a limit fails the session.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    /// The renderer's frame rate.
    pub frame_hz: f64,
    pub origin_to_world_p99_us: Option<f64>,
    pub hop_p99_us: Option<f64>,
    pub origin_to_photon_p99_ms: Option<f64>,
    pub max_dropped: Option<u64>,
    /// The longest the source may go without delivering a sample (from the session's start,
    /// between samples, and to its end), milliseconds.
    pub source_silence_ms: f64,
    /// How far below `frame_hz` (or the world's rate, when that is lower) the renderer's frame
    /// rate may fall, as a fraction: 0.25 = frames per second at least 75 % of it.
    pub frame_rate_margin: f64,
}

impl Default for Budget {
    fn default() -> Self {
        Budget {
            frame_hz: 90.0,
            origin_to_world_p99_us: None,
            hop_p99_us: None,
            origin_to_photon_p99_ms: None,
            max_dropped: None,
            source_silence_ms: 1000.0,
            frame_rate_margin: 0.25,
        }
    }
}

/// `--set KEY=VALUE`: one key of a session file given on the command line, e.g.
/// `renderer.mode=off` or `budget.max_dropped=0`. It replaces (or adds) the key before the file
/// is checked, so it is validated exactly as the file's own keys are.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// The dotted key path.
    pub key: String,
    pub value: toml::Value,
}

impl Override {
    /// `KEY=VALUE`; VALUE is read as TOML (`0`, `true`, `[0, 1, 2]`, `"text"`), else as text
    /// (`off`, `out/live.mcap`).
    pub fn parse(text: &str) -> Result<Override, String> {
        let (key, value) = text.split_once('=').ok_or_else(|| {
            format!("{text:?}: give KEY=VALUE, e.g. renderer.mode=off or budget.max_dropped=0")
        })?;
        let key = key.trim();
        if key.is_empty()
            || !key.split('.').all(|p| {
                !p.is_empty()
                    && p.chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            })
        {
            return Err(format!(
                "{key:?}: a key is a dotted path of names, e.g. renderer.mode"
            ));
        }
        let value = value.trim();
        let value = match format!("v = {value}").parse::<toml::Table>() {
            Ok(mut t) => t.remove("v").unwrap_or_else(|| value.into()),
            Err(_) => toml::Value::String(value.to_string()),
        };
        Ok(Override {
            key: key.to_string(),
            value,
        })
    }

    pub(crate) fn apply(&self, file: &Path, table: &mut toml::Table) -> Result<(), ConfigError> {
        // Another kind of source takes other keys: `--set source.kind=replay` starts the
        // [source] table afresh, so the file's `rate_hz` of a scripted source is not refused
        // as a key a replay does not take.
        if self.key == "source.kind" {
            let same = table
                .get("source")
                .and_then(|s| s.get("kind"))
                .is_some_and(|k| *k == self.value);
            if !same {
                table.insert("source".into(), toml::Value::Table(toml::Table::new()));
            }
        }
        let parts: Vec<&str> = self.key.split('.').collect();
        let Some((last, path)) = parts.split_last() else {
            return Ok(());
        };
        let mut t = table;
        let mut at = String::new();
        for p in path {
            if !at.is_empty() {
                at.push('.');
            }
            at.push_str(p);
            let entry = t
                .entry(p.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            t = match entry {
                toml::Value::Table(t) => t,
                v => {
                    return Err(ConfigError::new(
                        file,
                        at.clone(),
                        format!(
                            "--set {}: `{at}` is {}, not a table",
                            self.key,
                            v.type_str()
                        ),
                    ))
                }
            };
        }
        t.insert(last.to_string(), self.value.clone());
        Ok(())
    }
}

impl Session {
    /// Reads a session file and the scene it names.
    pub fn load(file: &Path) -> Result<Session, ConfigError> {
        Session::load_with(file, &[])
    }

    /// Reads a session file with `--set` overrides applied, and the scene it names. An error
    /// about an overridden key says it came from `--set`.
    ///
    /// A scene file given in place of a session runs as a session of that scene with the
    /// default settings (the scripted hand, the headless renderer).
    pub fn load_with(file: &Path, overrides: &[Override]) -> Result<Session, ConfigError> {
        let mut table = parse_file(file)?;
        let is_scene = !table.contains_key("scene")
            && ["block", "world", "effects", "hand"]
                .iter()
                .any(|k| table.contains_key(*k));
        if is_scene {
            table = toml::Table::new();
            let name = file
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            table.insert("scene".into(), toml::Value::String(name));
        }
        // `scene.KEY` overrides the scene's KEY (`--set scene.world.hands=tracked`): they go to
        // the scene file as `simulate --set` would give them.
        let (scene_overrides, session_overrides): (Vec<&Override>, Vec<&Override>) =
            overrides.iter().partition(|o| o.key.starts_with("scene."));
        let scene_overrides: Vec<Override> = scene_overrides
            .into_iter()
            .map(|o| Override {
                key: o.key["scene.".len()..].to_string(),
                value: o.value.clone(),
            })
            .collect();
        // `source.kind` first: it starts [source] afresh (`Override::apply`), whatever the
        // order the other source keys were given in.
        let (kinds, rest): (Vec<&Override>, Vec<&Override>) = session_overrides
            .into_iter()
            .partition(|o| o.key == "source.kind");
        for o in kinds.into_iter().chain(rest) {
            o.apply(file, &mut table)?;
        }
        Session::from_table(file, &table, &scene_overrides).map_err(|e| e.given_with_set(overrides))
    }

    fn from_table(
        file: &Path,
        table: &toml::Table,
        scene_overrides: &[Override],
    ) -> Result<Session, ConfigError> {
        let r = Reader::root(file, FileKind::Session, table);
        let dir = file.parent().unwrap_or(Path::new("."));
        let scene_name = r
            .string("scene")?
            .ok_or_else(|| r.err("scene", "required: the scene file, relative to this file"))?;
        let scene_file = dir.join(&scene_name);
        if std::fs::symlink_metadata(&scene_file).is_err() {
            // Named here, with the session's key: the scene loader would name only the
            // missing file, not where it was asked for.
            return Err(r.err(
                "scene",
                format!(
                    "{}: no such scene file (in the file: relative to its folder; with --set: \
                     to the current folder); `handblocks list` lists the scenes",
                    scene_file.display()
                ),
            ));
        }
        let mut scene = Scene::load_with(&scene_file, scene_overrides)?;
        let (source, remote_source) = source(r.table("source")?, dir)?;
        let link = match (remote_source, r.table("remote")?) {
            (Some(_), Some(_)) => {
                return Err(r.err(
                    "remote",
                    "not with [source] kind = \"remote\": a remote-fed session's link is \
                     [source] (endpoint, role, key, subscribe); [remote] is for the session \
                     whose source is on this machine",
                ))
            }
            (Some(link), None) => Some(link),
            (None, Some(t)) => Some(super::remote::remote_table(t, dir)?),
            (None, None) => None,
        };
        let (foxglove, foxglove_clients) = match r.table("viewer")? {
            Some(t) => super::remote::viewer_table(t)?,
            None => (None, super::remote::DEFAULT_FOXGLOVE_CLIENTS),
        };
        let shared_host = matches!(source, Source::Shared);
        let shared = match r.table("shared")? {
            Some(t) => Some(super::shared::shared_table(t, shared_host, dir)?),
            None if shared_host => {
                return Err(r.err(
                    "shared",
                    "required with [source] kind = \"shared\": the host's side of the shared \
                     world (listen, token; docs/sessions.md \"Shared sessions\")",
                ))
            }
            None => None,
        };
        if shared.is_some() {
            let clash = if link.is_some() {
                Some(if matches!(source, Source::Remote) {
                    "source"
                } else {
                    "remote"
                })
            } else if foxglove.is_some() {
                Some("viewer")
            } else {
                None
            };
            if let Some(key) = clash {
                return Err(r.err(
                    key,
                    "not in a shared session yet: its bridge carries the shared world's link \
                     (remove the table, or [shared])",
                ));
            }
            if scene.world.model == super::scene::ModelKind::Precise {
                return Err(ConfigError::new(
                    file,
                    "shared",
                    "a shared world holds several people's hands, which the paper model takes \
                     (docs/model.md \"Two hands\"); the scene's [world] model is \"precise\", \
                     which takes one hand: --set scene.world.model=paper",
                ));
            }
        }
        let bridge = BridgeSettings {
            link,
            shared,
            foxglove,
            foxglove_clients,
        };
        if matches!(source, Source::Scripted { .. }) && scene.hand.is_none() {
            // Any scene can be launched: without a [hand] the hand rests out of the way.
            scene.hand = Some(hand_at_rest(&scene));
        }
        let two_hands = match &source {
            Source::Replay { hands, .. } => *hands == crate::HandsUsed::Both,
            Source::Webxr(w) => w.hand == crate::HandsUsed::Both,
            _ => false,
        };
        if two_hands && scene.world.model == super::scene::ModelKind::Precise {
            let key = match &source {
                Source::Webxr(_) => "source.hand",
                _ => "source.hands",
            };
            return Err(ConfigError::new(
                file,
                key,
                "\"both\": two hands are the paper model's (docs/model.md \"Two hands\"), and \
                 the scene's [world] model is \"precise\", which takes one: give one hand \
                 (\"right\" or \"left\") or --set scene.world.model=paper",
            ));
        }
        let renderer = renderer(r.table("renderer")?)?;
        let budget_reader = r.table("budget")?;
        let budget = budget(budget_reader)?;
        if renderer.mode == RenderMode::Off && budget.origin_to_photon_p99_ms.is_some() {
            return Err(ConfigError::new(
                file,
                "budget.origin_to_photon_p99_ms",
                "cannot be judged: [renderer] mode = \"off\" draws no frame; remove the key or \
                 render (mode = \"headless\" or \"window\")",
            ));
        }
        let (wait, wake) = pipeline(r.table("pipeline")?)?;
        let session = Session {
            file: file.to_path_buf(),
            scene_file,
            scene,
            source,
            renderer,
            recorder: recorder(r.table("recorder")?, dir)?,
            budget,
            hand_model: match r.string("hand_model")? {
                Some(f) => HandModelSpec::load(&dir.join(f))?,
                None => HandModelSpec::default(),
            },
            wait,
            wake,
            supervise: supervise(r.table("supervise")?)?,
            bridge,
        };
        r.finish()?;
        Ok(session)
    }
}

impl Session {
    /// The topics this session's bridge reads from its bus ([`BridgeSettings::inputs`]; a
    /// remote-fed session's view shows what its link brings, not what its bus carries).
    pub fn bridge_inputs(&self) -> Vec<crate::topic::Topic> {
        self.bridge.inputs(!matches!(self.source, Source::Remote))
    }
}

/// `[pipeline] wait`: "event" (sleep until woken, the default), "spin" (poll always, for
/// machines with cores to spare) or "adaptive" (sleep until shortly before the next sample is
/// due, then poll a bounded window, then sleep on the event).
fn pipeline(r: Option<Reader>) -> Result<(WaitStrategy, WakeUp), ConfigError> {
    let Some(r) = r else {
        return Ok((WaitStrategy::default(), WakeUp::default()));
    };
    let wait = match r.choice("wait", &["event", "spin", "adaptive"])? {
        "spin" => WaitStrategy::Spin,
        "adaptive" => WaitStrategy::Adaptive,
        _ => WaitStrategy::Event,
    };
    let wake = match r.choice("wake", &["doorbell", "event"])? {
        "event" => WakeUp::Event,
        _ => WakeUp::Doorbell,
    };
    r.finish()?;
    Ok((wait, wake))
}

/// `[supervise]`: restarting a process that dies mid-session ([`Supervise`]).
fn supervise(r: Option<Reader>) -> Result<Supervise, ConfigError> {
    let d = Supervise::default();
    let Some(r) = r else {
        return Ok(d);
    };
    let s = Supervise {
        restart: match r.choice("restart", &["never", "on-failure"])? {
            "on-failure" => RestartPolicy::OnFailure,
            _ => RestartPolicy::Never,
        },
        max_restarts: r.u64_in("max_restarts", d.max_restarts.into(), 0..=1000)? as u32,
        backoff_ms: r.u64_in("backoff_ms", d.backoff_ms, 0..=60_000)?,
        backoff_max_ms: r.u64_in("backoff_max_ms", d.backoff_max_ms, 0..=600_000)?,
    };
    if s.backoff_max_ms < s.backoff_ms {
        return Err(r.err(
            "backoff_max_ms",
            format!(
                "{} is below backoff_ms = {}; allowed: backoff_ms to 600000",
                s.backoff_max_ms, s.backoff_ms
            ),
        ));
    }
    r.finish()?;
    Ok(s)
}

/// An open hand at rest beside the scene's blocks (40 cm past their +x side, 30 cm above the
/// highest), where it touches none of them.
pub fn hand_at_rest(scene: &Scene) -> HandScript {
    let mut x_max: f64 = 0.0;
    let mut y_max: f64 = 0.0;
    let mut z_mid = 0.0;
    for b in &scene.blocks {
        x_max = x_max.max(b.position[0]);
        y_max = y_max.max(b.position[1]);
        z_mid += b.position[2] / scene.blocks.len() as f64;
    }
    HandScript {
        keys: vec![HandKey {
            t: 0.0,
            wrist: [x_max + 0.4, (y_max + 0.3).max(0.4), z_mid],
            wrist_rotation: [0.0, 0.0, 0.0, 1.0],
            pose: HandPoseSpec::Grip(0.0),
        }],
    }
}

/// `[source]`, and for `kind = "remote"` the link it is fed by.
fn source(r: Option<Reader>, dir: &Path) -> Result<(Source, Option<RemoteLink>), ConfigError> {
    let Some(r) = r else {
        return Ok((Source::Scripted { rate_hz: 120.0 }, None));
    };
    let mut link = None;
    let s = match r.choice("kind", &Source::KINDS)? {
        "external" => Source::External {
            command: external_command(&r)?,
        },
        "webxr" => Source::Webxr(webxr_source(&r, dir)?),
        "remote" => {
            link = Some(super::remote::remote_source(&r, dir)?);
            Source::Remote
        }
        "devices" => {
            let table = |key: &'static str| -> Result<&toml::Table, ConfigError> {
                match r.raw(key, || Spec {
                    default: Some("required".into()),
                    ..Spec::of("table")
                }) {
                    Some(toml::Value::Table(t)) => Ok(t),
                    Some(v) => Err(r.err(key, format!("expected a table, found {}", v.type_str()))),
                    None => Err(r.err(
                        key,
                        "required for kind = \"devices\": { port = \"/dev/ttyUSB0\", ... }",
                    )),
                }
            };
            // Both devices share one timeline; acquisition sets its own epoch when it starts.
            let epoch_ns = crate::monotonic_ns();
            Source::Devices {
                glove: Box::new(devices::glove_config(
                    r.file,
                    &r.key("glove"),
                    table("glove")?,
                    dir,
                    epoch_ns,
                )?),
                tracker: Box::new(devices::tracker_config(
                    r.file,
                    &r.key("tracker"),
                    table("tracker")?,
                    epoch_ns,
                )?),
            }
        }
        "replay" => {
            let f = r.string("file")?.ok_or_else(|| {
                r.err(
                    "file",
                    "required for kind = \"replay\": the recording or CARL file",
                )
            })?;
            Source::Replay {
                file: dir.join(f),
                speed: r.f64_in("speed", Some(1.0), 0.0..=1000.0)?.unwrap_or(1.0),
                offset: r.array_or::<3>("offset", -1.0e5..=1.0e5, [0.0; 3])?,
                looped: r.bool("loop", false)?,
                topics: {
                    let sources = [
                        crate::topic::Topic::Glove,
                        crate::topic::Topic::Tracker,
                        crate::topic::Topic::Joints,
                    ];
                    let topics = super::remote::topics(&r, "topics", &[])?;
                    if let Some(t) = topics.iter().find(|t| !sources.contains(t)) {
                        return Err(r.err(
                            "topics",
                            format!(
                                "{:?} is not a source topic; a replay plays \"glove\", \
                                 \"tracker\" or \"joints\" (the rest the pipeline makes)",
                                t.name()
                            ),
                        ));
                    }
                    topics
                },
                hands: crate::HandsUsed::parse(r.choice("hands", &["right", "left", "both"])?)
                    .unwrap_or_default(),
            }
        }
        "null" => Source::Null {
            rate_hz: r
                .f64_in("rate_hz", Some(120.0), 1.0..=10_000.0)?
                .unwrap_or(120.0),
        },
        "shared" => Source::Shared,
        _ => Source::Scripted {
            rate_hz: r
                .f64_in("rate_hz", Some(120.0), 1.0..=10_000.0)?
                .unwrap_or(120.0),
        },
    };
    r.finish()?;
    Ok((s, link))
}

/// `[source] kind = "external"`'s `command`: a non-empty list of strings (the program, then
/// its arguments), or one string, split at spaces.
fn external_command(r: &Reader) -> Result<Vec<String>, ConfigError> {
    const WHAT: &str = "required for kind = \"external\": the program that publishes the \
                        joints and its arguments, e.g. [\"python3\", \"my_tracker.py\"]";
    let command: Vec<String> = match r.raw("command", || Spec {
        default: Some("required".into()),
        ..Spec::of("list of strings, or one string (split at spaces)")
    }) {
        None => return Err(r.err("command", WHAT)),
        Some(toml::Value::String(s)) => s.split_whitespace().map(str::to_string).collect(),
        Some(toml::Value::Array(items)) => items
            .iter()
            .map(|v| v.as_str().map(str::to_string))
            .collect::<Option<Vec<_>>>()
            .ok_or_else(|| r.err("command", format!("every item is a string; {WHAT}")))?,
        Some(v) => {
            return Err(r.err(
                "command",
                format!("expected a list of strings, found {}; {WHAT}", v.type_str()),
            ))
        }
    };
    if command.first().is_none_or(|p| p.is_empty()) {
        return Err(r.err("command", format!("is empty; {WHAT}")));
    }
    Ok(command)
}

/// `[source] kind = "webxr"`'s keys.
fn webxr_source(r: &Reader, dir: &Path) -> Result<WebxrSource, ConfigError> {
    const PORT: u16 = 8443;
    let tls = r.bool("tls", true)?;
    let listen = match r.string("listen")? {
        // Plain HTTP stays on this machine unless told otherwise (`adb reverse` reaches it).
        None if !tls => std::net::SocketAddr::from(([127, 0, 0, 1], PORT)),
        None => std::net::SocketAddr::from(([0, 0, 0, 0], PORT)),
        Some(a) => match (a.parse(), a.parse::<std::net::IpAddr>()) {
            (Ok(addr), _) => addr,
            (_, Ok(ip)) => std::net::SocketAddr::new(ip, PORT),
            (Err(e), _) => {
                return Err(r.err(
                    "listen",
                    format!(
                        "{a:?} is not an address and port ({e}); e.g. \"0.0.0.0:8443\" (every \
                         interface), \"127.0.0.1:8443\" (this machine only) or \"0.0.0.0\""
                    ),
                ))
            }
        },
    };
    let token = r.string("token")?;
    if let Some(t) = &token {
        let ok = |c: char| c.is_ascii_alphanumeric() || c == '-' || c == '_';
        if t.len() < 16 || t.len() > 128 || !t.chars().all(ok) {
            return Err(r.err(
                "token",
                "16 to 128 characters of A-Z, a-z, 0-9, - and _; leave it out for a new random \
                 token each session",
            ));
        }
    }
    Ok(WebxrSource {
        listen,
        tls,
        certificate_dir: r.string("certificate_dir")?.map(|d| dir.join(d)),
        hand: crate::HandsUsed::parse(r.choice("hand", &["right", "left", "both"])?)
            .unwrap_or_default(),
        offset: r.array_or::<3>("offset", -1.0e5..=1.0e5, [0.0; 3])?,
        token,
    })
}

fn renderer(r: Option<Reader>) -> Result<RendererSettings, ConfigError> {
    let d = RendererSettings::default();
    let Some(r) = r else { return Ok(d) };
    let place = -1.0e5..=1.0e5;
    let s = RendererSettings {
        mode: match r.choice("mode", &["headless", "window", "off"])? {
            "window" => RenderMode::Window,
            "off" => RenderMode::Off,
            _ => RenderMode::Headless,
        },
        width: r.u64_in("width", 640, 16..=8192)? as u32,
        height: r.u64_in("height", 480, 16..=8192)? as u32,
        output: r
            .choice("output", &["side-by-side", "anaglyph", "separate"])?
            .to_string(),
        ipd_mm: r
            .f64_in("ipd_mm", Some(d.ipd_mm), 0.0..=100.0)?
            .unwrap_or(d.ipd_mm),
        screen_distance_m: r
            .f64_in("screen_distance_m", Some(d.screen_distance_m), 0.05..=100.0)?
            .unwrap_or(d.screen_distance_m),
        screen_width_m: r
            .f64_in("screen_width_m", Some(d.screen_width_m), 0.01..=100.0)?
            .unwrap_or(d.screen_width_m),
        auto_camera: !r.has("eye") && !r.has("target"),
        eye: r.array_or::<3>("eye", place.clone(), d.eye)?,
        target: r.array_or::<3>("target", place, d.target)?,
        shadows: r.bool("shadows", d.shadows)?,
        frames_every: r.u64_in("frames_every", 1, 1..=1_000_000)? as u32,
        own_cpus: r.bool("own_cpus", d.own_cpus)?,
    };
    if s.eye == s.target {
        return Err(r.err(
            "target",
            "must differ from `eye` (the camera looks from eye to target)",
        ));
    }
    r.finish()?;
    Ok(s)
}

fn recorder(r: Option<Reader>, dir: &Path) -> Result<RecorderSettings, ConfigError> {
    let Some(r) = r else {
        return Ok(RecorderSettings::off());
    };
    let s = RecorderSettings {
        file: r.string("file")?.map(|f| dir.join(f)),
        flush_ms: r.u64_in("flush_ms", RecorderSettings::DEFAULT_FLUSH_MS, 10..=60_000)?,
        chunk_kib: r.u64_in(
            "chunk_kib",
            RecorderSettings::DEFAULT_CHUNK_KIB,
            16..=65_536,
        )?,
        scene_hz: r.u64_in("scene_hz", RecorderSettings::DEFAULT_SCENE_HZ, 0..=1000)?,
    };
    r.finish()?;
    Ok(s)
}

fn budget(r: Option<Reader>) -> Result<Budget, ConfigError> {
    let d = Budget::default();
    let Some(r) = r else { return Ok(d) };
    let b = Budget {
        frame_hz: r
            .f64_in("frame_hz", Some(d.frame_hz), 1.0..=1000.0)?
            .unwrap_or(d.frame_hz),
        origin_to_world_p99_us: r.f64_in("origin_to_world_p99_us", None, 0.0..=1e9)?,
        hop_p99_us: r.f64_in("hop_p99_us", None, 0.0..=1e9)?,
        origin_to_photon_p99_ms: r.f64_in("origin_to_photon_p99_ms", None, 0.0..=1e6)?,
        max_dropped: r.u64_opt("max_dropped", 0..=u64::MAX >> 1)?,
        source_silence_ms: r
            .f64_in("source_silence_ms", Some(d.source_silence_ms), 1.0..=1e9)?
            .unwrap_or(d.source_silence_ms),
        frame_rate_margin: r
            .f64_in("frame_rate_margin", Some(d.frame_rate_margin), 0.0..=1.0)?
            .unwrap_or(d.frame_rate_margin),
    };
    r.finish()?;
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn tmpdir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hb-session-test-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    const SCENE: &str = "[hand]\n[[hand.key]]\nt = 0\nwrist = [0, 0.3, 0]\n";

    #[test]
    fn a_session_resolves_its_scene_and_budget() {
        let d = tmpdir("ok");
        write(&d, "scene.toml", SCENE);
        let s = write(&d, "s.toml", "scene = \"scene.toml\"\n[budget]\nframe_hz = 60\nmax_dropped = 0\norigin_to_world_p99_us = 500\n");
        let s = Session::load(&s).unwrap();
        assert_eq!(s.scene_file, d.join("scene.toml"));
        assert_eq!(s.budget.max_dropped, Some(0));
        assert_eq!(s.budget.origin_to_world_p99_us, Some(500.0));
        assert_eq!(s.source, Source::Scripted { rate_hz: 120.0 });
        std::fs::remove_dir_all(d).unwrap();
    }

    /// A session carries what the block world takes: its world topic is sized from the scene
    /// (the scene loader refuses more than `MAX_SCENE_BLOCKS`, naming the file and the limit).
    #[test]
    fn a_session_takes_a_scene_of_more_than_128_blocks() {
        let d = tmpdir("big");
        let blocks: String = (0..300)
            .map(|i| {
                format!(
                    "[[block]]\nsize = [0.04, 0.04, 0.04]\nposition = [{}, 0.02, {}]\n",
                    (i % 20) as f64 * 0.08,
                    (i / 20) as f64 * 0.08
                )
            })
            .collect();
        write(&d, "scene.toml", &blocks);
        let f = write(&d, "s.toml", "scene = \"scene.toml\"\n");
        let s = Session::load(&f).unwrap();
        assert_eq!(s.scene.blocks.len(), 300);
        std::fs::remove_dir_all(d).unwrap();
    }

    /// `[pipeline] wait` picks the stages' wait strategy; event is the default; a wrong value
    /// names the key and the choices.
    #[test]
    fn pipeline_wait_is_event_spin_or_adaptive() {
        let d = tmpdir("wait");
        write(&d, "scene.toml", SCENE);
        let load = |text: &str| Session::load(&write(&d, "w.toml", text));
        assert_eq!(
            load("scene = \"scene.toml\"\n").unwrap().wait,
            WaitStrategy::Event
        );
        let s = load("scene = \"scene.toml\"\n[pipeline]\nwait = \"adaptive\"\n").unwrap();
        assert_eq!(s.wait, WaitStrategy::Adaptive);
        let s = load("scene = \"scene.toml\"\n[pipeline]\nwait = \"spin\"\n").unwrap();
        assert_eq!(s.wait, WaitStrategy::Spin);
        assert_eq!(s.wake, WakeUp::Doorbell, "the doorbell unless asked");
        let s = load("scene = \"scene.toml\"\n[pipeline]\nwake = \"event\"\n").unwrap();
        assert_eq!((s.wait, s.wake), (WaitStrategy::Event, WakeUp::Event));
        let e = load("scene = \"scene.toml\"\n[pipeline]\nwake = \"bell\"\n").unwrap_err();
        assert_eq!(e.key, "pipeline.wake");
        let e = load("scene = \"scene.toml\"\n[pipeline]\nwait = \"nap\"\n").unwrap_err();
        assert_eq!(e.key, "pipeline.wait");
        assert!(
            e.problem.contains("\"event\", \"spin\", \"adaptive\""),
            "{e}"
        );
        std::fs::remove_dir_all(d).unwrap();
    }

    /// Issue 16: `[supervise]` is `never` unless a session asks; each bad value names its key
    /// and range.
    #[test]
    fn supervise_keys_are_checked_and_never_is_the_default() {
        let d = tmpdir("supervise");
        write(&d, "scene.toml", SCENE);
        let load = |text: &str| Session::load(&write(&d, "s.toml", text));
        let s = load("scene = \"scene.toml\"\n").unwrap();
        assert_eq!(s.supervise, Supervise::default());
        assert_eq!(s.supervise.restart, RestartPolicy::Never);
        let s = load(
            "scene = \"scene.toml\"\n[supervise]\nrestart = \"on-failure\"\nmax_restarts = 2\n\
             backoff_ms = 50\nbackoff_max_ms = 120\n",
        )
        .unwrap();
        assert_eq!(s.supervise.restart, RestartPolicy::OnFailure);
        assert_eq!(s.supervise.max_restarts, 2);
        let waits: Vec<u128> = (1..=4)
            .map(|n| s.supervise.backoff(n).as_millis())
            .collect();
        assert_eq!(waits, [50, 100, 120, 120]);
        let bad = |text: &str, key: &str, says: &str| {
            let e = load(&format!("scene = \"scene.toml\"\n[supervise]\n{text}\n")).unwrap_err();
            assert_eq!(e.key, key, "{e}");
            assert!(e.to_string().contains(says), "{e}");
            assert!(e.to_string().contains("s.toml"), "{e}");
        };
        bad(
            "restart = \"always\"",
            "supervise.restart",
            "\"never\", \"on-failure\"",
        );
        bad(
            "max_restarts = -1",
            "supervise.max_restarts",
            "allowed: 0 to 1000",
        );
        bad(
            "max_restarts = 5000",
            "supervise.max_restarts",
            "allowed: 0 to 1000",
        );
        bad("backoff_ms = 1.5", "supervise.backoff_ms", "whole number");
        bad(
            "backoff_ms = 500\nbackoff_max_ms = 100",
            "supervise.backoff_max_ms",
            "below backoff_ms",
        );
        bad("retries = 3", "supervise.retries", "");
        std::fs::remove_dir_all(d).unwrap();
    }

    #[test]
    fn errors_name_file_key_and_allowed_values() {
        let d = tmpdir("bad");
        write(&d, "scene.toml", SCENE);
        let f = write(
            &d,
            "s.toml",
            "scene = \"scene.toml\"\n[source]\nkind = \"telepathy\"\n",
        );
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.file, f);
        assert_eq!(e.key, "source.kind");
        assert!(
            e.problem.contains("\"scripted\", \"devices\", \"replay\""),
            "{e}"
        );

        let f = write(
            &d,
            "s2.toml",
            "scene = \"scene.toml\"\n[budget]\nframe_hz = -3\n",
        );
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.key, "budget.frame_hz");
        assert!(e.to_string().contains("allowed: 1 to 1000"), "{e}");

        let f = write(&d, "s3.toml", "scene = \"missing.toml\"\n");
        let e = Session::load(&f).unwrap_err();
        // The session's key, and the scene file it names.
        assert_eq!((e.file.as_path(), e.key.as_str()), (f.as_path(), "scene"));
        assert!(
            e.problem.contains(&format!(
                "{}: no such scene file",
                d.join("missing.toml").display()
            )),
            "{e}"
        );

        let f = write(&d, "s4.toml", "scene = \"scene.toml\"\n[budget\n");
        let e = Session::load(&f).unwrap_err();
        assert!(e.problem.contains("not valid TOML"), "{e}");

        let f = write(&d, "s5.toml", "scene = \"scene.toml\"\nbudjet = 1\n");
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.key, "budjet");
        assert!(e.problem.contains("allowed here: budget"), "{e}");

        // The recorder's flush bound: a stated default, a checked range.
        let f = write(
            &d,
            "s6.toml",
            "scene = \"scene.toml\"\n[recorder]\nflush_ms = 5\n",
        );
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.key, "recorder.flush_ms");
        assert!(e.to_string().contains("allowed: 10 to 60000"), "{e}");
        let f = write(&d, "s7.toml", "scene = \"scene.toml\"\n[recorder]\n");
        let r = Session::load(&f).unwrap().recorder;
        assert_eq!((r.flush_ms, r.chunk_kib), (500, 1024));
        std::fs::remove_dir_all(d).unwrap();
    }

    #[test]
    fn set_overrides_are_checked_as_the_files_keys_are() {
        let d = tmpdir("set");
        write(&d, "scene.toml", SCENE);
        let f = write(
            &d,
            "s.toml",
            "scene = \"scene.toml\"\n[renderer]\nmode = \"headless\"\n",
        );
        let o = |t: &str| Override::parse(t).unwrap();
        let s =
            Session::load_with(&f, &[o("renderer.mode=off"), o("budget.max_dropped=0")]).unwrap();
        assert_eq!(s.renderer.mode, RenderMode::Off);
        assert_eq!(s.budget.max_dropped, Some(0));
        let s = Session::load_with(&f, &[o("renderer.eye=[0, 1, 2]")]).unwrap();
        assert_eq!(s.renderer.eye, [0.0, 1.0, 2.0]);
        assert!(!s.renderer.auto_camera);
        let e = Session::load_with(&f, &[o("renderer.colour=red")]).unwrap_err();
        assert_eq!(e.key, "renderer.colour");
        assert!(
            e.problem.contains("unknown key") && e.problem.contains("(given with --set)"),
            "{e}"
        );
        let e = Session::load_with(&f, &[o("budget.frame_hz=0")]).unwrap_err();
        assert_eq!(e.key, "budget.frame_hz");
        // `scene.KEY` is the scene's KEY, checked as the scene file's own keys are.
        let s = Session::load_with(&f, &[o("scene.world.hands=tracked")]).unwrap();
        assert_eq!(
            s.scene.world.hands,
            crate::config::scene::HandRules::Tracked
        );
        let e = Session::load_with(&f, &[o("scene.x=1")]).unwrap_err();
        assert_eq!(
            (e.key.as_str(), e.file.clone()),
            ("x", d.join("scene.toml"))
        );
        assert!(e.problem.contains("(given with --set)"), "{e}");
        let e = Session::load_with(&f, &[o("scene.world.hands=both")]).unwrap_err();
        assert_eq!(e.key, "world.hands");
        assert!(Override::parse("renderer.mode").is_err());
        assert!(Override::parse("=off").is_err());
        assert!(Override::parse("a..b=1").is_err());
        std::fs::remove_dir_all(d).unwrap();
    }

    /// Issue 16 (found writing the `session` fuzz target): a session names its scene and hand
    /// model by path, and reading `/dev/zero` (or a pipe, or a `/proc` file that says it is
    /// empty) never ended, growing memory until the process died. Only regular files of at
    /// most MAX_CONFIG_BYTES are read; the error names the file.
    #[test]
    fn a_session_naming_a_device_or_a_folder_as_its_scene_or_hand_is_refused() {
        let d = tmpdir("devzero");
        write(&d, "scene.toml", SCENE);
        for (text, named) in [
            ("scene = \"/dev/zero\"\n", "/dev/zero"),
            (
                "scene = \"scene.toml\"\nhand_model = \"/dev/zero\"\n",
                "/dev/zero",
            ),
            ("scene = \"/tmp\"\n", "/tmp"),
        ] {
            let f = write(&d, "s.toml", text);
            let e = Session::load(&f).unwrap_err();
            assert_eq!(e.file, Path::new(named), "{e}");
            assert!(
                e.problem.starts_with("cannot read the file: it is a")
                    && e.problem.contains("not a regular file"),
                "{e}"
            );
        }
        // A file that is not UTF-8 is named with the offset of its first bad byte.
        std::fs::write(d.join("bad.toml"), b"[[block]]\nname = \"\xff\"\n").unwrap();
        let f = write(&d, "s.toml", "scene = \"bad.toml\"\n");
        let e = Session::load(&f).unwrap_err();
        assert!(e.problem.contains("the byte at offset 18"), "{e}");
        std::fs::remove_dir_all(d).unwrap();
    }

    #[test]
    fn a_photon_budget_without_a_renderer_is_refused_naming_the_key() {
        let d = tmpdir("photon");
        write(&d, "scene.toml", SCENE);
        let f = write(
            &d,
            "s.toml",
            "scene = \"scene.toml\"\n[renderer]\nmode = \"off\"\n[budget]\norigin_to_photon_p99_ms = 11\n",
        );
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.file, f);
        assert_eq!(e.key, "budget.origin_to_photon_p99_ms");
        assert!(e.problem.contains("cannot be judged"), "{e}");
        std::fs::remove_dir_all(d).unwrap();
    }

    /// Two hands are the paper model's: a two-hand source over a precise scene is refused
    /// before anything starts, naming the key (issue 41).
    #[test]
    fn two_hands_with_the_precise_model_are_refused_naming_the_key() {
        let d = tmpdir("two-precise");
        write(&d, "scene.toml", SCENE);
        write(&d, "t.carl", "");
        let f = write(
            &d,
            "s.toml",
            "scene = \"scene.toml\"\n[source]\nkind = \"replay\"\nfile = \"t.carl\"\n\
             hands = \"both\"\n",
        );
        let ok = Session::load(&f).unwrap();
        assert!(matches!(
            ok.source,
            Source::Replay {
                hands: crate::HandsUsed::Both,
                ..
            }
        ));
        let e = Session::load_with(&f, &[Override::parse("scene.world.model=precise").unwrap()])
            .unwrap_err();
        assert_eq!(
            (e.file.as_path(), e.key.as_str()),
            (f.as_path(), "source.hands")
        );
        assert!(e.problem.contains("paper model"), "{e}");
        std::fs::remove_dir_all(d).unwrap();
    }

    #[test]
    fn a_scene_runs_as_a_session_and_without_a_hand_gets_one_at_rest_beside_its_blocks() {
        let d = tmpdir("scene");
        let f = write(
            &d,
            "blocks.toml",
            "[[block]]\nname = \"a\"\nshape = \"box\"\nsize = [0.1, 0.1, 0.1]\nposition = [0.2, 0.05, 0.0]\n",
        );
        let s = Session::load(&f).unwrap();
        assert_eq!(s.scene_file, d.join("blocks.toml"));
        assert_eq!(s.source, Source::Scripted { rate_hz: 120.0 });
        let hand = s.scene.hand.expect("a hand at rest");
        assert_eq!(hand.keys.len(), 1);
        // 40 cm beside the block, above it: nowhere near its 10 cm.
        assert!(
            (hand.keys[0].wrist[0] - 0.6).abs() < 1e-12,
            "{:?}",
            hand.keys[0].wrist
        );
        assert!(hand.keys[0].wrist[1] >= 0.35);
        std::fs::remove_dir_all(d).unwrap();
    }

    #[test]
    fn webxr_without_tls_listens_on_this_machine_unless_told_otherwise() {
        let d = tmpdir("webxr-listen");
        write(&d, "scene.toml", SCENE);
        let load = |source: &str| {
            let text = format!("scene = \"scene.toml\"\n[source]\nkind = \"webxr\"\n{source}");
            Session::load(&write(&d, "s.toml", &text))
        };
        let listen = |source: &str| match load(source).unwrap().source {
            Source::Webxr(w) => w.listen.to_string(),
            other => panic!("{other:?}"),
        };
        assert_eq!(listen(""), "0.0.0.0:8443");
        assert_eq!(listen("tls = false\n"), "127.0.0.1:8443");
        assert_eq!(
            listen("tls = false\nlisten = \"0.0.0.0\"\n"),
            "0.0.0.0:8443"
        );
        assert_eq!(listen("listen = \"[::1]:9000\"\n"), "[::1]:9000");
        let e = load("listen = \"everywhere\"\n").unwrap_err().to_string();
        assert!(
            e.contains("s.toml") && e.contains("listen") && e.contains("127.0.0.1:8443"),
            "{e}"
        );
        std::fs::remove_dir_all(d).unwrap();
    }
}
