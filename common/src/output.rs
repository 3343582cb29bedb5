//! The files a session writes for its user: the recording and its restart segments, the
//! `--report` JSON, the preview and `--frames-dir`'s frames.
//!
//! They hold a person's hand motion, so they are private (mode 0600, as the bus's files are:
//! the umask can only narrow it). And they are never written through a link or over a file
//! the user did not ask to replace: a path is created new (`O_CREAT | O_EXCL`, which refuses
//! any existing entry, a symlink too, dangling or not, so nothing is ever written at a link's
//! target), and `--force` removes the entry itself first (the link, never what it points to).
//! A session's own scratch output at a fixed path (the preview) is written whole beside the
//! path and renamed over it ([`replace`]), which also replaces a link rather than follow it.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// The mode of every file this module creates.
pub const PRIVATE_MODE: u32 = 0o600;

/// Whether anything is at `path`: a file, a folder, or a link, even one that points nowhere
/// (`Path::exists` follows links and says a dangling one is not there).
pub fn taken(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok()
}

/// Whether `path` is a symbolic link (dangling or not).
pub fn is_link(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
}

/// Creates `path` as a new private file: an existing entry there, a link included, is an
/// error (`AlreadyExists`), so a planted link is never written through.
pub fn create_new(path: &Path) -> io::Result<File> {
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(PRIVATE_MODE)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(path)
}

/// Makes way for a forced write: removes the file or link at `path` (a link itself, never its
/// target). Nothing there is fine; a folder is refused (`--force` replaces a file, it does
/// not empty a folder).
pub fn remove_for_replace(path: &Path) -> io::Result<()> {
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e),
        Ok(m) if m.is_dir() => Err(io::Error::new(
            io::ErrorKind::IsADirectory,
            "a folder is there; --force replaces a file or a link, not a folder",
        )),
        Ok(_) => std::fs::remove_file(path),
    }
}

/// Creates `path` new, after removing what is there when `force` (see [`remove_for_replace`]).
pub fn create(path: &Path, force: bool) -> io::Result<File> {
    if force {
        remove_for_replace(path)?;
    }
    create_new(path)
}

/// Writes a file whole beside `path` (a new private file of a name no one else uses) and
/// renames it over `path`: a reader never sees half of it, and whatever was at `path`, a
/// link included, is replaced, not followed. `write` fills the file.
pub fn replace(path: &Path, write: impl FnOnce(&mut File) -> io::Result<()>) -> io::Result<()> {
    let tmp = sibling(path, "writing");
    let result = create_new(&tmp).and_then(|mut f| {
        write(&mut f)?;
        f.flush()?;
        f.sync_all()
    });
    match result.and_then(|()| std::fs::rename(&tmp, path)) {
        Ok(()) => Ok(()),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// Checks that a file can be created in `path`'s folder (made if missing) without touching
/// `path`: a private probe file of its own name is created there and removed.
pub fn check_folder_writable(path: &Path) -> io::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let probe = sibling(path, "probe");
    create_new(&probe)?;
    std::fs::remove_file(&probe)
}

/// `.NAME.<what>.<pid>.<n>` beside `path`: a hidden name of this process's own.
fn sibling(path: &Path, what: &str) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let name = path
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy());
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.{what}.{}.{n}", std::process::id()))
}

/// Opens (creating it, 0600, keeping what it holds) a file of the session folder that a
/// process keeps for its restart: a publisher's seq store, the stepper's hand log. Not a
/// user's output: the session folder is private (0700) and removed with the session.
pub fn open_restart_file(path: &Path) -> io::Result<File> {
    OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .mode(PRIVATE_MODE)
        .open(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::{symlink, PermissionsExt};

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hb-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_new_file_is_private_and_an_existing_one_or_a_link_is_refused() {
        let d = scratch("new");
        let f = d.join("rec.mcap");
        create_new(&f).unwrap().write_all(b"x").unwrap();
        let mode = std::fs::metadata(&f).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        assert_eq!(
            create_new(&f).unwrap_err().kind(),
            io::ErrorKind::AlreadyExists
        );
        // A link to a file, and a dangling one: refused, nothing written at the target.
        let target = d.join("victim");
        std::fs::write(&target, b"keep").unwrap();
        let link = d.join("link");
        symlink(&target, &link).unwrap();
        assert!(create_new(&link).is_err());
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
        let dangling = d.join("dangling");
        symlink(d.join("nowhere"), &dangling).unwrap();
        assert!(taken(&dangling) && !dangling.exists());
        assert!(create_new(&dangling).is_err());
        assert!(!d.join("nowhere").exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn force_replaces_the_link_never_its_target_and_refuses_a_folder() {
        let d = scratch("force");
        let target = d.join("victim");
        std::fs::write(&target, b"keep").unwrap();
        let link = d.join("report.json");
        symlink(&target, &link).unwrap();
        create(&link, true).unwrap().write_all(b"new").unwrap();
        assert!(!is_link(&link));
        assert_eq!(std::fs::read(&link).unwrap(), b"new");
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
        let folder = d.join("folder");
        std::fs::create_dir(&folder).unwrap();
        assert_eq!(
            create(&folder, true).unwrap_err().kind(),
            io::ErrorKind::IsADirectory
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn replace_renames_over_a_link_and_leaves_no_scratch() {
        let d = scratch("replace");
        let target = d.join("victim");
        std::fs::write(&target, b"keep").unwrap();
        let link = d.join("preview.png");
        symlink(&target, &link).unwrap();
        replace(&link, |f| f.write_all(b"png")).unwrap();
        assert!(!is_link(&link));
        assert_eq!(std::fs::read(&link).unwrap(), b"png");
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
        let mode = std::fs::metadata(&link).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        // A failed write leaves the old file and no scratch beside it.
        let err = replace(&link, |_| Err(io::Error::other("disk full")));
        assert!(err.is_err());
        assert_eq!(std::fs::read(&link).unwrap(), b"png");
        check_folder_writable(&link).unwrap();
        let left: Vec<_> = std::fs::read_dir(&d).unwrap().collect();
        assert_eq!(left.len(), 2, "{left:?}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
