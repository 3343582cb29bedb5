//! The live view's front door: it checks every opening request, accepts both WebSocket
//! subprotocols Foxglove clients offer, and hands every connection it admits to the `foxglove`
//! crate's server.
//!
//! Two names are in use for one protocol. `foxglove.websocket.v1` is the published spec's, the
//! one the npm client `@foxglove/ws-protocol`, Lichtblick and Foxglove Studio builds before the
//! SDK offer; `foxglove.sdk.v1` (and `.v1.1`) is what the `foxglove` crate's server accepts, and
//! it refuses any other with "HTTP 400 Missing expected sec-websocket-protocol header". The
//! messages of `foxglove.websocket.v1` and `foxglove.sdk.v1` are the same (serverInfo,
//! advertise with inline schemas, subscribe, binary message data), so the gate only renames:
//! where a client's opening request offers `foxglove.websocket.v1` and no SDK name, it offers
//! `foxglove.sdk.v1` in its place to the server (listening on a loopback port of its own) and
//! names `foxglove.websocket.v1` again in the server's answer. The WebSocket handshake's key
//! and accept do not cover the subprotocol, so the renaming is invisible to both. After the
//! handshake it copies bytes both ways untouched.
//!
//! The gate is a server of the shared HTTP front ([`http_front`], as the webxr stage's page
//! is): tokio tasks on two threads of its own, hyper reading each request's head, the server's
//! answer read by hyper's client ([`http_front::pass_on`]). What a client may cost is bounded
//! here, because the view faces a network:
//!
//! * **Every refused request is answered**, with the reason in the body: 400 for a request
//!   that is not a WebSocket opening the server would take (not `GET`, not HTTP/1.1, no
//!   `Upgrade: websocket`, no key, another WebSocket version, no Foxglove subprotocol), 408 for
//!   one not complete by its deadline, 503 when the view is full. The server behind would
//!   close most of these without a word, which a user cannot act on. hyper answers what it
//!   cannot read as HTTP/1 itself: 400, or 431 for a head over 16 KiB.
//! * **One deadline per request** ([`HEAD_TIMEOUT`] in all, not per read), so a request
//!   trickled a byte at a time ends with the rest.
//! * **A cap on clients** (`[viewer] foxglove_clients`) and on requests being read at once
//!   ([`OPENING_AT_ONCE`]; one beyond is answered 503 unread). Connections are tasks, not
//!   threads, so whatever connects costs the gate no thread.
//! * **A client that takes no byte for [`STALL_TIMEOUT`] is closed**: otherwise one that
//!   stopped reading (a laptop put to sleep) would keep its place for ever. What it costs
//!   meanwhile is bounded by the server's backlog ([`crate::viewer`] sets it).
//! * **Memory goes back when clients leave**: glibc keeps what a thread's arena freed, so the
//!   megabytes of a departed client's backlog stayed resident; the gate trims the heap once the
//!   server has dropped it.
//!
//! None of these threads is on the session's pipeline.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use http_front::http::header::{self, HeaderMap, HeaderValue};
use http_front::http::{request, Method, Request, Response, StatusCode, Version};
use http_front::{
    Front, FrontBuilder, Handler, OpenError, Opened, PassError, Passed, Reading, StartError,
    Switched, Upstream,
};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::{timeout, Instant};

/// The published protocol's subprotocol name.
pub const WEBSOCKET_V1: &str = "foxglove.websocket.v1";
/// The SDK server's names, newest last.
pub const SDK_V1: &str = "foxglove.sdk.v1";
pub const SDK_V1_1: &str = "foxglove.sdk.v1.1";

/// The most an opening request may take before its blank line.
const MAX_HEAD_BYTES: usize = 16 * 1024;
/// How long a client may take to send its whole opening request, however it trickles it.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// Opening requests read at once; a connection beyond them is answered 503 at once. A view's
/// clients open a connection or two each; this only bounds a flood.
pub const OPENING_AT_ONCE: usize = 16;
/// A client that accepts no byte of what the view sends for this long is closed.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(10);
/// After a refusal, how long the gate reads (and drops) what the client still sends before
/// it closes: closing with unread bytes resets the connection, and the client could lose the
/// answer.
const LINGER: Duration = Duration::from_secs(1);
/// When, after a client leaves, the heap is trimmed: the server drops the client's backlog on
/// its own runtime once it sees the connection close, a moment after the gate does (the
/// second trim is for a loaded machine, where that moment can be long).
const TRIM_AFTER: [Duration; 2] = [Duration::from_millis(300), Duration::from_secs(2)];
/// The bytes copied at a time each way.
const RELAY_BUFFER: usize = 16 * 1024;

