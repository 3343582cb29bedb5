//! The session's outputs on disk: the recording (with the segments a restarted recorder
//! writes), the report, the frames and the preview. Preflight checks that each can be written;
//! `--force` removes what an earlier session left at their paths. A link there is never
//! followed: it is refused, or removed itself.

use std::path::{Path, PathBuf};

use common::config::session::{recording_segment, RestartPolicy};
use common::config::Session;

use crate::{LaunchError, LaunchOptions};

/// The frames an earlier session left in `dir` (`frame_*.png`, links too): a session writes
/// its frames new, so these are refused without `--force` and removed with it.
pub(crate) fn frames_in(dir: &Path) -> Vec<PathBuf> {
    let mut frames: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| {
            let name = e.file_name();
            let name = name.to_string_lossy();
            name.starts_with("frame_") && name.ends_with(".png")
        })
        .map(|e| e.path())
        .collect();
    frames.sort();
    frames
}

/// `path` can be written: it is not a folder, and its folder exists (or can be made) and takes
/// a new file. `path` itself is not opened (that would follow a link there): a probe file of
/// its own is created beside it and removed.
pub(crate) fn check_writable(what: &'static str, path: &Path) -> Result<(), LaunchError> {
    if std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir()) {
        return Err(LaunchError::OutputIsFolder {
            what,
            path: path.to_path_buf(),
        });
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|reason| LaunchError::OutputFolder {
            what,
            dir: dir.to_path_buf(),
            path: path.to_path_buf(),
            reason,
        })?;
    }
    common::output::check_folder_writable(path).map_err(|reason| LaunchError::OutputUnwritable {
        what,
        path: path.to_path_buf(),
        reason,
    })
}

/// `--force`: what is at the outputs' paths goes, the entry itself (a link, never its
/// target), and the outputs are then created new. The recording's restart segments go with
/// it, so that no stale `name.1.mcap` sits beside the new recording as if a restart had
/// written it (preflight refused all of these without --force).
pub(crate) fn remove_for_force(opts: &LaunchOptions, session: &Session) -> Result<(), LaunchError> {
    let supervised = session.supervise.restart == RestartPolicy::OnFailure;
    let mut replaced: Vec<PathBuf> = Vec::new();
    if let Some(rec) = &session.recorder.file {
        let restarts = if supervised {
            session.supervise.max_restarts
        } else {
            0
        };
        replaced.extend((0..=restarts).map(|n| recording_segment(rec, n)));
    }
    replaced.extend(opts.report.iter().cloned());
    replaced.extend(opts.frames_dir.iter().flat_map(|d| frames_in(d)));
    for path in replaced {
        common::output::remove_for_replace(&path).map_err(|reason| {
            LaunchError::OutputUnwritable {
                what: "--force",
                path,
                reason,
            }
        })?;
    }
    Ok(())
}
