//! The live view's front door: it accepts both WebSocket subprotocols Foxglove clients offer and
//! hands every connection to the `foxglove` crate's server.
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
//! A client that offers neither gets a 400 that names both. Each connection costs two threads
//! (a view has a handful of clients), none of them on the session's pipeline.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// The published protocol's subprotocol name.
pub const WEBSOCKET_V1: &str = "foxglove.websocket.v1";
/// The SDK server's names, newest last.
pub const SDK_V1: &str = "foxglove.sdk.v1";
pub const SDK_V1_1: &str = "foxglove.sdk.v1.1";

/// The most an opening request (or the server's answer) may take before its blank line.
const MAX_HEAD_BYTES: usize = 16 * 1024;
/// How long a client may take to send its opening request.
const HEAD_TIMEOUT: Duration = Duration::from_secs(5);

/// A running gate: stopping it closes the listener (connections already open end when the
/// server behind closes them).
pub struct Gate {
    stop: Arc<AtomicBool>,
    addr: SocketAddr,
    acceptor: Option<JoinHandle<()>>,
}

impl Gate {
    /// Listens on `host:port` (port 0: any free one, see [`Gate::port`]) and forwards each
    /// connection to `server` (the `foxglove` server's loopback address).
    pub fn start(host: &str, port: u16, server: SocketAddr) -> io::Result<Gate> {
        let listener = TcpListener::bind((host, port))?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = stop.clone();
        let acceptor = std::thread::Builder::new()
            .name("foxglove-gate".into())
            .spawn(move || {
                for client in listener.incoming() {
                    if stopping.load(Ordering::Acquire) {
                        break;
                    }
                    let Ok(client) = client else { continue };
                    let _ = std::thread::Builder::new()
                        .name("foxglove-client".into())
                        .spawn(move || {
                            let _ = serve(client, server);
                        });
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

/// Reads up to and including the blank line that ends an HTTP head; returns the head and any
/// bytes read past it.
fn read_head(stream: &mut TcpStream) -> io::Result<(Vec<u8>, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            return Ok((buf, rest));
        }
        if buf.len() > MAX_HEAD_BYTES {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "an HTTP head over 16 KiB",
            ));
        }
        let n = stream.read(&mut chunk)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// The subprotocols a head's `Sec-WebSocket-Protocol` lines offer.
fn offered(head: &str) -> Vec<&str> {
    head.lines()
        .filter_map(|line| line.split_once(':'))
        .filter(|(name, _)| name.trim().eq_ignore_ascii_case("sec-websocket-protocol"))
        .flat_map(|(_, value)| value.split(',').map(str::trim))
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

fn serve(mut client: TcpStream, server: SocketAddr) -> io::Result<()> {
    client.set_read_timeout(Some(HEAD_TIMEOUT))?;
    let (head, early) = read_head(&mut client)?;
    let head = String::from_utf8_lossy(&head).into_owned();
    let admission = admit(&offered(&head));
    if admission == Admission::Refused {
        let body = format!(
            "This is handblocks' live Foxglove view. Offer the WebSocket subprotocol \
             {WEBSOCKET_V1} or {SDK_V1} (in Foxglove: Open connection -> Foxglove WebSocket).\n"
        );
        let _ = write!(
            client,
            "HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\nContent-Length: {}\r\n\
             Connection: close\r\n\r\n{body}",
            body.len()
        );
        return Ok(());
    }
    client.set_read_timeout(None)?;
    let mut upstream = TcpStream::connect(server)?;
    upstream.set_nodelay(true)?;
    client.set_nodelay(true)?;
    let request = match admission {
        Admission::Renamed => with_protocol(&head, SDK_V1),
        _ => head,
    };
    upstream.write_all(request.as_bytes())?;
    upstream.write_all(&early)?;
    let (answer, after) = read_head(&mut upstream)?;
    let answer = String::from_utf8_lossy(&answer).into_owned();
    let answer = match admission {
        Admission::Renamed if !offered(&answer).is_empty() => with_protocol(&answer, WEBSOCKET_V1),
        _ => answer,
    };
    client.write_all(answer.as_bytes())?;
    client.write_all(&after)?;
    // From here on, bytes both ways, untouched.
    let (mut client_in, mut upstream_out) = (client.try_clone()?, upstream.try_clone()?);
    let to_server = std::thread::Builder::new()
        .name("foxglove-up".into())
        .spawn(move || {
            let _ = io::copy(&mut client_in, &mut upstream_out);
            let _ = upstream_out.shutdown(Shutdown::Write);
        })?;
    let _ = io::copy(&mut upstream, &mut client);
    let _ = client.shutdown(Shutdown::Both);
    let _ = upstream.shutdown(Shutdown::Both);
    let _ = to_server.join();
    Ok(())
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
}