/// A running gate: stopping it closes the listener and the connections it relays.
pub struct Gate {
    front: Front,
}

/// What the connections share: the server's address, and the places taken.
struct Shared {
    server: SocketAddr,
    max_clients: usize,
    clients: AtomicUsize,
    trim_pending: AtomicBool,
}

/// One client's place (of at most `max_clients`), given back when dropped, whatever path the
/// connection's task ends by.
struct Place {
    shared: Arc<Shared>,
}

impl Place {
    fn take(shared: &Arc<Shared>) -> Option<Place> {
        shared
            .clients
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < shared.max_clients).then_some(n + 1)
            })
            .ok()?;
        Some(Place {
            shared: shared.clone(),
        })
    }
}

impl Drop for Place {
    fn drop(&mut self) {
        self.shared.clients.fetch_sub(1, Ordering::AcqRel);
    }
}

impl Gate {
    /// Listens on `host:port` (port 0: any free one, see [`Gate::port`]) and forwards each
    /// connection it admits to `server` (the `foxglove` server's loopback address), at most
    /// `max_clients` at once (at least 1).
    pub fn start(
        host: &str,
        port: u16,
        server: SocketAddr,
        max_clients: usize,
    ) -> std::io::Result<Gate> {
        let shared = Arc::new(Shared {
            server,
            max_clients: max_clients.max(1),
            clients: AtomicUsize::new(0),
            trim_pending: AtomicBool::new(false),
        });
        let reading = Reading::default()
            .head_timeout(HEAD_TIMEOUT)
            .max_head_bytes(MAX_HEAD_BYTES)
            .linger(LINGER);
        let front = FrontBuilder::new("foxglove-gate")
            .threads(2)
            .reading(reading)
            .opening_at_once(OPENING_AT_ONCE)
            .start((host, port), GateHandler { shared })
            .map_err(|e| match e {
                StartError::Listen(e) | StartError::Runtime(e) => e,
            })?;
        Ok(Gate { front })
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.front.local_addr().port()
    }

    /// Stops accepting connections and closes those it relays.
    pub fn stop(mut self) {
        self.front.stop();
    }
}

/// The gate as the front's [`Handler`].
struct GateHandler {
    shared: Arc<Shared>,
}

impl Handler for GateHandler {
    async fn serve(&self, opened: Opened) {
        let admission = match check(&opened.request) {
            Ok(a) => a,
            Err(refusal) => return opened.answer(refusal.response()).await,
        };
        let Some(place) = Place::take(&self.shared) else {
            let n = self.shared.max_clients;
            let refusal = Refusal {
                status: StatusCode::SERVICE_UNAVAILABLE,
                body: format!(
                    "handblocks' live Foxglove view serves {n} client{} at once and has {n}: \
                     close one, or raise [viewer] foxglove_clients in the session file (or \
                     --set viewer.foxglove_clients=N).\n",
                    if n == 1 { "" } else { "s" }
                ),
            };
            return opened.answer(refusal.response()).await;
        };
        let left = pass(opened, self.shared.server, admission).await;
        drop(place);
        if left {
            give_back_memory(&self.shared).await;
        }
    }

    fn unopened(&self, why: &OpenError) -> Option<Response<String>> {
        let body = match why {
            OpenError::Late => format!(
                "handblocks' live Foxglove view: the opening request took over {} s; send it \
                 whole (a Foxglove client does).\n",
                HEAD_TIMEOUT.as_secs()
            ),
            OpenError::Busy => "handblocks' live Foxglove view: too many connections are \
                                opening at once; try again in a few seconds.\n"
                .to_string(),
            _ => return None,
        };
        let status = match why {
            OpenError::Late => StatusCode::REQUEST_TIMEOUT,
            _ => StatusCode::SERVICE_UNAVAILABLE,
        };
        Some(Refusal { status, body }.response())
    }
}

