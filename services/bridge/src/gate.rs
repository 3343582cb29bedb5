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
//! it reads a client's opening request, and where the client offers `foxglove.websocket.v1`
//! and no SDK name, it offers `foxglove.sdk.v1` in its place to the server (listening on a
//! loopback port of its own) and names `foxglove.websocket.v1` again in the server's answer.
//! The WebSocket handshake's key and accept do not cover the subprotocol, so the renaming is
//! invisible to both. After the handshake it copies bytes both ways untouched.
//!
//! What a client may cost is bounded here, because the view faces a network:
//!
//! * **Every refused request is answered**, with the reason in the body: 400 for a request
//!   that is not a WebSocket opening the server would take (not `GET`, not HTTP/1.1, no
//!   `Upgrade: websocket`, no key, another WebSocket version, no Foxglove subprotocol, over
//!   16 KiB), 408 for one not complete by its deadline, 503 when the view is full. The server
//!   behind would close most of these without a word, which a user cannot act on.
//! * **One deadline per request** ([`HEAD_TIMEOUT`] in all, not per read), so a request
//!   trickled a byte at a time ends with the rest.
//! * **A cap on clients** (`[viewer] foxglove_clients`) and on requests being read at once
//!   ([`OPENING_AT_ONCE`]): each connection costs a thread while its request is read and two
//!   while it is a client, so the gate's threads are bounded whatever connects.
//! * **A client that takes no byte for [`STALL_TIMEOUT`] is closed** (within twice that, as
//!   the kernel times each write): otherwise one that stopped reading (a laptop put to sleep)
//!   would keep its place for ever. What it costs meanwhile is bounded by the server's backlog
//!   ([`crate::viewer`] sets it).
//! * **Memory goes back when clients leave**: glibc keeps what a thread's arena freed, so the
//!   megabytes of a departed client's backlog stayed resident; the gate trims the heap once the
//!   server has dropped it.
//!
//! None of these threads is on the session's pipeline.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The published protocol's subprotocol name.
pub const WEBSOCKET_V1: &str = "foxglove.websocket.v1";
/// The SDK server's names, newest last.
pub const SDK_V1: &str = "foxglove.sdk.v1";
pub const SDK_V1_1: &str = "foxglove.sdk.v1.1";

/// The most an opening request (or the server's answer) may take before its blank line.
const MAX_HEAD_BYTES: usize = 16 * 1024;
/// How long a client may take to send its whole opening request, however it trickles it.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// Opening requests read at once (a thread each); a connection beyond them is answered 503
/// at once. A view's clients open a connection or two each; this only bounds a flood.
pub const OPENING_AT_ONCE: usize = 16;
/// A client that accepts no byte of what the view sends for this long is closed. The kernel
/// times each write: one that took some bytes before it stalled returns them when this
/// runs out, and the next times out, so a stalled client goes within twice this.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(10);
/// After a refusal, how long the gate reads (and drops) what the client still sends before
/// it closes: closing with unread bytes resets the connection, and the client could lose the
/// answer.
const LINGER: Duration = Duration::from_secs(1);
/// When, after a client leaves, the heap is trimmed: the server drops the client's backlog on
/// its own runtime once it sees the connection close, a moment after the gate does (the
/// second trim is for a loaded machine, where that moment can be long).
const TRIM_AFTER: [Duration; 2] = [Duration::from_millis(300), Duration::from_secs(2)];

/// A running gate: stopping it closes the listener (connections already open end when the
/// server behind closes them).
pub struct Gate {
    stop: Arc<AtomicBool>,
    addr: SocketAddr,
    acceptor: Option<JoinHandle<()>>,
}

/// What the connections share: the server's address, and the places taken.
struct Shared {
    server: SocketAddr,
    max_clients: usize,
    clients: AtomicUsize,
    opening: AtomicUsize,
    trim_pending: AtomicBool,
}

/// One place of `counter` (of at most `max`), given back when dropped, whatever path the
/// connection's thread ends by.
struct Place {
    shared: Arc<Shared>,
    client: bool,
}

impl Place {
    fn take(shared: &Arc<Shared>, client: bool) -> Option<Place> {
        let (counter, max) = if client {
            (&shared.clients, shared.max_clients)
        } else {
            (&shared.opening, OPENING_AT_ONCE)
        };
        counter
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < max).then_some(n + 1)
            })
            .ok()?;
        Some(Place {
            shared: shared.clone(),
            client,
        })
    }
}

