//! A session's resources: its /dev/shm prefix and its private folder, and removing what a
//! dead session left.

use super::*;

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
            return Err(BusError::config(format!(
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
                BusError::config(format!(
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
            return Err(BusError::config(format!(
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
            .map_err(|e| BusError::config(format!("root path {root:?}: {e:?}")))?;
        config.global.set_root_path(&root);
        config.global.prefix = FileName::new(self.prefix.as_bytes())
            .map_err(|e| BusError::config(format!("prefix {:?}: {e:?}", self.prefix)))?;
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
    /// exit; a sweep waits up to [`LAUNCHER_GONE_WAIT`] for them to. A folder or /dev/shm file another user owns is never removed (also as root): it
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
            let launcher_gone = session.launcher_gone();
            let abandoned = match launcher_gone {
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
            if !abandoned {
                continue;
            }
            // A killed launcher's processes notice at once (their stdin closes) and are gone
            // moments later: a launch started right after the kill waits for them, or it would
            // leave the folder to the next launch on the same bus id (issue 40).
            if launcher_gone == Some(true) {
                let deadline = std::time::Instant::now() + LAUNCHER_GONE_WAIT;
                while session.has_live_processes() && std::time::Instant::now() < deadline {
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
            if session.has_live_processes() {
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
            .map_err(|e| BusError::config(format!("cannot write {}: {e}", file.display())))
    }

    /// Whether the launcher the session's folder names is gone: Some(true) when no process
    /// of that pid and start time runs, Some(false) when it does, None without a record (or
    /// with one that is not this user's regular file: never read, a FIFO would block).
    pub fn launcher_gone(&self) -> Option<bool> {
        let text = read_own_file(&self.root.join(LAUNCHER_FILE), 64)?;
        let mut words = text.split_whitespace().map(|w| w.parse::<u64>().ok());
        let (Some(Some(pid)), Some(Some(started))) = (words.next(), words.next()) else {
            return None;
        };
        let pid = u32::try_from(pid).ok()?;
        Some(!launcher_alive(pid, started))
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
        // What is gone already is not an error: another launcher's sweep, or a reader
        // tidying up, may be removing the same dead session's files at the same moment.
        let gone = |r: std::io::Result<()>| match r {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
            r => r.map(|()| true),
        };
        let mut removed = 0;
        for f in self.leftover_shm_files() {
            removed += usize::from(gone(std::fs::remove_file(&f))?);
        }
        if self.root.exists() {
            removed += usize::from(gone(std::fs::remove_dir_all(&self.root))?);
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

/// Whether process `pid` runs, started at `started` (ticks after boot, as
/// [`process_start_ticks`] reads them), and is this user's: a launcher that was killed and
/// whose pid the kernel gave to another process is gone, as is a pid another user runs.
fn launcher_alive(pid: u32, started: u64) -> bool {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: as in base_dir.
    let uid = unsafe { libc::getuid() };
    pid > 0
        && process_start_ticks(pid) == Some(started)
        && std::fs::metadata(format!("/proc/{pid}")).is_ok_and(|m| m.uid() == uid)
}

/// How long a sweep waits for the processes of a session whose launcher was killed to exit.
const LAUNCHER_GONE_WAIT: Duration = Duration::from_secs(3);

/// How long a reader that let go of an ended session waits for its launcher, which removes the
/// session's files and then exits, before it looks what is left.
const LAUNCHER_EXIT_WAIT: Duration = Duration::from_secs(3);

/// The most a session's card holds: a few hundred bytes; more is not a card.
const MAX_CARD_BYTES: u64 = 64 << 10;

/// The text of `path` when it is a regular file of this user's of at most `max` bytes; None
/// otherwise. A session's folder is this user's own (0700), but the tools walk every folder
/// in it: a FIFO there would block them forever, a link to `/dev/zero` would be read until
/// memory ran out, and a file another user owns is not this user's session. The type and the
/// owner are taken from the open descriptor ([`crate::config::open_regular`]: a FIFO is
/// refused before anything could block), and at most `max` + 1 bytes are ever read.
fn read_own_file(path: &StdPath, max: u64) -> Option<String> {
    use std::io::Read as _;
    use std::os::unix::fs::MetadataExt;
    // SAFETY: as in base_dir.
    let uid = unsafe { libc::getuid() };
    let file = crate::config::open_regular(path).ok()?;
    let meta = file.metadata().ok()?;
    if meta.uid() != uid || meta.len() > max {
        return None;
    }
    let mut text = String::new();
    file.take(max + 1).read_to_string(&mut text).ok()?;
    (text.len() as u64 <= max).then_some(text)
}

/// Whether `path` is a folder (not a link to one) of this user's.
fn own_dir(path: &StdPath) -> bool {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: as in base_dir.
    let uid = unsafe { libc::getuid() };
    std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir() && m.uid() == uid)
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
pub(super) fn make_private_dir(dir: &StdPath) -> Result<(), BusError> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => {
            return Err(BusError::config(format!(
                "cannot create the session folder {}: {e}",
                dir.display()
            )))
        }
    }
    let meta = std::fs::symlink_metadata(dir).map_err(|e| {
        BusError::config(format!(
            "cannot read the session folder {}: {e}",
            dir.display()
        ))
    })?;
    // SAFETY: as in base_dir.
    let uid = unsafe { libc::getuid() };
    if !meta.is_dir() || meta.uid() != uid {
        return Err(BusError::config(format!(
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
            BusError::config(format!("cannot make {} private (0700): {e}", dir.display()))
        })?;
    }
    Ok(())
}

/// Makes this session's files in /dev/shm this user's alone (0600): iceoryx2 creates its
/// per-prefix management segment readable and writable by everyone. A file of the prefix
/// that another user owns is refused.
pub(super) fn make_shm_private(prefix: &str) -> Result<(), BusError> {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    // SAFETY: as in base_dir.
    let uid = unsafe { libc::getuid() };
    for f in leftover_files(StdPath::new("/dev/shm"), prefix) {
        let Ok(meta) = std::fs::symlink_metadata(&f) else {
            continue; // removed meanwhile
        };
        if meta.uid() != uid {
            return Err(BusError::config(format!(
                "{} belongs to uid {}, not this user (uid {uid}): refusing to attach a session \
                 to shared memory it does not own; choose another --bus-id",
                f.display(),
                meta.uid()
            )));
        }
        if meta.mode() & 0o077 != 0 {
            std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).map_err(|e| {
                BusError::config(format!("cannot make {} private (0600): {e}", f.display()))
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

/// The card a launcher leaves in its session's folder, for the tools that look at a running
/// session (`handblocks sessions`, `echo`, `hz`): how to open its bus, and what it runs.
const CARD_FILE: &str = "session.toml";

/// A session running on this machine, as its launcher's card describes it.
#[derive(Debug, Clone)]
pub struct RunningSession {
    /// Its bus, opened as its processes open it (world size, lossless).
    pub bus: BusConfig,
    /// The session file it runs.
    pub session_file: String,
    /// Its source's kind (`scripted`, `replay`, `external`, ...), as its launcher read it.
    pub source: String,
    /// When it started (Unix seconds) and the launcher's pid.
    pub started_unix_s: u64,
    pub launcher_pid: u32,
    /// When the launcher process started (clock ticks after boot, /proc/PID/stat's 22nd
    /// field): with the pid it names one process, so a pid the kernel reused after the
    /// launcher was killed is not taken for it.
    pub launcher_start_ticks: u64,
}

impl RunningSession {
    /// The running session `id` names, or the only one running; otherwise a message that
    /// says what runs and what to do (`handblocks echo`, Python's `handblocks.Session`).
    pub fn find(id: Option<&str>) -> Result<RunningSession, String> {
        let mut running = BusConfig::running();
        match id {
            Some(id) => running.into_iter().find(|s| s.bus.id == id).ok_or_else(|| {
                format!("no session {id:?} runs here (`handblocks sessions` lists those that do)")
            }),
            None => match running.len() {
                0 => Err(
                    "no session runs on this machine; start one with `handblocks launch`".into(),
                ),
                1 => Ok(running.remove(0)),
                n => Err(format!(
                    "{n} sessions run ({}); choose one by its id",
                    running
                        .iter()
                        .map(|s| s.bus.id.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )),
            },
        }
    }

    /// True while its launcher (that pid, started at that time) still runs and its card is
    /// there.
    pub fn is_running(&self) -> bool {
        launcher_alive(self.launcher_pid, self.launcher_start_ticks)
            && std::fs::symlink_metadata(self.bus.root.join(CARD_FILE)).is_ok_and(|m| m.is_file())
    }

    /// Removes what this reader (a tool: `echo`, `hz`, Python's `Session`) may have left of
    /// the session once it has let go of its bus (its node dropped) and the session has
    /// ended: its launcher gone, and no process attached to the bus. The launcher, when it
    /// ends, withdraws the card and waits a moment for readers to let go before it removes
    /// the session's files ([`BusConfig::withdraw_card`]); a reader that held on past that
    /// (a Python program keeping its `Session`) would otherwise leave iceoryx2's files of its
    /// own node and ports in /dev/shm. Nothing is removed while the session runs, before its
    /// launcher, which removes the files itself, has exited (waited for up to
    /// [`LAUNCHER_EXIT_WAIT`]), while a new session has claimed the bus id, or while any
    /// process is attached. Returns how many entries were removed.
    pub fn tidy_after_reader(&self) -> usize {
        let bus = &self.bus;
        // Once the card is withdrawn the launcher is removing the files itself: let it finish
        // (it exits right after), so that two removals never meet.
        let deadline = std::time::Instant::now() + LAUNCHER_EXIT_WAIT;
        while launcher_alive(self.launcher_pid, self.launcher_start_ticks) {
            let card = std::fs::symlink_metadata(bus.root.join(CARD_FILE)).is_ok();
            if card || std::time::Instant::now() >= deadline {
                return 0;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        if bus.launcher_gone() == Some(false) || (bus.root.exists() && bus.has_live_processes()) {
            return 0;
        }
        bus.remove_resources().unwrap_or(0)
    }

    /// Silences iceoryx2's own log for a tool that looks at a session from outside (`echo`,
    /// `hz`, Python's `Session`): when the session ends its launcher removes the session's
    /// files while the tool is still attached, and iceoryx2 would print raw warnings about
    /// each storage it can no longer remove. The tool says in one line that the session ended
    /// instead; iceoryx2's fatal errors still print.
    pub fn quiet_bus_log() {
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Fatal);
    }

    /// The processes attached to its bus now: (iceoryx2 node name, pid), the launcher's own
    /// node included.
    pub fn processes(&self) -> Vec<(String, u32)> {
        let mut out = Vec::new();
        let Ok(config) = self.bus.iceoryx() else {
            return out;
        };
        let _ = Node::<ipc::Service>::list(&config, |state| {
            use iceoryx2::node::NodeView as _;
            if let NodeState::Alive(view) = state {
                let name = view
                    .details()
                    .as_ref()
                    .map_or_else(|| "?".to_string(), |d| d.name().as_str().to_string());
                let pid = view
                    .id()
                    .pid::<ipc::Service>()
                    .map_or(0, |p| p.value() as u32);
                out.push((name, pid));
            }
            CallbackProgression::Continue
        });
        out.sort();
        out
    }
}

impl BusConfig {
    /// Leaves the card of this session in its folder (after [`BusConfig::claim_as_launcher`]).
    pub fn write_card(&self, session_file: &StdPath, source: &str) -> Result<(), BusError> {
        let started = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let mut card = toml::Table::new();
        card.insert("id".into(), self.id.clone().into());
        card.insert("session".into(), session_file.display().to_string().into());
        card.insert("source".into(), source.into());
        card.insert("world_blocks".into(), (self.world_blocks as i64).into());
        card.insert("lossless".into(), self.lossless.into());
        card.insert("started_unix_s".into(), (started as i64).into());
        let pid = std::process::id();
        card.insert("launcher_pid".into(), (pid as i64).into());
        // The reader checks the pid and this together (a reused pid is another process).
        let ticks = process_start_ticks(pid).unwrap_or(0);
        card.insert("launcher_start_ticks".into(), (ticks as i64).into());
        let file = self.root.join(CARD_FILE);
        std::fs::write(&file, card.to_string())
            .map_err(|e| BusError::config(format!("cannot write {}: {e}", file.display())))
    }

    /// Takes the card away at the session's end, so that the tools reading the session from
    /// outside (`echo`, `hz`, Python's `Session`: not the launcher's children) see that it
    /// ended and let go of the bus, and waits up to `wait` for them to: their nodes then
    /// remove their own files, iceoryx2 does not warn about files removed under them, and
    /// [`BusConfig::remove_resources`] that follows removes everything. Call it once the
    /// session's own processes are gone. Returns whether a reader was still attached when
    /// the wait ended.
    pub fn withdraw_card(&self, wait: Duration) -> bool {
        let _ = std::fs::remove_file(self.root.join(CARD_FILE));
        let deadline = std::time::Instant::now() + wait;
        loop {
            let attached = self.has_live_processes();
            if !attached || std::time::Instant::now() >= deadline {
                return attached;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The sessions of this user running on this machine, oldest first: those whose card is
    /// a regular file of this user's (of at most [`MAX_CARD_BYTES`]), in a folder of this
    /// user's, and whose launcher, the pid and start time the card records, still runs as
    /// this user. Anything else in the folder (another user's card, a FIFO, a link to a
    /// device, a card naming a pid that is not its launcher) is not a session, and is never
    /// read past its size.
    pub fn running() -> Vec<RunningSession> {
        let bases = [
            base_dir(&std::env::temp_dir()),
            base_dir(StdPath::new("/tmp")),
        ];
        let mut found: Vec<RunningSession> = bases
            .iter()
            .take(if bases[0] == bases[1] { 1 } else { 2 })
            .filter(|b| own_dir(b))
            .filter_map(|b| std::fs::read_dir(b).ok())
            .flat_map(|e| e.flatten())
            .filter(|entry| own_dir(&entry.path()))
            .filter_map(|entry| {
                let text = read_own_file(&entry.path().join(CARD_FILE), MAX_CARD_BYTES)?;
                let card: toml::Table = text.parse().ok()?;
                let id = card.get("id")?.as_str()?;
                let blocks = card.get("world_blocks")?.as_integer()?;
                let bus = BusConfig::for_session(id)
                    .ok()?
                    .with_world_blocks(usize::try_from(blocks).ok()?)
                    .ok()?
                    .with_lossless(card.get("lossless")?.as_bool()?);
                let pid = u32::try_from(card.get("launcher_pid")?.as_integer()?).ok()?;
                let ticks = u64::try_from(card.get("launcher_start_ticks")?.as_integer()?).ok()?;
                (bus.root == entry.path() && launcher_alive(pid, ticks)).then(|| RunningSession {
                    session_file: card
                        .get("session")
                        .and_then(|s| s.as_str())
                        .unwrap_or("?")
                        .to_string(),
                    source: card
                        .get("source")
                        .and_then(|s| s.as_str())
                        .unwrap_or("?")
                        .to_string(),
                    started_unix_s: card
                        .get("started_unix_s")
                        .and_then(|s| s.as_integer())
                        .map_or(0, |s| s as u64),
                    launcher_pid: pid,
                    launcher_start_ticks: ticks,
                    bus,
                })
            })
            .collect();
        found.sort_by_key(|s| s.started_unix_s);
        found
    }
}