/// The subprotocols a head's `Sec-WebSocket-Protocol` lines offer.
fn offered(headers: &HeaderMap) -> Vec<&str> {
    http_front::tokens(headers, header::SEC_WEBSOCKET_PROTOCOL).collect()
}

/// `headers` with every `Sec-WebSocket-Protocol` line replaced by one naming `protocol`.
fn set_protocol(headers: &mut HeaderMap, protocol: &'static str) {
    headers.insert(
        header::SEC_WEBSOCKET_PROTOCOL,
        HeaderValue::from_static(protocol),
    );
}

/// What the gate does with a client's opening request.
#[derive(Debug, PartialEq, Eq)]
enum Admission {
    /// It offers an SDK name: passed on unchanged.
    AsIs,
    /// It offers only the published name: renamed both ways.
    Renamed,
    /// It offers neither: refused.
    Refused,
}

fn admit(offers: &[&str]) -> Admission {
    if offers.iter().any(|p| *p == SDK_V1 || *p == SDK_V1_1) {
        Admission::AsIs
    } else if offers.contains(&WEBSOCKET_V1) {
        Admission::Renamed
    } else {
        Admission::Refused
    }
}

/// An answer to a refused request: its status, and the body.
#[derive(Debug, PartialEq, Eq)]
struct Refusal {
    status: StatusCode,
    body: String,
}

impl Refusal {
    fn bad(problem: &str) -> Refusal {
        Refusal {
            status: StatusCode::BAD_REQUEST,
            body: format!(
                "This is handblocks' live Foxglove view; {problem}. Connect a Foxglove client \
                 (Foxglove or Lichtblick: Open connection -> Foxglove WebSocket, \
                 ws://HOST:PORT), which opens a WebSocket (GET, HTTP/1.1, Upgrade: websocket, \
                 Sec-WebSocket-Key, Sec-WebSocket-Version: 13) offering the subprotocol \
                 {WEBSOCKET_V1} or {SDK_V1}.\n"
            ),
        }
    }

    /// The refusal as an answer: a 400 names the WebSocket version spoken, a 503 when to come
    /// back.
    fn response(self) -> Response<String> {
        let mut response = http_front::text(self.status, self.body);
        let headers = response.headers_mut();
        match self.status {
            StatusCode::BAD_REQUEST => {
                headers.insert(
                    header::SEC_WEBSOCKET_VERSION,
                    HeaderValue::from_static("13"),
                );
            }
            StatusCode::SERVICE_UNAVAILABLE => {
                headers.insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
            }
            _ => {}
        }
        response
    }
}

/// Checks an opening request the way the server behind would (so that every request it
/// would drop without a word is answered here), and says how to pass it on.
fn check(request: &request::Parts) -> Result<Admission, Refusal> {
    if request.method != Method::GET {
        return Err(Refusal::bad(&format!(
            "a WebSocket opens with GET, not {}",
            request.method
        )));
    }
    if request.version != Version::HTTP_11 {
        return Err(Refusal::bad(&format!(
            "a WebSocket opens over HTTP/1.1, not {:?}",
            request.version
        )));
    }
    let headers = &request.headers;
    if !http_front::has_token(headers, header::UPGRADE, "websocket") {
        return Err(Refusal::bad("the request has no \"Upgrade: websocket\""));
    }
    if !http_front::has_token(headers, header::CONNECTION, "upgrade") {
        return Err(Refusal::bad("the request has no \"Connection: Upgrade\""));
    }
    if headers
        .get_all(header::SEC_WEBSOCKET_KEY)
        .iter()
        .all(|k| k.is_empty())
    {
        return Err(Refusal::bad("the request has no Sec-WebSocket-Key"));
    }
    if !headers
        .get_all(header::SEC_WEBSOCKET_VERSION)
        .iter()
        .any(|v| v == "13")
    {
        return Err(Refusal::bad(
            "the request names no WebSocket version 13 (Sec-WebSocket-Version: 13), the one \
             this server speaks",
        ));
    }
    match admit(&offered(headers)) {
        Admission::Refused => Err(Refusal::bad(
            "the request offers no Foxglove subprotocol (Sec-WebSocket-Protocol)",
        )),
        a => Ok(a),
    }
}

