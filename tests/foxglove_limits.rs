//! The live Foxglove view's bounds (issue 40): what a client that never reads, never finishes
//! its opening request, or sends a malformed one may cost the bridge. Each test runs the view
//! (`bridge::viewer::Viewer`: the gate and the `foxglove` server behind it) inside this test
//! process, fed by the test, so what it measures (this process's threads and resident memory)
//! is the view's alone; the tests take one lock, so none measures another's clients.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use bridge::viewer::Viewer;
use common::config::Scene;
use common::samples::{BlockState, WorldHeader};
use common::Topic;
use serde_json::Value;
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

mod support;
use support::repo;

/// One test at a time: they count this process's threads and resident memory.
fn serial() -> MutexGuard<'static, ()> {
    static SERIAL: Mutex<()> = Mutex::new(());
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn scene(name: &str) -> Scene {
    Scene::load(&repo().join("config/scenes").join(name)).expect("the scene loads")
}

/// A view of `scene` on a free loopback port, serving `/world`, with the default limits.
fn view(scene: &Scene) -> Viewer {
    Viewer::start("127.0.0.1", 0, scene, &[Topic::World]).expect("the view starts")
}

/// A `/world` message of `blocks` blocks, as the bridge hands the view one.
fn world_message(blocks: usize) -> Vec<u8> {
    let header = WorldHeader {
        block_count: blocks as u32,
        ..WorldHeader::default()
    };
    let states = vec![BlockState::default(); blocks];
    let mut out = Vec::new();
    recording::encode_slice(Topic::World, &header, &states, &mut out);
    out
}

/// Resident memory of this process, in MiB.
fn rss_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    let kib: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("VmRSS in /proc/self/status");
    kib / 1024.0
}

/// Threads of this process.
fn threads() -> usize {
    std::fs::read_dir("/proc/self/task")
        .expect("/proc/self/task")
        .count()
}

type Client = WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

/// A Foxglove client of the view on `port` (the SDK subprotocol), or the HTTP status it was
/// refused with.
fn connect(port: u16) -> Result<Client, u16> {
    let mut req = format!("ws://127.0.0.1:{port}")
        .into_client_request()
        .expect("a request");
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.sdk.v1".parse().expect("a header value"),
    );
    match tungstenite::connect(req) {
        Ok((socket, _)) => Ok(socket),
        Err(tungstenite::Error::Http(r)) => Err(r.status().as_u16()),
        Err(e) => panic!("connecting to the view: {e}"),
    }
}

fn stream(c: &Client) -> &TcpStream {
    match c.get_ref() {
        tungstenite::stream::MaybeTlsStream::Plain(s) => s,
        _ => unreachable!("no TLS here"),
    }
}

/// Subscribes `client` to `/world` and waits for its first world (logging worlds meanwhile),
/// so the server then queues every world for it.
fn subscribe_to_world(client: &mut Client, viewer: &mut Viewer, message: &[u8]) {
    stream(client)
        .set_read_timeout(Some(Duration::from_millis(20)))
        .expect("a read timeout");
    let until = Instant::now() + Duration::from_secs(10);
    let mut subscribed = false;
    while Instant::now() < until {
        viewer.log(Topic::World, message);
        match client.read() {
            Ok(Message::Text(t)) if !subscribed => {
                let v: Value = serde_json::from_str(&t).expect("JSON from the server");
                if v["op"] != "advertise" {
                    continue;
                }
                for c in v["channels"].as_array().expect("channels") {
                    if c["topic"] == "/world" {
                        let sub = serde_json::json!({
                            "op": "subscribe",
                            "subscriptions": [{"id": 1, "channelId": c["id"]}],
                        });
                        client
                            .send(Message::text(sub.to_string()))
                            .expect("subscribe");
                        subscribed = true;
                    }
                }
            }
            Ok(Message::Binary(_)) => return,
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("reading from the view: {e}"),
        }
    }
    panic!("no world reached a subscribed client in 10 s");
}

/// Sends `head` raw and returns what the view answered before it closed (all of it, up to
/// `wait`).
fn answer_to(port: u16, head: &str, wait: Duration) -> String {
    let mut s = TcpStream::connect(("127.0.0.1", port)).expect("connect");
    s.write_all(head.as_bytes()).expect("send the head");
    s.set_read_timeout(Some(wait)).expect("a read timeout");
    let mut answer = Vec::new();
    let _ = s.read_to_end(&mut answer);
    String::from_utf8_lossy(&answer).into_owned()
}

