//! A stage's doorbell: one futex word in shared memory that every publisher of a topic the
//! stage reads rings after each send, and that the stage sleeps on (issue 46).
//!
//! Why: iceoryx2's event (`ipc::Service`'s) wakes a reader with a Unix datagram per listener
//! beside a bit set in shared memory; a stage that reads two topics sleeps in `ppoll` on two
//! sockets and, woken, reads each socket dry: four or five system calls per hop besides the
//! publisher's `sendto` per listener. iceoryx2's semaphore event is no cheaper where a
//! deadline is needed (its timed wait polls the semaphore, sleeping in steps;
//! [`crate::bus::semaphore`]). A doorbell is what `bench latency transport` measures as
//! `futex`: a publisher adds one to the word and, only when the stage sleeps, makes one
//! `FUTEX_WAKE`; the stage makes one `FUTEX_WAIT`, which returns when the word moved, at its
//! deadline, or on a signal (a shutdown request), so every inlet and the deadline still wake it.
//!
//! One per stage, not per topic: a stage sleeps on one word whichever of its inlets is
//! written. It lives in a file of the session's folder (`doorbell.STAGE`), so a restarted stage
//! finds the one its publishers still ring, and it goes with the session's folder.
//!
//! What it cannot do is join a `ppoll` with other descriptors (a device, a server's wake, a
//! zenoh callback's eventfd): the stages that sleep on those keep iceoryx2's event
//! ([`crate::topic::Stage::doorbell`] says which stages have one).

use std::path::Path;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use crate::output::open_restart_file;

/// The bytes a doorbell maps: the ring count (the futex word) and the sleepers.
const DOORBELL_BYTES: usize = 8;

/// A stage's doorbell, mapped into this process (see the module's doc).
pub struct Doorbell {
    words: NonNull<AtomicU32>,
}

// SAFETY: the mapping is shared memory of two atomics, valid while the value lives; every
// access is atomic.
unsafe impl Send for Doorbell {}
// SAFETY: as above.
unsafe impl Sync for Doorbell {}

impl std::fmt::Debug for Doorbell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Doorbell")
            .field("rings", &self.rings().load(Ordering::Relaxed))
            .field("sleepers", &self.sleepers().load(Ordering::Relaxed))
            .finish()
    }
}

impl Doorbell {
    /// The doorbell in file `path` (made, zeroed, when it is not there yet).
    pub fn open(path: &Path) -> std::io::Result<Doorbell> {
        use std::os::unix::io::AsRawFd;
        let file = open_restart_file(path)?;
        if file.metadata()?.len() < DOORBELL_BYTES as u64 {
            file.set_len(DOORBELL_BYTES as u64)?;
        }
        // SAFETY: maps the 8 bytes of a file opened read-write and sized to at least 8; the
        // mapping is page-aligned, so it holds two aligned AtomicU32, and it stays valid until
        // `drop` unmaps it.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                DOORBELL_BYTES,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if p == libc::MAP_FAILED {
            return Err(std::io::Error::last_os_error());
        }
        NonNull::new(p.cast())
            .map(|words| Doorbell { words })
            .ok_or_else(|| std::io::Error::other("mmap returned null"))
    }

    /// The futex word: how many times the bell rang (wrapping).
    fn rings(&self) -> &AtomicU32 {
        // SAFETY: the first of the two atomics of our live mapping.
        unsafe { self.words.as_ref() }
    }

    /// How many threads sleep on it now (a publisher makes a system call only then).
    fn sleepers(&self) -> &AtomicU32 {
        // SAFETY: the second of the two atomics of our live mapping.
        unsafe { &*self.words.as_ptr().add(1) }
    }

    /// Rings: after a sample was sent, so that a stage that finds the count moved finds the
    /// sample too. No system call unless the stage sleeps.
    pub fn ring(&self) {
        self.rings().fetch_add(1, Ordering::SeqCst);
        if self.sleepers().load(Ordering::SeqCst) > 0 {
            // SAFETY: FUTEX_WAKE on the mapped word (shared: other processes sleep on it);
            // no timeout is read.
            unsafe {
                libc::syscall(
                    libc::SYS_futex,
                    self.rings().as_ptr(),
                    libc::FUTEX_WAKE,
                    i32::MAX,
                    std::ptr::null::<libc::timespec>(),
                )
            };
        }
    }

    /// The ring count now: read it, then look for samples, then [`Doorbell::sleep`] with it,
    /// and a sample sent between the look and the sleep is not slept through.
    pub fn seen(&self) -> u32 {
        self.rings().load(Ordering::SeqCst)
    }

    /// Sleeps until the bell rings after `seen` was read, `timeout` passes, or a signal comes.
    pub fn sleep(&self, seen: u32, timeout: Duration) {
        self.sleepers().fetch_add(1, Ordering::SeqCst);
        let ts = libc::timespec {
            tv_sec: timeout.as_secs().min(i32::MAX as u64) as libc::time_t,
            tv_nsec: timeout.subsec_nanos() as libc::c_long,
        };
        // SAFETY: FUTEX_WAIT on the mapped word with a relative timeout on the stack. It
        // returns at once when the word no longer reads `seen` (EAGAIN), at the timeout
        // (ETIMEDOUT), on a wake or a signal (EINTR): every one is a return to look again.
        unsafe {
            libc::syscall(
                libc::SYS_futex,
                self.rings().as_ptr(),
                libc::FUTEX_WAIT,
                seen,
                &ts as *const libc::timespec,
            )
        };
        self.sleepers().fetch_sub(1, Ordering::SeqCst);
    }

    /// Sleeps as [`Doorbell::sleep`] unless `ready()` (samples waiting) says there is work.
    pub fn wait_unless(&self, ready: impl Fn() -> bool, timeout: Duration) {
        let seen = self.seen();
        if !ready() {
            self.sleep(seen, timeout);
        }
    }
}

impl Drop for Doorbell {
    fn drop(&mut self) {
        // SAFETY: unmaps the bytes `open` mapped, once; nothing refers to them after.
        unsafe { libc::munmap(self.words.as_ptr().cast(), DOORBELL_BYTES) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    #[test]
    fn a_ring_wakes_a_sleeper_and_a_ring_before_the_sleep_is_not_slept_through() {
        let dir = std::env::temp_dir().join(format!("hb-doorbell-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("doorbell.stepper");
        let stage = Doorbell::open(&path).unwrap();
        let publisher = Doorbell::open(&path).unwrap();

        // Rung between the look and the sleep: the sleep returns at once (the ceilings here are
        // half of a 60 s deadline: only a wake-up that never comes reaches them).
        let seen = stage.seen();
        publisher.ring();
        let t = Instant::now();
        stage.sleep(seen, Duration::from_secs(60));
        assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());

        // Nothing rings: the deadline ends the sleep.
        let t = Instant::now();
        stage.sleep(stage.seen(), Duration::from_millis(30));
        assert!(
            t.elapsed() >= Duration::from_millis(25),
            "{:?}",
            t.elapsed()
        );

        // A ring from another thread (another process maps the same file) wakes it.
        let ringer = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(50));
            publisher.ring();
        });
        let t = Instant::now();
        stage.sleep(stage.seen(), Duration::from_secs(60));
        assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());
        ringer.join().unwrap();

        // Work waiting: no sleep at all.
        let t = Instant::now();
        stage.wait_unless(|| true, Duration::from_secs(60));
        assert!(t.elapsed() < Duration::from_secs(30));
        drop(stage);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
