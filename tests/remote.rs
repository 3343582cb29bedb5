//! Issue 17, beyond one machine: a session on one host, its renderer and recorder on another,
//! joined by the bridge over zenoh; and a live Foxglove view.
//!
//! Two hosts are two network namespaces joined by a veth pair (10.77.N.1 and 10.77.N.2), each
//! half of the session running inside its own with its own iceoryx2 bus, so the samples cross a
//! real (virtual) network link. Where namespaces cannot be made (not root, no CAP_NET_ADMIN),
//! the halves run over loopback with their own buses, and the test says so. Both namespaces
//! share this machine's CLOCK_MONOTONIC, so the clock offset the bridges estimate must come out
//! near 0: that checks the estimate.
//!
//! The figures the issue asks for are printed (`--nocapture` shows them): the bridged hop
//! beside the local iceoryx2 hop, the remote session's origin -> photon, and what a killed
//! viewer cost the local session.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::bus::BusConfig;
use common::{Topic, WorldHeader, WorldSample};
use recording::Recording;
use serde_json::Value;

mod support;
use support::{assert_nothing_left, both, free_port, repo, Scratch, EXE};

/// Two hosts: network namespaces joined by a veth pair, or this machine's loopback.
struct Hosts {
    /// (namespace, address) of the session's host and the viewer's host.
    local: (Option<String>, String),
    remote: (Option<String>, String),
}

