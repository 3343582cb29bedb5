//! `handblocks bench shared`: a shared world (issue 45) under a bad network. A host and two
//! participants (the scripted hand, and a real Quest recording looped) on this machine, each
//! participant behind its own [`crate::netem::UdpProxy`] (zenoh's TLS link is QUIC over UDP:
//! the proxy's loss is real packet loss), at several one-way delays and loss rates.
//!
//! Per condition and participant: its hand -> world (its own hand's origin, on its clock, to
//! the host's world whose frame held it, taken in: `bridge.shared.hand_to_world_us`), and the
//! latency it adds over the injected round trip; world-hash divergences from the host's
//! recording (0 asked); worlds lost (resyncs: a world missed is caught up by the next, which is
//! the whole state); hands lost or refused; what the participant costs the host (bytes a
//! second each way, the host bridge's CPU). The peer of every latency is the same run's
//! injected round trip (2 x the delay): no other figure is compared across conditions.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use serde_json::{json, Value};

use crate::netem::{Impairment, UdpProxy};
use crate::page::{self, Provenance};
use crate::plot::{Axis, Figure, Join, Panel, Series};

/// What to run.
#[derive(Debug, Clone)]
pub struct SharedBench {
    /// The handblocks binary (this one).
    pub exe: PathBuf,
    /// The repository (the session files).
    pub repo: PathBuf,
    pub out_dir: PathBuf,
    /// A CARL recording for the second participant's hand (the scripted hand when missing).
    pub carl: PathBuf,
    pub seconds: f64,
    pub quick: bool,
}

/// The conditions: one-way delay (ms) and loss (%), each way.
pub const CONDITIONS: [(u64, f64); 5] = [(0, 0.0), (20, 1.0), (50, 1.0), (100, 1.0), (100, 5.0)];
const QUICK_CONDITIONS: [(u64, f64); 2] = [(0, 0.0), (20, 1.0)];

/// One participant's figures in one condition.
#[derive(Debug, Clone)]
struct Row {
    delay_ms: u64,
    loss_pct: f64,
    participant: String,
    p50_ms: f64,
    p99_ms: f64,
    worlds: u64,
    divergent: u64,
    worlds_lost: u64,
    /// Worlds the host did not send it (its link behind).
    worlds_held_back: u64,
    hands_sent: u64,
    hands_taken: u64,
    hands_lost: u64,
    hands_refused: u64,
    /// Superseded by a newer hand while the link was behind (the host counts them lost).
    hands_held_back: u64,
    /// Sent and neither taken, lost nor refused when the host ended: still in the link.
    hands_in_flight: u64,
    /// What it sent: hands, bytes a second.
    sent_kb_s: f64,
    world_kb_s: f64,
    hand_kb_s: f64,
    /// The other participants' hands the host sent it, KB/s, and how many it took in.
    peer_kb_s: f64,
    peer_hands_taken: u64,
}

/// The host's cost in one condition.
#[derive(Debug, Clone)]
struct HostRow {
    delay_ms: u64,
    loss_pct: f64,
    bridge_cpu_s: f64,
    stepper_cpu_s: f64,
    seconds: f64,
    participants: usize,
    frames: u64,
}

fn report(path: &Path) -> Result<Value, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// Each recorded world's step and hash.
fn world_hashes(file: &Path) -> Result<BTreeMap<u64, u64>, String> {
    let rec = recording::Recording::open_topics(file, &[common::Topic::World])
        .map_err(|e| format!("{}: {e}", file.display()))?;
    Ok(rec
        .worlds()
        .map(|w| {
            (
                w.header.step,
                common::world_hash::world_hash(&w.header, &w.blocks),
            )
        })
        .collect())
}

