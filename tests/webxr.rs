//! `[source] kind = "webxr"` (issue 31): a headset's page as the session's hand, over the
//! page's own protocol, spoken here by a client that plays a CARL trace as a headset would
//! (one hands frame per trace sample, in the sample's own time). What a browser adds (the
//! page's WebXR calls, IWER's emulated Quest) is tests/webxr_browser.rs's.

mod support;

use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

use common::{Pose, WorldSample};
use recording::Recording;
use support::{
    assert_nothing_left, assert_same_poses, carl_example as carl, free_port, launch_webxr, repo,
    simulate_trace, Scratch, EXE,
};
use tungstenite::{Message, WebSocket};
use webxr_wire::page;
use webxr_wire::{HandJoints, HandsFrame, WEBXR_JOINTS};

const TOKEN: &str = "test-token-0123456789";

/// `config/sessions/webxr.toml` over plain HTTP (see `support::launch_webxr`).
fn launch(name: &str, id: &str, port: u16, seconds: f64, rec: &Path, report: &Path) -> Child {
    let extra = ["source.tls=false".to_string()];
    launch_webxr(name, id, port, TOKEN, seconds, &extra, (rec, report))
}

/// `simulate --json --hands both --frames FRAMES --hand-offset X,Y,Z --hand TRACE SCENE`,
/// which must succeed: its JSON report.
fn simulate_both(scene: &Path, trace: &Path, offset: [f64; 3], frames: u64) -> serde_json::Value {
    let out = Command::new(EXE)
        .args(["simulate", "--json", "--hands", "both", "--frames"])
        .arg(frames.to_string())
        .arg("--hand-offset")
        .arg(format!("{},{},{}", offset[0], offset[1], offset[2]))
        .arg("--hand")
        .arg(trace)
        .arg(scene)
        .output()
        .expect("run handblocks simulate");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("simulate --json prints JSON")
}

type Socket = WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

