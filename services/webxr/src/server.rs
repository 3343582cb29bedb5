//! The page's server: HTTPS (or plain HTTP for `http://localhost`) and one WebSocket per page,
//! on the shared HTTP front's tokio threads ([`http_front`]) beside the synchronous stage loop.
//!
//! Routes: `GET /?token=T` the page (403 without the session's token), `GET /app.js` and
//! `GET /gl.js` its scripts, `GET /ws?token=T` the socket (a wrong token is accepted as a
//! WebSocket and closed at once with code 4001 and a reason the page shows, since a browser
//! cannot read an HTTP refusal of a WebSocket). Another method is 405, another path 404. The
//! front reads each request: one not complete in 10 s (the TLS handshake included) is answered
//! 408 where it can be and closed, one over 8 KiB is answered 431, one that is not HTTP 400;
//! each counted `request`.
//!
//! Per socket: the scene (text, once), a clock ping every 100 ms for the first second and every
//! second after, and the newest world whenever there is one (a slow page skips worlds, never
//! queues them); in a shared world, the other participants' hands the same way. What the page sends is decoded here ([`webxr_wire`]); a refused message is
//! counted by its kind in [`Tally`] and the socket stays open; a message over
//! [`MAX_MESSAGE_BYTES`] closes it (counted `oversized`); hands frames beyond
//! [`MAX_FRAMES_PER_S`] are dropped (counted `flood`); a hands frame timed more than
//! [`MAX_AHEAD_OF_CLOCK_MS`] ahead of its page's clock is refused (`clock`). A page that
//! answers no ping for [`PONG_TIMEOUT`], or takes longer than that to take a message, is
//! closed ([`CLOSE_UNANSWERED`], counted in [`Tally::unanswered`]), so idle pages do not hold
//! the [`MAX_PAGES`] slots. The stage gets the rest through a bounded queue ([`Inbound`]) and
//! a [`Wake`].
//!
//! **The clock.** Each pong gives an estimate of the page's clock against this machine's
//! (CLOCK_MONOTONIC): the ping's send and the pong's receive bracket the page's reading, so
//! `offset = (sent + received) / 2 - page`, within half the round trip. The estimate with the
//! shortest round trip so far is kept; after [`PONGS_BEFORE_READY`] pongs the page is told
//! `ready` (it sends hands only then) and the stage is given the offset.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bytes::Bytes;
use common::bus::Wake;
use common::monotonic_ns;
use futures_util::{SinkExt, StreamExt};
use http_front::http::{header, HeaderValue, Method, Response, StatusCode};
use http_front::{FrontBuilder, Handler, OpenError, Opened, Reading, StartError};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::watch;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::protocol::{CloseFrame, WebSocketConfig};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::WebSocketStream;
use webxr_wire::page::{self, FrameStats};
use webxr_wire::{HandsFrame, KIND_HANDS};

use crate::page::{APP_JS, GL_JS, INDEX_HTML};

/// The largest message a page may send (a hands frame is 1624 bytes).
pub const MAX_MESSAGE_BYTES: usize = 4096;
/// Hands frames a page may send per second, sustained (a headset draws at most 120).
pub const MAX_FRAMES_PER_S: f64 = 240.0;
/// Pages served at once; more are refused (503).
pub const MAX_PAGES: u64 = 8;
/// Pongs before the clock is trusted.
pub const PONGS_BEFORE_READY: u32 = 5;
/// A page that answers no ping for this long is dropped (counted `unanswered`), so pages
/// left open and asleep (a headset taken off, a laptop's lid shut) do not hold the
/// [`MAX_PAGES`] slots: pings go out every second, and a page, even one in the background,
/// answers each within a round trip. A page that wakes reconnects by itself.
pub const PONG_TIMEOUT: Duration = Duration::from_secs(5);
/// The close code a page that stopped answering pings is given.
pub const CLOSE_UNANSWERED: u16 = 4008;
/// How far ahead of the page's own clock (as the pings estimate it) a frame's time may be.
/// A frame's `predictedDisplayTime` is at most a few display frames ahead of the page's
/// `performance.now()`; one much further ahead is refused (`clock`), since a source time far
/// in the future would hold every later frame of the session to it (they would all be
/// refused as `order`). Frames behind the clock are let through: a page may play a recording
/// in the recording's own time (`emulate headset` does), and a late frame holds nobody.
pub const MAX_AHEAD_OF_CLOCK_MS: f64 = 5000.0;
/// Messages queued for the stage; beyond it they are dropped (counted `queue_full`).
const INBOUND_QUEUE: usize = 256;
/// The longest request head read.
const MAX_HEAD_BYTES: usize = 8192;
/// How long a connection may take to finish its TLS handshake and send its request head.
const HEAD_TIMEOUT: Duration = Duration::from_secs(10);
/// The close code a page with a wrong token is given.
pub const CLOSE_WRONG_TOKEN: u16 = 4001;

