//! The front: a runtime, a listener, and a task per connection.

use std::future::Future;
use std::io;
use std::net::{SocketAddr, ToSocketAddrs};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use http::Response;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tokio::time::{timeout_at, Instant};

use crate::open::{self, Conn, OpenError, Opened, Reading};
use crate::Stream;

/// What a server does with its connections.
pub trait Handler: Send + Sync + 'static {
    /// Answers a request whose head was read (once: answered, or switched to another
    /// protocol and served until it ends).
    fn serve(&self, opened: Opened) -> impl Future<Output = ()> + Send;

    /// A connection that gave no request (`why`): the answer to give it, where it can still
    /// be given one (a late head, or one beyond those read at once); the default is
    /// [`OpenError::answer`]. Counting refusals goes here.
    fn unopened(&self, why: &OpenError) -> Option<Response<String>> {
        why.answer()
    }
}

/// Why a front could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// The address cannot be listened on (in use, not this machine's, not resolved).
    #[error("cannot listen")]
    Listen(#[source] io::Error),
    /// The runtime's threads (or the listener's registration with it) could not be made.
    #[error("cannot start the server's threads")]
    Runtime(#[source] io::Error),
}

/// How a [`Front`] is made: its threads, how it reads requests, how many it reads at once,
/// and TLS.
#[derive(Debug)]
pub struct FrontBuilder {
    name: String,
    threads: usize,
    reading: Reading,
    opening_at_once: Option<usize>,
    tls: Option<Arc<rustls::ServerConfig>>,
}

impl FrontBuilder {
    /// A front whose threads are named `name`: two of them, requests read by
    /// [`Reading::default`], as many at once as come, no TLS.
    pub fn new(name: &str) -> FrontBuilder {
        FrontBuilder {
            name: name.to_string(),
            threads: 2,
            reading: Reading::default(),
            opening_at_once: None,
            tls: None,
        }
    }

    /// The runtime's worker threads (at least 1).
    pub fn threads(mut self, threads: usize) -> FrontBuilder {
        self.threads = threads.max(1);
        self
    }

    /// How requests are read and answered.
    pub fn reading(mut self, reading: Reading) -> FrontBuilder {
        self.reading = reading;
        self
    }

    /// At most `at_once` connections have their request read at the same time; one beyond
    /// them is answered at once, unread ([`OpenError::Busy`]), so a flood of connections
    /// that send nothing holds at most this many for their deadline.
    pub fn opening_at_once(mut self, at_once: usize) -> FrontBuilder {
        self.opening_at_once = Some(at_once.max(1));
        self
    }

    /// HTTPS (and WSS) with `config`, where given.
    pub fn tls(mut self, config: Option<Arc<rustls::ServerConfig>>) -> FrontBuilder {
        self.tls = config;
        self
    }

    /// Binds `listen` now (so an address in use fails the caller before anyone counts on
    /// it) and serves every connection with `handler`.
    pub fn start<H: Handler>(
        self,
        listen: impl ToSocketAddrs,
        handler: H,
    ) -> Result<Front, StartError> {
        let listener = std::net::TcpListener::bind(listen).map_err(StartError::Listen)?;
        listener
            .set_nonblocking(true)
            .map_err(StartError::Runtime)?;
        let local_addr = listener.local_addr().map_err(StartError::Runtime)?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(self.threads)
            .thread_name(self.name)
            .enable_io()
            .enable_time()
            .build()
            .map_err(StartError::Runtime)?;
        let listener = {
            let _guard = runtime.enter();
            TcpListener::from_std(listener).map_err(StartError::Runtime)?
        };
        let (stop, stopped) = watch::channel(false);
        let shared = Arc::new(Shared {
            handler,
            reading: self.reading,
            opening_at_once: self.opening_at_once.unwrap_or(usize::MAX),
            opening: AtomicUsize::new(0),
            tls: self.tls.map(tokio_rustls::TlsAcceptor::from),
        });
        runtime.spawn(accept(listener, shared, stopped));
        Ok(Front {
            runtime: Some(runtime),
            stop,
            local_addr,
        })
    }
}

/// A running front; stopped (or dropped), it accepts no more and its tasks end: every
/// connection still open is closed.
pub struct Front {
    runtime: Option<tokio::runtime::Runtime>,
    stop: watch::Sender<bool>,
    local_addr: SocketAddr,
}

impl Front {
    /// Where it listens (the port chosen, where 0 was asked for).
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Stops accepting and ends every connection's task (waiting at most 2 s for the
    /// runtime's threads).
    pub fn stop(&mut self) {
        let _ = self.stop.send(true);
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_timeout(Duration::from_secs(2));
        }
    }
}

