//! Issue 45: several people, each with their own source of hands, in one block world. A host
//! session (config/sessions/shared-host.toml) and participants (shared-join.toml), each a whole
//! `handblocks launch` with its own bus, over zenoh on loopback: every world a participant
//! records is one the host stepped, bit for bit (`inspect --world-hashes`), every hand it sent
//! is accounted for, a late joiner is in step within a second, a participant with a wrong
//! token is refused and counted by name while the others go on, each participant records the
//! others' hands, and the host's recording replays (offline and live) to the same worlds.

mod support;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use serde_json::Value;
use support::{assert_nothing_left, both, carl_example, free_port, repo, Scratch, EXE};

const TOKEN: &str = "shared-test-token-0123456789";

/// The tests here each run four or five sessions at once: one at a time on a 2-core machine.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn launch(session: &str, id: &str, seconds: f64, scratch: &Scratch, sets: &[String]) -> Child {
    let mut c = Command::new(EXE);
    c.current_dir(repo())
        .args(["launch", "--quiet", "--force", "--no-preview"])
        .args(["--duration", &seconds.to_string()])
        .args(["--bus-id", id, "--report"])
        .arg(scratch.path(&format!("{id}.json")))
        .arg("--record")
        .arg(scratch.path(&format!("{id}.mcap")))
        .args(["--set", "renderer.mode=off"]);
    for s in sets {
        c.args(["--set", s]);
    }
    c.arg(repo().join("config/sessions").join(session))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run handblocks")
}

fn link_sets(endpoint_key: &str, port: u16, token: &str) -> Vec<String> {
    vec![
        format!("shared.{endpoint_key}=tcp/127.0.0.1:{port}"),
        "shared.allow_plain=true".into(),
        format!("shared.token={token}"),
        format!("shared.key=handblocks/test-{port}"),
    ]
}

fn finish(child: Child, id: &str) -> Output {
    let out = child.wait_with_output().expect("wait for handblocks");
    assert_nothing_left(id);
    out
}

fn report(scratch: &Scratch, id: &str) -> Value {
    let path = scratch.path(&format!("{id}.json"));
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap_or_default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// `inspect FILE --world-hashes`, as (step, hash) lines in order.
fn world_hashes(file: &Path) -> Vec<(u64, String)> {
    let out = Command::new(EXE)
        .arg("inspect")
        .arg(file)
        .arg("--world-hashes")
        .output()
        .expect("run inspect");
    assert!(out.status.success(), "{}", both(&out));
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| {
            let (step, hash) = l.split_once(' ').expect("STEP HASH");
            (step.parse().expect("a step"), hash.to_string())
        })
        .collect()
}

