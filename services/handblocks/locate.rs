//! Finding the sessions and scenes wherever `handblocks` is run from.
//!
//! A path the user gives that exists is used as given. Otherwise a path under `config/`
//! (`config/sessions/live.toml`, the default session) or a bare name (`live`, `grasp-throw`)
//! is looked up in the first configuration folder of:
//! 1. `$HANDBLOCKS_CONFIG` (`builtin`: the copy built into the binary, step 5);
//! 2. `./config` (run from the repository's root, as the README does);
//! 3. the repository the binary was built from, while its `config/` is still there (a
//!    `target/release/handblocks` run from another folder, with `../shared` still beside the
//!    checkout for the CARL traces);
//! 4. `share/handblocks/config` beside the binary's folder (an installed package);
//! 5. the copy built into the binary (`build.rs`), written out once into
//!    `$XDG_CACHE_HOME/handblocks/config-COMMIT` (or `~/.cache/...`): `cargo install --path .`
//!    gives a binary that runs its default session from any folder, the repository gone.

use std::path::{Path, PathBuf};

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/embedded_config.rs"));
}

/// A configuration folder and how it was found.
#[derive(Debug, Clone)]
pub struct ConfigRoot {
    pub dir: PathBuf,
    pub how: &'static str,
}

/// The configuration folder (see the module's doc); None only when no folder exists and the
/// built-in copy cannot be written out (no cache folder can be made).
pub fn config_root() -> Option<ConfigRoot> {
    let found = |dir: PathBuf, how| {
        dir.join("sessions")
            .is_dir()
            .then_some(ConfigRoot { dir, how })
    };
    if let Some(dir) = std::env::var_os("HANDBLOCKS_CONFIG") {
        // `builtin`: the copy built into the binary, whatever folders exist.
        if dir == "builtin" {
            return written_out().map(|dir| ConfigRoot {
                dir,
                how: "the copy built into the binary",
            });
        }
        if let Some(r) = found(PathBuf::from(dir), "named by $HANDBLOCKS_CONFIG") {
            return Some(r);
        }
    }
    if let Some(r) = found(PathBuf::from("config"), "in this folder") {
        return Some(r);
    }
    let built_in = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    if let Some(r) = found(built_in, "in the repository this binary was built from") {
        return Some(r);
    }
    if let Some(dir) = std::env::current_exe()
        .ok()
        .and_then(|exe| Some(exe.parent()?.parent()?.join("share/handblocks/config")))
    {
        if let Some(r) = found(dir, "installed beside the binary") {
            return Some(r);
        }
    }
    written_out().map(|dir| ConfigRoot {
        dir,
        how: "the copy built into the binary",
    })
}

/// The built-in copy, written out once per commit into the user's cache folder.
fn written_out() -> Option<PathBuf> {
    let cache = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    let dir = cache
        .join("handblocks")
        .join(format!("config-{}", env!("HANDBLOCKS_COMMIT")));
    if dir.join("sessions").is_dir() {
        return Some(dir);
    }
    // Written beside and renamed into place: a half-written copy is never used.
    let part = cache.join("handblocks").join(format!(
        ".config-{}.{}",
        env!("HANDBLOCKS_COMMIT"),
        std::process::id()
    ));
    let write = || -> std::io::Result<()> {
        for (rel, bytes) in embedded::FILES {
            let path = part.join(rel);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)?;
            }
            std::fs::write(path, bytes)?;
        }
        Ok(())
    };
    let written = write().and_then(|()| std::fs::rename(&part, &dir));
    let _ = std::fs::remove_dir_all(&part);
    (written.is_ok() || dir.join("sessions").is_dir()).then_some(dir)
}

/// What kind of file a name means when it is not a path that exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A session (or a scene, which `launch` also runs): `sessions/NAME.toml`,
    /// `devices/NAME.toml`, then `scenes/NAME.toml`.
    Session,
    /// A scene: `scenes/NAME.toml`.
    Scene,
}

/// `given` as the user meant it: itself when it exists; else found in the configuration
/// folder; else itself (its error then names it as given).
pub fn resolve(given: &Path, kind: Kind) -> PathBuf {
    if given.exists() || given.is_absolute() {
        return given.to_path_buf();
    }
    let Some(root) = config_root() else {
        return given.to_path_buf();
    };
    let mut candidates = Vec::new();
    if let Ok(rest) = given.strip_prefix("config") {
        candidates.push(root.dir.join(rest));
    }
    if given.components().count() == 1 {
        let name = given.to_string_lossy();
        let file = if name.ends_with(".toml") {
            name.into_owned()
        } else {
            format!("{name}.toml")
        };
        if kind == Kind::Session {
            candidates.push(root.dir.join("sessions").join(&file));
            candidates.push(root.dir.join("devices").join(&file));
        }
        candidates.push(root.dir.join("scenes").join(&file));
    }
    candidates
        .into_iter()
        .find(|c| c.is_file())
        .unwrap_or_else(|| given.to_path_buf())
}