/// Connects to the session's socket with `token`, trying until the server listens.
fn connect(port: u16, token: &str) -> Socket {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        match tungstenite::connect(format!("ws://127.0.0.1:{port}/ws?token={token}")) {
            Ok((s, _)) => return s,
            Err(e) if Instant::now() > deadline => panic!("no webxr server on {port}: {e}"),
            Err(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

/// A headset's page, as far as the protocol goes: answers pings, waits for `ready`, sends
/// frames, measures round trips from the worlds that answer its frames.
struct Page {
    socket: Socket,
    start: Instant,
    scene: Option<serde_json::Value>,
    ready: bool,
    sent_at: Vec<(u32, f64)>,
    round_trips_ms: Vec<f64>,
    worlds: u64,
    closed: Option<String>,
    out: Vec<u8>,
}

impl Page {
    fn open(port: u16, token: &str) -> Page {
        let socket = connect(port, token);
        if let tungstenite::stream::MaybeTlsStream::Plain(s) = socket.get_ref() {
            s.set_read_timeout(Some(Duration::from_millis(2))).unwrap();
        }
        Page {
            socket,
            start: Instant::now(),
            scene: None,
            ready: false,
            sent_at: Vec::new(),
            round_trips_ms: Vec::new(),
            worlds: 0,
            closed: None,
            out: Vec::new(),
        }
    }

    /// The page's clock (ms), as performance.now() is.
    fn now_ms(&self) -> f64 {
        self.start.elapsed().as_secs_f64() * 1e3 + 1000.0
    }

    /// Reads what has arrived, answering it; stops at the first read that would block.
    fn pump(&mut self) {
        loop {
            match self.socket.read() {
                Ok(Message::Text(t)) => match page::decode_text(&t) {
                    Ok(page::Text::Scene(_)) => {
                        self.scene = Some(serde_json::from_str(&t).unwrap())
                    }
                    Ok(page::Text::Ready(_)) => self.ready = true,
                    Err(e) => panic!("unexpected text {t:?}: {e}"),
                },
                Ok(Message::Binary(b)) => match page::kind_of(&b).unwrap() {
                    page::KIND_PING => {
                        let ping = page::decode_ping(&b).unwrap();
                        let pong = page::Pong {
                            seq: ping.seq,
                            server_ms: ping.server_ms,
                            page_ms: self.now_ms(),
                        };
                        page::encode_pong(&pong, &mut self.out);
                        self.socket.send(Message::binary(self.out.clone())).unwrap();
                    }
                    page::KIND_WORLD => {
                        self.worlds += 1;
                        let seq = page::decode_world(&b).unwrap().page_seq;
                        if let Some(&(_, at)) = self.sent_at.iter().rev().find(|(s, _)| *s == seq) {
                            let rt = self.now_ms() - at;
                            self.round_trips_ms.push(rt);
                            let stats = page::FrameStats {
                                seq,
                                js_ms: 0.2,
                                round_trip_ms: Some(rt),
                            };
                            page::encode_stats(&stats, &mut self.out);
                            self.socket.send(Message::binary(self.out.clone())).unwrap();
                        }
                    }
                    k => panic!("unexpected kind {k}"),
                },
                Ok(Message::Close(f)) => {
                    self.closed = Some(
                        f.map(|f| format!("{} {}", u16::from(f.code), f.reason))
                            .unwrap_or_default(),
                    );
                    return;
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return
                }
                Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => {
                    self.closed.get_or_insert_with(String::new);
                    return;
                }
                Err(e) => panic!("socket: {e}"),
            }
        }
    }

    fn wait_ready(&mut self) {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !self.ready {
            assert!(Instant::now() < deadline, "no ready from the server");
            self.pump();
        }
    }

    fn send(&mut self, bytes: &[u8]) {
        self.socket.send(Message::binary(bytes.to_vec())).unwrap();
    }
}

/// The trace's samples as a headset's right hand: WebXR's 25 joints (the wrist pose, then
/// OpenXR's joints after palm and wrist), source time (ns from the first) and whether tracked.
fn headset_samples(trace: &Path) -> Vec<(u64, bool, HandJoints)> {
    let t = replay::CarlTrace::load(trace).unwrap();
    let mut joints = Vec::new();
    t.joints([0.0; 3], &mut joints);
    joints
        .iter()
        .map(|j| {
            let hand = HandJoints {
                poses: webxr_wire::from_joints(j),
                radii: [0.01; WEBXR_JOINTS],
            };
            (j.stamp.source_time_ns, j.tracked != 0, hand)
        })
        .collect()
}

/// The world that answers frame `k` of the session (0: the first frame published): the last
/// world of that frame's source time. A frame of two hands is two `joints` samples of one time,
/// and the stepper publishes a world after each (the first still the world before the frame).
fn world_of_frame<'w>(
    worlds: &'w [WorldSample],
    joints: &[common::JointsSample],
    k: usize,
) -> &'w WorldSample {
    let mut times: Vec<u64> = joints.iter().map(|j| j.stamp.source_time_ns).collect();
    times.dedup();
    let t = times[k];
    worlds
        .iter()
        .rev()
        .find(|w| w.stamp.source_time_ns == t)
        .unwrap_or_else(|| panic!("no world of frame {k} (source time {t} ns)"))
}

/// Both hands of the trace as a headset's, one frame per sample: source time (ns from the
/// first) and each hand (`Handedness` order: left, right) when tracked.
fn headset_samples_both(trace: &Path) -> Vec<(u64, [Option<HandJoints>; 2])> {
    let hand_of = |side| {
        let t = replay::CarlTrace::load_hand(trace, side).unwrap();
        let mut joints = Vec::new();
        t.joints([0.0; 3], &mut joints);
        joints
    };
    let (left, right) = (
        hand_of(common::HandSide::Left),
        hand_of(common::HandSide::Right),
    );
    let webxr = |j: &common::JointsSample| {
        (j.tracked != 0).then(|| HandJoints {
            poses: webxr_wire::from_joints(j),
            radii: [0.01; WEBXR_JOINTS],
        })
    };
    left.iter()
        .zip(&right)
        .map(|(l, r)| {
            assert_eq!(l.stamp.source_time_ns, r.stamp.source_time_ns);
            (r.stamp.source_time_ns, [webxr(l), webxr(r)])
        })
        .collect()
}

/// Plays `samples` through `page` at their own pace, one frame each.
fn play(page: &mut Page, samples: &[(u64, bool, HandJoints)]) {
    play_frames(page, samples.iter().map(|s| s.0), |i, frame| {
        let (_, tracked, hand) = samples[i];
        frame.present = [false, tracked];
        frame.hands[1] = hand;
    });
}

/// Sends one hands frame at each of `times` (ns from now), `fill` setting frame `i`'s hands,
/// pumping the page's socket while it waits.
fn play_frames(
    page: &mut Page,
    times: impl Iterator<Item = u64>,
    mut fill: impl FnMut(usize, &mut HandsFrame),
) {
    let start = Instant::now();
    let mut frame = HandsFrame::default();
    let mut bytes = Vec::new();
    for (i, t_ns) in times.enumerate() {
        while start.elapsed() < Duration::from_nanos(t_ns) {
            page.pump();
        }
        frame.seq = i as u32 + 1;
        frame.frame_time_ms = t_ns as f64 / 1e6;
        fill(i, &mut frame);
        webxr_wire::encode(&frame, &mut bytes);
        let now = page.now_ms();
        page.sent_at.push((frame.seq, now));
        page.send(&bytes);
        page.pump();
    }
}

fn wait_for(child: Child, what: &str) -> String {
    let out = child.wait_with_output().unwrap();
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{what}: {text}");
    text
}

/// A headset that plays the CARL lift trace through the socket drives the session: the world
/// that answers its last frame is `simulate --hand` of the trace, bit for bit; its frames'
/// round trips come back and are in the report; a page with the wrong token is closed with
/// 4001 and a page without it is refused.
#[test]
fn a_headset_playing_the_lift_trace_drives_the_session_as_simulate_does() {
    let dir = Scratch::new("webxr-lift");
    let port = free_port();
    let id = format!("wx{}", std::process::id());
    let (rec, report) = (dir.path("run.mcap"), dir.path("report.json"));
    let samples = headset_samples(&carl("lift"));
    let seconds = samples.last().unwrap().0 as f64 / 1e9 + 6.0;
    let child = launch("lift", &id, port, seconds, &rec, &report);

    // The wrong token: closed with 4001 and a reason the page can show.
    let mut wrong = Page::open(port, "wrong-token-0123456789");
    let deadline = Instant::now() + Duration::from_secs(5);
    while wrong.closed.is_none() && Instant::now() < deadline {
        wrong.pump();
    }
    let closed = wrong.closed.clone().unwrap_or_default();
    assert!(closed.starts_with("4001"), "closed with {closed:?}");
    // The page itself without the token: 403.
    let mut http = TcpStream::connect(("127.0.0.1", port)).unwrap();
    use std::io::{Read, Write};
    http.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        .unwrap();
    let mut answer = String::new();
    http.read_to_string(&mut answer).unwrap();
    assert!(answer.starts_with("HTTP/1.1 403"), "{answer}");

    let mut page = Page::open(port, TOKEN);
    page.wait_ready();
    let scene = page.scene.clone().expect("the scene first");
    assert_eq!(scene["blocks"].as_array().unwrap().len(), 1);
    assert!(!scene["blocks"][0]["indices"].as_array().unwrap().is_empty());
    play(&mut page, &samples);
    let until = Instant::now() + Duration::from_millis(800);
    while Instant::now() < until {
        page.pump();
    }
    drop(page);
    let text = wait_for(child, "the webxr session");
    assert_nothing_left(&id);
    assert!(text.contains("handblocks webxr:"), "{text}");

    let rec = Recording::open(&rec).unwrap();
    let worlds: Vec<WorldSample> = rec.worlds().collect();
    let tracked_from = samples.iter().position(|s| s.1).unwrap();
    let played = samples.len() - tracked_from;
    assert!(
        worlds.len() >= played,
        "{} worlds for {played} frames",
        worlds.len()
    );
    // The world that answers the last frame (later ones: the page gone, the hand untracked).
    let last = &worlds[played - 1];
    let session =
        common::config::Session::load(&repo().join("config/sessions/webxr.toml")).unwrap();
    let common::config::session::Source::Webxr(settings) = &session.source else {
        panic!("not a webxr session");
    };
    let v = simulate_trace(
        &repo().join("config/scenes/carl-lift.toml"),
        &carl("lift"),
        settings.offset,
        last.step,
    );
    assert_same_poses(&v, last);
    let top = worlds[..played]
        .iter()
        .filter(|w| w.grasped_block == 0)
        .map(|w| w.blocks()[0].pose.position[1])
        .fold(f64::MIN, f64::max);
    assert!(top > 0.4, "lifted only to {top} m");

    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let stage = &r["stages"]["webxr"];
    assert!(stage["photon_us"]["count"].as_u64().unwrap() > 0, "{stage}");
    assert!(
        stage["page_js_us"]["count"].as_u64().unwrap() > 0,
        "{stage}"
    );
    eprintln!(
        "webxr lift: {played} frames; the page's round trip p50 {} us, p99 {} us; the stepper's \
         origin -> world p50 {} us, p99 {} us",
        stage["photon_us"]["p50"],
        stage["photon_us"]["p99"],
        r["stages"]["stepper"]["origin_us"]["p50"],
        r["stages"]["stepper"]["origin_us"]["p99"],
    );
}

/// Issue 41: `hand = "both"`. A headset that sends both hands of a CARL trace (one frame per
/// sample, each hand when tracked) drives a two-hand world: the session publishes each frame's
/// right then left hand at one source time (a lost hand untracked, a hand not seen yet not at
/// all), and the world that answers the last frame is `simulate --hands both` of the trace, bit
/// for bit. Lift has both hands in view throughout; pull's left comes into view 58 frames in.
#[test]
fn a_headset_sending_both_hands_drives_a_two_hand_world_as_simulate_does() {
    for name in ["lift", "pull"] {
        let dir = Scratch::new(&format!("webxr-both-{name}"));
        let port = free_port();
        let id = format!("wh{name}{}", std::process::id());
        let (rec, report) = (dir.path("run.mcap"), dir.path("report.json"));
        let trace = carl(name);
        let samples = headset_samples_both(&trace);
        let seconds = samples.last().unwrap().0 as f64 / 1e9 + 6.0;
        let extra = [
            "source.tls=false".to_string(),
            "source.hand=both".to_string(),
        ];
        let child = launch_webxr(name, &id, port, TOKEN, seconds, &extra, (&rec, &report));
        let mut page = Page::open(port, TOKEN);
        page.wait_ready();
        assert_eq!(page.scene.as_ref().unwrap()["hand"], "both");
        play_frames(&mut page, samples.iter().map(|s| s.0), |i, frame| {
            for (k, hand) in samples[i].1.iter().enumerate() {
                frame.present[k] = hand.is_some();
                frame.hands[k] = hand.unwrap_or_default();
            }
        });
        let until = Instant::now() + Duration::from_millis(800);
        while Instant::now() < until {
            page.pump();
        }
        drop(page);
        let text = wait_for(child, "the webxr session");
        assert_nothing_left(&id);
        let line = text
            .lines()
            .find(|l| l.starts_with("handblocks webxr:") && l.contains("frames published"))
            .unwrap_or_else(|| panic!("no webxr summary: {text}"));
        assert!(line.contains("untracked: the right hand"), "{line}");

        let rec = Recording::open(&rec).unwrap();
        let joints: Vec<common::JointsSample> = rec.samples(common::Topic::Joints).collect();
        // Each frame: the right, then the left once it was seen, at the frame's time.
        let first_left = samples.iter().position(|s| s.1[0].is_some()).unwrap();
        let tracked_from = samples.iter().position(|s| s.1[1].is_some()).unwrap();
        assert_eq!(
            tracked_from, 0,
            "{name}: the right hand is in view from the start"
        );
        let frames = samples.len();
        assert!(
            joints.len() >= 2 * frames - first_left,
            "{name}: {} joints for {frames} frames",
            joints.len()
        );
        let (before, after) = joints[..2 * frames - first_left].split_at(first_left);
        assert!(before.iter().all(|j| j.side == 0), "{name}");
        for (k, pair) in after.chunks(2).enumerate() {
            let (r, l) = (&pair[0], &pair[1]);
            assert!(
                r.side == 0 && l.side == 1 && r.stamp.source_time_ns == l.stamp.source_time_ns,
                "{name}: frame {}: sides {} {}",
                first_left + k,
                r.side,
                l.side
            );
            assert_eq!(
                l.tracked != 0,
                samples[first_left + k].1[0].is_some(),
                "{name}: the left hand's tracking in frame {}",
                first_left + k
            );
        }
        let worlds: Vec<WorldSample> = rec.worlds().collect();
        assert!(worlds.len() >= frames, "{} worlds", worlds.len());
        let last = world_of_frame(&worlds, &joints, frames - 1);
        let v = simulate_both(
            &repo().join(format!("config/scenes/carl-{name}.toml")),
            &trace,
            [0.0, -0.92, 0.0],
            last.step,
        );
        assert_same_poses(&v, last);
        // The blocks say which hand held them.
        let held_by = worlds[..frames]
            .iter()
            .flat_map(|w| w.blocks().iter().map(|b| b.held_by))
            .fold(0, |a, b| a | b);
        eprintln!(
            "webxr both hands {name}: {frames} frames ({} with the left hand seen), the world \
             of the last frame identical to simulate --hands both; blocks held by (bits) \
             {held_by:#b}",
            frames - first_left
        );
    }
}

/// Bad input on the socket: malformed, truncated, oversized, out-of-order and replayed frames,
/// NaN and huge joints, a flood: each refused by name and counted, the session unharmed.
#[test]
fn bad_frames_are_refused_by_name_and_the_session_goes_on() {
    let dir = Scratch::new("webxr-bad");
    let port = free_port();
    let id = format!("wb{}", std::process::id());
    let (rec, report) = (dir.path("run.mcap"), dir.path("report.json"));
    let child = launch("lift", &id, port, 6.0, &rec, &report);
    let mut page = Page::open(port, TOKEN);
    page.wait_ready();
    let samples = headset_samples(&carl("lift"));
    let (_, _, hand) = samples.iter().find(|s| s.1).copied().unwrap();
    let mut frame = HandsFrame {
        seq: 1,
        frame_time_ms: 10.0,
        present: [false, true],
        ..Default::default()
    };
    frame.hands[1] = hand;
    let mut good = Vec::new();
    webxr_wire::encode(&frame, &mut good);
    page.send(&good);
    // Replayed (same seq) and out of order (an older time).
    page.send(&good);
    frame.seq = 2;
    frame.frame_time_ms = 5.0;
    webxr_wire::encode(&frame, &mut good);
    page.send(&good);
    // Truncated, a NaN joint, a huge joint.
    page.send(&good[..100]);
    let mut nan = good.clone();
    nan[24..28].copy_from_slice(&f32::NAN.to_le_bytes());
    page.send(&nan);
    let mut huge = good.clone();
    huge[24..28].copy_from_slice(&1e30f32.to_le_bytes());
    page.send(&huge);
    // Not ours at all.
    page.send(b"GARBAGE-GARBAGE-GARBAGE");
    page.socket.send(Message::text("hello")).unwrap();
    // A flood: 600 frames at once (240 a second allowed).
    for k in 0..600 {
        frame.seq = 10 + k;
        frame.frame_time_ms = 20.0 + f64::from(k);
        webxr_wire::encode(&frame, &mut good);
        page.send(&good);
    }
    page.pump();
    // Oversized: closes this socket (and only it).
    page.send(&vec![0u8; 10_000]);
    let deadline = Instant::now() + Duration::from_secs(3);
    while page.closed.is_none() && Instant::now() < deadline {
        page.pump();
    }
    drop(page);
    let text = wait_for(child, "the webxr session");
    assert_nothing_left(&id);
    let line = text
        .lines()
        .find(|l| l.starts_with("handblocks webxr:") && l.contains("refused"))
        .unwrap_or_else(|| panic!("no webxr summary: {text}"));
    for kind in [
        "length",
        "non_finite",
        "position",
        "magic",
        "text",
        "flood",
        "oversized",
        "order",
    ] {
        assert!(line.contains(kind), "{kind} not counted: {line}");
    }
    // Issue 40: the JSON report names them too (it gave only a total), adding up to it.
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let headset = &v["devices"]["headset"];
    let refused = headset["refused"]
        .as_object()
        .unwrap_or_else(|| panic!("no refusals by name: {headset}"));
    for kind in [
        "length",
        "non_finite",
        "magic",
        "flood",
        "oversized",
        "order",
    ] {
        assert!(
            refused.get(kind).is_some_and(|n| n.as_u64() > Some(0)),
            "{kind}: {headset}"
        );
    }
    let named: u64 = refused.values().filter_map(|n| n.as_u64()).sum();
    assert_eq!(
        Some(named),
        headset["rejected_records"].as_u64(),
        "{headset}"
    );
    let worlds: Vec<WorldSample> = Recording::open(&rec).unwrap().worlds().collect();
    assert!(!worlds.is_empty());
    for w in &worlds {
        assert!(w.blocks().iter().all(|b| b.pose.is_finite()));
        let p: Pose = w.blocks()[0].pose;
        assert!(p.position.iter().all(|v| v.abs() < 100.0));
    }
}

/// The tracking rule: a hand that loses tracking mid-carry holds its grasp through a 50 ms gap,
/// lets go once a gap passes 100 ms (counted), and a socket that drops is counted while the
/// world goes on (the released block falls to the floor).
#[test]
fn a_lost_hand_holds_its_grasp_for_100_ms_then_lets_go_and_a_dropped_socket_is_counted() {
    let dir = Scratch::new("webxr-gap");
    let port = free_port();
    let id = format!("wg{}", std::process::id());
    let (rec, report) = (dir.path("run.mcap"), dir.path("report.json"));
    let samples = headset_samples(&carl("lift"));
    let child = launch("lift", &id, port, 8.0, &rec, &report);
    let mut page = Page::open(port, TOKEN);
    page.wait_ready();
    // The lift until the block is held up (about 1.9 s in: steps 200-240 hold it at ~0.55 m).
    let held = samples
        .iter()
        .position(|s| s.0 >= 1_900_000_000)
        .expect("a 2.9 s trace");
    play(&mut page, &samples[..=held]);
    let (t_held, _, hand) = samples[held];
    let mut frame = HandsFrame::default();
    let mut bytes = Vec::new();
    let mut seq = held as u32 + 1;
    let mut send = |page: &mut Page, ms: f64, hand: Option<&HandJoints>| {
        seq += 1;
        frame.seq = seq;
        frame.frame_time_ms = ms;
        frame.present = [false, hand.is_some()];
        if let Some(h) = hand {
            frame.hands[1] = *h;
        }
        webxr_wire::encode(&frame, &mut bytes);
        page.send(&bytes);
        page.pump();
        std::thread::sleep(Duration::from_millis(5));
    };
    let t0 = t_held as f64 / 1e6;
    // A 44 ms gap (frames without the hand), then the hand again: held throughout.
    for k in 1..=4 {
        send(&mut page, t0 + 11.0 * f64::from(k), None);
    }
    send(&mut page, t0 + 55.0, Some(&hand));
    // A 220 ms gap: let go after 100 ms.
    let gap_from = t0 + 55.0;
    for k in 1..=20 {
        send(&mut page, gap_from + 11.0 * f64::from(k), None);
    }
    // The socket drops; the world goes on without a hand.
    drop(page);
    let text = wait_for(child, "the webxr session");
    assert_nothing_left(&id);

    let worlds: Vec<WorldSample> = Recording::open(&rec).unwrap().worlds().collect();
    let first = worlds[0].stamp.source_time_ns;
    let at_ms = |w: &WorldSample| (w.stamp.source_time_ns - first) as f64 / 1e6;
    let grasped = |from: f64, to: f64| {
        worlds
            .iter()
            .filter(|w| (from..=to).contains(&at_ms(w)))
            .map(|w| w.grasped_block == 0)
            .collect::<Vec<_>>()
    };
    let short_gap = grasped(t0, t0 + 55.0);
    assert!(
        !short_gap.is_empty() && short_gap.iter().all(|g| *g),
        "let go in a 44 ms gap: {short_gap:?}"
    );
    let within_hold = grasped(gap_from, gap_from + 99.0);
    assert!(
        within_hold.iter().all(|g| *g),
        "let go within the hold: {within_hold:?}"
    );
    let after_hold = grasped(gap_from + 111.0, gap_from + 220.0);
    assert!(
        !after_hold.is_empty() && after_hold.iter().all(|g| !*g),
        "still held after 100 ms: {after_hold:?}"
    );
    let last = worlds.last().unwrap();
    assert!(
        last.blocks()[0].pose.position[1] < 0.1,
        "the released block fell: at {} m",
        last.blocks()[0].pose.position[1]
    );
    let line = text
        .lines()
        .find(|l| l.starts_with("handblocks webxr:") && l.contains("refused"))
        .unwrap_or_else(|| panic!("no webxr summary: {text}"));
    assert!(line.contains("driving sockets lost 1"), "{line}");
    assert!(
        line.contains("tracking gaps over 100 ms (the hand let go) 1"),
        "{line}"
    );
}

/// A webxr session's keys are checked before anything starts, naming the file, the key and
/// what is allowed; `emulate headset` says what it needs.
#[test]
fn bad_webxr_settings_and_emulate_usage_name_what_is_wrong() {
    let session = repo().join("config/sessions/webxr.toml");
    let check = |set: &str, want: &[&str]| {
        let out = Command::new(EXE)
            .args(["launch", "--quiet", "--duration", "1", "--set", set])
            .arg(&session)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{set}: {err}");
        for w in want {
            assert!(err.contains(w), "{set}: {w:?} not in {err}");
        }
    };
    check("source.token=short", &["webxr.toml", "token", "16 to 128"]);
    check(
        "source.listen=nowhere",
        &["webxr.toml", "listen", "0.0.0.0:8443"],
    );
    check(
        "source.hand=middle",
        &["webxr.toml", "hand", "\"right\", \"left\", \"both\""],
    );
    let emulate = |args: &[&str], want: &str| {
        let out = Command::new(EXE)
            .arg("emulate")
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {want:?} not in {err}");
    };
    emulate(&["headset"], "the page's URL");
    emulate(&["headset", "https://127.0.0.1:1/?token=x"], "--trace FILE");
    // Issue 43: --spectator with --trace was played as a spectator, the trace dropped unsaid.
    emulate(
        &[
            "headset",
            "https://127.0.0.1:1/?token=x",
            "--spectator",
            "--trace",
            "x.carl",
        ],
        "--spectator plays no trace",
    );
    emulate(&["glove"], "--link PATH");
}

/// One hands frame of the right hand, encoded.
fn hands_frame(seq: u32, time_ms: f64, hand: &HandJoints) -> Vec<u8> {
    let mut frame = HandsFrame {
        seq,
        frame_time_ms: time_ms,
        present: [false, true],
        ..Default::default()
    };
    frame.hands[1] = *hand;
    let mut bytes = Vec::new();
    webxr_wire::encode(&frame, &mut bytes);
    bytes
}

/// The session's summary line (`handblocks webxr: ... refused: ...`).
fn summary(text: &str) -> &str {
    text.lines()
        .find(|l| l.starts_with("handblocks webxr:") && l.contains("refused"))
        .unwrap_or_else(|| panic!("no webxr summary: {text}"))
}

/// The count after `label` in the summary line (`... label N ...`).
fn count_after(line: &str, label: &str) -> u64 {
    let rest = line
        .split_once(label)
        .unwrap_or_else(|| panic!("no {label:?} in {line}"))
        .1;
    rest.trim_start()
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count after {label:?} in {line}"))
}

/// Issue 40, finding 4: a frame timed 1e9 ms ahead of its page's clock is refused by name
/// (`clock`) instead of holding every later frame of the session to it, and a page that sent a
/// time ahead (within the limit) does not hold the next driver to it either: a fresh page
/// that plays the lift trace after it has every frame published, none refused as `order`,
/// and the driver is not lost and retaken frame after frame.
#[test]
fn a_frame_far_ahead_of_its_pages_clock_is_refused_and_the_next_page_still_drives() {
    let dir = Scratch::new("webxr-clock");
    let port = free_port();
    let id = format!("wc{}", std::process::id());
    let (rec, report) = (dir.path("run.mcap"), dir.path("report.json"));
    let samples = headset_samples(&carl("lift"));
    let seconds = samples.last().unwrap().0 as f64 / 1e9 + 7.0;
    let child = launch("lift", &id, port, seconds, &rec, &report);
    let (_, _, hand) = samples.iter().find(|s| s.1).copied().unwrap();

    let mut first = Page::open(port, TOKEN);
    first.wait_ready();
    let now = first.now_ms();
    first.send(&hands_frame(1, now, &hand));
    // The session-freezing frame: refused (`clock`).
    first.send(&hands_frame(2, now + 1e9, &hand));
    // Ahead, but within the limit: published, and its page's own business.
    first.send(&hands_frame(3, now + 4000.0, &hand));
    let until = Instant::now() + Duration::from_millis(300);
    while Instant::now() < until {
        first.pump();
    }
    drop(first);

    let mut second = Page::open(port, TOKEN);
    second.wait_ready();
    play(&mut second, &samples);
    let until = Instant::now() + Duration::from_millis(500);
    while Instant::now() < until {
        second.pump();
    }
    drop(second);
    let text = wait_for(child, "the webxr session");
    assert_nothing_left(&id);
    let line = summary(&text);
    assert!(
        line.contains("clock 1"),
        "the far frame not refused: {line}"
    );
    assert!(
        !line.contains(", order"),
        "the next page held to it: {line}"
    );
    assert!(
        count_after(line, "driving sockets lost") <= 2,
        "the driver lost and retaken: {line}"
    );
    assert_eq!(count_after(line, "handblocks webxr:"), 2, "{line}");
    assert!(
        count_after(line, "pages connected;") >= samples.len() as u64 + 2,
        "not every frame of the second page published: {line}"
    );
    assert!(second_page_drove(&rec), "no world grasped the block");
}

/// The second page of the test above lifted the block: some world has it grasped.
fn second_page_drove(rec: &Path) -> bool {
    Recording::open(rec)
        .unwrap()
        .worlds()
        .any(|w| w.grasped_block == 0)
}

/// Issue 40, finding 5: a user who leaves XR for 2.5 s (the page stays, answering pings,
/// sending no frame) is a pause within the session's silence budget: the untracked samples
/// that keep the world going begin before the budget ends, and the session passes, here with
/// the default budget of 1 s.
#[test]
fn a_pause_of_the_driving_page_stays_within_the_silence_budget() {
    let dir = Scratch::new("webxr-pause");
    let port = free_port();
    let id = format!("wp{}", std::process::id());
    let (rec, report) = (dir.path("run.mcap"), dir.path("report.json"));
    let samples = headset_samples(&carl("lift"));
    let extra = [
        "source.tls=false".to_string(),
        "budget.source_silence_ms=1000".to_string(),
    ];
    let child = launch_webxr("lift", &id, port, TOKEN, 7.0, &extra, (&rec, &report));
    let mut page = Page::open(port, TOKEN);
    page.wait_ready();
    let played = samples.len() / 3;
    play(&mut page, &samples[..played]);
    // Out of XR: pings answered, no frame.
    let until = Instant::now() + Duration::from_millis(2500);
    while Instant::now() < until {
        page.pump();
    }
    // Back in XR: frames again, in the page's time after the pause.
    let t_last = samples[played - 1].0;
    let (_, _, hand) = samples.iter().find(|s| s.1).copied().unwrap();
    for k in 1..=20u32 {
        let ms = t_last as f64 / 1e6 + 2500.0 + 11.0 * f64::from(k);
        page.send(&hands_frame(played as u32 + k, ms, &hand));
        page.pump();
        std::thread::sleep(Duration::from_millis(11));
    }
    drop(page);
    let text = wait_for(child, "a webxr session with a 2.5 s pause");
    assert_nothing_left(&id);
    assert!(!text.contains("VIOLATED"), "{text}");
    let line = summary(&text);
    assert!(
        count_after(line, "driving sockets lost") >= 1,
        "the pause not taken as a gap: {line}"
    );
}

/// Issue 40, findings 5 and 10: a session no headset joined says so plainly and exits 1 (as
/// docs/webxr.md says); plain HTTP on every interface says where it listens and warns that
/// the token crosses the network in clear.
#[test]
fn a_session_no_headset_joined_says_so_and_plain_http_on_a_network_is_warned_of() {
    let dir = Scratch::new("webxr-nobody");
    let port = free_port();
    let id = format!("wn{}", std::process::id());
    let (rec, report) = (dir.path("run.mcap"), dir.path("report.json"));
    let extra = [
        "source.tls=false".to_string(),
        format!("source.listen=0.0.0.0:{port}"),
    ];
    let child = launch_webxr("lift", &id, port, TOKEN, 2.0, &extra, (&rec, &report));
    let out = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_nothing_left(&id);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(text.contains("no headset joined this session"), "{text}");
    assert!(
        text.contains(&format!(
            "listening on 0.0.0.0:{port} (plain HTTP): every interface"
        )),
        "{text}"
    );
    assert!(
        text.contains("WARNING") && text.contains("in clear"),
        "{text}"
    );
}

/// Issue 40, finding 7: pages that stop answering pings are dropped within a few seconds
/// (counted), so eight idle pages do not hold every slot: a new page is served after them.
#[test]
fn pages_that_stop_answering_pings_are_dropped_and_free_their_slots() {
    let dir = Scratch::new("webxr-idle");
    let port = free_port();
    let id = format!("wi{}", std::process::id());
    let (rec, report) = (dir.path("run.mcap"), dir.path("report.json"));
    let child = launch("lift", &id, port, 20.0, &rec, &report);
    // Eight pages that read nothing, so answer no ping.
    let idle: Vec<Socket> = (0..8).map(|_| connect(port, TOKEN)).collect();
    // The server counts a page once past the handshake the client has already seen.
    std::thread::sleep(Duration::from_millis(500));
    let mut ninth = Page::open(port, TOKEN);
    let deadline = Instant::now() + Duration::from_secs(5);
    while ninth.closed.is_none() && Instant::now() < deadline {
        ninth.pump();
    }
    let closed = ninth.closed.clone().unwrap_or_default();
    assert!(
        closed.starts_with("4003"),
        "every slot held: closed {closed:?}"
    );
    // After the pong timeout (5 s) and a ping's period: the idle pages are gone.
    std::thread::sleep(Duration::from_millis(7500));
    let mut late = Page::open(port, TOKEN);
    late.wait_ready();
    assert!(late.closed.is_none(), "closed with {:?}", late.closed);
    drop(late);
    drop(idle);
    // The session has no hand: it ends failing its silence budget (exit 1), as it should.
    let out = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_nothing_left(&id);
    let line = summary(&text);
    assert_eq!(
        count_after(line, "pages dropped for not answering pings"),
        8,
        "{line}"
    );
}

/// Issue 40, finding 10: `webxr.toml` with `tls = false` serves this machine only (the token
/// would cross the network in clear otherwise), unless `listen` names a network address.
#[test]
fn webxr_toml_with_tls_off_listens_on_this_machine_only_unless_told() {
    use common::config::session::{Override, Source};
    let file = repo().join("config/sessions/webxr.toml");
    let listen = |sets: &[&str]| {
        let overrides: Vec<Override> = sets.iter().map(|s| Override::parse(s).unwrap()).collect();
        match common::config::Session::load_with(&file, &overrides)
            .unwrap()
            .source
        {
            Source::Webxr(w) => w.listen.to_string(),
            _ => panic!("not a webxr session"),
        }
    };
    assert_eq!(listen(&[]), "0.0.0.0:8443");
    assert_eq!(listen(&["source.tls=false"]), "127.0.0.1:8443");
    assert_eq!(
        listen(&["source.tls=false", "source.listen=0.0.0.0"]),
        "0.0.0.0:8443"
    );
}
