//! `handblocks inspect RECORDING`: a recording's topics, as text or `--json` (or a line per
//! sample: `--samples TOPIC`, `--world-hashes`). The figures are
//! [`Recording::summary`]'s; this module only lays them out.

use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, UNIX_EPOCH};

use recording::{Recording, RecordingError, SegmentChain};

use crate::cli::InspectLines;

/// `inspect FILE --samples TOPIC` or `inspect FILE --world-hashes`: a line per sample instead
/// of the table.
pub fn samples(path: &Path, lines: &InspectLines) -> Result<ExitCode, RecordingError> {
    match (&lines.samples, lines.world_hashes) {
        (Some(topic), _) => topic_samples(path, topic),
        (None, true) => world_hashes(path),
        (None, false) => run(path, false),
    }
}

/// `inspect FILE --world-hashes`: `STEP HASH` for each world sample, in file order, and
/// nothing else on stdout, so that two participants' recordings of one shared session can be
/// `diff`ed (HASH: [`common::world_hash`], 16 lowercase hex digits). A file without worlds is
/// refused (exit 2), naming it; a damaged one lists the worlds before the damage (exit 1).
pub fn world_hashes(path: &Path) -> Result<ExitCode, RecordingError> {
    use common::Topic;
    use std::io::Write as _;
    let rec = Recording::open_topics(path, &[Topic::World])?;
    if !rec.messages.iter().any(|m| m.topic == Topic::World) {
        let stats = rec.stats();
        let held: Vec<String> = Topic::RECORDED
            .iter()
            .filter(|t| stats[**t as usize].messages > 0)
            .map(|t| format!("{} {}", t.name(), stats[*t as usize].messages))
            .collect();
        let holds = if held.is_empty() {
            "no samples of any topic".to_string()
        } else {
            format!("samples of {} only", held.join(", "))
        };
        let why = match (&rec.damage, rec.refused_messages) {
            (Some(d), _) => format!(" (read up to the damage: {d})"),
            (None, n) if n > 0 => format!(
                " ({n} messages were skipped: their counts do not fit their arrays, the first {})",
                rec.first_refused.as_deref().unwrap_or("")
            ),
            _ => String::new(),
        };
        eprintln!(
            "handblocks inspect: {}: holds no world samples, so it has no world hashes: it holds \
             {holds}{why}; --world-hashes reads a recording of a session's `world` topic \
             (`handblocks launch --record FILE`)",
            path.display()
        );
        return Ok(ExitCode::from(2));
    }
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let written = rec
        .messages
        .iter()
        .filter_map(|m| rec.world(m))
        .try_for_each(|w| {
            let hash = common::world_hash::of_view(&w.view());
            writeln!(out, "{} {hash:016x}", w.step)
        })
        .and_then(|()| out.flush());
    if let Err(e) = written {
        eprintln!("handblocks inspect: writing the world hashes: {e}");
        return Ok(ExitCode::from(1));
    }
    // What a line-by-line comparison would silently miss goes to stderr.
    if rec.refused_messages > 0 {
        eprintln!(
            "handblocks inspect: {} messages were skipped, their worlds not listed: their \
             counts do not fit their arrays (the first {})",
            rec.refused_messages,
            rec.first_refused.as_deref().unwrap_or("")
        );
    }
    let next = common::config::session::recording_segment(path, 1);
    if std::fs::symlink_metadata(&next).is_ok() {
        eprintln!(
            "handblocks inspect: the recorder was restarted and the recording goes on in {} \
             (and any later segments): these are {}'s worlds only",
            next.display(),
            path.display()
        );
    }
    Ok(said_damage(&rec))
}

/// `inspect FILE --samples TOPIC`: every sample of one topic, one JSON object a line, in file
/// order, field by field as the recording's schema names them (what Python's
/// `handblocks.Recording` arrays hold, from the reader every tool here uses).
fn topic_samples(path: &Path, topic: &str) -> Result<ExitCode, RecordingError> {
    use common::samples::{
        FrameSample, GloveSample, HandSample, JointsSample, PeerHandSample, TrackerSample,
    };
    use common::Topic;
    let Some(topic) = Topic::from_channel(topic).filter(|t| t.is_recorded()) else {
        eprintln!(
            "handblocks inspect: {topic:?} is not a topic; one of: {}",
            Topic::RECORDED.map(|t| t.name()).join(", ")
        );
        return Ok(ExitCode::from(2));
    };
    let rec = Recording::open_topics(path, &[topic])?;
    let mut message = Vec::new();
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for m in rec.messages.iter().filter(|m| m.topic == topic) {
        message.clear();
        match topic {
            Topic::World => {
                let Some(w) = rec.world(m) else { continue };
                recording::encode_slice(Topic::World, &w.header, &w.blocks, &mut message);
            }
            Topic::Glove => encode(rec.sample::<GloveSample>(m), &mut message),
            Topic::Tracker => encode(rec.sample::<TrackerSample>(m), &mut message),
            Topic::Joints => encode(rec.sample::<JointsSample>(m), &mut message),
            Topic::Hand => encode(rec.sample::<HandSample>(m), &mut message),
            Topic::Frame => encode(rec.sample::<FrameSample>(m), &mut message),
            Topic::PeerHand => encode(rec.sample::<PeerHandSample>(m), &mut message),
            Topic::Latency => continue,
        }
        use std::io::Write as _;
        if writeln!(out, "{}", crate::monitor::to_json(topic, &message)).is_err() {
            break;
        }
    }
    Ok(said_damage(&rec))
}

