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
use crate::topic::{SliceTopicSpec, Topic, TopicSpec, TopicVisitor};

/// A sample read from an [`Inlet`].
pub type Received<T> = Sample<ipc::Service, T, ()>;
/// A sample read from a [`SliceInlet`]: its header is iceoryx2's user header
/// (`user_header()`), its elements the payload (`payload()`).
pub type ReceivedSlice<P> =
    Sample<ipc::Service, [<P as SliceTopicSpec>::Element], <P as SliceTopicSpec>::Header>;

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

/// Something went wrong on the bus; each variant says which operation and which topic.
#[derive(Debug)]
pub enum BusError {
    /// The session's prefix or root path is not usable by iceoryx2.
    Config(String),
    /// This process's node could not be created.
    Node(String),
    /// A service could not be created or opened (e.g. another build with a different sample
    /// layout is attached: `IncompatibleTypes`).
    Service { topic: &'static str, reason: String },
    /// A publisher, subscriber, notifier or listener could not be created.
    Port { topic: &'static str, reason: String },
    /// A sample could not be loaned or sent.
    Send { topic: &'static str, reason: String },
    /// A sample could not be received.
    Receive { topic: &'static str, reason: String },
    /// Waiting for samples failed.
    Wait(String),
}

impl fmt::Display for BusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BusError::Config(r) => write!(f, "bus configuration: {r}"),
            BusError::Node(r) => write!(f, "cannot create the iceoryx2 node: {r}"),
            BusError::Service { topic, reason } => write!(
                f,
                "cannot open the `{topic}` service: {reason} (a process of another build may be attached; stop it or use another session id)"
            ),
            BusError::Port { topic, reason } => {
                write!(f, "cannot attach to the `{topic}` service: {reason}")
            }
            BusError::Send { topic, reason } => write!(f, "cannot send on `{topic}`: {reason}"),
            BusError::Receive { topic, reason } => {
                write!(f, "cannot receive on `{topic}`: {reason}")
            }
            BusError::Wait(r) => write!(f, "waiting for samples failed: {r}"),
        }
    }
}

impl std::error::Error for BusError {}

/// Where one session's iceoryx2 resources live.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusConfig {
    /// The session id: letters, digits, `_` and `-`.
    pub id: String,
    /// Prefix of every file in /dev/shm (`hb_<id>_`).
    pub prefix: String,
    /// iceoryx2's root directory for this session (service and node bookkeeping).
    pub root: PathBuf,
    /// The most blocks one `world` sample carries: the session's scene's block count. It sizes
    /// the world topic (each sample's memory, the subscribers' buffer depth), so every process
    /// of a session must open the bus with the same value ([`BusConfig::with_world_blocks`]).
    pub world_blocks: usize,
    /// Every data topic without loss (a speed-0 replay, which promises every sample to every
    /// reader): a publisher whose reader's buffer is full waits for it instead of overwriting
    /// its oldest sample (iceoryx2's safe overflow off, back-pressure "retry until
    /// delivered"). Live sessions keep safe overflow: a slow reader loses its oldest sample
    /// rather than stalling the pipeline. The `latency` topic is never lossless. Every process
    /// of a session must open the bus with the same value (services are created with it).
    pub lossless: bool,
}

/// The longest Unix socket path (`sun_path` holds 108 bytes with its NUL).
const MAX_SOCKET_PATH: usize = 107;
/// What iceoryx2 0.10 puts after root + prefix in its longest socket path: a decimal u128 id
/// (up to 39 digits) and `.event`.
const SOCKET_NAME_TAIL: usize = 39 + ".event".len();
/// The longest session key in file names (a longer id is hashed down to this).
const MAX_KEY: usize = 12;

impl BusConfig {
    /// The resources of session `id`: prefix `hb_<key>_`, root `<base>/<key>/`, where `key` is
    /// the id itself up to 12 characters, else `h` and 11 hex digits of its hash, and `base`
    /// is `$TMPDIR/hb-iox2-<uid>` (this user's own folder, mode 0700), or `/tmp/hb-iox2-<uid>`
    /// where `$TMPDIR` is too long. iceoryx2's event sockets live in the root with the prefix
    /// in their names, and a Unix socket's path holds at most 107 bytes: root and prefix may
    /// take at most 62 of them whatever the id and `$TMPDIR` (issue 16: an id of 44
    /// characters the validator accepted broke every launch).
    pub fn for_session(id: &str) -> Result<BusConfig, BusError> {
        BusConfig::for_session_in(id, &std::env::temp_dir())
    }