#[test]
fn three_participants_share_one_world_bit_for_bit_and_a_late_joiner_is_in_step_within_a_second() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let scratch = Scratch::new("shared");
    let port = free_port();
    let tag = std::process::id();
    let (host_id, alice_id, bob_id, carol_id, eve_id) = (
        format!("shh{tag}"),
        format!("sha{tag}"),
        format!("shb{tag}"),
        format!("shc{tag}"),
        format!("she{tag}"),
    );
    let host = launch(
        "shared-host.toml",
        &host_id,
        16.0,
        &scratch,
        &link_sets("listen", port, TOKEN),
    );
    let join = |id: &str, name: &str, seconds: f64, token: &str, extra: &[String]| {
        let mut sets = link_sets("host", port, token);
        sets.push(format!("shared.name={name}"));
        sets.extend_from_slice(extra);
        launch("shared-join.toml", id, seconds, &scratch, &sets)
    };
    // Alice: the scene's scripted hand. Bob: a real Quest recording, looped. Carol joins late.
    let alice = join(&alice_id, "alice", 11.0, TOKEN, &[]);
    let bob_source = carl_source();
    let bob = join(&bob_id, "bob", 11.0, TOKEN, &bob_source);
    std::thread::sleep(Duration::from_secs(4));
    let carol = join(&carol_id, "carol", 6.0, TOKEN, &[]);
    // Eve has the wrong token: refused by name, and nobody else notices.
    let eve = join(&eve_id, "eve", 6.0, "not-the-token-0123456789", &[]);
    let eve = finish(eve, &eve_id);
    assert!(
        !eve.status.success(),
        "a wrong token joined:\n{}",
        both(&eve)
    );
    assert!(both(&eve).contains("wrong token"), "{}", both(&eve));
    finish_all([
        ("alice", alice, &alice_id),
        ("bob", bob, &bob_id),
        ("carol", carol, &carol_id),
        ("host", host, &host_id),
    ]);

    // The host names every participant, and accounts for every hand each sent.
    let host = report(&scratch, &host_id);
    let shared = &host["bridge"]["shared"];
    let people = shared["participants"].as_array().expect("participants");
    let by_name = |name: &str| {
        people
            .iter()
            .find(|p| p["name"] == name)
            .unwrap_or_else(|| panic!("{name} not in the host's report: {shared}"))
    };
    assert!(
        shared["refused"]["a join with a wrong token"].as_u64() >= Some(1),
        "{shared}"
    );
    for (name, id) in [("alice", &alice_id), ("bob", &bob_id), ("carol", &carol_id)] {
        let theirs = &report(&scratch, id)["bridge"]["shared"];
        let ours = by_name(name);
        assert_every_hand_accounted_for(name, ours, theirs);
        assert!(
            theirs["hands_sent"].as_u64() > Some(100),
            "{name}: {theirs}"
        );
        assert!(
            theirs["hand_to_world_us"]["count"].as_u64() > Some(50),
            "{name}: {theirs}"
        );
    }
    let carol = &report(&scratch, &carol_id)["bridge"]["shared"];
    let in_step = carol["first_world_after_join_s"].as_f64().expect("a world");
    assert!(
        in_step < 1.0,
        "carol's first world {in_step} s after joining"
    );

    // Every world a participant recorded is the host's world of that step, bit for bit.
    let host_worlds: BTreeMap<u64, String> =
        world_hashes(&scratch.path(&format!("{host_id}.mcap")))
            .into_iter()
            .collect();
    for (name, id) in [("alice", &alice_id), ("bob", &bob_id), ("carol", &carol_id)] {
        let theirs = world_hashes(&scratch.path(&format!("{id}.mcap")));
        assert!(theirs.len() > 300, "{name}: {} worlds", theirs.len());
        let divergent = theirs
            .iter()
            .filter(|(step, hash)| host_worlds.get(step) != Some(hash))
            .count();
        assert_eq!(divergent, 0, "{name}: worlds not the host's");
    }

    // `inspect` lists every participant's hands in the host's recording.
    let listed = Command::new(EXE)
        .arg("inspect")
        .arg(scratch.path(&format!("{host_id}.mcap")))
        .output()
        .expect("run inspect");
    let listed = both(&listed);
    for k in 0..3 {
        assert!(
            listed.contains(&format!("participant {k} right")),
            "{listed}"
        );
    }

    // Each participant sees the others: its bridge took their hands from the host and its
    // recording holds them (`peer_hand`) beside its own, each under the host's number.
    let numbers: Vec<u64> = [&alice_id, &bob_id, &carol_id]
        .iter()
        .map(|id| {
            report(&scratch, id)["bridge"]["shared"]["participant"]
                .as_u64()
                .expect("a participant number")
        })
        .collect();
    for (k, (name, id)) in [("alice", &alice_id), ("bob", &bob_id), ("carol", &carol_id)]
        .into_iter()
        .enumerate()
    {
        let theirs = &report(&scratch, id)["bridge"]["shared"];
        assert!(
            theirs["peer_hands_taken"].as_u64() > Some(50),
            "{name}: {theirs}"
        );
        assert_eq!(
            theirs["peer_hands_refused"].as_object().map(|m| m.len()),
            Some(0),
            "{name}: {theirs}"
        );
        let listed = Command::new(EXE)
            .arg("inspect")
            .arg(scratch.path(&format!("{id}.mcap")))
            .output()
            .expect("run inspect");
        let listed = both(&listed);
        assert!(
            listed.contains(&format!("participant {}'s recording", numbers[k])),
            "{name}: {listed}"
        );
        for n in &numbers {
            assert!(
                listed.contains(&format!("participant {n} right")),
                "{name} shows no participant {n}: {listed}"
            );
        }
    }

    // Replayed as one: the host's recording holds every participant's hands as its stepper
    // took them, and `simulate --hand` of it steps the same worlds, step for step.
    let out = Command::new(EXE)
        .current_dir(repo())
        .args([
            "simulate",
            "config/scenes/grasp-throw.toml",
            "--world-hashes",
            "--hand",
        ])
        .arg(scratch.path(&format!("{host_id}.mcap")))
        .output()
        .expect("run simulate");
    assert!(out.status.success(), "{}", both(&out));
    let replayed: BTreeMap<u64, String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_once(' '))
        .map(|(step, hash)| (step.parse().expect("a step"), hash.to_string()))
        .collect();
    let stepped: Vec<_> = host_worlds.keys().filter(|s| **s > 0).collect();
    let differ = stepped
        .iter()
        .filter(|s| replayed.get(s) != host_worlds.get(s))
        .count();
    assert!(stepped.len() > 1000, "{} host steps", stepped.len());
    assert_eq!(
        differ,
        0,
        "of {} steps, {differ} replayed differently",
        stepped.len()
    );

    // And live: `handblocks replay` of the host's recording plays its hands (no source
    // samples in it) straight to a stepper, which steps the same worlds again, every one.
    let replayed_file = scratch.path("replayed.mcap");
    let out = Command::new(EXE)
        .current_dir(repo())
        .args([
            "replay",
            "--speed",
            "0",
            "--force",
            "--no-preview",
            "--record",
        ])
        .arg(&replayed_file)
        .args(["--set", "renderer.mode=off"])
        .arg(scratch.path(&format!("{host_id}.mcap")))
        .output()
        .expect("run replay");
    assert!(out.status.success(), "{}", both(&out));
    // Every world the host recorded, stepped again live (the replay may step one more: the
    // host's last frame, whose world came after its recorder had stopped).
    let live: BTreeMap<u64, String> = world_hashes(&replayed_file).into_iter().collect();
    let differ = host_worlds
        .iter()
        .filter(|(step, hash)| live.get(step) != Some(hash))
        .count();
    assert_eq!(
        differ,
        0,
        "of the host's {} worlds, {differ} not stepped the same live ({} live): {}",
        host_worlds.len(),
        live.len(),
        both(&out)
    );
    assert!(live.len() <= host_worlds.len() + 2, "{} live", live.len());
}