/// What the server was started with.
pub struct ServerSettings {
    pub listen: SocketAddr,
    /// Some: HTTPS and WSS.
    pub tls: Option<Arc<rustls::ServerConfig>>,
    pub token: String,
    /// The scene message every page is sent first (JSON).
    pub scene_json: String,
}

/// What a page's socket hands the stage. The queue's slots are sized for the largest (a
/// hands frame, 1.6 KB) and made once, so nothing is allocated per message: boxing the frame
/// would allocate one per frame.
#[derive(Debug, Clone, Copy)]
#[allow(clippy::large_enum_variant)]
pub enum Inbound {
    /// A hands frame, decoded, with when its message arrived (CLOCK_MONOTONIC).
    Hands {
        page: u64,
        arrived_ns: u64,
        frame: HandsFrame,
    },
    /// The page's timing of one of its frames.
    Stats { page: u64, stats: FrameStats },
    /// The page's clock: add `offset_ns` to its time (ns) for this machine's.
    Clock {
        page: u64,
        offset_ns: i64,
        round_trip_ns: u64,
        pongs: u32,
    },
    /// The page's socket closed.
    Closed { page: u64 },
}

/// Kinds of refusal, counted by name (each message refused once, under its first fault).
pub const REFUSALS: [&str; 19] = [
    "token",
    "busy",
    "request",
    "oversized",
    "flood",
    "text",
    "queue_full",
    "magic",
    "kind",
    "reserved",
    "hands",
    "length",
    "frame_time",
    "clock",
    "value",
    "non_finite",
    "position",
    "orientation",
    "radius",
];

/// The server's counts, read by the stage for its report.
#[derive(Debug, Default)]
pub struct Tally {
    refused: [AtomicU64; REFUSALS.len() + 1],
    pub sockets: AtomicU64,
    pages_now: AtomicU64,
    /// Pages dropped because they answered no ping for [`PONG_TIMEOUT`].
    pub unanswered: AtomicU64,
}

impl Tally {
    /// Counts a refusal of kind `kind` (a name of [`REFUSALS`]; anything else as "other").
    pub fn refuse(&self, kind: &str) {
        let i = REFUSALS
            .iter()
            .position(|k| *k == kind)
            .unwrap_or(REFUSALS.len());
        self.refused[i].fetch_add(1, Ordering::Relaxed);
    }

    /// Each kind of refusal with its count, those counted only.
    pub fn refusals(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        REFUSALS
            .iter()
            .copied()
            .chain(["other"])
            .zip(self.refused.iter().map(|c| c.load(Ordering::Relaxed)))
            .filter(|(_, n)| *n > 0)
    }

    /// Every message refused.
    pub fn refused_total(&self) -> u64 {
        self.refused.iter().map(|c| c.load(Ordering::Relaxed)).sum()
    }
}