/// Passes an admitted request on to the server, answers the client with the server's answer
/// (renamed back), and copies bytes both ways until either side closes (or the client
/// stalls, [`STALL_TIMEOUT`]); true once a client had been connected.
async fn pass(opened: Opened, server: SocketAddr, admission: Admission) -> bool {
    let unavailable = |what: &str| Refusal {
        status: StatusCode::BAD_GATEWAY,
        body: format!(
            "handblocks' live Foxglove view: its server {what}; the bridge's output says why \
             (restart the session if it stopped).\n"
        ),
    };
    let mut request = Request::from_parts(opened.request.clone(), ());
    if admission == Admission::Renamed {
        set_protocol(request.headers_mut(), SDK_V1);
    }
    let deadline = Instant::now() + HEAD_TIMEOUT;
    let (answer, upstream) = match http_front::pass_on(server, request, deadline).await {
        Ok(Passed::Switched { response, stream }) => (response, stream),
        Ok(Passed::Answered(answer)) => {
            opened.answer(answer).await;
            return false;
        }
        Err(PassError::Connect { .. }) => {
            opened
                .answer(unavailable("does not answer").response())
                .await;
            return false;
        }
        Err(_) => {
            let refusal = unavailable("did not answer the opening request");
            opened.answer(refusal.response()).await;
            return false;
        }
    };
    let mut answer = Response::from_parts(answer, ());
    if admission == Admission::Renamed && !offered(answer.headers()).is_empty() {
        set_protocol(answer.headers_mut(), WEBSOCKET_V1);
    }
    if let Ok(client) = opened.switch(answer).await {
        relay(client, upstream).await;
    }
    true
}

/// From here on, bytes both ways, untouched: the client's to the server as they come, the
/// server's to the client unless it takes none for [`STALL_TIMEOUT`]. Ends when the server
/// closes, the client goes, or the client stalls; the connections close when it returns.
async fn relay(client: Switched, upstream: Upstream) {
    let Switched { stream, early } = client;
    let (mut client_in, mut client_out) = tokio::io::split(stream);
    let (mut upstream_in, mut upstream_out) = tokio::io::split(upstream);
    let to_server = async {
        if upstream_out.write_all(&early).await.is_ok() {
            let _ = tokio::io::copy(&mut client_in, &mut upstream_out).await;
        }
        // The client closed its side: the server hears it, and answers (or closes) below.
        let _ = upstream_out.shutdown().await;
        std::future::pending::<()>().await
    };
    let to_client = async {
        copy_unless_stalled(&mut upstream_in, &mut client_out).await;
        let _ = timeout(LINGER, client_out.shutdown()).await;
    };
    tokio::select! {
        () = to_server => {}
        () = to_client => {}
    }
}

/// Copies `from` to `to` until `from` ends or either fails, or `to` takes no byte for
/// [`STALL_TIMEOUT`].
async fn copy_unless_stalled<R, W>(from: &mut R, to: &mut W)
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
{
    let mut buffer = vec![0u8; RELAY_BUFFER];
    loop {
        let n = match from.read(&mut buffer).await {
            Ok(0) | Err(_) => return,
            Ok(n) => n,
        };
        let mut sent = 0;
        while sent < n {
            match timeout(STALL_TIMEOUT, to.write(&buffer[sent..n])).await {
                Ok(Ok(k)) if k > 0 => sent += k,
                _ => return,
            }
        }
        if !matches!(timeout(STALL_TIMEOUT, to.flush()).await, Ok(Ok(()))) {
            return;
        }
    }
}