/// Says the recording's damage, if any: exit 0 for a complete, undamaged file, else 1.
fn said_damage(rec: &Recording) -> ExitCode {
    if let Some(d) = &rec.damage {
        eprintln!("handblocks inspect: damage: {d}");
    }
    if rec.complete && rec.damage.is_none() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    }
}

fn encode<T: common::bus::Stamped>(sample: Option<T>, out: &mut Vec<u8>) {
    if let Some(s) = sample {
        recording::encode_sample(&s, out);
    }
}

/// The most segments `inspect` follows (a recorder restarted this often is a broken setup).
const MAX_SEGMENTS: u32 = 1000;

/// Lists the recording; 0 when it is intact, 1 when it is damaged (what could be read is
/// listed), an error when it cannot be read at all.
/// Why `path` is plainly not a recording to inspect, with what to do instead: None when it may
/// be one (the reader then says what is wrong inside it).
pub fn refuse(path: &Path) -> Option<String> {
    if std::fs::symlink_metadata(path).is_err() {
        return Some(format!(
            "{}: no such file; inspect reads an MCAP recording, which `handblocks launch \
             --record FILE` (or a session's [recorder] file) writes",
            path.display()
        ));
    }
    // Only a regular file is read here: opening a FIFO would block (the reader refuses it).
    if !path.is_file() {
        return None;
    }
    let mut head = [0u8; 4];
    let n = std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
        .ok()?;
    (&head[..n] == b"CARL").then(|| {
        format!(
            "{}: a CARL trace, not an MCAP recording: `handblocks replay {0}` plays it, and \
             Python's `handblocks.Recording(\"{0}\")` reads its joints as arrays",
            path.display()
        )
    })
}