    /// [`BusConfig::for_session`] with `tmp` for `$TMPDIR`.
    pub fn for_session_in(id: &str, tmp: &StdPath) -> Result<BusConfig, BusError> {
        if id.is_empty()
            || id.len() > 48
            || !id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(BusError::Config(format!(
                "session id {id:?} must be 1 to 48 letters, digits, `_` or `-`"
            )));
        }
        let key = if id.len() <= MAX_KEY {
            id.to_string()
        } else {
            // FNV-1a: stable across builds and platforms, unlike std's hasher.
            let hash = id.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
                (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
            });
            format!("h{:011x}", hash & 0xfff_ffff_ffff)
        };
        let prefix = format!("hb_{key}_");
        let fits = |base: &StdPath| {
            base.as_os_str().len() + 1 + key.len() + 1 + prefix.len() + SOCKET_NAME_TAIL
                <= MAX_SOCKET_PATH
        };
        let base = [base_dir(tmp), base_dir(StdPath::new("/tmp"))]
            .into_iter()
            .find(|b| fits(b))
            .ok_or_else(|| {
                BusError::Config(format!(
                    "no folder for the session's sockets: {} is too long for a Unix socket \
                     path (at most {} bytes); set TMPDIR to a shorter folder",
                    base_dir(tmp).display(),
                    MAX_SOCKET_PATH - SOCKET_NAME_TAIL - prefix.len() - key.len() - 2
                ))
            })?;
        Ok(BusConfig {
            id: id.to_string(),
            root: base.join(&key),
            prefix,
            world_blocks: DEFAULT_WORLD_BLOCKS,
            lossless: false,
        })
    }

    /// The session whose root folder is named `key` (as [`BusConfig::for_session`] names it).
    fn for_key(key: &str) -> Option<BusConfig> {
        (key.len() <= MAX_KEY)
            .then(|| BusConfig::for_session(key).ok())
            .flatten()
    }

    /// The same session with world samples of `blocks` blocks (its scene's count; 1 to
    /// [`MAX_SCENE_BLOCKS`]).
    pub fn with_world_blocks(mut self, blocks: usize) -> Result<BusConfig, BusError> {
        if blocks == 0 || blocks > MAX_SCENE_BLOCKS {
            return Err(BusError::Config(format!(
                "world samples of {blocks} blocks: allowed 1 to {MAX_SCENE_BLOCKS}"
            )));
        }
        self.world_blocks = blocks;
        Ok(self)
    }

    /// The bus of session `id` as every process of `session` opens it: world samples sized
    /// from its scene, lossless for a speed-0 replay (which promises every sample to every
    /// reader, as fast as the slowest takes them).
    pub fn for_session_of(
        id: &str,
        session: &crate::config::Session,
    ) -> Result<BusConfig, BusError> {
        let lossless = matches!(
            session.source,
            crate::config::session::Source::Replay { speed, .. } if speed == 0.0
        );
        Ok(BusConfig::for_session(id)?
            .with_world_blocks(session.scene.blocks.len().max(1))?
            .with_lossless(lossless))
    }

    /// The same session, lossless or not (see [`BusConfig::lossless`]).
    pub fn with_lossless(mut self, lossless: bool) -> BusConfig {
        self.lossless = lossless;
        self
    }

    /// A fresh id for a new session: unique per process and moment.
    pub fn fresh_id() -> String {
        format!("s{}_{:x}", std::process::id(), monotonic_ns() & 0xffff_ffff)
    }

    /// The iceoryx2 configuration for this session.
    pub fn iceoryx(&self) -> Result<Config, BusError> {
        let mut config = Config::default();
        let mut root = self.root.to_string_lossy().into_owned();
        if !root.ends_with('/') {
            root.push('/');
        }
        let root = iceoryx2::prelude::Path::new(root.as_bytes())
            .map_err(|e| BusError::Config(format!("root path {root:?}: {e:?}")))?;
        config.global.set_root_path(&root);
        config.global.prefix = FileName::new(self.prefix.as_bytes())
            .map_err(|e| BusError::Config(format!("prefix {:?}: {e:?}", self.prefix)))?;
        Ok(config)
    }

    /// True while some process of this session still runs (an iceoryx2 node of it is alive,
    /// or cannot be judged).
    pub fn has_live_processes(&self) -> bool {
        let Ok(config) = self.iceoryx() else {
            return false;
        };
        let mut live = false;
        let listed = Node::<ipc::Service>::list(&config, |state| {
            if matches!(state, NodeState::Alive(_) | NodeState::Inaccessible(_)) {
                live = true;
                return CallbackProgression::Stop;
            }
            CallbackProgression::Continue
        });
        // If the node list cannot be read, assume the worst and leave the session alone.
        live || listed.is_err()
    }

    /// Removes what sessions of other launchers left behind when those launchers were killed
    /// (SIGKILL leaves no chance to clean up), whatever their bus ids: every session folder of
    /// this user's whose processes are all gone and whose launcher is gone too (the pid and
    /// start time it recorded, [`BusConfig::claim_as_launcher`], name no running process), or,
    /// for a folder with no such record, that has been untouched for [`ABANDONED_AFTER`].
    /// Their processes notice the launcher's death themselves (their stdin pipe closes) and
    /// exit. A folder or /dev/shm file another user owns is never removed (also as root): it
    /// is named and left. Returns one line per session: what was removed, or left and why.
    pub fn sweep_abandoned() -> Vec<String> {
        let mut said = Vec::new();
        let bases = [
            base_dir(&std::env::temp_dir()),
            base_dir(StdPath::new("/tmp")),
        ];
        let entries = bases
            .iter()
            .take(if bases[0] == bases[1] { 1 } else { 2 })
            .filter_map(|b| std::fs::read_dir(b).ok())
            .flat_map(|e| e.flatten());
        for entry in entries {
            let id = entry.file_name().to_string_lossy().into_owned();
            let Some(session) = BusConfig::for_key(&id) else {
                continue;
            };
            if session.root != entry.path() {
                continue;
            }
            let abandoned = match session.launcher_gone() {
                Some(gone) => gone,
                None => {
                    // No launcher record (a session being set up right now has its folder
                    // before it): only folders untouched for a while can be abandoned.
                    let age = entry
                        .metadata()
                        .and_then(|m| m.modified())
                        .ok()
                        .and_then(|t| t.elapsed().ok());
                    age.is_some_and(|a| a >= ABANDONED_AFTER)
                }
            };
            if !abandoned || session.has_live_processes() {
                continue;
            }
            let shm = session.leftover_shm_files().len();
            match session.remove_resources() {
                Ok(_) => said.push(format!(
                    "removed abandoned session {id} (its launcher and processes are gone): \
                     {shm} file(s) of prefix {} in /dev/shm and its folder {}",
                    session.prefix,
                    session.root.display()
                )),
                Err(e) => said.push(format!("left abandoned session {id} alone: {e}")),
            }
        }
        said
    }

    /// Records this process as the launcher of the session, in the session's folder (created
    /// private, 0700): its pid and its start time, so that a sweep by another launcher
    /// ([`BusConfig::sweep_abandoned`]) knows at once when this one was killed, and a pid
    /// reused by another process is not taken for it.
    pub fn claim_as_launcher(&self) -> Result<(), BusError> {
        if let Some(base) = self.root.parent() {
            make_private_dir(base)?;
        }
        make_private_dir(&self.root)?;
        let pid = std::process::id();
        let started = process_start_ticks(pid).unwrap_or(0);
        let file = self.root.join(LAUNCHER_FILE);
        std::fs::write(&file, format!("{pid} {started}\n"))
            .map_err(|e| BusError::Config(format!("cannot write {}: {e}", file.display())))
    }

    /// Whether the launcher the session's folder names is gone: Some(true) when no process
    /// of that pid and start time runs, Some(false) when it does, None without a record.
    fn launcher_gone(&self) -> Option<bool> {
        let text = std::fs::read_to_string(self.root.join(LAUNCHER_FILE)).ok()?;
        let mut words = text.split_whitespace().map(|w| w.parse::<u64>().ok());
        let (Some(Some(pid)), Some(Some(started))) = (words.next(), words.next()) else {
            return None;
        };
        let pid = u32::try_from(pid).ok()?;
        Some(process_start_ticks(pid).is_none_or(|now| now != started))
    }

    /// How many samples of `topic` its supervised publishers have sent so far: the largest
    /// next seq they keep in the session's folder ([`Bus::supervised`]); None when no
    /// supervised publisher of it has sent. The launcher reads it when a reader dies, to tell
    /// the samples published while it was down from those it read before it died.
    pub fn published_count(&self, topic: Topic) -> Option<u64> {
        let tail = format!(".{}", topic.name());
        std::fs::read_dir(&self.root)
            .ok()?
            .flatten()
            .filter(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                name.starts_with("seq.") && name.ends_with(&tail)
            })
            .filter_map(|e| {
                let bytes = std::fs::read(e.path()).ok()?;
                Some(u64::from_ne_bytes(bytes.get(..8)?.try_into().ok()?))
            })
            .max()
    }

    /// Files of this session still in /dev/shm.
    pub fn leftover_shm_files(&self) -> Vec<PathBuf> {
        leftover_files(StdPath::new("/dev/shm"), &self.prefix)
    }

    /// Removes what this session's iceoryx2 nodes leave behind once every one of them has
    /// exited: files of its prefix in /dev/shm and its root directory. Call it only when no
    /// process of the session lives (iceoryx2 0.10 keeps one management file per prefix).
    /// Returns how many entries were removed.
    pub fn remove_resources(&self) -> std::io::Result<usize> {
        // Another user's file or folder is refused, never deleted (as root too, which the
        // file system would let delete anything): nothing is removed then.
        let shm = self.leftover_shm_files();
        for f in shm.iter().chain(std::iter::once(&self.root)) {
            refuse_foreign(f)?;
        }
        let mut removed = 0;
        for f in self.leftover_shm_files() {
            std::fs::remove_file(&f)?;
            removed += 1;
        }
        if self.root.exists() {
            std::fs::remove_dir_all(&self.root)?;
            removed += 1;
        }
        // The shared parent folder goes too once the last session has left it.
        if let Some(parent) = self.root.parent() {
            let _ = std::fs::remove_dir(parent);
        }
        Ok(removed)
    }
}

