//! Passing an opening request on to a server behind (a gate's other side), with hyper's
//! client reading the server's answer.

use std::io;
use std::net::SocketAddr;

use bytes::Bytes;
use http::{response, Request, Response, StatusCode};
use http_body_util::{BodyExt, Empty, Limited};
use hyper::upgrade::Upgraded;
use hyper_util::rt::TokioIo;
use tokio::net::TcpStream;
use tokio::time::{timeout_at, Instant};

/// The server's side of a switched connection (what it sent past its answer is read first).
pub type Upstream = TokioIo<Upgraded>;

/// The most of a refusal's body kept to pass on (a server's refusal is a line or two).
const MAX_ANSWER_BODY: usize = 64 * 1024;

/// What the server behind answered.
pub enum Passed {
    /// It switched protocols: its answer's head, and its side of the connection.
    Switched {
        response: response::Parts,
        stream: Upstream,
    },
    /// It answered otherwise (a refusal): the whole answer.
    Answered(Response<Bytes>),
}

/// Why an opening could not be passed on.
#[derive(Debug, thiserror::Error)]
pub enum PassError {
    /// Nothing accepts connections at the server's address.
    #[error("cannot connect to {server}")]
    Connect {
        server: SocketAddr,
        #[source]
        source: io::Error,
    },
    /// The server took the request but gave no whole answer by the deadline.
    #[error("{server} did not answer in time")]
    Late { server: SocketAddr },
    /// The server's answer was not HTTP, or the connection failed.
    #[error("{server} gave no answer")]
    Answer {
        server: SocketAddr,
        #[source]
        source: hyper::Error,
    },
    /// A refusal's body failed, or was over 64 KiB.
    #[error("{server}'s answer had a body that could not be read")]
    Body {
        server: SocketAddr,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// Sends `request` (a head: no body) to `server` and reads its answer by `deadline`.
pub async fn pass_on(
    server: SocketAddr,
    request: Request<()>,
    deadline: Instant,
) -> Result<Passed, PassError> {
    let tcp = match timeout_at(deadline, TcpStream::connect(server)).await {
        Ok(Ok(tcp)) => tcp,
        Ok(Err(source)) => return Err(PassError::Connect { server, source }),
        Err(_) => {
            let source = io::ErrorKind::TimedOut.into();
            return Err(PassError::Connect { server, source });
        }
    };
    let _ = tcp.set_nodelay(true);
    let answer = |source| PassError::Answer { server, source };
    let (mut sender, connection) = hyper::client::conn::http1::handshake(TokioIo::new(tcp))
        .await
        .map_err(answer)?;
    // The connection runs beside the request until it ends, or hands its stream over to the
    // upgrade below.
    tokio::spawn(connection.with_upgrades());
    let request = request.map(|()| Empty::<Bytes>::new());
    let mut response = match timeout_at(deadline, sender.send_request(request)).await {
        Ok(Ok(response)) => response,
        Ok(Err(e)) => return Err(answer(e)),
        Err(_) => return Err(PassError::Late { server }),
    };
    if response.status() == StatusCode::SWITCHING_PROTOCOLS {
        let upgraded = match timeout_at(deadline, hyper::upgrade::on(&mut response)).await {
            Ok(Ok(upgraded)) => upgraded,
            Ok(Err(e)) => return Err(answer(e)),
            Err(_) => return Err(PassError::Late { server }),
        };
        return Ok(Passed::Switched {
            response: response.into_parts().0,
            stream: TokioIo::new(upgraded),
        });
    }
    let (head, body) = response.into_parts();
    let body = match timeout_at(deadline, Limited::new(body, MAX_ANSWER_BODY).collect()).await {
        Ok(Ok(body)) => body.to_bytes(),
        Ok(Err(source)) => return Err(PassError::Body { server, source }),
        Err(_) => return Err(PassError::Late { server }),
    };
    Ok(Passed::Answered(Response::from_parts(head, body)))
}