/// Why the server could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    #[error("cannot listen on {listen}: {source}; another program (or session) uses the port? set [source] listen = \"0.0.0.0:PORT\"")]
    Listen {
        listen: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot start the page's server: {0}")]
    Runtime(#[source] std::io::Error),
}

/// The running server; dropped, it stops (sockets closed, threads joined).
pub struct Server {
    front: http_front::Front,
    pub inbound: crossbeam_channel::Receiver<Inbound>,
    wake: Arc<Wake>,
    world: watch::Sender<Bytes>,
    peers: watch::Sender<Bytes>,
    stop: watch::Sender<bool>,
    pub tally: Arc<Tally>,
    pub local_addr: SocketAddr,
}

/// What every connection's task shares: the front's [`Handler`].
struct Shared {
    token: String,
    scene_json: String,
    inbound: crossbeam_channel::Sender<Inbound>,
    wake: Arc<Wake>,
    tally: Arc<Tally>,
    world: watch::Receiver<Bytes>,
    /// The other participants' hands (a shared world's), newest only; a page that opens
    /// gets the current ones at once (never marked seen here).
    peers: watch::Receiver<Bytes>,
    stop: watch::Receiver<bool>,
    next_page: AtomicU64,
}

impl Server {
    /// Binds `listen` now (so a port in use fails the process before the session counts on
    /// it) and serves on two tokio threads.
    pub fn start(settings: ServerSettings) -> Result<Server, ServerError> {
        let (tx, inbound) = crossbeam_channel::bounded(INBOUND_QUEUE);
        let wake = Arc::new(Wake::new().map_err(ServerError::Runtime)?);
        let tally = Arc::new(Tally::default());
        let (world, world_rx) = watch::channel(Bytes::new());
        let (peers, peers_rx) = watch::channel(Bytes::new());
        let (stop, stop_rx) = watch::channel(false);
        let shared = Shared {
            token: settings.token,
            scene_json: settings.scene_json,
            inbound: tx,
            wake: wake.clone(),
            tally: tally.clone(),
            world: world_rx,
            peers: peers_rx,
            stop: stop_rx,
            next_page: AtomicU64::new(1),
        };
        let reading = Reading::default()
            .head_timeout(HEAD_TIMEOUT)
            .max_head_bytes(MAX_HEAD_BYTES);
        let front = FrontBuilder::new("webxr-server")
            .threads(2)
            .reading(reading)
            .tls(settings.tls)
            .start(settings.listen, shared)
            .map_err(|e| match e {
                StartError::Listen(source) => ServerError::Listen {
                    listen: settings.listen,
                    source,
                },
                StartError::Runtime(e) => ServerError::Runtime(e),
            })?;
        let local_addr = front.local_addr();
        Ok(Server {
            front,
            inbound,
            wake,
            world,
            peers,
            stop,
            tally,
            local_addr,
        })
    }

    /// The descriptor the stage sleeps on besides its inlets.
    pub fn wake_fd(&self) -> std::os::fd::RawFd {
        self.wake.fd()
    }

    /// Consumes the wake-ups (the queue is drained by the caller).
    pub fn clear_wake(&self) {
        self.wake.clear();
    }

    /// Sends `message` (a world) to every page: one copy, shared by all sockets, which each
    /// send the newest they have not sent.
    pub fn send_world(&self, message: &[u8]) {
        self.world.send_replace(Bytes::copy_from_slice(message));
    }

    /// Sends `message` (the other participants' hands, [`page::encode_peers`]) to every page,
    /// as [`Server::send_world`] does: each sends the newest it has not sent.
    pub fn send_peers(&self, message: &[u8]) {
        self.peers.send_replace(Bytes::copy_from_slice(message));
    }

    /// Closes every socket and stops the server's threads.
    pub fn stop(&mut self) {
        let _ = self.stop.send(true);
        self.front.stop();
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop();
    }
}

impl Handler for Shared {
    async fn serve(&self, opened: Opened) {
        route(opened, self).await
    }

    fn unopened(&self, why: &OpenError) -> Option<Response<String>> {
        // Every connection that gave no request counts, a TLS handshake refused included (a
        // browser that does not trust the certificate yet closes it, asks, and comes back).
        self.tally.refuse("request");
        why.answer()
    }
}

/// Constant-time comparison of the token (its length is not secret).
fn token_ok(given: Option<&str>, token: &str) -> bool {
    given.is_some_and(|g| {
        g.len() == token.len()
            && g.bytes()
                .zip(token.bytes())
                .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                == 0
    })
}

/// An answer of ours: `body` as `kind`, never cached (a new session serves a new page).
fn reply(status: StatusCode, kind: &'static str, body: &'static str) -> Response<&'static str> {
    let mut response = Response::new(body);
    *response.status_mut() = status;
    let headers = response.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(kind));
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    headers.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    response
}

