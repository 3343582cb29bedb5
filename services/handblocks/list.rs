//! `handblocks list [DIR]`: the scenes and sessions under a folder, each with its first
//! comment line, told apart by their keys (a session names a `scene`; a scene has blocks or a
//! hand).

use std::fmt;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Why there is nothing to list.
#[derive(Debug)]
pub enum ListError {
    /// The folder itself cannot be read (unreadable folders below it are skipped).
    Unreadable { dir: PathBuf },
}

impl fmt::Display for ListError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ListError::Unreadable { dir } => {
                write!(f, "cannot read the folder {}", dir.display())
            }
        }
    }
}

impl std::error::Error for ListError {}

/// `handblocks list`: scenes and sessions with their first comment line.
pub fn run(dir: &Path) -> Result<ExitCode, ListError> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            if d == dir {
                return Err(ListError::Unreadable {
                    dir: dir.to_path_buf(),
                });
            }
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "toml") {
                files.push(p);
            }
        }
    }
    files.sort();
    let mut scenes = Vec::new();
    let mut sessions = Vec::new();
    for f in files {
        let Ok(text) = std::fs::read_to_string(&f) else {
            continue;
        };
        let Ok(table) = text.parse::<toml::Table>() else {
            continue;
        };
        let first = text
            .lines()
            .map(str::trim)
            .find(|l| l.starts_with('#'))
            .map(|l| l.trim_start_matches('#').trim().to_string())
            .unwrap_or_default();
        if table.contains_key("scene") {
            sessions.push((f, first));
        } else if table.contains_key("block") || table.contains_key("hand") {
            scenes.push((f, first));
        }
    }
    let w = scenes
        .iter()
        .chain(&sessions)
        .map(|(f, _)| f.display().to_string().len())
        .max()
        .unwrap_or(0);
    println!("sessions (handblocks launch SESSION, or ./run SESSION):");
    for (f, first) in &sessions {
        println!("  {:w$}  {first}", f.display().to_string());
    }
    println!("scenes (handblocks simulate SCENE; handblocks launch SCENE runs it with the scripted hand):");
    for (f, first) in &scenes {
        println!("  {:w$}  {first}", f.display().to_string());
    }
    Ok(ExitCode::SUCCESS)
}