/// Why a bare name names no file, when it names none (None when [`resolve`] finds it, or
/// `given` is a path): no such file and no name of its kind, the nearest names of that kind (a "did you mean"), and where
/// they are listed. The caller puts the file in front.
pub fn missing(given: &Path, kind: Kind) -> Option<String> {
    // A path (`/data/s.toml`, `config/x.toml`) is the loader's to refuse ("cannot read the
    // file"); only a bare name can be a misspelt name.
    if given.components().count() != 1 || resolve(given, kind).exists() {
        return None;
    }
    let what = match kind {
        Kind::Session => "session or scene",
        Kind::Scene => "scene",
    };
    let asked = given
        .file_stem()
        .map(|s| s.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let mut near: Vec<(usize, String)> = names_of(kind)
        .into_iter()
        .filter(|n| common::config::near_enough(&asked, &n.to_lowercase()))
        .map(|n| (common::config::edit_distance(&asked, &n.to_lowercase()), n))
        .collect();
    near.sort();
    near.dedup_by(|a, b| a.1 == b.1);
    let mut why = format!("no such file, and no {what} of that name");
    if !near.is_empty() {
        why.push_str(&format!(
            " (did you mean {}?)",
            near.iter()
                .take(3)
                .map(|(_, n)| format!("`{n}`"))
                .collect::<Vec<_>>()
                .join(" or ")
        ));
    }
    why.push_str("; `handblocks list` lists them");
    Some(why)
}

/// Why `given` (found by [`resolve`]) is not a file of `kind` though it exists, when it is
/// plainly something else, with the command that takes it: a folder (`handblocks list DIR`),
/// a recorded hand (`replay`, or `simulate --hand`), a session given to `simulate`. None when
/// it may be one (the loader then checks every key).
pub fn wrong_kind(given: &Path, kind: Kind) -> Option<String> {
    let file = resolve(given, kind);
    let shown = file.display();
    if file.is_dir() {
        return Some(format!(
            "a folder, not a {} file: `handblocks list {shown}` lists the sessions and scenes in \
             it",
            match kind {
                Kind::Session => "session",
                Kind::Scene => "scene",
            }
        ));
    }
    // Only a regular file is read here: opening a FIFO would block (the loader refuses it).
    if !file.is_file() {
        return None;
    }
    let mut head = [0u8; 8];
    let n = std::fs::File::open(&file)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
        .ok()?;
    let trace = if head[..n].starts_with(b"CARL") {
        Some("a CARL trace")
    } else if head[..n].starts_with(b"\x89MCAP") {
        Some("an MCAP recording")
    } else {
        None
    };
    if let Some(trace) = trace {
        return Some(match kind {
            Kind::Session => format!(
                "{trace} (a recorded hand), not a session: play it with `handblocks replay \
                 {shown}`"
            ),
            Kind::Scene => format!(
                "{trace} (a recorded hand), not a scene: let it drive a scene's hand with \
                 `handblocks simulate SCENE --hand {shown}` (the carl-* scenes are made for CARL \
                 traces), or play it live with `handblocks replay {shown}`"
            ),
        });
    }
    if kind == Kind::Scene {
        // A session names its scene; a scene has blocks.
        let table = std::fs::read_to_string(&file)
            .ok()?
            .parse::<toml::Table>()
            .ok()?;
        if let (Some(scene), false) = (table.get("scene"), table.contains_key("block")) {
            // Named from the session's folder, as the session reads it; shown as a name
            // when it is one of the configuration's scenes.
            let named = Path::new(scene.as_str().unwrap_or("SCENE"));
            let path = file.parent().unwrap_or(Path::new("")).join(named);
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
            let scene = match stem {
                Some(stem)
                    if path.canonicalize().ok().is_some_and(|p| {
                        resolve(Path::new(&stem), Kind::Scene).canonicalize().ok() == Some(p)
                    }) =>
                {
                    stem
                }
                _ => path.display().to_string(),
            };
            return Some(format!(
                "a session file, not a scene: simulate its scene with `handblocks simulate \
                 {scene}`, or run the session with `handblocks launch {shown}`"
            ));
        }
    }
    None
}

/// The names (file stems) a bare name of `kind` can mean, from the configuration folder.
fn names_of(kind: Kind) -> Vec<String> {
    let Some(root) = config_root() else {
        return Vec::new();
    };
    let folders: &[&str] = match kind {
        Kind::Session => &["sessions", "devices", "scenes"],
        Kind::Scene => &["scenes"],
    };
    let mut names = Vec::new();
    for folder in folders {
        let Ok(entries) = std::fs::read_dir(root.dir.join(folder)) else {
            continue;
        };
        for e in entries.flatten() {
            let path = e.path();
            if path.extension().is_some_and(|x| x == "toml") {
                if let Some(stem) = path.file_stem() {
                    names.push(stem.to_string_lossy().into_owned());
                }
            }
        }
    }
    names.sort();
    names
}

/// A folder of configuration (`list`'s): itself when it exists, else `config` or a folder
/// under it found in the configuration folder.
pub fn resolve_dir(given: &Path) -> PathBuf {
    if given.is_dir() || given.is_absolute() {
        return given.to_path_buf();
    }
    match (config_root(), given.strip_prefix("config")) {
        (Some(root), Ok(rest)) => root.dir.join(rest),
        _ => given.to_path_buf(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_misspelt_name_gets_the_nearest_names_and_a_pointer_to_list() {
        assert_eq!(
            common::config::edit_distance("grasp-thrw", "grasp-throw"),
            1
        );
        assert_eq!(common::config::edit_distance("", "abc"), 3);
        let why = missing(Path::new("grasp-thrw"), Kind::Scene).unwrap_or_default();
        assert!(
            why.contains("did you mean `grasp-throw`") && why.contains("handblocks list"),
            "{why}"
        );
        let why = missing(Path::new("nosuch.toml"), Kind::Session).unwrap_or_default();
        assert!(
            why.contains("no session or scene of that name") && !why.contains("did you mean"),
            "{why}"
        );
        assert!(missing(Path::new("grasp-throw"), Kind::Scene).is_none());
    }

    #[test]
    fn the_built_in_copy_holds_the_default_session_and_its_scene() {
        let names: Vec<&str> = embedded::FILES.iter().map(|(n, _)| *n).collect();
        assert!(names.contains(&"sessions/live.toml"), "{names:?}");
        assert!(names.contains(&"scenes/grasp-throw.toml"));
        assert!(names.contains(&"hand.toml"));
    }
}
