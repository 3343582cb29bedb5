//! What crashed sessions leave in /dev/shm outside their session folders, removed when a
//! session is launched ([`sweep_shm`]).
//!
//! `BusConfig::sweep_abandoned` removes a dead session's folder and the files of its prefix
//! together, found from the folder. Two kinds of file outlive that:
//! * files of a session prefix (`hb_KEY_...`) whose folder is gone already: the launcher
//!   removed the folder while a tool (`echo`, Python) was still attached, and the tool was
//!   killed before it could tidy up; or the session's files were made again after it ended;
//! * zenoh's shared-memory segments (`/dev/shm/N.zenoh`), which a zenoh built with shared
//!   memory (not this project's bridge, whose zenoh has TCP only, but a zenoh program of the
//!   user's beside a session, or a build that turns it on) leaves when its process crashes.
//!
//! Neither names its owner. A file is stale when no process of the machine has it open or
//! mapped (`/proc/PID/fd`, `/proc/PID/maps`: a live iceoryx2 node maps its session's files, a
//! live zenoh its segments), it belongs to this user, and it is older than [`STALE_AFTER`] (a
//! file being made is not yet mapped). A prefix's files go together, and only when none of
//! them is in use and no session folder of that key exists (that folder is the launcher's to
//! judge). Another user's files are never touched.

use std::collections::{BTreeMap, HashSet};
use std::ffi::OsString;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use common::bus::BusConfig;

/// How old a file must be before it can be stale.
pub const STALE_AFTER: Duration = Duration::from_secs(10);

const SHM: &str = "/dev/shm";

/// Removes the stale files of [the module](self) from /dev/shm; one line for each prefix or
/// segment removed (or that could not be).
pub fn sweep_shm() -> Vec<String> {
    sweep_in(Path::new(SHM), &files_in_use)
}

/// [`sweep_shm`] on folder `shm`, with `in_use` for the names of its files that processes hold.
fn sweep_in(shm: &Path, in_use: &dyn Fn(&Path) -> HashSet<OsString>) -> Vec<String> {
    // SAFETY: getuid has no preconditions and cannot fail.
    let uid = unsafe { libc::getuid() };
    let Ok(entries) = std::fs::read_dir(shm) else {
        return Vec::new();
    };
    let now = SystemTime::now();
    let mut zenoh = Vec::new();
    let mut prefixes: BTreeMap<String, Vec<(PathBuf, SystemTime)>> = BTreeMap::new();
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Ok(meta) = std::fs::symlink_metadata(entry.path()) else {
            continue;
        };
        if !meta.is_file() || meta.uid() != uid {
            continue;
        }
        let modified = meta.modified().unwrap_or(now);
        if is_zenoh_segment(&name) {
            zenoh.push((entry.path(), modified));
        } else if let Some(key) = session_key(&name) {
            prefixes
                .entry(key.to_string())
                .or_default()
                .push((entry.path(), modified));
        }
    }
    if zenoh.is_empty() && prefixes.is_empty() {
        return Vec::new();
    }
    let held = in_use(shm);
    let stale = |files: &[(PathBuf, SystemTime)]| {
        files.iter().all(|(f, modified)| {
            f.file_name().is_none_or(|n| !held.contains(n))
                && now
                    .duration_since(*modified)
                    .is_ok_and(|age| age >= STALE_AFTER)
        })
    };
    let mut said = Vec::new();
    for (file, modified) in zenoh {
        if !stale(&[(file.clone(), modified)]) {
            continue;
        }
        said.push(match std::fs::remove_file(&file) {
            Ok(()) => format!(
                "removed {}: zenoh shared memory no process holds (a crashed zenoh's)",
                file.display()
            ),
            Err(e) => format!("left {}: {e}", file.display()),
        });
    }
    for (key, files) in prefixes {
        if has_folder(&key) || !stale(&files) {
            continue;
        }
        let removed = files
            .iter()
            .filter(|(f, _)| std::fs::remove_file(f).is_ok())
            .count();
        said.push(format!(
            "removed {removed} file(s) of prefix hb_{key}_ in {}: no session folder and no \
             process holds them (a session that ended or crashed left them)",
            shm.display()
        ));
    }
    said
}

/// `N.zenoh`: a zenoh shared-memory segment, N its decimal id.
fn is_zenoh_segment(name: &str) -> bool {
    name.strip_suffix(".zenoh")
        .is_some_and(|id| !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()))
}

