//! What the world came to, as a session's end prints it: a summary a person reads before the
//! latency table and the verdict, not the stepper's whole outcome (a 1024-block field is a
//! thousand poses and a few thousand events, which buried the verdict 3,000 lines up).
//!
//! The summary counts the blocks by mode and the events by kind, lists each block only in a
//! small scene, and lists the events that change who holds what: grasps, releases (a throw is
//! a release in flight) and topples. `--blocks` and `--events` print them all, exactly as
//! `simulate` does. The stepper's notes (a jumping clock, refused hand samples, the tracked
//! hand rules' counts) are always printed: each is rare and says something went differently.

use std::fmt::Write;

use serde_json::Value;

use crate::cli::WorldPrint;

/// A scene of at most this many blocks has each listed without `--blocks`.
pub const BLOCKS_LISTED: usize = 8;
/// At most this many of the events that matter are listed without `--events`.
pub const EVENTS_LISTED: usize = 12;
/// The events that matter: who holds what, and what fell over.
const EVENTS_THAT_MATTER: [&str; 3] = ["grasp", "release", "topple"];

/// The stepper's outcome text (`simulate`'s form) cut into its parts.
struct Outcome<'a> {
    /// `after N steps:`
    header: &'a str,
    blocks: Vec<&'a str>,
    /// The stepper's notes between the blocks and the events.
    notes: Vec<&'a str>,
    /// `events (N):` or `events: none`.
    events_header: Option<&'a str>,
    /// One line per kept event, then `... and N later events, not kept` when some were not.
    events: Vec<&'a str>,
}

fn parse(text: &str) -> Outcome<'_> {
    let mut lines = text.lines();
    let header = lines.next().unwrap_or("");
    let mut o = Outcome {
        header,
        blocks: Vec::new(),
        notes: Vec::new(),
        events_header: None,
        events: Vec::new(),
    };
    for line in lines {
        if o.events_header.is_some() {
            o.events.push(line);
        } else if line.starts_with("events") {
            o.events_header = Some(line);
        } else if line.starts_with("  ") && o.notes.is_empty() {
            o.blocks.push(line);
        } else {
            o.notes.push(line);
        }
    }
    o
}