impl Drop for Place {
    fn drop(&mut self) {
        let counter = if self.client {
            &self.shared.clients
        } else {
            &self.shared.opening
        };
        counter.fetch_sub(1, Ordering::AcqRel);
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
    ) -> io::Result<Gate> {
        let listener = TcpListener::bind((host, port))?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = stop.clone();
        let shared = Arc::new(Shared {
            server,
            max_clients: max_clients.max(1),
            clients: AtomicUsize::new(0),
            opening: AtomicUsize::new(0),
            trim_pending: AtomicBool::new(false),
        });
        let acceptor = std::thread::Builder::new()
            .name("foxglove-gate".into())
            .spawn(move || {
                for client in listener.incoming() {
                    if stopping.load(Ordering::Acquire) {
                        break;
                    }
                    let client = match client {
                        Ok(c) => c,
                        Err(_) => {
                            // Out of descriptors, most likely: let some connections end
                            // rather than spin on the error.
                            std::thread::sleep(Duration::from_millis(20));
                            continue;
                        }
                    };
                    let Some(place) = Place::take(&shared, false) else {
                        refuse_at_once(client);
                        continue;
                    };
                    let shared = shared.clone();
                    // A thread that cannot start drops the closure: the place is given back
                    // and the connection closed.
                    let _ = std::thread::Builder::new()
                        .name("foxglove-client".into())
                        .spawn(move || serve(client, &shared, place));
                }
            })?;
        Ok(Gate {
            stop,
            addr,
            acceptor: Some(acceptor),
        })
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.addr.port()
    }

    /// Stops accepting connections.
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Release);
        // Wake the blocking accept with a connection of our own; it then sees `stop`.
        let wake = match self.addr {
            SocketAddr::V4(a) if a.ip().is_unspecified() => {
                SocketAddr::from(([127, 0, 0, 1], a.port()))
            }
            SocketAddr::V6(a) if a.ip().is_unspecified() => {
                SocketAddr::from((std::net::Ipv6Addr::LOCALHOST, a.port()))
            }
            a => a,
        };
        let _ = TcpStream::connect_timeout(&wake, Duration::from_secs(1));
        if let Some(t) = self.acceptor.take() {
            let _ = t.join();
        }
    }
}

/// Why a head could not be read.
#[derive(Debug)]
enum HeadError {
    /// Not complete by its deadline.
    Late,
    /// Over [`MAX_HEAD_BYTES`].
    TooLarge,
    /// The peer closed, or the connection failed: nobody to answer.
    Gone,
}

/// Reads up to and including the blank line that ends an HTTP head, by `deadline` (one for
/// the whole head, however many reads it takes); returns the head and any bytes read past it.
fn read_head(stream: &mut TcpStream, deadline: Instant) -> Result<(Vec<u8>, Vec<u8>), HeadError> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            return Ok((buf, rest));
        }
        if buf.len() > MAX_HEAD_BYTES {
            return Err(HeadError::TooLarge);
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(HeadError::Late);
        }
        stream
            .set_read_timeout(Some(left))
            .map_err(|_| HeadError::Gone)?;
        match stream.read(&mut chunk) {
            Ok(0) => return Err(HeadError::Gone),
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                return Err(HeadError::Late)
            }
            Err(_) => return Err(HeadError::Gone),
        }
    }
}

/// The values of every `name` header line of `head` (the request line excluded).
fn header_values<'a>(head: &'a str, name: &'a str) -> impl Iterator<Item = &'a str> + 'a {
    head.lines()
        .skip(1)
        .filter_map(|line| line.split_once(':'))
        .filter(move |(n, _)| n.trim().eq_ignore_ascii_case(name))
        .map(|(_, v)| v.trim())
}

/// Whether some `name` header lists `token` (comma-separated, any case).
fn has_token(head: &str, name: &str, token: &str) -> bool {
    header_values(head, name)
        .flat_map(|v| v.split(','))
        .any(|t| t.trim().eq_ignore_ascii_case(token))
}

/// The subprotocols a head's `Sec-WebSocket-Protocol` lines offer.
fn offered(head: &str) -> Vec<&str> {
    header_values(head, "sec-websocket-protocol")
        .flat_map(|value| value.split(',').map(str::trim))
        .filter(|v| !v.is_empty())
        .collect()
}

