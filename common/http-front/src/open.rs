//! Reading a request's head (hyper) and answering it (one writer).

use std::cell::Cell;
use std::future::{poll_fn, ready, Ready};
use std::io;
use std::time::Duration;

use bytes::Bytes;
use http::header::{self, HeaderValue};
use http::{request, Request, Response};
use hyper::body::Incoming;
use hyper::service::Service;
use hyper_util::rt::TokioIo;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::{sleep_until, timeout, timeout_at, Instant};
use tokio_tungstenite::tungstenite::handshake::server::write_response;
use tokio_tungstenite::tungstenite::protocol::{Role, WebSocketConfig};
use tokio_tungstenite::WebSocketStream;

use crate::Stream;

/// How requests are read and answered: the deadline of a head, its largest size, and how
/// long a refused client is read from before it is closed.
#[derive(Debug, Clone)]
pub struct Reading {
    head_timeout: Duration,
    max_head_bytes: usize,
    linger: Duration,
}

impl Default for Reading {
    fn default() -> Reading {
        Reading {
            head_timeout: Duration::from_secs(10),
            max_head_bytes: 8 * 1024,
            linger: Duration::from_secs(1),
        }
    }
}

impl Reading {
    /// The most a connection may take, from its first byte, to send its whole request head
    /// (and, with TLS, to finish the handshake before it), however it trickles it: one
    /// deadline in all, not one a read. Also the longest an answer may take to be written.
    pub fn head_timeout(mut self, timeout: Duration) -> Reading {
        self.head_timeout = timeout;
        self
    }

    /// The largest request head (its first line and headers) read; a larger one is answered
    /// 431 by hyper.
    pub fn max_head_bytes(mut self, bytes: usize) -> Reading {
        self.max_head_bytes = bytes;
        self
    }

    /// After an answer that closes the connection, how long what the client still sends is
    /// read and dropped: closing with unread bytes resets the connection, and the client
    /// could lose the answer.
    pub fn linger(mut self, linger: Duration) -> Reading {
        self.linger = linger;
        self
    }

    /// The head deadline set by [`Reading::head_timeout`].
    pub fn timeout(&self) -> Duration {
        self.head_timeout
    }
}