/// Runs one condition; its rows and the host's.
fn condition(
    b: &SharedBench,
    delay_ms: u64,
    loss_pct: f64,
    scratch: &Path,
) -> Result<(Vec<Row>, HostRow), String> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| format!("no free port: {e}"))?;
    let keys = scratch.join("keys");
    let token = "bench-shared-token-0123456789";
    let key = format!("handblocks/bench-{port}");
    let id = |who: &str| format!("bsh{}{who}{port}", std::process::id());
    let launch = |session: &str, who: &str, seconds: f64, sets: &[String]| {
        let mut c = Command::new(&b.exe);
        c.current_dir(&b.repo)
            .args(["launch", "--quiet", "--force", "--no-preview"])
            .args(["--duration", &seconds.to_string(), "--bus-id", &id(who)])
            .arg("--report")
            .arg(scratch.join(format!("{who}.json")))
            .arg("--record")
            .arg(scratch.join(format!("{who}.mcap")))
            .args(["--set", "renderer.mode=off"])
            .args(["--set", &format!("shared.key_dir={}", keys.display())])
            .args(["--set", &format!("shared.token={token}")])
            .args(["--set", &format!("shared.key={key}")]);
        for s in sets {
            c.args(["--set", s]);
        }
        c.arg(b.repo.join("config/sessions").join(session))
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", b.exe.display()))
    };
    let impairment = Impairment {
        delay: Duration::from_millis(delay_ms),
        loss: loss_pct / 100.0,
    };
    let target = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let proxies: Vec<UdpProxy> = (0..2)
        .map(|k| UdpProxy::start(target, impairment, 1 + k))
        .collect::<Result<_, _>>()
        .map_err(|e| format!("cannot start a proxy: {e}"))?;
    let host = launch(
        "shared-host.toml",
        "host",
        b.seconds + 4.0,
        &[format!("shared.listen=tls/127.0.0.1:{port}")],
    )?;
    let mut people = vec![("alice", Vec::new())];
    let bob: Vec<String> = if b.carl.exists() {
        vec![
            "source.kind=replay".into(),
            format!("source.file={}", b.carl.display()),
            "source.offset=[0.0, -0.92, 0.0]".into(),
            "source.loop=true".into(),
        ]
    } else {
        Vec::new()
    };
    people.push(("bob", bob));
    let mut joined = Vec::new();
    for ((name, extra), proxy) in people.iter().zip(&proxies) {
        let mut sets = vec![
            format!("shared.host=tls/127.0.0.1:{}", proxy.port),
            format!("shared.name={name}"),
        ];
        sets.extend(extra.iter().cloned());
        joined.push((*name, launch("shared-join.toml", name, b.seconds, &sets)?));
    }
    for (name, child) in joined {
        let out = child
            .wait_with_output()
            .map_err(|e| format!("{name}: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "{name} failed:\n{}",
                String::from_utf8_lossy(&out.stderr)
            ));
        }
    }
    let out = host.wait_with_output().map_err(|e| format!("host: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "the host failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let host = report(&scratch.join("host.json"))?;
    let shared = &host["bridge"]["shared"];
    let host_worlds = world_hashes(&scratch.join("host.mcap"))?;
    let mut rows = Vec::new();
    for (name, _) in &people {
        let theirs = report(&scratch.join(format!("{name}.json")))?;
        let theirs = &theirs["bridge"]["shared"];
        let ours = shared["participants"]
            .as_array()
            .and_then(|a| a.iter().find(|p| p["name"] == *name))
            .cloned()
            .unwrap_or_default();
        let worlds = world_hashes(&scratch.join(format!("{name}.mcap")))?;
        let divergent = worlds
            .iter()
            .filter(|(step, hash)| host_worlds.get(step) != Some(hash))
            .count() as u64;
        let u = |v: &Value| v.as_u64().unwrap_or(0);
        let ms = |v: &Value| v.as_f64().map_or(f64::NAN, |us| us / 1e3);
        let hands_refused: u64 = ours["refused"]
            .as_object()
            .map_or(0, |m| m.values().filter_map(Value::as_u64).sum());
        let accounted = u(&ours["hands_taken"]) + u(&ours["hands_lost"]) + hands_refused;
        rows.push(Row {
            delay_ms,
            loss_pct,
            participant: name.to_string(),
            p50_ms: ms(&theirs["hand_to_world_us"]["p50"]),
            p99_ms: ms(&theirs["hand_to_world_us"]["p99"]),
            worlds: worlds.len() as u64,
            divergent,
            worlds_lost: u(&theirs["worlds_lost"]),
            worlds_held_back: u(&ours["worlds_held_back"]),
            hands_sent: u(&theirs["hands_sent"]),
            hands_taken: u(&ours["hands_taken"]),
            hands_lost: u(&ours["hands_lost"]),
            hands_refused,
            hands_held_back: u(&theirs["hands_held_back"]),
            hands_in_flight: (u(&theirs["hands_sent"]) + u(&theirs["hands_held_back"]))
                .saturating_sub(accounted),
            sent_kb_s: theirs["hand_bytes_out_per_s"].as_f64().unwrap_or(0.0) / 1e3,
            world_kb_s: shared["world_bytes_out_per_s_per_participant"]
                .as_f64()
                .unwrap_or(0.0)
                / 1e3,
            hand_kb_s: ours["bytes_in_per_s"].as_f64().unwrap_or(0.0) / 1e3,
            peer_kb_s: ours["peer_bytes_out_per_s"].as_f64().unwrap_or(0.0) / 1e3,
            peer_hands_taken: u(&theirs["peer_hands_taken"]),
        });
    }
    let cpu = |stage: &str| host["stages"][stage]["cpu_s"].as_f64().unwrap_or(f64::NAN);
    let host_row = HostRow {
        delay_ms,
        loss_pct,
        bridge_cpu_s: cpu("bridge"),
        stepper_cpu_s: cpu("stepper"),
        seconds: host["session"]["seconds"].as_f64().unwrap_or(f64::NAN),
        participants: people.len(),
        frames: shared["frames"].as_u64().unwrap_or(0),
    };
    Ok((rows, host_row))
}

/// The Mathis et al. (1997) bound of a loss-based congestion control's rate, KB/s: MSS / RTT
/// x sqrt(3/2) / sqrt(p), with QUIC's 1200-byte datagram and the injected round trip (no bound
/// without loss or delay: infinite).
fn mathis_kb_s(delay_ms: u64, loss_pct: f64) -> f64 {
    let rtt_s = 2.0 * delay_ms as f64 / 1e3;
    let p = loss_pct / 100.0;
    if rtt_s <= 0.0 || p <= 0.0 {
        return f64::INFINITY;
    }
    1200.0 / rtt_s * (1.5f64).sqrt() / p.sqrt() / 1e3
}

/// Runs every condition and writes shared.json, shared.md and shared.png into `out_dir`.
pub fn run(b: &SharedBench) -> Result<Value, Box<dyn std::error::Error>> {
    std::fs::create_dir_all(&b.out_dir)?;
    let conditions: &[(u64, f64)] = if b.quick {
        &QUICK_CONDITIONS
    } else {
        &CONDITIONS
    };
    let mut rows = Vec::new();
    let mut hosts = Vec::new();
    let mut failed: Vec<(u64, f64, String)> = Vec::new();
    for (i, &(delay, loss)) in conditions.iter().enumerate() {
        eprintln!(
            "bench shared: {}/{}: {delay} ms each way, {loss} % loss, {} s",
            i + 1,
            conditions.len(),
            b.seconds
        );
        let scratch = std::env::temp_dir().join(format!(
            "hb-bench-shared-{}-{delay}-{loss}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&scratch);
        std::fs::create_dir_all(&scratch)?;
        let result = condition(b, delay, loss, &scratch);
        let _ = std::fs::remove_dir_all(&scratch);
        match result {
            Ok((r, h)) => {
                rows.extend(r);
                hosts.push(h);
            }
            // A condition whose session failed (a join that took longer than the launcher
            // waits for its processes, on a slow lossy link) is named on the page; the others
            // stand.
            Err(e) => {
                let first = e
                    .lines()
                    .find(|l| l.starts_with("handblocks:"))
                    .unwrap_or("");
                let why = format!("{} {first}", e.lines().next().unwrap_or(""))
                    .trim()
                    .to_string();
                eprintln!("bench shared: {delay} ms, {loss} %: failed: {why}");
                failed.push((delay, loss, why));
            }
        }
    }
    let provenance = Provenance::of_this_run(b.quick, &b.out_dir);
    let value = json!({
        "what": "a shared world: a host and two participants on this machine, each \
                 participant behind a UDP proxy adding the delay each way and dropping the \
                 share of datagrams (zenoh's TLS link on QUIC)",
        "peer": "the injected round trip (2 x the one-way delay): added_ms = p50 - it",
        "seconds": b.seconds,
        "rows": rows.iter().map(|r| json!({
            "delay_ms_each_way": r.delay_ms,
            "loss_pct": r.loss_pct,
            "participant": r.participant,
            "hand_to_world_p50_ms": page::num(r.p50_ms),
            "hand_to_world_p99_ms": page::num(r.p99_ms),
            "added_over_round_trip_p50_ms": page::num(r.p50_ms - 2.0 * r.delay_ms as f64),
            "worlds": r.worlds,
            "divergent_worlds": r.divergent,
            "worlds_lost": r.worlds_lost,
            "worlds_held_back_by_the_host": r.worlds_held_back,
            "hands_sent": r.hands_sent,
            "hands_taken": r.hands_taken,
            "hands_lost": r.hands_lost,
            "hands_refused": r.hands_refused,
            "hands_held_back": r.hands_held_back,
            "hands_in_flight_at_the_end": r.hands_in_flight,
            "its_hand_kb_per_s_sent": page::num(r.sent_kb_s),
            "reliable_link_bound_kb_per_s": page::num(mathis_kb_s(r.delay_ms, r.loss_pct)),
            "host_world_kb_per_s_to_it": page::num(r.world_kb_s),
            "its_hand_kb_per_s_to_host": page::num(r.hand_kb_s),
            "others_hands_kb_per_s_to_it": page::num(r.peer_kb_s),
            "others_hands_taken": r.peer_hands_taken,
        })).collect::<Vec<_>>(),
        "failed": failed.iter().map(|(d, l, why)| json!({
            "delay_ms_each_way": d, "loss_pct": l, "why": why,
        })).collect::<Vec<_>>(),
        "host": hosts.iter().map(|h| json!({
            "delay_ms_each_way": h.delay_ms,
            "loss_pct": h.loss_pct,
            "participants": h.participants,
            "frames": h.frames,
            "seconds": page::num(h.seconds),
            "bridge_cpu_s_per_s_per_participant": page::num(h.bridge_cpu_s / h.seconds / h.participants as f64),
            "stepper_cpu_s_per_s": page::num(h.stepper_cpu_s / h.seconds),
        })).collect::<Vec<_>>(),
    });
    std::fs::write(
        b.out_dir.join("shared.json"),
        serde_json::to_string_pretty(&value)?,
    )?;
    let mut md = page::head(
        "A shared world under a bad network",
        "A host and two participants (the scripted hand; a real Quest recording, looped) on \
         this machine, each participant behind its own UDP proxy that adds the one-way delay \
         each way and drops the share of datagrams (zenoh's TLS link is QUIC: the loss is real \
         and recovered by retransmission). **hand -> world** is a participant's own hand (its \
         origin, on its clock) to the host's world whose frame held it, taken in; **added** is \
         its p50 less the injected round trip (the peer, measured in the same run). \
         **divergent** counts the worlds a participant recorded that are not the host's world \
         of that step, bit for bit (0 asked). Worlds lost are resyncs: each world is the whole \
         state, so the next one catches up.",
        &provenance,
    );
    md.push_str(&page::figure("hand -> world per condition", "shared.png"));
    md.push_str(
        "| delay each way | loss | participant | hand -> world p50 | p99 | added p50 | worlds | \
         divergent | worlds missed (held back by the host) | hands sent / held back / taken / lost / refused / in flight at \
         the end | \
         world KB/s to it | its hands KB/s sent / taken | others' hands KB/s to it (taken) | \
         reliable-link bound KB/s |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let missed = format!("{} ({})", r.worlds_lost, r.worlds_held_back);
        md.push_str(&format!(
            "| {} ms | {} % | {} | {:.1} ms | {:.1} ms | {:.1} ms | {} | {} | {} | {} / {} / {} \
             / {} / {} / {} | {:.1} | {:.1} / {:.1} | {:.1} ({}) | {} |\n",
            r.delay_ms,
            r.loss_pct,
            r.participant,
            r.p50_ms,
            r.p99_ms,
            r.p50_ms - 2.0 * r.delay_ms as f64,
            r.worlds,
            r.divergent,
            missed,
            r.hands_sent,
            r.hands_held_back,
            r.hands_taken,
            r.hands_lost,
            r.hands_refused,
            r.hands_in_flight,
            r.world_kb_s,
            r.sent_kb_s,
            r.hand_kb_s,
            r.peer_kb_s,
            r.peer_hands_taken,
            if r.loss_pct > 0.0 {
                format!("{:.0}", mathis_kb_s(r.delay_ms, r.loss_pct))
            } else {
                "-".to_string()
            }
        ));
    }
    for (d, l, why) in &failed {
        md.push_str(&format!(
            "\n**{d} ms each way, {l} % loss: no figures, the session failed:** {why}\n"
        ));
    }
    md.push_str(
        "\n**Reading it.** zenoh's link is reliable (QUIC streams, congestion-controlled): a \
         loss is resent, and after a loss the sender slows. The most a loss-based congestion \
         control carries over a round trip RTT at loss p is about MSS / RTT x sqrt(3/2) / \
         sqrt(p) (Mathis et al. 1997; MSS 1200 B, QUIC's datagram): the bound column, beside \
         what a participant sends. Where its hands' rate nears or passes the bound, hands queue \
         in the link. A participant therefore sends newest-only: once its oldest unanswered hand \
         is older than three of its quickest turns and 100 ms (its report's send_window_ms), \
         it holds hands back and sends the newest when a world answers (held back: the host \
         counts them lost). The host sends each participant its worlds the same way, on the \
         participant's answers: a world held back is caught up by the next (each world is the \
         whole state); a participant counts the worlds it missed, the host those it held back. Those still \
         in the link when the host ends are the ones in flight.\n",
    );
    md.push_str(
        "\nWhat each participant costs the host (its bridge's CPU over the run, shared out per \
         participant; the stepper's beside it):\n\n| delay each way | loss | host bridge CPU \
         per participant | host stepper CPU | frames |\n|---|---|---|---|---|\n",
    );
    for h in &hosts {
        md.push_str(&format!(
            "| {} ms | {} % | {:.1} % of a core | {:.1} % of a core | {} |\n",
            h.delay_ms,
            h.loss_pct,
            100.0 * h.bridge_cpu_s / h.seconds / h.participants as f64,
            100.0 * h.stepper_cpu_s / h.seconds,
            h.frames
        ));
    }
    std::fs::write(b.out_dir.join("shared.md"), md)?;
    let names: Vec<String> = conditions
        .iter()
        .map(|(d, l)| format!("{d} ms, {l} %"))
        .collect();
    // One point per condition and participant, beside the injected round trip (the peer).
    let panel = |title: &str, p: fn(&Row) -> f64| {
        let of = |who: &str| -> Vec<(f64, f64)> {
            rows.iter()
                .filter(|r| r.participant == who)
                .filter_map(|r| {
                    let i = conditions
                        .iter()
                        .position(|&(d, l)| d == r.delay_ms && l == r.loss_pct)?;
                    Some((i as f64, p(r)))
                })
                .collect()
        };
        Panel {
            title: title.into(),
            x: Axis::categories("delay each way, loss", names.clone()),
            y: Axis::linear("ms"),
            series: vec![
                Series {
                    label: "alice (scripted)".into(),
                    points: of("alice"),
                },
                Series {
                    label: "bob (Quest recording)".into(),
                    points: of("bob"),
                },
                Series {
                    label: "injected round trip".into(),
                    points: conditions
                        .iter()
                        .enumerate()
                        .map(|(i, (d, _))| (i as f64, 2.0 * *d as f64))
                        .collect(),
                },
            ],
            marked: Vec::new(),
            join: Join::Settings,
        }
    };
    let p50 = panel("hand -> world p50", |r| r.p50_ms);
    let p99 = panel("hand -> world p99", |r| r.p99_ms);
    Figure {
        panels: vec![p50, p99],
        columns: 2,
        panel_width: 520,
        panel_height: 380,
        column_weights: Vec::new(),
    }
    .write_png(&b.out_dir.join("shared.png"))?;
    eprintln!(
        "bench shared: wrote {}",
        b.out_dir.join("shared.{json,md,png}").display()
    );
    Ok(value)
}