/// `head` with every `Sec-WebSocket-Protocol` line replaced by one naming `protocol`.
fn with_protocol(head: &str, protocol: &str) -> String {
    let mut out = String::with_capacity(head.len() + protocol.len());
    let mut replaced = false;
    for line in head.split_inclusive("\r\n") {
        let is_protocol = line
            .split_once(':')
            .is_some_and(|(name, _)| name.trim().eq_ignore_ascii_case("sec-websocket-protocol"));
        if !is_protocol {
            out.push_str(line);
        } else if !replaced {
            out.push_str("Sec-WebSocket-Protocol: ");
            out.push_str(protocol);
            out.push_str("\r\n");
            replaced = true;
        }
    }
    out
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

/// An answer to a refused request: its status line's code and reason, and the body.
#[derive(Debug, PartialEq, Eq)]
struct Refusal {
    status: u16,
    body: String,
}

impl Refusal {
    fn bad(problem: &str) -> Refusal {
        Refusal {
            status: 400,
            body: format!(
                "This is handblocks' live Foxglove view; {problem}. Connect a Foxglove client \
                 (Foxglove or Lichtblick: Open connection -> Foxglove WebSocket, \
                 ws://HOST:PORT), which opens a WebSocket (GET, HTTP/1.1, Upgrade: websocket, \
                 Sec-WebSocket-Key, Sec-WebSocket-Version: 13) offering the subprotocol \
                 {WEBSOCKET_V1} or {SDK_V1}.\n"
            ),
        }
    }
}

/// Checks an opening request the way the server behind would (so that every request it
/// would drop without a word is answered here), and says how to pass it on.
fn check(head: &str) -> Result<Admission, Refusal> {
    let request = head.lines().next().unwrap_or("");
    let mut parts = request.split(' ');
    let (method, target, version) = (parts.next(), parts.next(), parts.next());
    let (Some(method), Some(_), Some(version), None) = (method, target, version, parts.next())
    else {
        return Err(Refusal::bad("this is not an HTTP request"));
    };
    if !version.starts_with("HTTP/") {
        return Err(Refusal::bad("this is not an HTTP request"));
    }
    if method != "GET" {
        return Err(Refusal::bad(&format!(
            "a WebSocket opens with GET, not {method}"
        )));
    }
    if version != "HTTP/1.1" {
        return Err(Refusal::bad(&format!(
            "a WebSocket opens over HTTP/1.1, not {version}"
        )));
    }
    if let Some(line) = head
        .lines()
        .skip(1)
        .filter(|l| !l.is_empty())
        .find(|l| l.split_once(':').is_none_or(|(n, _)| !is_token(n)))
    {
        return Err(Refusal::bad(&format!("{line:?} is not a header line")));
    }
    if !has_token(head, "upgrade", "websocket") {
        return Err(Refusal::bad("the request has no \"Upgrade: websocket\""));
    }
    if !has_token(head, "connection", "upgrade") {
        return Err(Refusal::bad("the request has no \"Connection: Upgrade\""));
    }
    if header_values(head, "sec-websocket-key").all(str::is_empty) {
        return Err(Refusal::bad("the request has no Sec-WebSocket-Key"));
    }
    if !header_values(head, "sec-websocket-version").any(|v| v == "13") {
        return Err(Refusal::bad(
            "the request names no WebSocket version 13 (Sec-WebSocket-Version: 13), the one \
             this server speaks",
        ));
    }
    match admit(&offered(head)) {
        Admission::Refused => Err(Refusal::bad(
            "the request offers no Foxglove subprotocol (Sec-WebSocket-Protocol)",
        )),
        a => Ok(a),
    }
}

/// An HTTP header name: one or more token characters.
fn is_token(name: &str) -> bool {
    !name.is_empty()
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"!#$%&'*+-.^_`|~".contains(&b))
}