/// Issue 45, item 7: three participants for 60 s, each behind its own proxy adding 20 ms each
/// way and dropping 1 % of datagrams (zenoh's TLS link is QUIC over UDP: real loss, recovered
/// by retransmission); bob's link stalls for 2 s at 20 s and catches up; carol joins at 30 s.
/// No participant's world is ever not the host's; every hand is taken, or lost on the link
/// and counted, or refused by name; the host never waits (its frames keep their rate).
#[test]
fn under_20_ms_and_1_percent_loss_three_participants_for_60_s_never_diverge() {
    use handblocks_bench::netem::{Impairment, UdpProxy};
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let scratch = Scratch::new("shared-netem");
    let keys = scratch.path("keys");
    let port = free_port();
    let tag = std::process::id();
    let (host_id, alice_id, bob_id, carol_id) = (
        format!("snh{tag}"),
        format!("sna{tag}"),
        format!("snb{tag}"),
        format!("snc{tag}"),
    );
    let tls = |endpoint_key: &str, port: u16| {
        vec![
            format!("shared.{endpoint_key}=tls/127.0.0.1:{port}"),
            format!("shared.key_dir={}", keys.display()),
            format!("shared.token={TOKEN}"),
            format!("shared.key=handblocks/netem-{port}"),
        ]
    };
    let bad = Impairment {
        delay: Duration::from_millis(20),
        loss: 0.01,
    };
    let target = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let proxy = |seed| UdpProxy::start(target, bad, seed).expect("a proxy");
    let (pa, pb, pc) = (proxy(1), proxy(2), proxy(3));
    // Dropped only after 16 s of silence: longer than bob's stall as QUIC recovers from it
    // (after a blackout its probe timeout doubles with each unanswered probe, so the 2 s stall
    // has left the link dark for 4.3 s, and once, with a probe lost to the 1 %, for 9.4 s:
    // bob was dropped at 8 s), and than the time between the participants' ends and the host's.
    let mut host_sets = tls("listen", port);
    host_sets.push("shared.drop_after_s=16".into());
    let host = launch("shared-host.toml", &host_id, 62.0, &scratch, &host_sets);
    let join = |id: &str, name: &str, seconds: f64, via: u16, extra: &[String]| {
        let mut sets = tls("host", via);
        sets.push(format!("shared.key=handblocks/netem-{port}"));
        sets.push(format!("shared.name={name}"));
        sets.extend_from_slice(extra);
        launch("shared-join.toml", id, seconds, &scratch, &sets)
    };
    let alice = join(&alice_id, "alice", 58.0, pa.port, &[]);
    let bob_source = carl_source();
    let bob = join(&bob_id, "bob", 58.0, pb.port, &bob_source);
    std::thread::sleep(Duration::from_secs(20));
    pb.pause(Duration::from_secs(2));
    std::thread::sleep(Duration::from_secs(10));
    let carol = join(&carol_id, "carol", 28.0, pc.port, &[]);
    finish_all([
        ("alice", alice, &alice_id),
        ("bob", bob, &bob_id),
        ("carol", carol, &carol_id),
        ("host", host, &host_id),
    ]);
    let host = report(&scratch, &host_id);
    let shared = &host["bridge"]["shared"];
    eprintln!("host: {shared}");
    // The host never waited on anyone: a frame per tick over the whole session but its
    // first participant's start (60 s at 120 Hz less the first seconds).
    let frames = shared["frames"].as_u64().unwrap_or(0);
    assert!(frames > 55 * 120 * 9 / 10, "{frames} frames");
    let people = shared["participants"].as_array().expect("participants");
    let host_worlds: BTreeMap<u64, String> =
        world_hashes(&scratch.path(&format!("{host_id}.mcap")))
            .into_iter()
            .collect();
    for (name, id) in [("alice", &alice_id), ("bob", &bob_id), ("carol", &carol_id)] {
        let theirs = &report(&scratch, id)["bridge"]["shared"];
        eprintln!("{name}: {theirs}");
        let ours = people
            .iter()
            .find(|p| p["name"] == name)
            .unwrap_or_else(|| panic!("{name} not in the host's report: {shared}"));
        assert_every_hand_accounted_for(name, ours, theirs);
        assert_eq!(ours["drops"], 0, "{name} was dropped: {ours}");
        let worlds = world_hashes(&scratch.path(&format!("{id}.mcap")));
        let divergent = worlds
            .iter()
            .filter(|(step, hash)| host_worlds.get(step) != Some(hash))
            .count();
        assert_eq!(divergent, 0, "{name}: {divergent} worlds not the host's");
        assert!(worlds.len() > 1000, "{name}: {} worlds", worlds.len());
    }
    let carol = &report(&scratch, &carol_id)["bridge"]["shared"];
    let in_step = carol["first_world_after_join_s"].as_f64().expect("a world");
    assert!(
        in_step < 1.0,
        "carol's first world {in_step} s after joining"
    );
    // Bob's 2 s stall: the link dropped everything, and he caught up after it. On this one
    // machine every clock is the same monotonic clock: a world's age on bob's bus is its
    // publish there less its origin (bob's own hand that its frame held, else its arrival).
    let (stall_s, catch_up_s, after) = catch_up(&scratch.path(&format!("{bob_id}.mcap")));
    eprintln!(
        "bob: his worlds stopped for {stall_s:.2} s; {catch_up_s:.2} s after they came again \
         they were fresh again (under {FRESH_MS} ms old) and stayed so: {after} worlds to the end"
    );
    assert!(stall_s > 1.5, "bob's stall was not seen: {stall_s} s");
    assert!(
        catch_up_s < 15.0,
        "bob was behind for {catch_up_s} s after his stall"
    );
    assert!(after > 1000, "bob's fresh worlds after the stall: {after}");
    assert!(
        pb.stats()
            .paused_drops
            .load(std::sync::atomic::Ordering::Relaxed)
            > 0
    );
    for p in [&pa, &pb, &pc] {
        eprintln!(
            "proxy: {} forwarded, {} lost, {} dropped while paused",
            p.stats()
                .forwarded
                .load(std::sync::atomic::Ordering::Relaxed),
            p.stats().dropped.load(std::sync::atomic::Ordering::Relaxed),
            p.stats()
                .paused_drops
                .load(std::sync::atomic::Ordering::Relaxed)
        );
    }
}