/// Why a connection gave no request to answer.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// More connections were having their request read than the front reads at once.
    #[error("too many connections are opening at once")]
    Busy,
    /// The TLS handshake failed or was not done by the deadline (a browser that does not
    /// trust the certificate yet closes it, asks the user, and comes back).
    #[error("the TLS handshake failed")]
    Tls(#[source] io::Error),
    /// The request head was not complete by its deadline.
    #[error("the request was not complete in time")]
    Late,
    /// Not an HTTP/1 request hyper reads, or a head over the size allowed: hyper has answered
    /// it (400, or 431).
    #[error("not a request the server reads")]
    Malformed(#[source] hyper::Error),
    /// The connection closed, or failed, before a whole request: nobody to answer.
    #[error("the connection ended before a whole request")]
    Closed(#[source] Option<hyper::Error>),
}

impl OpenError {
    /// The usual answer to a connection that gave no request: 408 to one that was late, 503
    /// to one beyond those read at once (with when to come back); none where there is nobody
    /// to answer or hyper has answered.
    pub fn answer(&self) -> Option<Response<String>> {
        let mut response = match self {
            OpenError::Late => crate::text(
                http::StatusCode::REQUEST_TIMEOUT,
                "the request was not complete in time; send it whole\n",
            ),
            OpenError::Busy => crate::text(
                http::StatusCode::SERVICE_UNAVAILABLE,
                "too many connections are opening at once; try again in a few seconds\n",
            ),
            _ => return None,
        };
        if matches!(self, OpenError::Busy) {
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
        }
        Some(response)
    }
}

/// A connection past its request head: the stream, and the bytes read past the head.
pub(crate) struct Conn {
    stream: Stream,
    early: Bytes,
    reading: Reading,
}

/// A request whose head was read: answer it once.
pub struct Opened {
    /// The request's head (method, target, version, headers); its body, if any, is not read.
    pub request: request::Parts,
    conn: Conn,
}

/// A connection switched to another protocol: the stream, and what the client sent past its
/// request head (the first bytes of the new protocol, to be read before the stream's).
pub struct Switched {
    pub stream: Stream,
    pub early: Bytes,
}

/// The front's hyper service: it takes the request's head and ends hyper's part (the front
/// answers; see the crate's doc), so hyper writes nothing.
#[derive(Default)]
struct Take(Cell<Option<request::Parts>>);

/// What [`Take`] ends hyper's part with.
#[derive(Debug, thiserror::Error)]
#[error("the request is answered by the front")]
struct Taken;

impl Service<Request<Incoming>> for Take {
    type Response = Response<String>;
    type Error = Taken;
    type Future = Ready<Result<Response<String>, Taken>>;

    fn call(&self, request: Request<Incoming>) -> Self::Future {
        self.0.set(Some(request.into_parts().0));
        ready(Err(Taken))
    }
}

/// Reads a request's head from `stream` by `reading`'s deadline from now. Where there is
/// none, the connection is closed (no answer but the one hyper gives a malformed request).
pub async fn open(stream: Stream, reading: &Reading) -> Result<Opened, OpenError> {
    let deadline = Instant::now() + reading.head_timeout;
    read(stream, reading, deadline)
        .await
        .map_err(|(why, _)| why)
}

/// Reads a request's head by `deadline`; without one, why, and the connection where it can
/// still be answered (a late head) or must be closed gently (hyper answered it).
pub(crate) async fn read(
    stream: Stream,
    reading: &Reading,
    deadline: Instant,
) -> Result<Opened, (OpenError, Option<Conn>)> {
    let mut connection = hyper::server::conn::http1::Builder::new()
        .keep_alive(false)
        .max_header_size(reading.max_head_bytes)
        // The deadline is the front's (below): hyper's would close without an answer.
        .header_read_timeout(None)
        .serve_connection(TokioIo::new(stream), Take::default());
    let ended = tokio::select! {
        ended = poll_fn(|cx| connection.poll_without_shutdown(cx)) => Some(ended),
        () = sleep_until(deadline) => None,
    };
    let parts = connection.into_parts();
    let request = parts.service.0.take();
    let conn = Conn {
        stream: parts.io.into_inner(),
        early: parts.read_buf,
        reading: reading.clone(),
    };
    match (request, ended) {
        (Some(request), _) => Ok(Opened { request, conn }),
        (None, None) => Err((OpenError::Late, Some(conn))),
        (None, Some(Ok(()))) => Err((OpenError::Closed(None), None)),
        (None, Some(Err(e))) if e.is_parse() || e.is_parse_too_large() => {
            Err((OpenError::Malformed(e), Some(conn)))
        }
        (None, Some(Err(e))) => Err((OpenError::Closed(Some(e)), None)),
    }
}

impl Conn {
    /// A connection not read from (one refused before its request).
    pub(crate) fn unread(stream: Stream, reading: &Reading) -> Conn {
        Conn {
            stream,
            early: Bytes::new(),
            reading: reading.clone(),
        }
    }

    /// Writes `response` (its head with the body's `Content-Length` and `Connection: close`,
    /// then the body) and closes the connection; false when it could not be written whole.
    async fn write_answer<B: AsRef<[u8]>>(&mut self, mut response: Response<B>) -> bool {
        let length = response.body().as_ref().len();
        let headers = response.headers_mut();
        // A body is sent whole, so never chunked (an answer passed on from a server behind
        // may have been).
        headers.remove(header::TRANSFER_ENCODING);
        headers.insert(header::CONTENT_LENGTH, HeaderValue::from(length));
        headers.insert(header::CONNECTION, HeaderValue::from_static("close"));
        let mut out = Vec::with_capacity(256 + length);
        // Fails only on a header value of bytes that are not visible ASCII.
        if write_response(&mut out, &response).is_err() {
            return false;
        }
        out.extend_from_slice(response.body().as_ref());
        let wrote = timeout(self.reading.head_timeout, self.stream.write_all(&out)).await;
        matches!(wrote, Ok(Ok(())))
    }

    /// Answers `response`, then closes gently ([`Conn::close`]).
    pub(crate) async fn answer<B: AsRef<[u8]>>(mut self, response: Response<B>) {
        if self.write_answer(response).await {
            self.close().await;
        }
    }

    /// Answers `response` without waiting on the client (a connection refused before it
    /// was read: the few bytes fit its socket's buffer), and closes.
    pub(crate) async fn answer_at_once<B: AsRef<[u8]>>(mut self, response: Response<B>) {
        let linger = self.reading.linger;
        self.reading.head_timeout = linger;
        if self.write_answer(response).await {
            let _ = timeout(linger, self.stream.shutdown()).await;
        }
    }

    /// Ends the connection's writing, then reads and drops for at most the linger what the
    /// client still sends (see [`Reading::linger`]), at most 64 KiB of it.
    pub(crate) async fn close(mut self) {
        let until = Instant::now() + self.reading.linger;
        if !matches!(timeout_at(until, self.stream.shutdown()).await, Ok(Ok(()))) {
            return;
        }
        let mut sink = [0u8; 4096];
        let mut drained = 0usize;
        while drained < 64 * 1024 {
            match timeout_at(until, self.stream.read(&mut sink)).await {
                Ok(Ok(n)) if n > 0 => drained += n,
                _ => break,
            }
        }
    }

    /// Writes `response`'s head (a `101 Switching Protocols`) and hands the stream over.
    async fn switch(mut self, response: Response<()>) -> io::Result<Switched> {
        let mut head = Vec::with_capacity(256);
        write_response(&mut head, &response).map_err(io::Error::other)?;
        let wrote = timeout(self.reading.head_timeout, async {
            self.stream.write_all(&head).await?;
            self.stream.flush().await
        })
        .await;
        match wrote {
            Ok(Ok(())) => Ok(Switched {
                stream: self.stream,
                early: self.early,
            }),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(io::ErrorKind::TimedOut.into()),
        }
    }
}

impl Opened {
    /// Answers the request with `response` (`Content-Length` and `Connection: close` are
    /// set here) and closes the connection.
    pub async fn answer<B: AsRef<[u8]>>(self, response: Response<B>) {
        self.conn.answer(response).await
    }

    /// Switches the connection to another protocol: writes `response` (a `101`) and hands
    /// the stream over, with the bytes the client sent past its head.
    pub async fn switch(self, response: Response<()>) -> io::Result<Switched> {
        self.conn.switch(response).await
    }

    /// Accepts a WebSocket: writes `response` (a `101`, see
    /// [`switching_protocols`](crate::switching_protocols)) and returns the socket, of
    /// `config`'s limits.
    pub async fn into_websocket(
        self,
        response: Response<()>,
        config: Option<WebSocketConfig>,
    ) -> io::Result<WebSocketStream<Stream>> {
        let Switched { stream, early } = self.conn.switch(response).await?;
        Ok(
            WebSocketStream::from_partially_read(stream, early.to_vec(), Role::Server, config)
                .await,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::DuplexStream;

    /// `head` sent to a front reading by `reading`, and what the front got and answered.
    async fn opened(head: &[u8], reading: Reading) -> (Result<Opened, OpenError>, DuplexStream) {
        let (mut client, server) = tokio::io::duplex(64 * 1024);
        client.write_all(head).await.expect("sent");
        (open(Box::new(server), &reading).await, client)
    }

    async fn answer_of(client: &mut DuplexStream) -> String {
        let mut answer = Vec::new();
        let _ = timeout(Duration::from_secs(2), client.read_to_end(&mut answer)).await;
        String::from_utf8_lossy(&answer).into_owned()
    }

    #[tokio::test]
    async fn a_head_is_read_and_the_bytes_past_it_kept() {
        let (opened, _client) = opened(
            b"GET /ws?token=abc HTTP/1.1\r\nHost: h\r\nUpgrade: WebSocket\r\n\r\nearly",
            Reading::default(),
        )
        .await;
        let opened = opened.expect("a request");
        assert_eq!(opened.request.uri.path(), "/ws");
        assert_eq!(
            crate::query_value(&opened.request.uri, "token"),
            Some("abc")
        );
        assert!(crate::is_websocket(&opened.request));
        assert_eq!(&opened.conn.early[..], b"early");
    }

    #[tokio::test]
    async fn what_is_not_http_is_answered_400_by_hyper() {
        for head in [
            &b"hello\r\n\r\n"[..],
            b"GET /\r\n\r\n",
            b"GET / HTTP/1.1\r\nHost x\r\n\r\n",
        ] {
            let (opened, mut client) = opened(head, Reading::default()).await;
            assert!(matches!(opened, Err(OpenError::Malformed(_))), "{head:?}");
            let answer = answer_of(&mut client).await;
            assert!(answer.starts_with("HTTP/1.1 400"), "{head:?}: {answer}");
        }
    }

    #[tokio::test]
    async fn a_head_over_the_limit_is_answered_431() {
        let mut head = b"GET / HTTP/1.1\r\nX-Long: ".to_vec();
        head.resize(9000, b'a');
        head.extend_from_slice(b"\r\n\r\n");
        let (opened, mut client) = opened(&head, Reading::default().max_head_bytes(8192)).await;
        assert!(matches!(opened, Err(OpenError::Malformed(_))));
        assert!(answer_of(&mut client).await.starts_with("HTTP/1.1 431"));
    }

    #[tokio::test]
    async fn an_unfinished_head_is_late_at_its_deadline_and_answered_408() {
        let (client, server) = tokio::io::duplex(1024);
        let reading = Reading::default().head_timeout(Duration::from_millis(200));
        let mut client = client;
        client
            .write_all(b"GET / HTTP/1.1\r\nHost: x\r\n")
            .await
            .expect("sent");
        let deadline = Instant::now() + reading.head_timeout;
        let Err((OpenError::Late, Some(conn))) = read(Box::new(server), &reading, deadline).await
        else {
            panic!("not late");
        };
        let answer = OpenError::Late.answer().expect("an answer");
        tokio::spawn(conn.answer(answer));
        let text = answer_of(&mut client).await;
        assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    }

    #[tokio::test]
    async fn an_http_1_0_request_is_answered_in_http_1_1_with_its_length() {
        let (opened, mut client) =
            opened(b"GET / HTTP/1.0\r\nHost: x\r\n\r\n", Reading::default()).await;
        let opened = opened.expect("a request");
        assert_eq!(opened.request.version, http::Version::HTTP_10);
        opened
            .answer(crate::text(http::StatusCode::BAD_REQUEST, "no\n"))
            .await;
        let text = answer_of(&mut client).await;
        assert!(text.starts_with("HTTP/1.1 400 Bad Request\r\n"), "{text}");
        assert!(text.contains("content-length: 3\r\n"), "{text}");
        assert!(text.ends_with("\r\n\r\nno\n"), "{text}");
    }
}