/// Answers `refusal` and closes, after reading for at most [`LINGER`] what the client still
/// sends (see there).
fn refuse(mut client: TcpStream, refusal: &Refusal) {
    let reason = match refusal.status {
        400 => "Bad Request",
        408 => "Request Timeout",
        502 => "Bad Gateway",
        _ => "Service Unavailable",
    };
    let extra = match refusal.status {
        400 => "Sec-WebSocket-Version: 13\r\n",
        503 => "Retry-After: 5\r\n",
        _ => "",
    };
    let _ = client.set_write_timeout(Some(LINGER));
    let answer = format!(
        "HTTP/1.1 {} {reason}\r\nContent-Type: text/plain; charset=utf-8\r\n\
         Content-Length: {}\r\n{extra}Connection: close\r\n\r\n{}",
        refusal.status,
        refusal.body.len(),
        refusal.body
    );
    if client.write_all(answer.as_bytes()).is_err() {
        return;
    }
    let _ = client.shutdown(Shutdown::Write);
    let until = Instant::now() + LINGER;
    let mut sink = [0u8; 4096];
    let mut drained = 0usize;
    while drained < 64 * 1024 {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() || client.set_read_timeout(Some(left)).is_err() {
            break;
        }
        match client.read(&mut sink) {
            Ok(0) | Err(_) => break,
            Ok(n) => drained += n,
        }
    }
}

/// A connection beyond [`OPENING_AT_ONCE`]: answered 503 from the accepting thread without
/// waiting on the client (the few bytes fit its socket's buffer), and closed.
fn refuse_at_once(client: TcpStream) {
    let body = "handblocks' live Foxglove view: too many connections are opening at once; \
                try again in a few seconds.\n";
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain; charset=utf-8\r\n\
         Content-Length: {}\r\nRetry-After: 5\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    if client.set_nonblocking(true).is_ok() {
        let _ = (&client).write(answer.as_bytes());
    }
    let _ = client.shutdown(Shutdown::Write);
}

/// One connection, from its opening request to its end; `opening` is its place among the
/// requests read at once.
fn serve(mut client: TcpStream, shared: &Arc<Shared>, opening: Place) {
    let head = read_head(&mut client, Instant::now() + HEAD_TIMEOUT);
    let (head, early) = match head {
        Ok(h) => h,
        Err(HeadError::Gone) => return,
        Err(HeadError::Late) => {
            let refusal = Refusal {
                status: 408,
                body: format!(
                    "handblocks' live Foxglove view: the opening request took over {} s; send \
                     it whole (a Foxglove client does).\n",
                    HEAD_TIMEOUT.as_secs()
                ),
            };
            return refuse(client, &refusal);
        }
        Err(HeadError::TooLarge) => {
            return refuse(
                client,
                &Refusal::bad(&format!(
                    "the opening request is over {} KiB",
                    MAX_HEAD_BYTES / 1024
                )),
            )
        }
    };
    let head = String::from_utf8_lossy(&head).into_owned();
    let admission = match check(&head) {
        Ok(a) => a,
        Err(refusal) => return refuse(client, &refusal),
    };
    let Some(place) = Place::take(shared, true) else {
        let n = shared.max_clients;
        let refusal = Refusal {
            status: 503,
            body: format!(
                "handblocks' live Foxglove view serves {n} client{} at once and has {n}: close \
                 one, or raise [viewer] foxglove_clients in the session file (or --set \
                 viewer.foxglove_clients=N).\n",
                if n == 1 { "" } else { "s" }
            ),
        };
        return refuse(client, &refusal);
    };
    drop(opening);
    let left = relay(client, shared.server, &head, &early, admission);
    drop(place);
    if left {
        give_back_memory(shared);
    }
}