/// A world older than this on a participant's bus is behind (the 20 ms test's p99 is ~110 ms).
const FRESH_MS: u64 = 250;

/// A participant's recording: the longest pause between two of its worlds (the stall, s), the
/// time from the world after it to the first of the fresh worlds that run to the end (s), and
/// how many those are.
fn catch_up(file: &Path) -> (f64, f64, usize) {
    let rec = recording::Recording::open_topics(file, &[common::Topic::World])
        .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let worlds: Vec<(u64, u64)> = rec
        .worlds()
        .map(|w| {
            let s = w.header.stamp;
            (s.publish_ns, s.publish_ns.saturating_sub(s.origin_ns))
        })
        .collect();
    assert!(
        worlds.len() > 2,
        "{}: {} worlds",
        file.display(),
        worlds.len()
    );
    let (resumed, stall_ns) = (1..worlds.len())
        .map(|i| (i, worlds[i].0.saturating_sub(worlds[i - 1].0)))
        .max_by_key(|&(_, gap)| gap)
        .unwrap_or((0, 0));
    let fresh_from = worlds
        .iter()
        .rposition(|&(_, age)| age > FRESH_MS * 1_000_000)
        .map_or(0, |i| i + 1)
        .max(resumed);
    let caught_up_ns = worlds
        .get(fresh_from)
        .map_or(u64::MAX, |w| w.0.saturating_sub(worlds[resumed].0));
    (
        stall_ns as f64 / 1e9,
        caught_up_ns as f64 / 1e9,
        worlds.len() - fresh_from,
    )
}