/// `1000 resting, 20 carried, 4 pushed`: how many of each, most first (ties by name).
fn counts<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let mut n: Vec<(&str, usize)> = Vec::new();
    for name in names {
        match n.iter_mut().find(|(k, _)| *k == name) {
            Some((_, c)) => *c += 1,
            None => n.push((name, 1)),
        }
    }
    n.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
    n.iter()
        .map(|(k, c)| format!("{c} {k}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The summary (or, with `print`'s flags, the blocks and events in full) of the stepper's
/// outcome `text`, counted from its JSON form `json` (`simulate --json`'s). Without the JSON
/// (an older stepper, a damaged file) the text is printed whole: nothing is lost.
pub fn summary(text: &str, json: Option<&Value>, print: WorldPrint) -> String {
    let o = parse(text);
    let (Some(blocks), Some(events)) = (
        json.and_then(|j| j["blocks"].as_array()),
        json.and_then(|j| j["events"].as_array()),
    ) else {
        return format!("what the world came to: {text}");
    };
    let field = |v: &Value, k: &str| v[k].as_str().unwrap_or("?").to_string();
    let modes: Vec<String> = blocks.iter().map(|b| field(b, "mode")).collect();
    let kinds: Vec<String> = events.iter().map(|e| field(e, "kind")).collect();
    let mut out = String::new();
    let _ = writeln!(out, "what the world came to, {}", o.header);

    // The blocks: each of them, or their count by mode.
    let all_blocks = print.blocks || blocks.len() <= BLOCKS_LISTED;
    let _ = write!(
        out,
        "blocks ({}): {}",
        blocks.len(),
        counts(modes.iter().map(String::as_str))
    );
    out.push_str(if all_blocks {
        "\n"
    } else {
        "; each block's pose: --blocks\n"
    });
    if all_blocks {
        for line in &o.blocks {
            let _ = writeln!(out, "{line}");
        }
    }
    for note in &o.notes {
        let _ = writeln!(out, "{note}");
    }

    // The events: each of them, or their count by kind and the ones that matter.
    if events.is_empty() {
        out.push_str("events: none\n");
        return out;
    }
    let not_kept = o
        .events
        .last()
        .filter(|l| l.trim_start().starts_with("..."))
        .map(|l| format!(" {}", l.trim()));
    let _ = writeln!(
        out,
        "events ({}): {}{}",
        events.len(),
        counts(kinds.iter().map(String::as_str)),
        not_kept.unwrap_or_default()
    );
    if print.events {
        for line in o
            .events
            .iter()
            .filter(|l| !l.trim_start().starts_with("..."))
        {
            let _ = writeln!(out, "{line}");
        }
        return out;
    }
    // Each as `simulate` prints a lone event (its text folds runs on consecutive steps, so
    // its lines are not one per event: these are made from the JSON).
    let matter: Vec<String> = events
        .iter()
        .filter(|e| EVENTS_THAT_MATTER.contains(&e["kind"].as_str().unwrap_or("")))
        .map(|e| {
            // A shared world's other participants are named (the first, 0, is not: as
            // `simulate` prints them).
            let by = match (e["hand"].as_str(), e["participant"].as_u64()) {
                (Some(h), Some(p)) => format!(" (participant {p}'s {h} hand)"),
                (Some(h), None) => format!(" ({h} hand)"),
                (None, _) => String::new(),
            };
            format!(
                "  step {:6}  {:8} {}{by}",
                e["step"].as_u64().unwrap_or(0),
                field(e, "kind"),
                field(e, "block")
            )
        })
        .collect();
    if matter.is_empty() {
        let _ = writeln!(out, "no grasp, release or topple; every event: --events");
        return out;
    }
    let _ = writeln!(out, "the grasps, releases and topples ({}):", matter.len());
    for line in matter.iter().take(EVENTS_LISTED) {
        let _ = writeln!(out, "{line}");
    }
    if matter.len() > EVENTS_LISTED {
        let _ = writeln!(
            out,
            "  ... and {} more; every event: --events",
            matter.len() - EVENTS_LISTED
        );
    } else {
        out.push_str("every event: --events\n");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "after 636 steps:\n  red  resting    G = (0.000033, 0.030000, -0.855206) m  rotation 0.000 deg about (1.000, 0.000, 0.000)\nevents (4):\n  step      1  impact   red\n  step    117  grasp    red\n  step    231  release  red\n  step    274  rest     red\n";

    fn small_json() -> Value {
        serde_json::json!({
            "frames": 636,
            "blocks": [{"name": "red", "mode": "resting"}],
            "events": [
                {"step": 1, "kind": "impact", "block": "red"},
                {"step": 117, "kind": "grasp", "block": "red"},
                {"step": 231, "kind": "release", "block": "red"},
                {"step": 274, "kind": "rest", "block": "red"},
            ]
        })
    }

    #[test]
    fn a_small_world_lists_its_blocks_and_the_events_that_matter() {
        let s = summary(SMALL, Some(&small_json()), WorldPrint::default());
        assert!(
            s.starts_with("what the world came to, after 636 steps:\n"),
            "{s}"
        );
        assert!(s.contains("blocks (1): 1 resting\n  red  resting"), "{s}");
        assert!(
            s.contains("events (4): 1 grasp, 1 impact, 1 release, 1 rest\n"),
            "{s}"
        );
        assert!(
            s.contains("  step    117  grasp    red\n  step    231  release  red\n"),
            "{s}"
        );
        assert!(!s.contains("impact   red"), "{s}");
        assert!(s.contains("every event: --events"), "{s}");
    }

    #[test]
    fn events_prints_every_event() {
        let print = WorldPrint {
            blocks: false,
            events: true,
        };
        let s = summary(SMALL, Some(&small_json()), print);
        assert!(s.contains("  step      1  impact   red\n"), "{s}");
        assert!(s.contains("  step    274  rest     red\n"), "{s}");
    }

    #[test]
    fn a_large_world_is_counted_not_listed() {
        let mut text = String::from("after 10 steps:\n");
        let mut blocks = Vec::new();
        let mut events = Vec::new();
        for i in 0..100 {
            text.push_str(&format!("  b{i:<3}  resting    G = (0, 0, 0) m\n"));
            blocks.push(serde_json::json!({"name": format!("b{i}"), "mode": "resting"}));
        }
        text.push_str("hands: tracked (docs/model.md T1-T3): 3 step(s) held\n");
        text.push_str("events (40):\n");
        for i in 0..40 {
            let kind = if i % 2 == 0 { "push" } else { "topple" };
            text.push_str(&format!("  step {i:>6}  {kind:<8} b{i}\n"));
            events.push(serde_json::json!({"step": i, "kind": kind, "block": format!("b{i}")}));
        }
        text.push_str("  ... and 7 later events, not kept\n");
        let json = serde_json::json!({"frames": 10, "blocks": blocks, "events": events});
        let s = summary(&text, Some(&json), WorldPrint::default());
        assert!(
            s.contains("blocks (100): 100 resting; each block's pose: --blocks\n"),
            "{s}"
        );
        assert!(!s.contains("b5    resting"), "{s}");
        assert!(
            s.contains("hands: tracked"),
            "the stepper's notes stay: {s}"
        );
        assert!(
            s.contains("events (40): 20 push, 20 topple ... and 7 later events, not kept\n"),
            "{s}"
        );
        assert!(s.contains("the grasps, releases and topples (20):"), "{s}");
        assert!(s.contains("... and 8 more; every event: --events"), "{s}");
        assert!(s.lines().count() < 25, "{s}");
        let all = summary(
            &text,
            Some(&json),
            WorldPrint {
                blocks: true,
                events: true,
            },
        );
        assert!(all.contains("  b5    resting"), "{all}");
        assert!(all.contains("  step      0  push     b0"), "{all}");
    }

    #[test]
    fn without_its_json_the_outcome_is_printed_whole() {
        let s = summary(SMALL, None, WorldPrint::default());
        assert!(s.contains("impact   red"), "{s}");
    }
}