/// Passes an admitted request to the server and copies bytes both ways until either side
/// closes (or the client stalls, [`STALL_TIMEOUT`]); true once a client had been connected.
fn relay(
    client: TcpStream,
    server: SocketAddr,
    head: &str,
    early: &[u8],
    admission: Admission,
) -> bool {
    let unavailable = |what: &str| Refusal {
        status: 502,
        body: format!(
            "handblocks' live Foxglove view: its server {what}; the bridge's output says why \
             (restart the session if it stopped).\n"
        ),
    };
    let Ok(mut upstream) = TcpStream::connect_timeout(&server, HEAD_TIMEOUT) else {
        refuse(client, &unavailable("does not answer"));
        return false;
    };
    let request = match admission {
        Admission::Renamed => with_protocol(head, SDK_V1),
        _ => head.to_string(),
    };
    let sent = upstream
        .write_all(request.as_bytes())
        .and_then(|()| upstream.write_all(early));
    let answer = sent
        .ok()
        .and_then(|()| read_head(&mut upstream, Instant::now() + HEAD_TIMEOUT).ok());
    let Some((answer, after)) = answer else {
        refuse(client, &unavailable("did not answer the opening request"));
        return false;
    };
    let answer = String::from_utf8_lossy(&answer).into_owned();
    let answer = match admission {
        Admission::Renamed if !offered(&answer).is_empty() => with_protocol(&answer, WEBSOCKET_V1),
        _ => answer,
    };
    let mut client = client;
    let ready = [
        client.set_read_timeout(None),
        upstream.set_read_timeout(None),
        client.set_write_timeout(Some(STALL_TIMEOUT)),
        upstream.set_write_timeout(Some(STALL_TIMEOUT)),
        client.set_nodelay(true),
        upstream.set_nodelay(true),
    ];
    if ready.iter().any(Result::is_err)
        || client.write_all(answer.as_bytes()).is_err()
        || client.write_all(&after).is_err()
    {
        return true;
    }
    // From here on, bytes both ways, untouched.
    let (Ok(mut client_in), Ok(mut upstream_out)) = (client.try_clone(), upstream.try_clone())
    else {
        return true;
    };
    let to_server = std::thread::Builder::new()
        .name("foxglove-up".into())
        .spawn(move || {
            let _ = io::copy(&mut client_in, &mut upstream_out);
            let _ = upstream_out.shutdown(Shutdown::Write);
        });
    if to_server.is_ok() {
        // Ends when the server closes, the client goes, or a write to it stalls.
        let _ = io::copy(&mut upstream, &mut client);
    }
    let _ = client.shutdown(Shutdown::Both);
    let _ = upstream.shutdown(Shutdown::Both);
    if let Ok(t) = to_server {
        let _ = t.join();
    }
    true
}

/// Gives the heap's free pages back to the system once the server has dropped a departed
/// client's backlog. glibc keeps what a thread's arena freed for that thread's next
/// allocations: 20 clients that never read left ~500 MB resident after they went. One trim
/// covers the clients that leave together.
fn give_back_memory(shared: &Shared) {
    if shared.trim_pending.swap(true, Ordering::AcqRel) {
        return;
    }
    let mut waited = Duration::ZERO;
    for (i, at) in TRIM_AFTER.into_iter().enumerate() {
        std::thread::sleep(at.saturating_sub(waited));
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

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: x\r\nsec-websocket-protocol: \
                           foxglove.websocket.v1\r\nSec-WebSocket-Key: k\r\n\r\n";

    #[test]
    fn the_published_name_is_renamed_and_the_sdk_names_pass() {
        assert_eq!(admit(&offered(REQUEST)), Admission::Renamed);
        let renamed = with_protocol(REQUEST, SDK_V1);
        assert_eq!(offered(&renamed), [SDK_V1]);
        assert!(
            renamed.ends_with("Sec-WebSocket-Key: k\r\n\r\n"),
            "{renamed}"
        );
        assert_eq!(admit(&[WEBSOCKET_V1, SDK_V1_1]), Admission::AsIs);
        assert_eq!(admit(&["foxglove.sdk.v1"]), Admission::AsIs);
        assert_eq!(admit(&["other"]), Admission::Refused);
        assert_eq!(admit(&[]), Admission::Refused);
    }

    #[test]
    fn offers_are_read_from_every_protocol_line() {
        let head =
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: a, b\r\nSEC-WEBSOCKET-PROTOCOL:c\r\n\r\n";
        assert_eq!(offered(head), ["a", "b", "c"]);
        let one = with_protocol(head, "z");
        assert_eq!(offered(&one), ["z"]);
    }

    const GOOD: &str = "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: WebSocket\r\n\
                        Connection: keep-alive, Upgrade\r\nSec-WebSocket-Key: a2V5\r\n\
                        Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: \
                        foxglove.websocket.v1\r\n\r\n";

    #[test]
    fn a_websocket_opening_passes_and_anything_else_is_refused_with_the_reason() {
        assert_eq!(check(GOOD), Ok(Admission::Renamed));
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
            (GOOD.replace("Host: x", "Host x"), "not a header line"),
            ("hello\r\n\r\n".to_string(), "not an HTTP request"),
            ("GET /\r\n\r\n".to_string(), "not an HTTP request"),
        ];
        for (head, says) in cases {
            let refusal = check(&head).expect_err(&head);
            assert_eq!(refusal.status, 400);
            assert!(refusal.body.contains(says), "{says}: {}", refusal.body);
        }
    }
}