impl Hosts {
    /// Namespaces `hb<tag><pid>a` / `...b` when `ip netns` works here, else loopback.
    fn new(tag: &str, subnet: u8) -> Hosts {
        let pid = std::process::id() % 100_000;
        let (a, b) = (format!("hb{tag}{pid}a"), format!("hb{tag}{pid}b"));
        let (va, vb) = (format!("hv{tag}{pid}a"), format!("hv{tag}{pid}b"));
        let net = format!("10.77.{subnet}");
        let ip = |args: &[&str]| {
            Command::new("ip")
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        };
        let made = ip(&["netns", "add", &a])
            && ip(&["netns", "add", &b])
            && ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])
            && ip(&["link", "set", &va, "netns", &a])
            && ip(&["link", "set", &vb, "netns", &b])
            && ip(&["-n", &a, "addr", "add", &format!("{net}.1/24"), "dev", &va])
            && ip(&["-n", &b, "addr", "add", &format!("{net}.2/24"), "dev", &vb])
            && ip(&["-n", &a, "link", "set", &va, "up"])
            && ip(&["-n", &b, "link", "set", &vb, "up"])
            && ip(&["-n", &a, "link", "set", "lo", "up"])
            && ip(&["-n", &b, "link", "set", "lo", "up"]);
        if made {
            eprintln!("two hosts: network namespaces {a} ({net}.1) and {b} ({net}.2), veth");
            Hosts {
                local: (Some(a), format!("{net}.1")),
                remote: (Some(b), format!("{net}.2")),
            }
        } else {
            let _ = ip(&["netns", "del", &a]);
            let _ = ip(&["netns", "del", &b]);
            eprintln!(
                "network namespaces unavailable here (not root?): the two halves run over \
                 loopback, each on its own iceoryx2 bus"
            );
            Hosts {
                local: (None, "127.0.0.1".into()),
                remote: (None, "127.0.0.1".into()),
            }
        }
    }

    /// `handblocks ARGS` on a host (inside its namespace, if any).
    fn command(host: &(Option<String>, String)) -> Command {
        match &host.0 {
            Some(ns) => {
                let mut c = Command::new("ip");
                c.args(["netns", "exec", ns, EXE]);
                c
            }
            None => Command::new(EXE),
        }
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for ns in [&self.local.0, &self.remote.0].into_iter().flatten() {
            // Deleting a namespace removes its end of the veth pair, and so the pair.
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

/// One test's two halves: the hosts, the session's endpoint (on the session's host, a free
/// port), a zenoh key and a bus id per half, all of them the test's own.
struct Halves {
    hosts: Hosts,
    endpoint: String,
    key: String,
    local_id: String,
    viewer_id: String,
}

impl Halves {
    fn new(tag: &str, subnet: u8) -> Halves {
        let hosts = Hosts::new(tag, subnet);
        let pid = std::process::id();
        Halves {
            endpoint: format!("tls/{}:{}", hosts.local.1, free_port()),
            key: format!("hbtest/{tag}{pid}"),
            local_id: format!("rm{tag}L{pid}"),
            viewer_id: format!("rm{tag}V{pid}"),
            hosts,
        }
    }
}

/// Starts `handblocks launch SESSION` on `host` for `seconds`, recording to `rec`, with
/// `--set` overrides.
fn launch(
    host: &(Option<String>, String),
    session: &str,
    id: &str,
    seconds: f64,
    report: &Path,
    rec: &Path,
    sets: &[String],
) -> Child {
    let mut c = Hosts::command(host);
    c.current_dir(repo())
        .args(["launch", "--quiet", "--force", "--no-preview"])
        .args(["--duration", &seconds.to_string()])
        .args(["--bus-id", id, "--report"])
        .arg(report)
        .arg("--record")
        .arg(rec);
    for s in sets {
        c.args(["--set", s]);
    }
    c.arg(repo().join("config/sessions").join(session))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run handblocks")
}

fn report(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap_or_default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The viewer's overrides: its link to `endpoint`, a small headless renderer, and a budget a
/// software rasteriser on a loaded CI machine keeps (the frame rate is not what is tested).
/// Both halves keep their link keys in `keys` (one authority: they trust each other as two
/// halves on one machine do), the test's own.
fn viewer_sets(endpoint: &str, key: &str, keys: &Path) -> Vec<String> {
    vec![
        format!("source.endpoint={endpoint}"),
        format!("source.key={key}"),
        format!("source.key_dir={}", keys.display()),
        "renderer.width=160".into(),
        "renderer.height=120".into(),
        "renderer.shadows=false".into(),
        "budget.frame_rate_margin=1.0".into(),
        "budget.origin_to_photon_p99_ms=2000".into(),
    ]
}

fn local_sets(endpoint: &str, key: &str, keys: &Path) -> Vec<String> {
    vec![
        format!("remote.endpoint={endpoint}"),
        format!("remote.key={key}"),
        format!("remote.key_dir={}", keys.display()),
        // Judged here on what must hold on any machine: nothing dropped locally.
        "budget.origin_to_world_p99_us=1000000".into(),
    ]
}

/// A world with its wall-clock stamp fields (origin, publish: each machine's own clock) zeroed,
/// as bytes: what must be identical on both sides.
fn world_bytes(w: &WorldSample) -> Vec<u8> {
    let mut header: WorldHeader = w.header;
    header.stamp.origin_ns = 0;
    header.stamp.publish_ns = 0;
    let mut out = Vec::new();
    recording::encode_slice(Topic::World, &header, &w.blocks, &mut out);
    out
}

fn p(v: &Value, path: &[&str]) -> f64 {
    let mut x = v;
    for k in path {
        x = &x[*k];
    }
    x.as_f64().unwrap_or(f64::NAN)
}

/// The viewer starts first and waits for the session (either start order works: its link
/// keeps trying); the session runs 3 s on one host, the viewer renders and records on the
/// other. Every world the viewer recorded is the session's own world of that seq, bit for bit
/// but for the two wall-clock stamp fields; once the link was up none was lost; the clock
/// offset the bridge estimated is the true one (0: one clock) within its stated uncertainty.
#[test]
fn a_viewer_on_another_host_records_the_sessions_worlds_bit_for_bit() {
    let dir = Scratch::new("remote-same");
    let Halves {
        hosts,
        endpoint,
        key,
        local_id,
        viewer_id,
    } = Halves::new("s", 31);
    let (local_rec, viewer_rec) = (dir.path("local.mcap"), dir.path("viewer.mcap"));
    let (local_rep, viewer_rep) = (dir.path("local.json"), dir.path("viewer.json"));

    // Both directions: the viewer sends its frame stats back, the session records them.
    let mut sets = viewer_sets(&endpoint, &key, &dir.path("keys"));
    sets.push("source.publish=[\"frame\"]".into());
    let viewer = launch(
        &hosts.remote,
        "remote-viewer.toml",
        &viewer_id,
        9.0,
        &viewer_rep,
        &viewer_rec,
        &sets,
    );
    std::thread::sleep(Duration::from_millis(1500));
    let mut sets = local_sets(&endpoint, &key, &dir.path("keys"));
    sets.push("remote.subscribe=[\"frame\"]".into());
    // Issue 40: told to expect a viewer, the session starts its source once the viewer takes
    // its topics, so the viewer (started first) records it from its first sample.
    sets.push("remote.wait_for_viewer_s=20".into());
    let local = launch(
        &hosts.local,
        "live-remote.toml",
        &local_id,
        3.0,
        &local_rep,
        &local_rec,
        &sets,
    );
    let local_out = local.wait_with_output().unwrap();
    let viewer_out = viewer.wait_with_output().unwrap();
    assert!(local_out.status.success(), "{}", both(&local_out));
    assert!(viewer_out.status.success(), "{}", both(&viewer_out));
    assert_nothing_left(&local_id);
    assert_nothing_left(&viewer_id);

    let local_worlds: Vec<WorldSample> = Recording::open(&local_rec).unwrap().worlds().collect();
    let viewer_worlds: Vec<WorldSample> = Recording::open(&viewer_rec).unwrap().worlds().collect();
    assert!(
        local_worlds.len() >= 300,
        "{} local worlds",
        local_worlds.len()
    );
    let by_seq: std::collections::BTreeMap<u64, &WorldSample> = local_worlds
        .iter()
        .map(|w| (w.header.stamp.seq, w))
        .collect();
    for w in &viewer_worlds {
        let theirs = by_seq
            .get(&w.header.stamp.seq)
            .unwrap_or_else(|| panic!("world seq {} was never published", w.header.stamp.seq));
        assert_eq!(
            world_bytes(w),
            world_bytes(theirs),
            "world seq {}",
            w.header.stamp.seq
        );
    }
    let (first, last) = (
        viewer_worlds.first().unwrap().header.stamp.seq,
        viewer_worlds.last().unwrap().header.stamp.seq,
    );
    assert_eq!(
        viewer_worlds.len() as u64,
        last - first + 1,
        "worlds lost on the link once it was up"
    );
    assert_eq!(last, local_worlds.last().unwrap().header.stamp.seq);
    assert_eq!(
        (first, viewer_worlds.len()),
        (local_worlds[0].header.stamp.seq, local_worlds.len()),
        "a viewer attached before the source started missed the session's head"
    );

    let v = report(&viewer_rep);
    let l = report(&local_rep);
    let clock = &v["bridge"]["link"]["clock"];
    let (offset, uncertainty) = (p(clock, &["offset_ns"]), p(clock, &["uncertainty_ns"]));
    assert!(
        offset.abs() <= uncertainty.max(1000.0) + 1000.0,
        "one clock, yet an offset of {offset} ns +/- {uncertainty}: {clock}"
    );
    assert_eq!(v["session"]["source"], "remote");
    assert_eq!(v["topics"]["world"]["gaps"], 0, "{}", v["topics"]["world"]);
    assert_eq!(
        l["bridge"]["link"]["sent"]["world"].as_u64(),
        Some(local_worlds.len() as u64)
    );
    // The other way: the viewer's frame stats reached the session and its recording.
    let frames_back = Recording::open(&local_rec)
        .unwrap()
        .samples::<common::FrameSample>(Topic::Frame)
        .count();
    assert!(
        frames_back > 0,
        "no frame stats came back: {}\nthe viewer: {}\n{}",
        l["bridge"],
        v["topics"],
        v["stages"]["bridge"]
    );
    assert!(
        l["bridge"]["link"]["clock"]["offset_ns"].is_number(),
        "{}",
        l["bridge"]
    );
    eprintln!(
        "worlds: local {}, viewer {} (from seq {first}; the session waited for the viewer)\nclock offset {offset:.0} ns +/- {uncertainty:.0} ns over {} round trips\n\
         bridged hop (stepper publish there -> bridge here) p50 {:.0} / p99 {:.0} us; local \
         iceoryx2 hop to the stepper p50 {:.0} / p99 {:.0} us, to the local bridge p50 {:.0} / p99 \
         {:.0} us\n{frames_back} frame stats came back\nremote origin -> photon p50 {:.1} / p99 {:.1} ms; remote origin -> bridge \
         out p50 {:.0} / p99 {:.0} us",
        local_worlds.len(),
        viewer_worlds.len(),
        clock["exchanges"],
        p(&v, &["stages", "bridge", "hop_us", "p50"]),
        p(&v, &["stages", "bridge", "hop_us", "p99"]),
        p(&l, &["stages", "stepper", "hop_us", "p50"]),
        p(&l, &["stages", "stepper", "hop_us", "p99"]),
        p(&l, &["stages", "bridge", "hop_us", "p50"]),
        p(&l, &["stages", "bridge", "hop_us", "p99"]),
        p(&v, &["stages", "renderer", "photon_us", "p50"]) / 1e3,
        p(&v, &["stages", "renderer", "photon_us", "p99"]) / 1e3,
        p(&v, &["stages", "bridge", "origin_us", "p50"]),
        p(&v, &["stages", "bridge", "origin_us", "p99"]),
    );
}

/// The session starts first; a viewer joins, and is SIGKILLed mid-session with its whole
/// process set: the session goes on untouched (exit 0, budget kept, nothing dropped, every
/// world still sent to the link), and its bridge said what it sent.
#[test]
fn killing_the_viewer_does_not_disturb_the_session() {
    let dir = Scratch::new("remote-kill");
    let Halves {
        hosts,
        endpoint,
        key,
        local_id,
        viewer_id,
    } = Halves::new("k", 32);
    let (local_rep, viewer_rep) = (dir.path("local.json"), dir.path("viewer.json"));
    let local = launch(
        &hosts.local,
        "live-remote.toml",
        &local_id,
        5.0,
        &local_rep,
        &dir.path("local.mcap"),
        &local_sets(&endpoint, &key, &dir.path("keys")),
    );
    std::thread::sleep(Duration::from_millis(700));
    let mut viewer = launch(
        &hosts.remote,
        "remote-viewer.toml",
        &viewer_id,
        30.0,
        &viewer_rep,
        &dir.path("viewer.mcap"),
        &viewer_sets(&endpoint, &key, &dir.path("keys")),
    );
    // Until the viewer's recording has worlds in it (it is receiving), then kill everything
    // of it: its launcher and every process of its bus.
    let deadline = Instant::now() + Duration::from_secs(4);
    let viewer_mcap = dir.path("viewer.mcap");
    while Instant::now() < deadline
        && std::fs::metadata(&viewer_mcap).map_or(0, |m| m.len()) < 20_000
    {
        std::thread::sleep(Duration::from_millis(50));
    }
    let killed_at = Instant::now();
    let killed_ns = common::monotonic_ns();
    // The launcher first: its processes see their parent's pipe close and stop; any still
    // there a moment later are killed too.
    let _ = viewer.kill();
    let _ = viewer.wait();
    let stages = ["bridge", "renderer", "recorder"];
    let gone_by = Instant::now() + Duration::from_secs(5);
    while Instant::now() < gone_by {
        let left: Vec<u32> = stages
            .iter()
            .filter_map(|s| support::find_service_now(s, &viewer_id))
            .collect();
        if left.is_empty() {
            break;
        }
        if Instant::now() + Duration::from_secs(4) > gone_by {
            for pid in left {
                let _ = Command::new("kill")
                    .args(["-KILL", &pid.to_string()])
                    .status();
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let local_out = local.wait_with_output().unwrap();
    assert!(local_out.status.success(), "{}", both(&local_out));
    assert_nothing_left(&local_id);
    // What the killed viewer left (its launcher could not clean up): removed here.
    if let Ok(bus) = BusConfig::for_session(&viewer_id) {
        let _ = bus.remove_resources();
    }

    // What the dropped link cost the session, from its own recording: the age of each world
    // as it was published (origin -> world), in the 1.5 s before the kill and after it, and
    // the longest pause between two worlds after it.
    let local_worlds: Vec<WorldSample> = Recording::open(&dir.path("local.mcap"))
        .unwrap()
        .worlds()
        .collect();
    let window = 1_500_000_000u64;
    let ages = |from: u64, to: u64| {
        let mut v: Vec<u64> = local_worlds
            .iter()
            .map(|w| w.header.stamp)
            .filter(|s| s.publish_ns >= from && s.publish_ns < to)
            .map(|s| s.publish_ns - s.origin_ns)
            .collect();
        v.sort_unstable();
        let at = |q: f64| {
            v.get(((v.len() as f64 * q) as usize).min(v.len().saturating_sub(1)))
                .copied()
        };
        let us = |x: Option<u64>| x.map_or(f64::NAN, |ns| ns as f64 / 1e3);
        (v.len(), us(at(0.5)), us(at(0.99)))
    };
    let before = ages(killed_ns.saturating_sub(window), killed_ns);
    let after = ages(killed_ns, killed_ns + window);
    let longest_pause_ms = local_worlds
        .windows(2)
        .filter(|w| w[1].header.stamp.publish_ns > killed_ns)
        .map(|w| w[1].header.stamp.publish_ns - w[0].header.stamp.publish_ns)
        .max()
        .unwrap_or(0) as f64
        / 1e6;
    eprintln!(
        "origin -> world around the kill: before {} worlds p50 {:.0} / p99 {:.0} us; after {} \
         worlds p50 {:.0} / p99 {:.0} us; longest pause between worlds after it {longest_pause_ms:.1} ms",
        before.0, before.1, before.2, after.0, after.1, after.2
    );
    assert!(
        after.0 > 100,
        "the session published {} worlds after the kill",
        after.0
    );
    assert!(
        longest_pause_ms < 100.0,
        "the session paused {longest_pause_ms} ms after the kill"
    );

    let l = report(&local_rep);
    assert_eq!(l["budget"]["ok"], true, "{}", l["budget"]);
    let worlds = l["topics"]["world"]["published"].as_u64().unwrap();
    assert!(worlds >= 500, "{worlds} worlds in 5 s");
    assert_eq!(l["topics"]["world"]["dropped"].as_u64(), Some(0));
    assert_eq!(l["bridge"]["link"]["sent"]["world"].as_u64(), Some(worlds));
    eprintln!(
        "viewer killed {:.1} s into the session; the session: {worlds} worlds, 0 dropped, \
         origin -> world p50 {:.0} / p99 {:.0} us, its bridge's hop p99 {:.0} us, sent {} \
         worlds to the link; {} peer(s) at the end",
        killed_at.elapsed().as_secs_f64(),
        p(&l, &["stages", "stepper", "origin_us", "p50"]),
        p(&l, &["stages", "stepper", "origin_us", "p99"]),
        p(&l, &["stages", "bridge", "hop_us", "p99"]),
        l["bridge"]["link"]["sent"]["world"],
        l["bridge"]["link"]["peers_at_end"],
    );
}

/// `session` for `seconds`, renderer off, serving its live Foxglove view on `port`.
fn launch_with_view(session: &Path, id: &str, port: u16, report: &Path, seconds: &str) -> Child {
    Command::new(EXE)
        .current_dir(repo())
        .args(["launch", "--quiet", "--no-preview", "--duration", seconds])
        .args(["--bus-id", id, "--set", "renderer.mode=off"])
        // What is tested is the view, not this (shared, loaded) machine's latency.
        .args(["--set", "budget.origin_to_world_p99_us=1000000"])
        .args(["--set", &format!("viewer.foxglove=127.0.0.1:{port}")])
        .arg("--report")
        .arg(report)
        .arg(session)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run handblocks")
}

/// `[viewer] foxglove`: a Foxglove WebSocket client (the protocol, spoken here by tungstenite)
/// connects, sees the session's channels advertised with the recording's schemas and the
/// scene, subscribes to `/world` and decodes a world state of the scene's blocks.
#[test]
fn a_foxglove_client_subscribes_and_decodes_a_world() {
    use tungstenite::client::IntoClientRequest;
    use tungstenite::Message;

    let dir = Scratch::new("foxglove");
    let port = free_port();
    let id = format!("rmF{}", std::process::id());
    let rep = dir.path("report.json");
    let session = repo().join("config/sessions/live.toml");
    // 12 s, of which the client waits up to 8 for a world: under the whole suite on a loaded
    // 2-core machine a session's pipeline has started seconds after its view (issue 45's stop:
    // the read blocked until the session ended at 8 s and the server's close was a reset).
    let child = launch_with_view(&session, &id, port, &rep, "12");

    let connect = || {
        let deadline = Instant::now() + Duration::from_secs(4);
        loop {
            let mut req = format!("ws://127.0.0.1:{port}")
                .into_client_request()
                .unwrap();
            req.headers_mut()
                .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
            match tungstenite::connect(req) {
                Ok((s, _)) => break s,
                Err(e) if Instant::now() < deadline => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(50));
                }
                Err(e) => panic!("no Foxglove server on port {port}: {e}"),
            }
        }
    };
    let mut socket = connect();
    // Once in a full parallel run on a loaded 2-core machine (issue 43's stop), the first
    // connection was reset before any world came, with nothing said by the session; it did not
    // happen in the next runs. One reconnection is allowed, and said, so that the decode is
    // still tested and a second reset still fails.
    let mut reconnected = false;
    let mut world_channel = None;
    let mut scene_schema = None;
    let mut world: Option<WorldSample> = None;
    let until = Instant::now() + Duration::from_secs(8);
    let mut child = child;
    while world.is_none() && Instant::now() < until {
        let message = match socket.read() {
            Ok(m) => m,
            Err(e) if !reconnected && Instant::now() < until => {
                eprintln!("the view's connection ended ({e}); connecting again, once");
                reconnected = true;
                socket = connect();
                continue;
            }
            Err(e) => {
                // Say what the session said: the server went away under the client.
                let _ = child.kill();
                let out = child.wait_with_output().unwrap();
                panic!("a message: {e}; the session said:\n{}", both(&out));
            }
        };
        match message {
            Message::Text(t) => {
                let v: Value = serde_json::from_str(&t).unwrap();
                if v["op"] == "advertise" {
                    for c in v["channels"].as_array().unwrap() {
                        if c["topic"] == "/world" {
                            assert_eq!(c["encoding"], "cdr");
                            assert_eq!(c["schemaName"], "handblocks/msg/WorldSample");
                            assert_eq!(c["schemaEncoding"], "ros2msg");
                            world_channel = c["id"].as_u64();
                            let sub = serde_json::json!({
                                "op": "subscribe",
                                "subscriptions": [{"id": 1, "channelId": c["id"]}],
                            });
                            socket.send(Message::text(sub.to_string())).unwrap();
                        }
                        if c["topic"] == "/scene" {
                            scene_schema = c["schemaName"].as_str().map(String::from);
                        }
                    }
                }
            }
            Message::Binary(b) => {
                // opcode 1 (message data), subscription id, log time, the message.
                assert_eq!(b[0], 1);
                assert_eq!(u32::from_le_bytes(b[1..5].try_into().unwrap()), 1);
                let (header, body) =
                    recording::decode_slice::<WorldHeader>(Topic::World, &b[13..]).unwrap();
                let blocks = body
                    .chunks_exact(std::mem::size_of::<common::BlockState>())
                    .map(|c| unsafe {
                        std::ptr::read_unaligned(c.as_ptr() as *const common::BlockState)
                    })
                    .collect();
                world = Some(WorldSample { header, blocks });
            }
            _ => {}
        }
    }
    drop(socket);
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", both(&out));
    assert_nothing_left(&id);
    assert!(world_channel.is_some(), "/world was never advertised");
    assert_eq!(scene_schema.as_deref(), Some("foxglove.SceneUpdate"));
    let world = world.expect("no world state arrived");
    let scene = common::config::Session::load(&session).unwrap().scene;
    assert_eq!(world.blocks.len(), scene.blocks.len());
    assert_eq!(world.header.block_count as usize, scene.blocks.len());
    for b in &world.blocks {
        assert!(b.pose.position.iter().all(|x| x.is_finite()));
    }
    let r = report(&rep);
    assert!(
        r["bridge"]["foxglove"]["port"].as_u64() == Some(port as u64),
        "{}",
        r["bridge"]
    );
}

/// The stock Foxglove client: npm `@foxglove/ws-protocol` 0.8 (what Lichtblick and Foxglove
/// Studio builds before the SDK speak), offering `foxglove.websocket.v1`, connects to the live
/// view, and decodes a world with the Foxglove app's ROS 2 CDR decoder, and a scene update and
/// the hand's frames (`/tf`) with protobufjs from the advertised schemas
/// (tests/foxglove_check.js). Only topics that carry samples are offered: a scripted session
/// has no `/joints`.
#[test]
fn the_stock_foxglove_client_connects_and_decodes_a_world_and_a_scene() {
    // tests/run installs the npm packages into target/foxglove-node and names them here.
    let Some(node_path) = std::env::var_os("HB_FOXGLOVE_NODE_PATH") else {
        eprintln!(
            "skipped: HB_FOXGLOVE_NODE_PATH is not set (tests/run sets it to the npm packages \
             @foxglove/ws-protocol, ws, @foxglove/rosmsg2-serialization and protobufjs)"
        );
        return;
    };
    let dir = Scratch::new("foxglove-npm");
    let port = free_port();
    let id = format!("rmN{}", std::process::id());
    let rep = dir.path("report.json");
    let session = repo().join("config/sessions/live.toml");
    let child = launch_with_view(&session, &id, port, &rep, "8");
    // The script says {"error": ...} until the server listens; it is tried again until then
    // (on a loaded machine the bridge may take seconds to start).
    let deadline = Instant::now() + Duration::from_secs(15);
    let v: Value = loop {
        let out = Command::new("node")
            .arg(repo().join("tests/foxglove_check.js"))
            .arg(format!("ws://127.0.0.1:{port}"))
            .env("NODE_PATH", &node_path)
            .output()
            .expect("run node");
        let v: Value = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|_| panic!("not JSON: {}", both(&out)));
        if v["error"].is_null() || Instant::now() > deadline {
            break v;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", both(&out));
    assert_nothing_left(&id);
    assert!(v["error"].is_null(), "{v}");
    assert_eq!(v["subprotocol"], "foxglove.websocket.v1");
    let channels = v["channels"].as_array().unwrap();
    let channel = |topic: &str| channels.iter().find(|c| c["topic"] == topic).cloned();
    let world_channel = channel("/world").expect("/world advertised");
    assert_eq!(world_channel["encoding"], "cdr");
    assert_eq!(world_channel["schemaName"], "handblocks/msg/WorldSample");
    assert_eq!(
        channel("/scene").unwrap()["schemaName"],
        "foxglove.SceneUpdate"
    );
    assert!(
        channel("/joints").is_none(),
        "/joints carries nothing here: {channels:?}"
    );

    let scene = common::config::Session::load(&session).unwrap().scene;
    let world = &v["world"];
    assert_eq!(
        world["block_count"].as_u64(),
        Some(scene.blocks.len() as u64)
    );
    let blocks = world["blocks"].as_array().unwrap();
    assert_eq!(blocks.len(), scene.blocks.len());
    for b in blocks {
        assert!(b["pose"]["position"]
            .as_array()
            .unwrap()
            .iter()
            .all(|x| x.as_f64().is_some_and(f64::is_finite)));
        assert!(b["mode"].as_u64().is_some_and(|m| m < 7));
    }
    let entities = v["scene"]["entities"].as_array().unwrap();
    assert_eq!(
        entities.len(),
        scene.blocks.len() + 2,
        "floor, blocks, hand"
    );
    assert_eq!(entities[0]["id"], "floor");
    let colours = scene_view::block_colours(&scene);
    for (i, b) in scene.blocks.iter().enumerate() {
        let e = &entities[1 + i];
        assert_eq!(e["id"], b.name.as_str());
        assert_eq!(e["frameId"], "world");
        let label = e["texts"][0]["text"].as_str().unwrap();
        assert!(label.starts_with(&format!("{}: ", b.name)), "{label}");
        let c = &e["cubes"][0]["color"];
        let [r, g, bl] = colours[i];
        assert_eq!(
            [&c["r"], &c["g"], &c["b"]],
            [r, g, bl].map(Value::from).each_ref()
        );
        // z-up: the block rests on or above Foxglove's ground plane.
        assert!(e["cubes"][0]["pose"]["position"]["z"].as_f64().unwrap() > 0.0);
    }
    let hand = entities.last().unwrap();
    assert_eq!(hand["id"], "hand");
    assert_eq!(hand["lines"].as_array().unwrap().len(), 5);

    // The hand's frames: world -> hand (the wrist) -> each finger's joints, knuckle to tip,
    // z-up. Composed down the tree from `world`, each joint lands on the point of the finger
    // line the scene sent with them; each transform is stamped with its message's log time.
    let tf_channel = channel("/tf").expect("/tf advertised");
    assert_eq!(tf_channel["schemaName"], "foxglove.FrameTransforms");
    assert_eq!(tf_channel["encoding"], "protobuf");
    let transforms = v["tf"]["transforms"].as_array().unwrap();
    // The scripted hand goes through the kinematics: a thumb of 3 joints, 4 fingers of 4.
    assert_eq!(transforms.len(), 1 + 3 + 4 * 4, "{}", v["tf"]);
    let log_ns: u64 = v["tfLogTime"].as_str().unwrap().parse().unwrap();
    let num = |x: &Value| x.as_f64().unwrap();
    let mut frames: Vec<(String, [f64; 3], [f64; 4])> = Vec::new();
    for t in transforms {
        let (parent, child) = (
            t["parentFrameId"].as_str().unwrap(),
            t["childFrameId"].as_str().unwrap(),
        );
        let stamp = &t["timestamp"];
        assert_eq!(
            stamp["seconds"].as_u64().unwrap() * 1_000_000_000 + stamp["nanos"].as_u64().unwrap(),
            log_ns,
            "{child}: stamped with its message's log time"
        );
        let tr = &t["translation"];
        let q = &t["rotation"];
        let local = [num(&tr["x"]), num(&tr["y"]), num(&tr["z"])];
        let rotation = [num(&q["x"]), num(&q["y"]), num(&q["z"]), num(&q["w"])];
        let norm = rotation.iter().map(|c| c * c).sum::<f64>().sqrt();
        assert!(
            (norm - 1.0).abs() < 1e-9,
            "{child}: a unit rotation, {rotation:?}"
        );
        let (at, turn) = if parent == scene_view::FRAME_ID {
            ([0.0; 3], [0.0, 0.0, 0.0, 1.0])
        } else {
            let p = frames
                .iter()
                .find(|f| f.0 == parent)
                .unwrap_or_else(|| panic!("{child}'s parent {parent} comes before it"));
            // A joint is a bone's length or less from its parent.
            let bone = local.iter().map(|c| c * c).sum::<f64>().sqrt();
            assert!(bone < 0.15, "{child}: {bone} m from {parent}");
            (p.1, p.2)
        };
        let moved = quat_rotate(turn, local);
        frames.push((
            child.to_string(),
            [at[0] + moved[0], at[1] + moved[1], at[2] + moved[2]],
            quat_mul(turn, rotation),
        ));
    }
    assert_eq!(transforms[0]["parentFrameId"], "world");
    assert_eq!(transforms[0]["childFrameId"], "hand");
    // The wrist: above the floor (z-up), within a metre of the scene's origin.
    let wrist = frames[0].1;
    assert!(
        wrist[2] > 0.0 && wrist.iter().all(|c| c.abs() < 1.0),
        "{wrist:?}"
    );
    let lines = hand["lines"].as_array().unwrap();
    for (f, line) in lines.iter().enumerate() {
        let points = line["points"].as_array().unwrap();
        assert_eq!(points.len(), if f == 0 { 3 } else { 4 }, "finger {f}");
        for (k, p) in points.iter().enumerate() {
            let id = scene_view::joint_frame("hand", f, k, points.len());
            let at = frames
                .iter()
                .find(|fr| fr.0 == id)
                .unwrap_or_else(|| panic!("no frame {id}"))
                .1;
            let drawn = [num(&p["x"]), num(&p["y"]), num(&p["z"])];
            let off = (0..3).map(|i| (at[i] - drawn[i]).abs()).fold(0.0, f64::max);
            assert!(off < 1e-9, "{id} at {at:?}, the scene's point at {drawn:?}");
        }
    }
    assert_eq!(scene_view::joint_frame("hand", 1, 3, 4), "hand/index_tip");
}

/// The Hamilton product `a b` of quaternions `[x, y, z, w]`.
fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]
}

/// `v` turned by the unit quaternion `q`.
fn quat_rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let [x, y, z, _] = quat_mul(
        quat_mul(q, [v[0], v[1], v[2], 0.0]),
        [-q[0], -q[1], -q[2], q[3]],
    );
    [x, y, z]
}

/// Bad link settings are refused before anything starts, naming the file, key and form.
#[test]
fn bad_link_settings_name_the_key_and_the_form() {
    let session = repo().join("config/sessions/live-remote.toml");
    for (set, says) in [
        ("remote.endpoint=udp/1.2.3.4:7447", "remote.endpoint"),
        ("remote.endpoint=tls/1.2.3.4", "has no port"),
        // Issue 40: a plain link only when asked for, and then without certificates.
        ("remote.endpoint=tcp/1.2.3.4:7447", "allow_plain = true"),
        ("remote.allow_plain=true", "only with a tcp/ endpoint"),
        ("remote.names=[\"bad name\"]", "not a host name"),
        ("remote.publish=[\"hand\", \"stars\"]", "is not a topic"),
        ("remote.key=handblocks/*", "no wildcards"),
        ("remote.subscribe=[\"world\"]", "also in publish"),
        ("viewer.foxglove=localhost", "HOST:PORT"),
    ] {
        let out: Output = Command::new(EXE)
            .current_dir(repo())
            .args(["launch", "--duration", "1", "--set", set])
            .arg(&session)
            .output()
            .unwrap();
        let text = both(&out);
        assert_eq!(out.status.code(), Some(2), "{set}: {text}");
        assert!(text.contains(says), "{set}: {text}");
        assert!(text.contains("live-remote.toml"), "{set}: {text}");
    }
    let _: PathBuf = session;
}

/// Issue 40, finding 1: one hand from the link whose `finger_point_count[0]` is 6 (bytes
/// 100..103 of its message) crashed a viewer's recorder (its scene view drew the finger), and a
/// `palm_vertex_count` of 17 its renderer too. A trusted peer (this test, holding the viewer's
/// authority) sends both among good hands and worlds: the viewer refuses the two by name, draws
/// and records the rest, and ends its session cleanly.
#[test]
fn a_sample_whose_counts_overrun_its_arrays_is_refused_by_name_and_the_viewer_lives() {
    use bridge::link::Link;
    use common::config::remote::LinkSecurity;
    use common::config::session::{LinkRole, RemoteLink};
    use common::HandSample;

    let dir = Scratch::new("remote-counts");
    let keys = dir.path("keys");
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let key = format!("hbtest/counts{}", std::process::id());
    let id = format!("rmc{}", std::process::id());
    let (rec, rep) = (dir.path("viewer.mcap"), dir.path("viewer.json"));
    let viewer = launch(
        &(None, "127.0.0.1".into()),
        "remote-viewer.toml",
        &id,
        5.0,
        &rep,
        &rec,
        &viewer_sets(&endpoint, &key, &keys),
    );
    let peer = Link::open(&RemoteLink {
        endpoint: endpoint.clone(),
        security: LinkSecurity::Tls {
            key_dir: keys.clone(),
            peer_certificate: None,
            names: Vec::new(),
        },
        role: LinkRole::Listen,
        key,
        publish: vec![Topic::Hand, Topic::World],
        subscribe: vec![],
        wait_for_viewer_s: 0,
    })
    .unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    while !peer.every_topic_taken() {
        assert!(Instant::now() < deadline, "the viewer never attached");
        std::thread::sleep(Duration::from_millis(20));
    }
    let scene =
        common::config::Scene::load(&repo().join("config/scenes/grasp-throw.toml")).unwrap();
    let mut world = WorldSample::with_blocks(scene.blocks.len());
    let mut hand = HandSample {
        finger_count: 1,
        tracked: 1,
        ..HandSample::default()
    };
    hand.finger_point_count[0] = 2;
    hand.finger_points[0][1] = [0.0, 0.1, 0.0];
    let mut message = Vec::new();
    for seq in 0..300u64 {
        let now = common::monotonic_ns();
        hand.stamp.seq = seq;
        hand.stamp.origin_ns = now;
        hand.stamp.publish_ns = now;
        recording::encode_sample(&hand, &mut message);
        match seq {
            100 => message[100..104].copy_from_slice(&6u32.to_le_bytes()),
            150 => message[120..124].copy_from_slice(&17u32.to_le_bytes()),
            _ => {}
        }
        peer.put(Topic::Hand, &message).unwrap();
        world.header.stamp = hand.stamp;
        world.header.hand_seq = seq;
        recording::encode_slice(Topic::World, &world.header, &world.blocks, &mut message);
        peer.put(Topic::World, &message).unwrap();
        std::thread::sleep(Duration::from_millis(8));
    }
    let out = viewer.wait_with_output().unwrap();
    peer.close();
    let text = both(&out);
    assert!(out.status.success(), "{text}");
    assert!(!text.contains("panicked"), "{text}");
    assert_nothing_left(&id);
    let v = report(&rep);
    let link = &v["bridge"]["link"];
    assert_eq!(link["malformed"], 2, "{link}");
    assert_eq!(
        link["malformed_by_name"]["hand counts: finger_point_count"], 1,
        "{link}"
    );
    assert_eq!(
        link["malformed_by_name"]["hand counts: palm_vertex_count"], 1,
        "{link}"
    );
    let recorded = Recording::open(&rec).unwrap();
    let hands: Vec<HandSample> = recorded.samples(Topic::Hand).collect();
    assert!(hands.len() > 200, "{} hands recorded", hands.len());
    assert!(hands.iter().all(|h| h.check_counts().is_ok()));
    assert!(!hands
        .iter()
        .any(|h| h.stamp.seq == 100 || h.stamp.seq == 150));
}
