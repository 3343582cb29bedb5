//! `handblocks list [DIR]`: the scenes and sessions under a folder (by default the
//! configuration folder, wherever it was found: `locate`), each with the first sentence of its
//! opening comment, told apart by their keys (a session names a `scene`; a scene has blocks or
//! a hand).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Why there is nothing to list.
#[derive(Debug, thiserror::Error)]
pub enum ListError {
    /// The folder itself cannot be read (unreadable folders below it are skipped).
    #[error(
        "cannot read the folder {} (give a folder of sessions and scenes; `handblocks list` \
         alone lists the configuration's)",
        dir.display()
    )]
    Unreadable { dir: PathBuf },
    /// The folder holds no session and no scene (nothing to list is a mistake, not a list).
    #[error(
        "{}: no session (a file with [scene]) and no scene (a file with [[block]] or [hand]) in \
         it or below; `handblocks list` alone lists the configuration's",
        dir.display()
    )]
    Empty { dir: PathBuf },
}

/// `handblocks list`: scenes and sessions with their first comment line.
pub fn run(given: &Path) -> Result<ExitCode, ListError> {
    let dir_buf = crate::locate::resolve_dir(given);
    let dir = dir_buf.as_path();
    if dir != given {
        let how = crate::locate::config_root().map_or("", |r| r.how);
        println!("configuration: {} ({how})", dir.display());
    }
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
        // A regular file of a config's size only (a FIFO or a device there would hang it).
        let Ok(text) = common::config::read_bounded_text(&f, common::config::MAX_CONFIG_BYTES)
        else {
            continue;
        };
        let Ok(table) = text.parse::<toml::Table>() else {
            continue;
        };
        let first = first_sentence(&text);
        if table.contains_key("scene") {
            sessions.push((f, first));
        } else if table.contains_key("block") || table.contains_key("hand") {
            scenes.push((f, first));
        }
    }
    if sessions.is_empty() && scenes.is_empty() {
        return Err(ListError::Empty {
            dir: dir.to_path_buf(),
        });
    }
    println!("sessions (handblocks launch NAME-OR-FILE, or ./run SESSION):");
    for (f, first) in &sessions {
        print_entry(f, first);
    }
    println!("scenes (handblocks simulate NAME-OR-FILE; handblocks launch SCENE runs it with the scripted hand):");
    for (f, first) in &scenes {
        print_entry(f, first);
    }
    Ok(ExitCode::SUCCESS)
}

/// `  name  path` and, below it, the description wrapped at 100 columns.
fn print_entry(file: &Path, about: &str) {
    let name = file
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    println!("  {name:24} {}", file.display());
    let mut line = String::from("     ");
    for word in about.split_whitespace() {
        if line.len() + 1 + word.len() > 100 && !line.trim().is_empty() {
            println!("{line}");
            line = String::from("     ");
        }
        line.push(' ');
        line.push_str(word);
    }
    if !line.trim().is_empty() {
        println!("{line}");
    }
}

/// The first sentence of a file's opening comment (its leading `#` lines up to a blank one),
/// whole: a description is never cut mid-sentence.
fn first_sentence(text: &str) -> String {
    let mut joined = String::new();
    for line in text.lines().map(str::trim) {
        let Some(comment) = line.strip_prefix('#') else {
            if joined.is_empty() && line.is_empty() {
                continue;
            }
            break;
        };
        let comment = comment.trim();
        if comment.is_empty() {
            if joined.is_empty() {
                continue;
            }
            break;
        }
        if !joined.is_empty() {
            joined.push(' ');
        }
        joined.push_str(comment);
    }
    // The first ". " that ends a sentence (not the one of "e.g. " or "i.e. ").
    let end = joined
        .match_indices(". ")
        .map(|(i, _)| i)
        .find(|&i| !(joined[..i].ends_with("e.g") || joined[..i].ends_with("i.e")));
    match end {
        Some(end) => joined[..=end].to_string(),
        None => joined,
    }
}

#[cfg(test)]
mod tests {
    use super::first_sentence;

    #[test]
    fn a_description_is_its_first_whole_sentence() {
        let text = "# Replays a real hand (Meta Quest, from the CARL project) into the\n\
                    # pipeline in place of the glove. The hand thrusts.\n# more\nscene = \"x\"\n";
        assert_eq!(
            first_sentence(text),
            "Replays a real hand (Meta Quest, from the CARL project) into the pipeline in \
             place of the glove."
        );
        assert_eq!(first_sentence("\n# One line\n\n# Two\n"), "One line");
    }
}