/// The file in a session's folder naming its launcher ([`BusConfig::claim_as_launcher`]).
const LAUNCHER_FILE: &str = "launcher";

/// When process `pid` started (clock ticks after boot, /proc/PID/stat's 22nd field): with the
/// pid, which the kernel reuses, it names one process. None when no such process runs.
fn process_start_ticks(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count after it.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// An error naming `path` when it exists and another user owns it.
fn refuse_foreign(path: &StdPath) -> std::io::Result<()> {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: as in base_dir.
    let uid = unsafe { libc::getuid() };
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.uid() != uid => Err(std::io::Error::new(
            std::io::ErrorKind::PermissionDenied,
            format!(
                "{} belongs to uid {}, not this user (uid {uid}): refusing to remove it; \
                 its owner can, or choose another --bus-id",
                path.display(),
                m.uid()
            ),
        )),
        _ => Ok(()),
    }
}

/// This user's folder of session roots under `tmp`.
fn base_dir(tmp: &StdPath) -> PathBuf {
    // SAFETY: getuid has no preconditions and cannot fail.
    let uid = unsafe { libc::getuid() };
    tmp.join(format!("hb-iox2-{uid}"))
}

/// Issue 16, private shared memory: the session's root folder (and this user's folder above
/// it) is 0700 and this user's, so another local user can neither read the hand nor inject
/// samples through the session's sockets and bookkeeping; a folder someone else owns, or that
/// others may enter, is refused rather than used.
fn make_private_dir(dir: &StdPath) -> Result<(), BusError> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => {
            return Err(BusError::Config(format!(
                "cannot create the session folder {}: {e}",
                dir.display()
            )))
        }
    }
    let meta = std::fs::symlink_metadata(dir).map_err(|e| {
        BusError::Config(format!(
            "cannot read the session folder {}: {e}",
            dir.display()
        ))
    })?;
    // SAFETY: as in base_dir.
    let uid = unsafe { libc::getuid() };
    if !meta.is_dir() || meta.uid() != uid {
        return Err(BusError::Config(format!(
            "{} is not a folder of this user's (uid {uid}; it belongs to uid {}): refusing to \
             attach a session to resources it does not own; remove it or set TMPDIR elsewhere",
            dir.display(),
            meta.uid()
        )));
    }
    // Exactly 0700: open to others is not private, and without the owner's x (a 0600 folder
    // was seen once in a test run) a user other than root could not use it.
    if meta.mode() & 0o777 != 0o700 {
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700)).map_err(|e| {
            BusError::Config(format!("cannot make {} private (0700): {e}", dir.display()))
        })?;
    }
    Ok(())
}

