//! One HTTP front for the project's two servers: the webxr stage's page (HTTPS, a page, its
//! scripts and one WebSocket per page) and the live Foxglove view's gate (a WebSocket opening
//! checked, then passed on to the `foxglove` crate's server behind it).
//!
//! Both run the same way: a [`Front`] ([`FrontBuilder`]) owns a tokio runtime of a few
//! threads and a listener; each connection is a task, so a silent or slow client costs a task
//! and a buffer, never a thread. The front reads each request's head with **hyper** (one
//! deadline for the TLS handshake and the whole head however it is trickled, a bound on its
//! size, HTTP/1.x only: a request hyper cannot read is answered 400, or 431 when too large,
//! by hyper itself) and hands the [`Handler`] an [`Opened`] request: its head
//! (`http::request::Parts`) and the connection, which the handler answers once
//! ([`Opened::answer`]), or switches to a WebSocket ([`Opened::into_websocket`]) or to bytes
//! of its own ([`Opened::switch`]).
//!
//! **Why hyper only reads.** Every answer is written here, by one writer (tungstenite's
//! `write_response` for the head, the body after it), not by hyper's response path, because
//! the servers' answers are not all answers to a request hyper could still write one for: a
//! head not complete by its deadline is answered 408 and a connection beyond the ones being
//! read at once 503, both without a request; an HTTP/1.0 request is refused with an
//! `HTTP/1.1` status line (hyper would answer it in HTTP/1.0); and a WebSocket, or the gate's
//! byte relay, takes the stream with the bytes read past the head. So the front's hyper
//! service takes the request's head and ends hyper's part ([`Opened`]); the stream comes back
//! with `Connection::into_parts`.
//!
//! [`pass_on`] is the other side of a gate: it sends an opening request to a server behind
//! and reads its answer with hyper's client, handing over the upgraded stream.

mod front;
mod open;
mod pass;

pub use front::{Front, FrontBuilder, Handler, StartError};
pub use open::{open, OpenError, Opened, Reading, Switched};
pub use pass::{pass_on, PassError, Passed, Upstream};

/// The HTTP types the servers name (the same `http` crate hyper and tungstenite use).
pub use http;
/// The WebSocket a switched connection becomes, and its protocol crate.
pub use tokio_tungstenite::{tungstenite, WebSocketStream};

use http::header::{self, AsHeaderName, HeaderMap, HeaderValue};
use http::{Response, StatusCode, Uri};
use tokio::io::{AsyncRead, AsyncWrite};

/// What a connection is to a handler: TCP, or TLS over TCP.
pub trait Io: AsyncRead + AsyncWrite + Unpin + Send + 'static {}
impl<T: AsyncRead + AsyncWrite + Unpin + Send + 'static> Io for T {}

/// A connection, whichever it is: plain or TLS (boxed, so handlers have one type to name).
pub type Stream = Box<dyn Io>;

/// A plain-text answer: `status` with `body` (UTF-8).
pub fn text(status: StatusCode, body: impl Into<String>) -> Response<String> {
    let mut response = Response::new(body.into());
    *response.status_mut() = status;
    response.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; charset=utf-8"),
    );
    response
}

/// The comma-separated items of every `name` header (trimmed, empty ones left out); a value
/// that is not visible ASCII has none.
pub fn tokens<'a, K: AsHeaderName>(
    headers: &'a HeaderMap,
    name: K,
) -> impl Iterator<Item = &'a str> + 'a {
    headers
        .get_all(name)
        .into_iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .filter(|t| !t.is_empty())
}

/// Whether some `name` header lists `token` (any case), as `Connection: keep-alive, Upgrade`
/// lists `upgrade`.
pub fn has_token<K: AsHeaderName>(headers: &HeaderMap, name: K, token: &str) -> bool {
    tokens(headers, name).any(|t| t.eq_ignore_ascii_case(token))
}

/// Whether a request asks for a WebSocket (`Upgrade: websocket`).
pub fn is_websocket(request: &http::request::Parts) -> bool {
    has_token(&request.headers, header::UPGRADE, "websocket")
}

/// The value of `name` in `uri`'s query (`?a=1&token=T`), as written (no percent-decoding:
/// the values asked for here are of URL-safe characters).
pub fn query_value<'a>(uri: &'a Uri, name: &str) -> Option<&'a str> {
    uri.query()?
        .split('&')
        .find_map(|pair| pair.strip_prefix(name)?.strip_prefix('='))
}

/// The answer that accepts a WebSocket opening whose `Sec-WebSocket-Key` is `key`.
pub fn switching_protocols(key: &HeaderValue) -> Response<()> {
    let accept = tungstenite::handshake::derive_accept_key(key.as_bytes());
    let mut response = Response::new(());
    *response.status_mut() = StatusCode::SWITCHING_PROTOCOLS;
    let headers = response.headers_mut();
    headers.insert(header::UPGRADE, HeaderValue::from_static("websocket"));
    headers.insert(header::CONNECTION, HeaderValue::from_static("Upgrade"));
    if let Ok(accept) = HeaderValue::from_str(&accept) {
        headers.insert(header::SEC_WEBSOCKET_ACCEPT, accept);
    }
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_read_from_every_line_in_any_case() {
        let mut h = HeaderMap::new();
        h.append(
            header::CONNECTION,
            HeaderValue::from_static("keep-alive, Upgrade"),
        );
        h.append(
            header::SEC_WEBSOCKET_PROTOCOL,
            HeaderValue::from_static("a, b"),
        );
        h.append(
            header::SEC_WEBSOCKET_PROTOCOL,
            HeaderValue::from_static("c"),
        );
        assert!(has_token(&h, header::CONNECTION, "upgrade"));
        assert!(!has_token(&h, header::UPGRADE, "websocket"));
        let offered: Vec<_> = tokens(&h, header::SEC_WEBSOCKET_PROTOCOL).collect();
        assert_eq!(offered, ["a", "b", "c"]);
    }

    #[test]
    fn a_query_value_is_found_by_its_whole_name() {
        let uri: Uri = "/ws?xtoken=no&token=abc&x=1".parse().expect("a URI");
        assert_eq!(query_value(&uri, "token"), Some("abc"));
        assert_eq!(query_value(&uri, "y"), None);
        let bare: Uri = "/".parse().expect("a URI");
        assert_eq!(query_value(&bare, "token"), None);
    }

    #[test]
    fn the_accept_key_is_the_rfcs() {
        // RFC 6455, section 1.3.
        let r = switching_protocols(&HeaderValue::from_static("dGhlIHNhbXBsZSBub25jZQ=="));
        assert_eq!(r.status(), StatusCode::SWITCHING_PROTOCOLS);
        assert_eq!(
            r.headers()[header::SEC_WEBSOCKET_ACCEPT],
            "s3pPLMBiTxaQ9kYGzzhZRbK+xOo="
        );
    }
}