impl Drop for Front {
    fn drop(&mut self) {
        self.stop();
    }
}

/// What every connection's task shares.
struct Shared<H> {
    handler: H,
    reading: Reading,
    opening_at_once: usize,
    opening: AtomicUsize,
    tls: Option<tokio_rustls::TlsAcceptor>,
}

/// A connection's place among those whose request is being read, given back when dropped
/// (by whatever path its task ends).
struct Opening<H> {
    shared: Arc<Shared<H>>,
}

impl<H> Opening<H> {
    fn take(shared: &Arc<Shared<H>>) -> Option<Opening<H>> {
        shared
            .opening
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < shared.opening_at_once).then_some(n + 1)
            })
            .ok()?;
        Some(Opening {
            shared: shared.clone(),
        })
    }
}

impl<H> Drop for Opening<H> {
    fn drop(&mut self) {
        self.shared.opening.fetch_sub(1, Ordering::AcqRel);
    }
}

async fn accept<H: Handler>(
    listener: TcpListener,
    shared: Arc<Shared<H>>,
    mut stop: watch::Receiver<bool>,
) {
    loop {
        tokio::select! {
            accepted = listener.accept() => {
                let Ok((tcp, _peer)) = accepted else {
                    // Out of descriptors, most likely: let some connections end rather than
                    // spin on the error.
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                };
                let _ = tcp.set_nodelay(true);
                match Opening::take(&shared) {
                    Some(opening) => {
                        tokio::spawn(connection(tcp, shared.clone(), opening));
                    }
                    None => {
                        tokio::spawn(busy(tcp, shared.clone()));
                    }
                }
            }
            _ = stop.changed() => return,
        }
    }
}

/// One connection: TLS (if any) and its request's head by one deadline, then its handler.
async fn connection<H: Handler>(tcp: TcpStream, shared: Arc<Shared<H>>, opening: Opening<H>) {
    let deadline = Instant::now() + shared.reading.timeout();
    let stream: Stream = match &shared.tls {
        None => Box::new(tcp),
        Some(acceptor) => match timeout_at(deadline, acceptor.accept(tcp)).await {
            Ok(Ok(tls)) => Box::new(tls),
            handshake => {
                let e = match handshake {
                    Ok(Err(e)) => e,
                    _ => io::ErrorKind::TimedOut.into(),
                };
                // Nobody to answer in HTTP.
                let _ = shared.handler.unopened(&OpenError::Tls(e));
                return;
            }
        },
    };
    match open::read(stream, &shared.reading, deadline).await {
        Ok(opened) => {
            drop(opening);
            shared.handler.serve(opened).await;
        }
        Err((why, conn)) => {
            drop(opening);
            let answer = shared.handler.unopened(&why);
            match (why, conn, answer) {
                // hyper answered it.
                (OpenError::Malformed(_), Some(conn), _) => conn.close().await,
                (_, Some(conn), Some(answer)) => conn.answer(answer).await,
                _ => {}
            }
        }
    }
}

/// A connection beyond those read at once: answered without being read, and closed.
async fn busy<H: Handler>(tcp: TcpStream, shared: Arc<Shared<H>>) {
    if let Some(answer) = shared.handler.unopened(&OpenError::Busy) {
        Conn::unread(Box::new(tcp), &shared.reading)
            .answer_at_once(answer)
            .await;
    }
}