/// Never-reading clients on a 1024-block field: each costs the view a bounded backlog (the
/// server's queue of messages it could not send), not the `foxglove` crate's default of 1024
/// messages (~64 MiB a client here), and the memory is given back when they leave.
#[test]
fn never_reading_clients_cost_a_bounded_backlog_and_give_it_back() {
    let _serial = serial();
    let field = scene("field-1024.toml");
    let message = world_message(field.blocks.len());
    let mut viewer = view(&field);
    viewer.log(Topic::World, &message);
    const CLIENTS: usize = 4;
    let mut clients: Vec<Client> = (0..CLIENTS)
        .map(|_| connect(viewer.port).expect("a client under the cap"))
        .collect();
    for c in &mut clients {
        subscribe_to_world(c, &mut viewer, &message);
    }
    // They stop reading now: the sockets' buffers fill, then the server's queues.
    let before = rss_mib();
    let mut peak = before;
    for i in 0..3000 {
        viewer.log(Topic::World, &message);
        if i % 100 == 0 {
            peak = peak.max(rss_mib());
        }
    }
    std::thread::sleep(Duration::from_millis(300));
    peak = peak.max(rss_mib());
    drop(clients);
    let until = Instant::now() + Duration::from_secs(8);
    let mut after = rss_mib();
    while after > before + 16.0 && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(100));
        after = rss_mib();
    }
    eprintln!(
        "{CLIENTS} never-reading clients, {} blocks ({} KiB a world): RSS before {before:.0} \
         MiB, peak {peak:.0} MiB, after they left {after:.0} MiB",
        field.blocks.len(),
        message.len() / 1024
    );
    viewer.stop();
    // The default backlog is ~4 MiB a client; the sockets' buffers are the kernel's.
    assert!(
        peak - before < 12.0 * CLIENTS as f64,
        "{CLIENTS} never-reading clients grew the view by {:.0} MiB",
        peak - before
    );
    assert!(
        after < before + 16.0,
        "the view kept {:.0} MiB after its clients left",
        after - before
    );
}

/// The view serves at most `[viewer] foxglove_clients` clients (8 by default): the next is
/// answered 503 with what to do, and a place that frees is taken again.
#[test]
fn the_view_serves_at_most_its_cap_of_clients() {
    let _serial = serial();
    let field = scene("push.toml");
    let viewer = view(&field);
    let mut clients: Vec<Client> = (0..8)
        .map(|i| connect(viewer.port).unwrap_or_else(|s| panic!("client {i} refused: {s}")))
        .collect();
    assert_eq!(connect(viewer.port).err(), Some(503), "a ninth client");
    let answer = answer_to(
        viewer.port,
        "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
         Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n",
        Duration::from_secs(5),
    );
    assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
    assert!(answer.contains("foxglove_clients"), "{answer}");
    clients.pop().expect("a client").close(None).ok();
    drop(clients.pop());
    // The places free as the gate sees the connections end.
    let until = Instant::now() + Duration::from_secs(10);
    let again = loop {
        match connect(viewer.port) {
            Ok(c) => break c,
            Err(503) if Instant::now() < until => std::thread::sleep(Duration::from_millis(50)),
            Err(s) => panic!("a client after two left: {s}"),
        }
    };
    drop(again);
    drop(clients);
    viewer.stop();
}

/// Connections that send nothing cost at most a bounded number of threads between them
/// (each used to cost one for up to 5 s a read, for ever if it trickled).
#[test]
fn silent_connections_cost_a_bounded_number_of_threads() {
    let _serial = serial();
    let field = scene("push.toml");
    let viewer = view(&field);
    std::thread::sleep(Duration::from_millis(200));
    let base = threads();
    let silent: Vec<TcpStream> = (0..100)
        .filter_map(|_| TcpStream::connect(("127.0.0.1", viewer.port)).ok())
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let during = threads();
    eprintln!(
        "{} silent connections: {base} threads before, {during} with them",
        silent.len()
    );
    drop(silent);
    viewer.stop();
    assert!(
        during <= base + 40,
        "100 silent connections took {} threads",
        during - base
    );
}