pub fn run(path: &Path, json: bool) -> Result<ExitCode, RecordingError> {
    // Counts and gaps come from every message; no sample needs to stay in memory.
    // A session whose recorder was restarted went on in NAME.1.mcap, ...: what no segment
    // holds between them is the restarts' loss (issue 28).
    let has_segments =
        std::fs::symlink_metadata(common::config::session::recording_segment(path, 1)).is_ok();
    let (summary, chain) = if has_segments {
        let chain = SegmentChain::open(path, MAX_SEGMENTS)?;
        (chain.summaries[0].clone(), Some(chain))
    } else {
        (Recording::open_topics(path, &[])?.summary(), None)
    };
    let file_bytes = std::fs::metadata(path).map_or(0, |m| m.len());
    let utc = |ns: u64| launcher::report::rfc3339(UNIX_EPOCH + Duration::from_nanos(ns));
    let (start, end) = match summary.span_unix_ns {
        Some((a, b)) => (Some(utc(a)), Some(utc(b))),
        None => (None, None),
    };
    let hands = hands_by_participant(path);
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
        let segments: Option<Vec<serde_json::Value>> = chain.as_ref().map(|c| {
            c.files
                .iter()
                .zip(&c.summaries)
                .enumerate()
                .map(|(k, (f, s))| {
                    let missing: serde_json::Map<String, serde_json::Value> = k
                        .checked_sub(1)
                        .and_then(|j| c.gaps.get(j))
                        .into_iter()
                        .flatten()
                        .map(|g| {
                            (
                                g.topic.name().to_string(),
                                serde_json::json!({"lost": g.lost(), "from_seq": g.from_seq, "next_seq": g.next_seq}),
                            )
                        })
                        .collect();
                    serde_json::json!({
                        "file": f.display().to_string(),
                        "messages": s.messages,
                        "complete": s.complete,
                        "missing_before": missing,
                    })
                })
                .collect()
        });
        println!(
            "{}",
            serde_json::json!({
                "segments": segments,
                "file": path.display().to_string(),
                "bytes": file_bytes,
                "start": start,
                "end": end,
                "session": summary.session,
                "scene": summary.scene,
                "complete": summary.complete,
                "damage": summary.damage,
                "foreign_messages": summary.foreign_messages,
                "scene_messages": summary.scene_messages,
                "transform_messages": summary.transform_messages,
                "refused_messages": summary.refused_messages,
                "first_refused": summary.first_refused,
                "topics": topics,
                "hands_by_participant": hands.as_ref().map(|h| {
                    h.by.iter()
                        .map(|((k, side), n)| serde_json::json!({
                            "participant": k,
                            "side": side,
                            "hands": n,
                            "own": h.own == Some(*k),
                        }))
                        .collect::<Vec<_>>()
                }),
                "recorded_by_participant": hands.as_ref().and_then(|h| h.own),
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
        if let Some(h) = &hands {
            let people: Vec<String> =
                h.by.iter()
                    .map(|((k, side), n)| format!("participant {k} {side} {n}"))
                    .collect();
            let whose = match h.own {
                Some(k) => format!(
                    "participant {k}'s recording: its own on hand, the others' on peer_hand"
                ),
                None => "the host's recording".to_string(),
            };
            println!(
                "hands by participant (a shared world's, {whose}): {}",
                people.join(", ")
            );
        }
        if summary.scene_messages > 0 {
            println!(
                "{:<8} {:>9}  the scene view for Foxglove's 3D panel (foxglove.SceneUpdate, \
                 drawn from the world and hand above)",
                recording::SCENE_CHANNEL,
                summary.scene_messages
            );
        }
        if summary.transform_messages > 0 {
            println!(
                "{:<8} {:>9}  the hand's joints as a frame tree for Foxglove's 3D panel \
                 (foxglove.FrameTransforms, docs/foxglove.md)",
                recording::TF_CHANNEL,
                summary.transform_messages
            );
        }
        if summary.foreign_messages > 0 {
            println!(
                "{} messages on channels of other tools were skipped",
                summary.foreign_messages
            );
        }
        if summary.refused_messages > 0 {
            println!(
                "{} messages were skipped: their counts do not fit their arrays (the first {})",
                summary.refused_messages,
                summary.first_refused.as_deref().unwrap_or("")
            );
        }
        if let Some(d) = &summary.damage {
            println!("damage: {d}");
        }
        if let Some(c) = &chain {
            print_segments(c);
        }
    }
    Ok(if summary.complete {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// The segments after the file, and what no segment holds between each two.
fn print_segments(chain: &SegmentChain) {
    println!(
        "\nthe recorder was restarted; the recording goes on in {} more segment(s):",
        chain.files.len() - 1
    );
    for (k, (f, s)) in chain.files.iter().zip(&chain.summaries).enumerate().skip(1) {
        let missing = chain.gaps.get(k - 1).map_or(String::new(), |gaps| {
            if gaps.is_empty() {
                "none missing before it".to_string()
            } else {
                let each: Vec<String> = gaps
                    .iter()
                    .map(|g| {
                        format!(
                            "{} {} (seq {} to {})",
                            g.topic.name(),
                            g.lost(),
                            g.from_seq,
                            g.next_seq - 1
                        )
                    })
                    .collect();
                format!("in no segment before it: {}", each.join(", "))
            }
        });
        println!(
            "  {}: {} messages, {}; {missing}",
            f.display(),
            s.messages,
            if s.complete { "complete" } else { "damaged" },
        );
    }
    println!(
        "(counted from the seqs: the dead recorder's unwritten chunk, at most [recorder] \
         flush_ms of samples, and those published while none ran)"
    );
}

/// A shared world's recording: its hands by participant and side (`HandSample::participant`),
/// and whose recording it is. A host's holds every participant's on `hand` (None: the host's
/// own). A participant's holds its own on `hand` (participant 0 on its own bus, counted here
/// under the number the host gave it, `PeerHandSample::own_participant`) and the others' on
/// `peer_hand`. None for any other recording (every hand participant 0's) or one without hands.
fn hands_by_participant(path: &Path) -> Option<HandsByParticipant> {
    use common::{HandSample, HandSide, PeerHandSample, Topic};
    let rec = Recording::open_topics(path, &[Topic::Hand, Topic::PeerHand]).ok()?;
    let mut peers = rec.samples::<PeerHandSample>(Topic::PeerHand).peekable();
    let own = peers.peek().map(|p| p.own_participant);
    let mut by = std::collections::BTreeMap::new();
    for h in rec.samples::<HandSample>(Topic::Hand) {
        let participant = own.unwrap_or(h.participant);
        *by.entry((participant, HandSide::from_code(h.side).name()))
            .or_insert(0u64) += 1;
    }
    for p in peers {
        *by.entry((p.hand.participant, HandSide::from_code(p.hand.side).name()))
            .or_insert(0u64) += 1;
    }
    (own.is_some() || by.keys().any(|(k, _)| *k > 0)).then_some(HandsByParticipant { own, by })
}

/// What [`hands_by_participant`] found.
struct HandsByParticipant {
    /// A participant's recording: its number (None: the host's).
    own: Option<u32>,
    by: std::collections::BTreeMap<(u32, &'static str), u64>,
}