/// Gives the heap's free pages back to the system once the server has dropped a departed
/// client's backlog. glibc keeps what a thread's arena freed for that thread's next
/// allocations: 20 clients that never read left ~500 MB resident after they went. One trim
/// covers the clients that leave together.
async fn give_back_memory(shared: &Shared) {
    if shared.trim_pending.swap(true, Ordering::AcqRel) {
        return;
    }
    let mut waited = Duration::ZERO;
    for (i, at) in TRIM_AFTER.into_iter().enumerate() {
        tokio::time::sleep(at.saturating_sub(waited)).await;
        waited = at;
        if i == 0 {
            // A client that leaves from now on has a trim of its own.
            shared.trim_pending.store(false, Ordering::Release);
        }
        #[cfg(all(target_os = "linux", target_env = "gnu"))]
        // SAFETY: malloc_trim only returns free pages of glibc's heaps to the system.
        unsafe {
            libc::malloc_trim(0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `head` as the front reads it: the request's head, or none where hyper refuses it.
    fn read(head: &str) -> Option<request::Parts> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("a runtime");
        runtime.block_on(async {
            let (mut client, server) = tokio::io::duplex(64 * 1024);
            client.write_all(head.as_bytes()).await.ok()?;
            drop(client);
            let reading = Reading::default().head_timeout(Duration::from_secs(2));
            let opened = http_front::open(Box::new(server), &reading).await;
            opened.ok().map(|o| o.request)
        })
    }

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: x\r\nsec-websocket-protocol: \
                           foxglove.websocket.v1\r\nSec-WebSocket-Key: k\r\n\r\n";

    #[test]
    fn the_published_name_is_renamed_and_the_sdk_names_pass() {
        let mut request = read(REQUEST).expect("a request");
        assert_eq!(admit(&offered(&request.headers)), Admission::Renamed);
        set_protocol(&mut request.headers, SDK_V1);
        assert_eq!(offered(&request.headers), [SDK_V1]);
        assert_eq!(request.headers[header::SEC_WEBSOCKET_KEY], "k");
        assert_eq!(admit(&[WEBSOCKET_V1, SDK_V1_1]), Admission::AsIs);
        assert_eq!(admit(&["foxglove.sdk.v1"]), Admission::AsIs);
        assert_eq!(admit(&["other"]), Admission::Refused);
        assert_eq!(admit(&[]), Admission::Refused);
    }

    #[test]
    fn offers_are_read_from_every_protocol_line() {
        let head =
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: a, b\r\nSEC-WEBSOCKET-PROTOCOL:c\r\n\r\n";
        let mut request = read(head).expect("a request");
        assert_eq!(offered(&request.headers), ["a", "b", "c"]);
        set_protocol(&mut request.headers, "z");
        assert_eq!(offered(&request.headers), ["z"]);
    }

    const GOOD: &str = "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: WebSocket\r\n\
                        Connection: keep-alive, Upgrade\r\nSec-WebSocket-Key: a2V5\r\n\
                        Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: \
                        foxglove.websocket.v1\r\n\r\n";

    #[test]
    fn a_websocket_opening_passes_and_anything_else_is_refused_with_the_reason() {
        let checked = |head: &str| check(&read(head).expect(head));
        assert_eq!(checked(GOOD), Ok(Admission::Renamed));
        let cases = [
            (GOOD.replace("GET", "POST"), "not POST"),
            (GOOD.replace("HTTP/1.1", "HTTP/1.0"), "not HTTP/1.0"),
            (
                GOOD.replace("Sec-WebSocket-Key: a2V5\r\n", ""),
                "no Sec-WebSocket-Key",
            ),
            (
                GOOD.replace("Sec-WebSocket-Key: a2V5", "Sec-WebSocket-Key:"),
                "Key",
            ),
            (
                GOOD.replace("Upgrade: WebSocket\r\n", ""),
                "Upgrade: websocket",
            ),
            (
                GOOD.replace("keep-alive, Upgrade", "close"),
                "Connection: Upgrade",
            ),
            (GOOD.replace("Version: 13", "Version: 8"), "version 13"),
            (GOOD.replace("foxglove.websocket.v1", "mqtt"), "subprotocol"),
        ];
        for (head, says) in cases {
            let refusal = checked(&head).expect_err(&head);
            assert_eq!(refusal.status, 400);
            assert!(refusal.body.contains(says), "{says}: {}", refusal.body);
        }
        // What is not an HTTP/1 request (a line that is no header, no version, not HTTP) is
        // hyper's to refuse (400, tested in http-front): nothing reaches the check.
        for head in [
            GOOD.replace("Host: x", "Host x"),
            "hello\r\n\r\n".to_string(),
            "GET /\r\n\r\n".to_string(),
        ] {
            assert!(read(&head).is_none(), "{head}");
        }
    }
}