/// An opening request has one deadline (5 s) in all, not 5 s a read: one trickled a byte
/// every 500 ms is answered 408 and closed.
#[test]
fn a_trickled_head_is_closed_at_its_deadline() {
    let _serial = serial();
    let field = scene("push.toml");
    let viewer = view(&field);
    let mut s = TcpStream::connect(("127.0.0.1", viewer.port)).expect("connect");
    s.set_read_timeout(Some(Duration::from_millis(500)))
        .expect("a read timeout");
    let start = Instant::now();
    let head = b"GET / HTTP/1.1\r\nHost: x\r\nX-Slow: ";
    let mut answer = Vec::new();
    let mut closed = None;
    let mut i = 0;
    while start.elapsed() < Duration::from_secs(12) {
        if s.write_all(&[head.get(i).copied().unwrap_or(b'a')])
            .is_err()
        {
            closed = Some(start.elapsed());
            break;
        }
        i += 1;
        let mut buf = [0u8; 1024];
        match s.read(&mut buf) {
            Ok(0) => {
                closed = Some(start.elapsed());
                break;
            }
            Ok(n) => answer.extend_from_slice(&buf[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => {
                closed = Some(start.elapsed());
                break;
            }
        }
    }
    viewer.stop();
    let answer = String::from_utf8_lossy(&answer);
    let closed = closed.unwrap_or_else(|| {
        panic!("a head trickled a byte every 500 ms was still open after 12 s: {answer}")
    });
    eprintln!(
        "a trickled head closed after {:.1} s: {answer:?}",
        closed.as_secs_f64()
    );
    assert!(closed < Duration::from_secs(10), "closed after {closed:?}");
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
}

/// Every opening request the view refuses is answered 400 with the reason: an HTTP/1.0 one, a
/// POST, one without a key, without `Upgrade: websocket`, of another WebSocket version, or
/// without a Foxglove subprotocol.
#[test]
fn every_refused_head_is_answered_400() {
    let _serial = serial();
    let field = scene("push.toml");
    let viewer = view(&field);
    const KEY: &str = "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
    const UPGRADE: &str = "Upgrade: websocket\r\nConnection: Upgrade\r\n";
    const VERSION: &str = "Sec-WebSocket-Version: 13\r\n";
    const PROTOCOL: &str = "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n";
    let cases = [
        (
            "HTTP/1.0",
            format!("GET / HTTP/1.0\r\nHost: x\r\n{UPGRADE}{KEY}{VERSION}{PROTOCOL}\r\n"),
        ),
        (
            "POST",
            format!(
                "POST / HTTP/1.1\r\nHost: x\r\n{UPGRADE}{KEY}{VERSION}{PROTOCOL}\
                 Content-Length: 5\r\n\r\nhello"
            ),
        ),
        (
            "no key",
            format!("GET / HTTP/1.1\r\nHost: x\r\n{UPGRADE}{VERSION}{PROTOCOL}\r\n"),
        ),
        (
            "no upgrade",
            format!("GET / HTTP/1.1\r\nHost: x\r\n{KEY}{VERSION}{PROTOCOL}\r\n"),
        ),
        (
            "version 8",
            format!(
                "GET / HTTP/1.1\r\nHost: x\r\n{UPGRADE}{KEY}Sec-WebSocket-Version: 8\r\n\
                 {PROTOCOL}\r\n"
            ),
        ),
        (
            "no subprotocol",
            format!("GET / HTTP/1.1\r\nHost: x\r\n{UPGRADE}{KEY}{VERSION}\r\n"),
        ),
        ("not HTTP", "hello\r\n\r\n".to_string()),
    ];
    let mut wrong = Vec::new();
    for (what, head) in &cases {
        let answer = answer_to(viewer.port, head, Duration::from_secs(5));
        if !answer.starts_with("HTTP/1.1 400") {
            wrong.push(format!("{what}: {answer:?}"));
        }
    }
    viewer.stop();
    assert!(wrong.is_empty(), "not answered 400:\n{}", wrong.join("\n"));
}

/// The cap is a session key, checked with the file, the key and the range named.
#[test]
fn the_client_cap_is_a_checked_key() {
    let session = repo().join("config/sessions/live.toml");
    let load = |value: &str| {
        common::config::Session::load_with(
            &session,
            &[common::config::session::Override::parse(&format!(
                "viewer.foxglove_clients={value}"
            ))
            .expect("an override")],
        )
    };
    let s = load("3").expect("foxglove_clients = 3");
    assert_eq!(s.bridge.foxglove_clients, 3);
    for bad in ["0", "100000", "\"many\""] {
        let e = load(bad).expect_err(bad).to_string();
        assert!(
            e.contains("viewer.foxglove_clients") && e.contains("live.toml"),
            "{bad}: {e}"
        );
        if bad != "\"many\"" {
            assert!(e.contains("1 to 64"), "{bad}: {e}");
        }
    }
}
