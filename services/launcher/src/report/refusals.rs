//! What a source refused, by kind: the report's `devices.NAME.refused`.
//!
//! A source stage counts the samples it refuses by kind (a headset's page: `token`, `flood`,
//! `non_finite`, ...; Python's `Source`: `rate`, `order`, ...), but its `latency` reports carry
//! only their total ([`common::DeviceCounters::rejected_records`]), a fixed layout with no room
//! for names. So, as the bridge leaves `bridge.json`, such a stage leaves its counts by kind in
//! the session's folder as it stops, and the launcher reads them into the report before it
//! removes the folder.
//!
//! The file is `refused.NAME.json`, NAME the device's name in the report (`headset` for the
//! webxr stage, `external` for Python's `Source`): one JSON object of kind -> count,
//! `{"flood": 40, "token": 2}`. A file that is not a regular file, is over
//! [`MAX_REFUSALS_BYTES`], is not such an object, or names more than [`MAX_KINDS`] kinds (or a
//! kind longer than [`MAX_KIND_CHARS`]) is left out of the report, with a line on stderr that
//! names it: what a stage wrote is not trusted to be small or well formed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::samples::DeviceKind;

/// The most bytes a refusals file may hold.
pub const MAX_REFUSALS_BYTES: u64 = 64 << 10;
/// The most kinds one file may name.
pub const MAX_KINDS: usize = 64;
/// The longest kind's name.
pub const MAX_KIND_CHARS: usize = 64;

/// Refusals by kind, per device name.
pub type Refusals = BTreeMap<&'static str, BTreeMap<String, u64>>;

/// Where the stage of device `name` leaves its refusals by kind in the session's folder
/// `root`.
pub fn refusals_file(root: &Path, name: &str) -> PathBuf {
    root.join(format!("refused.{name}.json"))
}

/// Every refusals file in the session's folder `root`, by device name; what cannot be read
/// is said on stderr and left out.
pub fn read_refusals(root: &Path) -> Refusals {
    let mut out = Refusals::new();
    // The devices whose stages write their refusals by kind.
    let with_kinds = DeviceKind::ALL
        .into_iter()
        .filter(|d| d.writes_refusals_by_kind());
    for name in with_kinds.map(DeviceKind::name) {
        let file = refusals_file(root, name);
        if std::fs::symlink_metadata(&file).is_err() {
            continue;
        }
        match read_one(&file) {
            Ok(kinds) => {
                out.insert(name, kinds);
            }
            Err(why) => eprintln!(
                "handblocks: {} left out of the report: {why}",
                file.display()
            ),
        }
    }
    out
}

fn read_one(file: &Path) -> Result<BTreeMap<String, u64>, String> {
    let bytes = common::config::read_bounded(file, MAX_REFUSALS_BYTES)?;
    let kinds: BTreeMap<String, u64> = serde_json::from_slice(&bytes)
        .map_err(|e| format!("not a JSON object of kind -> count ({e})"))?;
    if kinds.len() > MAX_KINDS {
        return Err(format!("{} kinds (at most {MAX_KINDS})", kinds.len()));
    }
    if let Some(k) = kinds.keys().find(|k| k.chars().count() > MAX_KIND_CHARS) {
        return Err(format!(
            "a kind of {} characters (at most {MAX_KIND_CHARS})",
            k.chars().count()
        ));
    }
    Ok(kinds.into_iter().filter(|(_, n)| *n > 0).collect())
}