/// The session key of an iceoryx2 file of a session prefix: `hb_KEY_` then iceoryx2's name,
/// which starts with a 40-hex-digit hash and `_` or `.` (KEY is at most 12 letters, digits,
/// `_` or `-`).
fn session_key(name: &str) -> Option<&str> {
    let rest = name.strip_prefix("hb_")?;
    (1..=12.min(rest.len())).find_map(|end| {
        let key = &rest[..end];
        let tail = rest[end..].strip_prefix('_')?;
        let hash = tail.get(..40)?;
        let after = tail.as_bytes().get(40)?;
        (hash.bytes().all(|b| b.is_ascii_hexdigit())
            && matches!(after, b'_' | b'.')
            && key
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-'))
        .then_some(key)
    })
}

/// Whether a session folder of `key` exists (in this `$TMPDIR`'s folder of sessions or in
/// /tmp's): then the folder's sweep judges the session, not this one.
fn has_folder(key: &str) -> bool {
    // SAFETY: getuid has no preconditions and cannot fail.
    let uid = unsafe { libc::getuid() };
    let in_tmp = Path::new("/tmp").join(format!("hb-iox2-{uid}")).join(key);
    BusConfig::for_session(key).is_ok_and(|b| b.root.exists()) || in_tmp.exists()
}

/// The names of the files in `shm` that some process has open or mapped.
fn files_in_use(shm: &Path) -> HashSet<OsString> {
    let mut held = HashSet::new();
    let Ok(procs) = std::fs::read_dir("/proc") else {
        return held;
    };
    let mut keep = |path: &Path| {
        if path.parent() == Some(shm) {
            if let Some(name) = path.file_name() {
                held.insert(name.to_os_string());
            }
        }
    };
    for p in procs.flatten() {
        if !p
            .file_name()
            .to_string_lossy()
            .bytes()
            .all(|b| b.is_ascii_digit())
        {
            continue;
        }
        if let Ok(fds) = std::fs::read_dir(p.path().join("fd")) {
            for fd in fds.flatten() {
                if let Ok(target) = std::fs::read_link(fd.path()) {
                    keep(&target);
                }
            }
        }
        if let Ok(maps) = std::fs::read_to_string(p.path().join("maps")) {
            for line in maps.lines() {
                // address perms offset dev inode path: the path is the sixth field.
                if let Some(path) = line.split_whitespace().nth(5) {
                    keep(Path::new(path));
                }
            }
        }
    }
    held
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_told_apart() {
        let hash = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5";
        assert_eq!(
            session_key(&format!("hb_kla_{hash}_node.0_10_0.global_mgmt")),
            Some("kla")
        );
        assert_eq!(
            session_key(&format!("hb_a_b-c_{hash}_123.data")),
            Some("a_b-c")
        );
        assert_eq!(session_key(&format!("hb_kla_{hash}")), None);
        assert_eq!(session_key("hb_kla_x.data"), None);
        assert_eq!(session_key(&format!("iox2_{hash}_1.data")), None);
        assert!(is_zenoh_segment("123.zenoh"));
        assert!(!is_zenoh_segment(".zenoh") && !is_zenoh_segment("a1.zenoh"));
    }

    /// Issue 40: what a crash leaves in /dev/shm outside any session folder (zenoh's
    /// segments, a session prefix's files whose folder is gone) goes at the next launch when
    /// no process holds it; what a process holds, or is new, stays.
    #[test]
    fn stale_files_go_and_held_or_new_ones_stay() {
        let dir = std::env::temp_dir().join(format!("hb-sweep-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let hash = "0354a209029e7d094a819e2d4030ea331e6caaf0";
        let key = format!("zq{}", std::process::id() % 1_000_000);
        let old = SystemTime::now() - Duration::from_secs(60);
        let make = |name: &str, modified: SystemTime| {
            let f = std::fs::File::create(dir.join(name)).unwrap();
            f.set_modified(modified).unwrap();
            name.to_string()
        };
        let stale_zenoh = make("4000000001.zenoh", old);
        let held_zenoh = make("4000000002.zenoh", old);
        let new_zenoh = make("4000000003.zenoh", SystemTime::now());
        let stale_a = make(&format!("hb_{key}a_{hash}_node.0_10_0.global_mgmt"), old);
        let stale_b = make(&format!("hb_{key}a_{hash}_1.data"), old);
        let held_a = make(&format!("hb_{key}b_{hash}_node.0_10_0.global_mgmt"), old);
        let held_b = make(&format!("hb_{key}b_{hash}_2.data"), old);
        let other = make("someone-elses.data", old);
        let in_use = |_: &Path| -> HashSet<OsString> {
            [&held_zenoh, &held_b]
                .into_iter()
                .map(OsString::from)
                .collect()
        };
        let said = sweep_in(&dir, &in_use);
        let left = |n: &str| dir.join(n).exists();
        assert!(
            !left(&stale_zenoh) && !left(&stale_a) && !left(&stale_b),
            "{said:?}"
        );
        for n in [&held_zenoh, &new_zenoh, &held_a, &held_b, &other] {
            assert!(left(n), "{n} removed: {said:?}");
        }
        assert_eq!(said.len(), 2, "{said:?}");
        assert!(
            said.iter()
                .any(|l| l.contains(&format!("prefix hb_{key}a_"))),
            "{said:?}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The processes' open and mapped files are found: this test's own open file.
    #[test]
    fn a_file_this_process_holds_is_in_use() {
        let dir = std::env::temp_dir().join(format!("hb-sweep-held-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("1.zenoh");
        let _open = std::fs::File::create(&file).unwrap();
        assert!(files_in_use(&dir).contains(std::ffi::OsStr::new("1.zenoh")));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