const NO_TOKEN: &str =
    "This page needs the session's token: open the URL that `handblocks launch` \
printed (it ends in ?token=...), or scan its QR code.\n";

const PLAIN: &str = "text/plain";
const JS: &str = "text/javascript; charset=utf-8";

async fn route(opened: Opened, shared: &Shared) {
    let request = &opened.request;
    if request.method != Method::GET {
        shared.tally.refuse("request");
        let refusal = reply(StatusCode::METHOD_NOT_ALLOWED, PLAIN, "GET only\n");
        return opened.answer(refusal).await;
    }
    let token = token_ok(
        http_front::query_value(&request.uri, "token"),
        &shared.token,
    );
    let answer = match request.uri.path() {
        "/ws" if http_front::is_websocket(request) => return socket(opened, token, shared).await,
        "/" | "/index.html" if token => {
            reply(StatusCode::OK, "text/html; charset=utf-8", INDEX_HTML)
        }
        "/" | "/index.html" => {
            shared.tally.refuse("token");
            reply(StatusCode::FORBIDDEN, PLAIN, NO_TOKEN)
        }
        "/app.js" => reply(StatusCode::OK, JS, APP_JS),
        "/gl.js" => reply(StatusCode::OK, JS, GL_JS),
        _ => reply(StatusCode::NOT_FOUND, PLAIN, "not found\n"),
    };
    opened.answer(answer).await
}

/// The WebSocket handshake's answer, then the page's socket until it closes or we stop;
/// `token`: whether the request named the session's.
async fn socket(opened: Opened, token: bool, shared: &Shared) {
    let Some(key) = opened.request.headers.get(header::SEC_WEBSOCKET_KEY) else {
        shared.tally.refuse("request");
        let refusal = reply(StatusCode::BAD_REQUEST, PLAIN, "no Sec-WebSocket-Key\n");
        return opened.answer(refusal).await;
    };
    let accept = http_front::switching_protocols(key);
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_MESSAGE_BYTES))
        .max_frame_size(Some(MAX_MESSAGE_BYTES));
    let Ok(mut ws) = opened.into_websocket(accept, Some(config)).await else {
        return;
    };
    let refuse = |code: u16, reason: &'static str| CloseFrame {
        code: CloseCode::from(code),
        reason: reason.into(),
    };
    if !token {
        shared.tally.refuse("token");
        let why = "wrong token: open the URL the session printed";
        let _ = ws.close(Some(refuse(CLOSE_WRONG_TOKEN, why))).await;
        return;
    }
    if shared.tally.pages_now.fetch_add(1, Ordering::AcqRel) >= MAX_PAGES {
        shared.tally.pages_now.fetch_sub(1, Ordering::AcqRel);
        shared.tally.refuse("busy");
        let _ = ws
            .close(Some(refuse(
                4003,
                "too many pages are open on this session",
            )))
            .await;
        return;
    }
    let page = shared.next_page.fetch_add(1, Ordering::Relaxed);
    shared.tally.sockets.fetch_add(1, Ordering::Relaxed);
    page_loop(&mut ws, page, shared).await;
    shared.tally.pages_now.fetch_sub(1, Ordering::AcqRel);
    let _ = shared.inbound.try_send(Inbound::Closed { page });
    shared.wake.wake();
}

/// One page's clock estimate: the ping with the shortest round trip so far.
#[derive(Debug, Default)]
struct PageClock {
    sent_ns: [(u32, u64); 16],
    best: Option<(u64, i64)>,
    pongs: u32,
}