/// Bob's hands: the CARL lift recording, looped (the scene's scripted hand where it is missing).
fn carl_source() -> Vec<String> {
    let carl = carl_example("lift");
    if carl.exists() {
        vec![
            "source.kind=replay".into(),
            format!("source.file={}", carl.display()),
            "source.offset=[0.0, -0.92, 0.0]".into(),
            "source.loop=true".into(),
        ]
    } else {
        eprintln!("{} is missing: bob's hand is scripted too", carl.display());
        Vec::new()
    }
}

/// Waits for each session (`who`, its process, its bus id) to end; each must succeed.
fn finish_all<const N: usize>(sessions: [(&str, Child, &String); N]) {
    let outs: BTreeMap<&str, Output> = sessions
        .into_iter()
        .map(|(who, child, id)| (who, finish(child, id)))
        .collect();
    for (who, out) in &outs {
        assert!(out.status.success(), "{who}:\n{}", both(out));
    }
}

/// Every hand a participant sent or held back is one the host took, counted lost or refused.
/// A hand held back (the link behind, a newer one sent in its place) is one the host counts
/// lost: its seq lies between two it took.
fn assert_every_hand_accounted_for(name: &str, ours: &Value, theirs: &Value) {
    let refused: u64 = ours["refused"]
        .as_object()
        .map_or(0, |m| m.values().filter_map(Value::as_u64).sum());
    assert_eq!(
        ours["hands_taken"].as_u64().unwrap() + ours["hands_lost"].as_u64().unwrap() + refused,
        theirs["hands_sent"].as_u64().unwrap() + theirs["hands_held_back"].as_u64().unwrap(),
        "{name}: every hand sent or held back is taken, lost or refused: host {ours}, \
         participant {theirs}"
    );
}