/// Makes this session's files in /dev/shm this user's alone (0600): iceoryx2 creates its
/// per-prefix management segment readable and writable by everyone. A file of the prefix
/// that another user owns is refused.
fn make_shm_private(prefix: &str) -> Result<(), BusError> {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    // SAFETY: as in base_dir.
    let uid = unsafe { libc::getuid() };
    for f in leftover_files(StdPath::new("/dev/shm"), prefix) {
        let Ok(meta) = std::fs::symlink_metadata(&f) else {
            continue; // removed meanwhile
        };
        if meta.uid() != uid {
            return Err(BusError::Config(format!(
                "{} belongs to uid {}, not this user (uid {uid}): refusing to attach a session \
                 to shared memory it does not own; choose another --bus-id",
                f.display(),
                meta.uid()
            )));
        }
        if meta.mode() & 0o077 != 0 {
            std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).map_err(|e| {
                BusError::Config(format!("cannot make {} private (0600): {e}", f.display()))
            })?;
        }
    }
    Ok(())
}

fn leftover_files(dir: &StdPath, prefix: &str) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    entries
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
        .map(|e| e.path())
        .collect()
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
        let name = NodeName::new(node_name).map_err(|e| BusError::Node(format!("{e:?}")))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&iox)
            // Processes handle SIGINT/SIGTERM themselves (crate::shutdown), so that a stage can
            // finish its final report before it exits.
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| BusError::Node(format!("{e:?}")))?;
        // The node made the prefix's management segment (world-writable): make it private.
        make_shm_private(&config.prefix)?;
        Ok(Bus {
            node,
            slice_capacity: config.world_blocks,
            lossless: config.lossless,
            root: config.root.clone(),
            node_name: node_name.to_string(),
            supervised: None,
        })
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
    fn seq_store(&self, topic: Topic) -> Result<Option<SeqStore>, BusError> {
        if self.supervised.is_none() {
            return Ok(None);
        }
        let path = self
            .root
            .join(format!("seq.{}.{}", self.node_name, topic.name()));
        SeqStore::open(&path).map(Some).map_err(|e| BusError::Port {
            topic: topic.name(),
            reason: format!("cannot keep its seq in {}: {e}", path.display()),
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
        SeqCount {
            from_first: self.restart() > 0,
            connected_mark: Cell::new(connected_mark),
            ..SeqCount::default()
        }
    }

    /// On a lossless bus, what an outlet of `topic` waits for before it may fill a reader's
    /// buffer ([`ConnectGate`]); None elsewhere.
    fn connect_gate(
        &self,
        topic: Topic,
        buffer: usize,
        subscribers: impl Fn() -> usize + 'static,
    ) -> Option<ConnectGate> {
        self.is_lossless(topic).then(|| ConnectGate {
            topic,
            root: self.root.clone(),
            free: (buffer as u64 / 2).max(1),
            sent: 0,
            subscribers: Box::new(subscribers),
        })
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
        impl TopicVisitor for Create<'_> {
            type Error = BusError;
            fn visit<P: TopicSpec>(&mut self) -> Result<(), BusError> {
                let service = self.bus.pubsub::<P>()?;
                self.pubsub.push(Box::new(service));
                Ok(())
            }
            fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), BusError> {
                let service = self.bus.slice_pubsub::<P>()?;
                self.pubsub.push(Box::new(SliceService::<P>(service)));
                Ok(())
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

    /// Opens (or creates) topic `P`'s service, with its sample type and its row's sizing.
    fn pubsub<P: TopicSpec>(&self) -> Result<PubSub<P::Sample>, BusError> {
        let topic = P::TOPIC;
        let name = service_name(topic)?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<P::Sample>()
            .max_publishers(topic.max_publishers())
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(topic.subscriber_buffer())
            .subscriber_max_borrowed_samples(4)
            .history_size(0)
            // A slow reader loses its oldest unread sample instead of stalling the publisher,
            // but on a lossless bus (a speed-0 replay).
            .enable_safe_overflow(!self.is_lossless(topic))
            .open_or_create()
            .map_err(|e| BusError::Service {
                topic: topic.name(),
                reason: format!("{e:?}"),
            })
    }

    /// The subscriber buffer depth of slice topic `P` on this bus: the table's depth, or less
    /// when samples are large ([`SLICE_BUFFER_BYTES`]).
    pub fn slice_buffer<P: SliceTopicSpec>(&self) -> usize {
        let sample = std::mem::size_of::<P::Header>()
            + self.slice_capacity * std::mem::size_of::<P::Element>();
        let depth = P::TOPIC.subscriber_buffer();
        (SLICE_BUFFER_BYTES / sample.max(1)).clamp(MIN_SLICE_BUFFER.min(depth), depth)
    }

    /// Opens (or creates) slice topic `P`'s service: a user header and a slice payload, its
    /// buffer depth from [`Bus::slice_buffer`].
    fn slice_pubsub<P: SliceTopicSpec>(&self) -> Result<SlicePubSub<P>, BusError> {
        let topic = P::TOPIC;
        let name = service_name(topic)?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<[P::Element]>()
            .user_header::<P::Header>()
            .max_publishers(topic.max_publishers())
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(self.slice_buffer::<P>())
            .subscriber_max_borrowed_samples(4)
            .history_size(0)
            .enable_safe_overflow(!self.is_lossless(topic))
            .open_or_create()
            .map_err(|e| BusError::Service {
                topic: topic.name(),
                reason: format!("{e:?}"),
            })
    }

    /// The wake-up side of topic `topic`'s outlets.
    fn notifier(&self, topic: Topic) -> Result<Notifier<ipc::Service>, BusError> {
        self.event(topic)?
            .notifier_builder()
            .create()
            .map_err(|e| BusError::Port {
                topic: topic.name(),
                reason: format!("{e:?}"),
            })
    }

    /// What an inlet of topic `topic` sleeps on.
    fn listener(&self, topic: Topic) -> Result<Listener<ipc::Service>, BusError> {
        self.event(topic)?
            .listener_builder()
            .create()
            .map_err(|e| BusError::Port {
                topic: topic.name(),
                reason: format!("{e:?}"),
            })
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
            .map_err(|e| BusError::Service {
                topic: topic.name(),
                reason: format!("{e:?}"),
            })
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
        let topic = P::TOPIC;
        let port_err = |e: String| BusError::Port {
            topic: topic.name(),
            reason: e,
        };
        let service = self.pubsub::<P>()?;
        let publisher = service
            .publisher_builder()
            .max_loaned_samples(2)
            .create()
            .map_err(|e| port_err(format!("{e:?}")))?;
        let notifier = self.notifier(topic)?;
        let kept = self.seq_store(topic)?;
        let gate = self.connect_gate(topic, topic.subscriber_buffer(), move || {
            service.dynamic_config().number_of_subscribers()
        });
        Ok(Outlet {
            publisher,
            notifier,
            next_seq: kept.as_ref().map_or(0, |k| k.load(0)),
            skipped: kept.as_ref().map_or(0, |k| k.load(1)),
            kept,
            gate,
        })
    }

    /// A subscriber on topic `P` (a marker of [`crate::topics`]) with its listener; it
    /// receives `P`'s sample type:
    ///
    /// ```compile_fail
    /// # use common::{bus::Bus, topics, HandSample};
    /// # fn f(bus: &Bus) -> Result<(), common::bus::BusError> {
    /// let glove = bus.inlet::<topics::Glove>()?;
    /// let hand: Option<HandSample> = glove.receive()?.map(|s| *s.payload());
    /// # Ok(()) }
    /// ```
    pub fn inlet<P: TopicSpec>(&self) -> Result<Inlet<P>, BusError> {
        let topic = P::TOPIC;
        let port_err = |e: String| BusError::Port {
            topic: topic.name(),
            reason: e,
        };
        let subscriber = self
            .pubsub::<P>()?
            .subscriber_builder()
            .buffer_size(topic.subscriber_buffer())
            .create()
            .map_err(|e| port_err(format!("{e:?}")))?;
        let listener = self.listener(topic)?;
        Ok(Inlet {
            subscriber,
            listener,
            seqs: self.seq_count(topic),
        })
    }

    /// A publisher on slice topic `P` (the `world` topic) with its notifier; each sample it
    /// sends holds 0 to [`Bus::slice_capacity`] elements, written in place
    /// ([`SliceOutlet::publish_with`]).
    pub fn slice_outlet<P: SliceTopicSpec>(&self) -> Result<SliceOutlet<P>, BusError> {
        let topic = P::TOPIC;
        let port_err = |e: String| BusError::Port {
            topic: topic.name(),
            reason: e,
        };
        let service = self.slice_pubsub::<P>()?;
        let publisher = service
            .publisher_builder()
            .initial_max_slice_len(self.slice_capacity)
            .max_loaned_samples(2)
            .create()
            .map_err(|e| port_err(format!("{e:?}")))?;
        let notifier = self.notifier(topic)?;
        let kept = self.seq_store(topic)?;
        let gate = self.connect_gate(topic, self.slice_buffer::<P>(), move || {
            service.dynamic_config().number_of_subscribers()
        });
        Ok(SliceOutlet {
            publisher,
            notifier,
            capacity: self.slice_capacity,
            next_seq: kept.as_ref().map_or(0, |k| k.load(0)),
            skipped: 0,
            kept,
            gate,
        })
    }

    /// A subscriber on slice topic `P` with its listener.
    pub fn slice_inlet<P: SliceTopicSpec>(&self) -> Result<SliceInlet<P>, BusError> {
        let topic = P::TOPIC;
        let port_err = |e: String| BusError::Port {
            topic: topic.name(),
            reason: e,
        };
        let subscriber = self
            .slice_pubsub::<P>()?
            .subscriber_builder()
            .buffer_size(self.slice_buffer::<P>())
            .create()
            .map_err(|e| port_err(format!("{e:?}")))?;
        let listener = self.listener(topic)?;
        Ok(SliceInlet {
            subscriber,
            listener,
            seqs: self.seq_count(topic),
        })
    }
}

/// Something a process can sleep on: an inlet's wake-up listener; and poll: whether a
/// sample waits in it.
pub trait Wakeable {
    fn listener(&self) -> &Listener<ipc::Service>;
    /// True when a sample is there to receive (a poll that takes nothing).
    fn has_samples(&self) -> bool;
}

impl<P: TopicSpec> Wakeable for Inlet<P> {
    fn listener(&self) -> &Listener<ipc::Service> {
        &self.listener
    }
    fn has_samples(&self) -> bool {
        self.subscriber.has_samples().unwrap_or(true)
    }
}

impl<P: SliceTopicSpec> Wakeable for SliceInlet<P> {
    fn listener(&self) -> &Listener<ipc::Service> {
        &self.listener
    }
    fn has_samples(&self) -> bool {
        self.subscriber.has_samples().unwrap_or(true)
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
            let _ = inlet.listener().try_wait(|_| {});
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
            return Err(BusError::Wait(format!("ppoll: {e}")));
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
    use iceoryx2::prelude::FileDescriptorBased;
    let n = inlets.len().min(MAX_WAIT);
    let mut fds = [libc::pollfd {
        fd: -1,
        events: 0,
        revents: 0,
    }; MAX_WAIT + 1];
    for (slot, inlet) in fds.iter_mut().zip(inlets) {
        // SAFETY: the descriptor stays owned by the listener, which outlives this call; we only
        // poll it.
        slot.fd = unsafe { inlet.listener().file_descriptor().native_handle() };
        slot.events = libc::POLLIN;
    }
    let mut watched = n;
    if let Some(fd) = other {
        fds[n].fd = fd;
        fds[n].events = libc::POLLIN;
        watched += 1;
    }
    poll_readable(&mut fds[..watched], timeout)?;
    for inlet in &inlets[..n] {
        let _ = inlet.listener().try_wait(|_| {});
    }
    Ok(())
}

fn service_name(topic: Topic) -> Result<ServiceName, BusError> {
    ServiceName::new(topic.name()).map_err(|e| BusError::Config(format!("{e:?}")))
}

type PubSub<T> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>;
type SlicePubSub<P> = iceoryx2::service::port_factory::publish_subscribe::PortFactory<
    ipc::Service,
    [<P as SliceTopicSpec>::Element],
    <P as SliceTopicSpec>::Header,
>;
type EventService = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

/// The attachment counts of one publish-subscribe service, whatever its sample type.
trait AttachedPorts {
    fn subscribers(&self) -> usize;
    fn publishers(&self) -> usize;
}

impl<T: Stamped> AttachedPorts for PubSub<T> {
    fn subscribers(&self) -> usize {
        self.dynamic_config().number_of_subscribers()
    }
    fn publishers(&self) -> usize {
        self.dynamic_config().number_of_publishers()
    }
}

/// A slice topic's service, as [`AttachedPorts`] (a newtype: the port factory's type names the
/// topic's element and header types, which a blanket impl over them could not).
struct SliceService<P: SliceTopicSpec>(SlicePubSub<P>);

impl<P: SliceTopicSpec> AttachedPorts for SliceService<P> {
    fn subscribers(&self) -> usize {
        self.0.dynamic_config().number_of_subscribers()
    }
    fn publishers(&self) -> usize {
        self.0.dynamic_config().number_of_publishers()
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

/// A publisher with its notifier: stamps `seq` and `publish_ns`, sends, wakes the readers.
pub struct Outlet<P: TopicSpec> {
    publisher: Publisher<ipc::Service, P::Sample, ()>,
    notifier: Notifier<ipc::Service>,
    next_seq: u64,
    /// Seqs this topic's source never sent ([`Outlet::skip_to`]).
    skipped: u64,
    /// A supervised process's next seq (and skipped), kept where its restart finds it.
    kept: Option<SeqStore>,
    /// On a lossless bus, until every reader is connected ([`ConnectGate`]).
    gate: Option<ConnectGate>,
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
const CONNECTED_MARK: &str = "connected.";

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
struct ConnectGate {
    topic: Topic,
    root: PathBuf,
    /// Samples that may go before every reader is connected.
    free: u64,
    sent: u64,
    /// The topic's subscribers now.
    subscribers: Box<dyn Fn() -> usize>,
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
struct SeqCount {
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
struct SeqStore {
    words: std::ptr::NonNull<std::sync::atomic::AtomicU64>,
}

/// The bytes a [`SeqStore`] maps.
const SEQ_STORE_BYTES: usize = 16;

impl SeqStore {
    fn open(path: &StdPath) -> std::io::Result<SeqStore> {
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

    fn load(&self, i: usize) -> u64 {
        self.word(i).load(std::sync::atomic::Ordering::Relaxed)
    }

    fn store(&self, i: usize, v: u64) {
        self.word(i).store(v, std::sync::atomic::Ordering::Relaxed)
    }
}

impl Drop for SeqStore {
    fn drop(&mut self) {
        // SAFETY: unmaps the bytes `open` mapped, once; nothing refers to them after.
        unsafe { libc::munmap(self.words.as_ptr().cast(), SEQ_STORE_BYTES) };
    }
}

/// Sleeps on `listener` until a sample may have arrived, or `timeout` passes, to the
/// nanosecond; consumes the wake-ups.
fn wait_on(listener: &Listener<ipc::Service>, timeout: Duration) -> Result<(), BusError> {
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

/// A subscriber with its listener: counts what arrives and the gaps in `seq`.
pub struct Inlet<P: TopicSpec> {
    subscriber: Subscriber<ipc::Service, P::Sample, ()>,
    listener: Listener<ipc::Service>,
    seqs: SeqCount,
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
    publisher: Publisher<ipc::Service, [P::Element], P::Header>,
    notifier: Notifier<ipc::Service>,
    capacity: usize,
    next_seq: u64,
    /// As [`Outlet`]'s.
    skipped: u64,
    kept: Option<SeqStore>,
    gate: Option<ConnectGate>,
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
    subscriber: Subscriber<ipc::Service, [P::Element], P::Header>,
    listener: Listener<ipc::Service>,
    seqs: SeqCount,
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