impl PageClock {
    fn sent(&mut self, seq: u32, at_ns: u64) {
        self.sent_ns[seq as usize % 16] = (seq, at_ns);
    }

    /// A pong received at `now_ns`: true when the estimate improved.
    fn pong(&mut self, pong: &page::Pong, now_ns: u64) -> bool {
        let (seq, sent) = self.sent_ns[pong.seq as usize % 16];
        if seq != pong.seq || sent == 0 || now_ns < sent {
            return false;
        }
        self.pongs += 1;
        let round_trip = now_ns - sent;
        let offset = (sent + round_trip / 2) as i64 - (pong.page_ms * 1e6).round() as i64;
        if self.best.is_none_or(|(rt, _)| round_trip < rt) {
            self.best = Some((round_trip, offset));
            return true;
        }
        false
    }
}

/// Sends `message`, false when the socket failed or the page took more than [`PONG_TIMEOUT`]
/// to take it (a page that reads nothing would otherwise hold its task, and its slot, for
/// ever once the socket's buffers fill).
/// A page too slow to take it is counted in [`Tally::unanswered`].
async fn send_within<S: AsyncRead + AsyncWrite + Unpin + Send>(
    ws: &mut WebSocketStream<S>,
    message: Message,
    tally: &Tally,
) -> bool {
    match tokio::time::timeout(PONG_TIMEOUT, ws.send(message)).await {
        Ok(sent) => sent.is_ok(),
        Err(_) => {
            tally.unanswered.fetch_add(1, Ordering::Relaxed);
            false
        }
    }
}

/// True when a frame of time `frame_time_ms` (the page's clock), arriving at `arrived_ns`
/// (ours), is more than [`MAX_AHEAD_OF_CLOCK_MS`] ahead of the page's clock, whose offset to
/// ours is `offset_ns`.
fn ahead_of_clock(frame_time_ms: f64, offset_ns: i64, arrived_ns: u64) -> bool {
    let page_now_ms = (i128::from(arrived_ns) - i128::from(offset_ns)) as f64 / 1e6;
    frame_time_ms > page_now_ms + MAX_AHEAD_OF_CLOCK_MS
}

