//! Orderly shutdown of a process of the session.
//!
//! A stage stops when it receives SIGTERM or SIGINT, or when the launcher that started it
//! goes away (its standard input, a pipe from the launcher, reaches end of file). It then
//! publishes its final latency report and waits for the launcher to release it (by closing
//! that pipe) before its ports go: iceoryx2 discards samples a departed publisher had not yet
//! delivered, so leaving early would lose the final report.

use std::io::Read;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

static STOP: AtomicBool = AtomicBool::new(false);
static RELEASED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Installs the SIGINT/SIGTERM handlers. Idempotent.
pub fn install_signal_handlers() {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        let handler = on_signal as *const () as libc::sighandler_t;
        libc::signal(libc::SIGINT, handler);
        libc::signal(libc::SIGTERM, handler);
    }
}

/// Installs the SIGTERM handler only: for a program of the user's that the launcher started
/// (an external source in Python), whose Ctrl-C stays its own. Idempotent.
pub fn install_term_handler() {
    // SAFETY: as in `install_signal_handlers`.
    unsafe {
        let handler = on_signal as *const () as libc::sighandler_t;
        libc::signal(libc::SIGTERM, handler);
    }
}

/// For a process started by the launcher: a thread that reads standard input until end of
/// file, which means "stop" (if not yet asked) and "released" (the launcher has what it needs).
pub fn watch_parent_pipe() {
    let _ = std::thread::Builder::new()
        .name("parent-pipe".into())
        .spawn(|| {
            let mut buf = [0u8; 64];
            let mut stdin = std::io::stdin();
            loop {
                match stdin.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(_) => continue,
                }
            }
            RELEASED.store(true, Ordering::SeqCst);
            STOP.store(true, Ordering::SeqCst);
        });
}

/// True once the process has been asked to stop.
pub fn requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// Asks this process to stop (as a signal would).
pub fn request() {
    STOP.store(true, Ordering::SeqCst);
}

/// Says the launcher has what it needs from this process (as the end of its pipe does): a
/// final report waits no more. For a process that is its own launcher (common/examples/stage.rs),
/// where no one else reads the report.
pub fn release() {
    RELEASED.store(true, Ordering::SeqCst);
}

/// Waits until the launcher releases this process, at most `limit`. Returns false on timeout.
pub fn wait_for_release(limit: Duration) -> bool {
    let start = Instant::now();
    while !RELEASED.load(Ordering::SeqCst) {
        if start.elapsed() >= limit {
            return false;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    true
}
