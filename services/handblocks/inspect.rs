//! `handblocks inspect RECORDING`: a recording's topics, as text or `--json`. The figures are
//! [`Recording::summary`]'s; this module only lays them out.

use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, UNIX_EPOCH};

use recording::{Recording, RecordingError};

/// Lists the recording; 0 when it is intact, 1 when it is damaged (what could be read is
/// listed), an error when it cannot be read at all.
pub fn run(path: &Path, json: bool) -> Result<ExitCode, RecordingError> {
    // Counts and gaps come from every message; no sample needs to stay in memory.
    let rec = Recording::open_topics(path, &[])?;
    let summary = rec.summary();
    let file_bytes = std::fs::metadata(path).map_or(0, |m| m.len());
    let utc = |ns: u64| launcher::report::rfc3339(UNIX_EPOCH + Duration::from_nanos(ns));
    let (start, end) = match summary.span_unix_ns {
        Some((a, b)) => (Some(utc(a)), Some(utc(b))),
        None => (None, None),
    };
    if json {
        let topics: Vec<serde_json::Value> = summary
            .topics
            .iter()
            .map(|t| {
                serde_json::json!({
                    "topic": t.topic.name(), "messages": t.messages, "gaps": t.gaps,
                    "seconds": t.seconds, "rate_hz": t.rate_hz, "schema": t.schema,
                    "bytes": t.sample_bytes, "bytes_per_element": t.element_bytes,
                })
            })
            .collect();
        println!(
            "{}",
            serde_json::json!({
                "file": path.display().to_string(),
                "bytes": file_bytes,
                "start": start,
                "end": end,
                "session": summary.session,
                "scene": summary.scene,
                "complete": summary.complete,
                "damage": summary.damage,
                "foreign_messages": summary.foreign_messages,
                "topics": topics,
            })
        );
    } else {
        println!(
            "{}: {} messages, {:.1} KB, {}",
            path.display(),
            summary.messages,
            file_bytes as f64 / 1024.0,
            if summary.complete {
                "complete"
            } else {
                "damaged (read up to the damage)"
            }
        );
        if let (Some(a), Some(b)) = (&start, &end) {
            println!("from {a} to {b} (UTC)");
        }
        match &summary.session {
            Some(s) => println!("recorded by the session {s}"),
            None => println!("recorded by: not named in the file (not a session's recording)"),
        }
        println!(
            "{:<8} {:>9} {:>6} {:>9} {:>9}  schema",
            "topic", "messages", "gaps", "seconds", "rate_hz"
        );
        for t in &summary.topics {
            let size = match t.element_bytes {
                None => format!("{} bytes", t.sample_bytes),
                Some(e) => format!("{} bytes + {e} a block", t.sample_bytes),
            };
            println!(
                "{:<8} {:>9} {:>6} {:>9.3} {:>9.1}  {} ({size})",
                t.topic.name(),
                t.messages,
                t.gaps,
                t.seconds,
                t.rate_hz,
                t.schema,
            );
        }
        if summary.foreign_messages > 0 {
            println!(
                "{} messages on channels of other tools were skipped",
                summary.foreign_messages
            );
        }
        if let Some(d) = &summary.damage {
            println!("damage: {d}");
        }
    }
    Ok(if summary.complete {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