async fn page_loop<S: AsyncRead + AsyncWrite + Unpin + Send>(
    ws: &mut WebSocketStream<S>,
    page: u64,
    shared: &Shared,
) {
    let tally = &*shared.tally;
    if !send_within(ws, Message::text(shared.scene_json.clone()), tally).await {
        return;
    }
    let mut world = shared.world.clone();
    world.mark_unchanged();
    let mut peers = shared.peers.clone();
    let mut stop = shared.stop.clone();
    let mut clock = PageClock::default();
    let mut ping_seq: u32 = 0;
    let mut ping = tokio::time::interval(Duration::from_millis(100));
    ping.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut ready = false;
    let mut out = Vec::with_capacity(page::PING_BYTES);
    let mut frame = HandsFrame::default();
    // When the page last answered a ping (from its socket's start: it has PONG_TIMEOUT to
    // answer the first).
    let mut last_pong_ns = monotonic_ns();
    // The flood limit: a bucket of a second's frames, refilled continuously.
    let mut bucket = MAX_FRAMES_PER_S;
    let mut bucket_at = monotonic_ns();
    let hand_in = |inbound: Inbound| {
        if shared.inbound.try_send(inbound).is_ok() {
            shared.wake.wake();
        } else {
            shared.tally.refuse("queue_full");
        }
    };
    loop {
        tokio::select! {
            message = ws.next() => {
                let bytes = match message {
                    Some(Ok(Message::Binary(b))) => b,
                    Some(Ok(Message::Text(_))) => {
                        shared.tally.refuse("text");
                        continue;
                    }
                    Some(Ok(Message::Close(_))) | None => return,
                    Some(Ok(_)) => continue,
                    Some(Err(e)) => {
                        use tokio_tungstenite::tungstenite::Error;
                        if matches!(e, Error::Capacity(_)) {
                            shared.tally.refuse("oversized");
                            let why = "a message over 4096 bytes";
                            let _ = ws.close(Some(CloseFrame { code: CloseCode::Size, reason: why.into() })).await;
                        }
                        return;
                    }
                };
                let arrived_ns = monotonic_ns();
                let kind = match page::kind_of(&bytes) {
                    Ok(k) => k,
                    Err(e) => {
                        shared.tally.refuse(e.kind());
                        continue;
                    }
                };
                match kind {
                    KIND_HANDS => {
                        bucket = (bucket + (arrived_ns - bucket_at) as f64 * 1e-9 * MAX_FRAMES_PER_S)
                            .min(MAX_FRAMES_PER_S);
                        bucket_at = arrived_ns;
                        if bucket < 1.0 {
                            shared.tally.refuse("flood");
                            continue;
                        }
                        bucket -= 1.0;
                        match webxr_wire::decode_into(&bytes, &mut frame) {
                            Ok(()) if clock.best.is_some_and(|(_, offset_ns)| {
                                ahead_of_clock(frame.frame_time_ms, offset_ns, arrived_ns)
                            }) => shared.tally.refuse("clock"),
                            Ok(()) => hand_in(Inbound::Hands { page, arrived_ns, frame }),
                            Err(e) => shared.tally.refuse(e.kind()),
                        }
                    }
                    page::KIND_STATS => match page::decode_stats(&bytes) {
                        Ok(stats) => hand_in(Inbound::Stats { page, stats }),
                        Err(e) => shared.tally.refuse(e.kind()),
                    },
                    page::KIND_PONG => match page::decode_pong(&bytes) {
                        Ok(pong) => {
                            last_pong_ns = arrived_ns;
                            let improved = clock.pong(&pong, arrived_ns);
                            if let Some((round_trip_ns, offset_ns)) = clock.best {
                                if improved || (!ready && clock.pongs >= PONGS_BEFORE_READY) {
                                    hand_in(Inbound::Clock { page, offset_ns, round_trip_ns, pongs: clock.pongs });
                                }
                                if !ready && clock.pongs >= PONGS_BEFORE_READY {
                                    ready = true;
                                    let text = page::Ready::new(
                                        offset_ns as f64 / 1e6,
                                        round_trip_ns as f64 / 1e6,
                                    )
                                    .encode();
                                    if !send_within(ws, Message::text(text), tally).await {
                                        return;
                                    }
                                }
                            }
                        }
                        Err(e) => shared.tally.refuse(e.kind()),
                    },
                    _ => shared.tally.refuse("kind"),
                }
            }
            changed = world.changed() => {
                if changed.is_err() {
                    return;
                }
                let message = world.borrow_and_update().clone();
                if !message.is_empty() && !send_within(ws, Message::Binary(message), tally).await {
                    return;
                }
            }
            changed = peers.changed() => {
                if changed.is_err() {
                    return;
                }
                let message = peers.borrow_and_update().clone();
                if !message.is_empty() && !send_within(ws, Message::Binary(message), tally).await {
                    return;
                }
            }
            _ = ping.tick() => {
                if monotonic_ns().saturating_sub(last_pong_ns) > PONG_TIMEOUT.as_nanos() as u64 {
                    shared.tally.unanswered.fetch_add(1, Ordering::Relaxed);
                    let why = CloseFrame {
                        code: CloseCode::from(CLOSE_UNANSWERED),
                        reason: "no answer to pings for 5 s".into(),
                    };
                    let _ = tokio::time::timeout(PONG_TIMEOUT, ws.close(Some(why))).await;
                    return;
                }
                ping_seq = ping_seq.wrapping_add(1);
                if ping_seq == 11 {
                    // After the first second's ten, one a second keeps the estimate fresh.
                    ping = tokio::time::interval(Duration::from_secs(1));
                    ping.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
                    ping.tick().await;
                }
                let now = monotonic_ns();
                clock.sent(ping_seq, now);
                page::encode_ping(ping_seq, now as f64 / 1e6, &mut out);
                if !send_within(ws, Message::Binary(Bytes::copy_from_slice(&out)), tally).await {
                    return;
                }
            }
            _ = stop.changed() => {
                let bye = CloseFrame { code: CloseCode::Away, reason: "the session ended".into() };
                let _ = tokio::time::timeout(PONG_TIMEOUT, ws.close(Some(bye))).await;
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `head` read by the front as the server reads it: the request, or none.
    fn read(head: &str) -> Option<http_front::http::request::Parts> {
        use tokio::io::AsyncWriteExt;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("a runtime");
        runtime.block_on(async {
            let (mut client, server) = tokio::io::duplex(8192);
            client.write_all(head.as_bytes()).await.ok()?;
            // The client has sent all it will.
            drop(client);
            let reading = Reading::default().head_timeout(Duration::from_secs(2));
            let opened = http_front::open(Box::new(server), &reading).await;
            opened.ok().map(|o| o.request)
        })
    }

    #[test]
    fn a_request_head_gives_its_path_token_and_upgrade() {
        let r = read(
            "GET /ws?token=abc&x=1 HTTP/1.1\r\nHost: h\r\nUpgrade: WebSocket\r\nSec-WebSocket-Key: k==\r\n\r\n",
        )
        .unwrap();
        let token = http_front::query_value(&r.uri, "token");
        assert_eq!((r.uri.path(), token), ("/ws", Some("abc")));
        assert!(http_front::is_websocket(&r));
        assert_eq!(
            r.headers
                .get(header::SEC_WEBSOCKET_KEY)
                .map(|k| k.as_bytes()),
            Some(&b"k=="[..])
        );
        assert!(read("").is_none());
        assert!(token_ok(Some("abcdef"), "abcdef"));
        assert!(!token_ok(Some("abcdeg"), "abcdef"));
        assert!(!token_ok(Some("abc"), "abcdef"));
        assert!(!token_ok(None, "abcdef"));
    }

    #[test]
    fn a_frame_far_ahead_of_the_pages_clock_is_refused_and_one_behind_it_is_not() {
        // The page's clock reads 1000 ms when ours reads 5000 ms (offset +4000 ms).
        let offset = 4_000_000_000;
        let at = 5_000_000_000;
        assert!(
            !ahead_of_clock(1000.0 + 20.0, offset, at),
            "a predicted display time"
        );
        assert!(!ahead_of_clock(
            1000.0 + MAX_AHEAD_OF_CLOCK_MS - 1.0,
            offset,
            at
        ));
        assert!(ahead_of_clock(
            1000.0 + MAX_AHEAD_OF_CLOCK_MS + 1.0,
            offset,
            at
        ));
        assert!(
            ahead_of_clock(1000.0 + 1e9, offset, at),
            "the session-freezing frame"
        );
        assert!(
            !ahead_of_clock(0.0, offset, at),
            "a recording's own time, behind"
        );
        assert!(REFUSALS.contains(&"clock"));
    }

    #[test]
    fn the_clock_keeps_the_estimate_of_the_shortest_round_trip() {
        let mut c = PageClock::default();
        // The page's clock reads 1000 ms when ours reads 5000 ms: offset +4000 ms.
        c.sent(1, 5_000_000_000 - 2_000_000);
        let pong = |seq, page_ms| page::Pong {
            seq,
            server_ms: 0.0,
            page_ms,
        };
        assert!(c.pong(&pong(1, 1000.0), 5_000_000_000 + 2_000_000));
        assert_eq!(c.best, Some((4_000_000, 4_000_000_000)));
        // A slower ping (10 ms) whose midpoint is off does not replace it.
        c.sent(2, 6_000_000_000);
        assert!(!c.pong(&pong(2, 2003.0), 6_010_000_000));
        assert_eq!(c.best.unwrap().1, 4_000_000_000);
        // A pong for a ping never sent is ignored.
        assert!(!c.pong(&pong(9, 1.0), 7_000_000_000));
        assert_eq!(c.pongs, 2);
    }
}
