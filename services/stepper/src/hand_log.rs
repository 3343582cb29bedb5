//! Issue 16, supervision: the hand samples a supervised stepper has taken, in order, kept in
//! the session's folder (removed with it) so that a restarted stepper takes them all again and
//! rebuilds the exact world (`stepper::service`).
//!
//! A file mapped into memory: appending a sample is a copy into the mapping and a store of
//! the count (no system call: a `write` to a file on ext4 cost the stepper ~37 us per sample),
//! and what was copied outlives the process (the page cache keeps it when the process is
//! killed). The file grows by [`CHUNK`] samples at a time (one `ftruncate` and `mmap` per
//! chunk, ~8 s at 120 Hz). Layout: the count of whole samples (u64), the sample size (u64, a
//! check that the file was written by this layout), then the samples' bytes.

use std::fs::File;
use std::path::Path;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, Ordering};

use common::samples::{HandSample, Pose, MAX_FINGERS, MAX_FINGER_POINTS, MAX_PALM_VERTICES};
use common::stamp::Stamp;

/// The bytes of one sample in the log: its memory, which has no padding (checked here), so
/// every byte copied is initialised.
pub const HAND_BYTES: usize = std::mem::size_of::<HandSample>();
const _: () = assert!(
    HAND_BYTES
        == std::mem::size_of::<Stamp>()
            + std::mem::size_of::<Pose>()
            + 4 * (3 + MAX_FINGERS)
            + 4 * 2
            + 8 * 3 * MAX_FINGER_POINTS * MAX_FINGERS
            + 8 * MAX_FINGERS
            + 8 * 3 * MAX_PALM_VERTICES,
    "HandSample has padding: the hand log must not copy uninitialised bytes"
);
/// The count and the sample size.
const HEADER: usize = 16;
/// Samples the file grows by.
pub const CHUNK: usize = 1024;

/// An append-only log of hand samples in a mapped file.
pub struct HandLog {
    file: File,
    map: NonNull<u8>,
    /// Bytes mapped (the file's size).
    mapped: usize,
    count: u64,
}

impl HandLog {
    /// Opens (or creates) the log at `path` and returns the samples already in it. A sample
    /// whose copy a kill cut short is not counted (the count is stored after the copy).
    pub fn open(path: &Path) -> Result<(HandLog, Vec<HandSample>), String> {
        let what = |e: std::io::Error| format!("the stepper's hand log {}: {e}", path.display());
        let file = common::output::open_restart_file(path).map_err(what)?;
        let size = file.metadata().map_err(what)?.len() as usize;
        let mut log = HandLog {
            file,
            map: NonNull::dangling(),
            mapped: 0,
            count: 0,
        };
        log.map_to(size.max(HEADER + CHUNK * HAND_BYTES))
            .map_err(what)?;
        let kept_size = log.word(1).load(Ordering::Acquire);
        if kept_size != 0 && kept_size != HAND_BYTES as u64 {
            return Err(format!(
                "the stepper's hand log {}: samples of {kept_size} bytes, this build's are \
                 {HAND_BYTES}: it was written by another build; end the session and start anew",
                path.display()
            ));
        }
        log.word(1).store(HAND_BYTES as u64, Ordering::Release);
        let room = ((log.mapped - HEADER) / HAND_BYTES) as u64;
        log.count = log.word(0).load(Ordering::Acquire).min(room);
        let taken = (0..log.count as usize)
            .map(|i| {
                // SAFETY: sample i lies inside the mapping (i < count <= room); its bytes were
                // copied from a HandSample by this layout (checked above), and every field of
                // HandSample is an integer or a float, for which any bit pattern is a value.
                unsafe {
                    std::ptr::read_unaligned(
                        log.map
                            .as_ptr()
                            .add(HEADER + i * HAND_BYTES)
                            .cast::<HandSample>(),
                    )
                }
            })
            .collect();
        Ok((log, taken))
    }

    /// Samples in the log.
    pub fn len(&self) -> u64 {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Appends `hand`: a copy into the mapping, then the count (so a kill between the two
    /// leaves the sample out, never half of it in).
    pub fn append(&mut self, hand: &HandSample) -> std::io::Result<()> {
        let at = HEADER + self.count as usize * HAND_BYTES;
        if at + HAND_BYTES > self.mapped {
            self.map_to(self.mapped + CHUNK * HAND_BYTES)?;
        }
        // SAFETY: `at + HAND_BYTES <= mapped`, so the destination lies in our writable
        // mapping; the source is a live HandSample without padding (HAND_BYTES, checked
        // above); the two cannot overlap (the mapping is ours alone).
        unsafe {
            std::ptr::copy_nonoverlapping(
                std::ptr::from_ref(hand).cast::<u8>(),
                self.map.as_ptr().add(at),
                HAND_BYTES,
            );
        }
        self.count += 1;
        self.word(0).store(self.count, Ordering::Release);
        Ok(())
    }

    /// Header word `i` (0: count, 1: sample size).
    fn word(&self, i: usize) -> &AtomicU64 {
        // SAFETY: the mapping is page-aligned and at least HEADER bytes long, so words 0 and
        // 1 are aligned u64s inside it; i is 0 or 1.
        unsafe { &*self.map.as_ptr().cast::<AtomicU64>().add(i.min(1)) }
    }

    /// Sizes the file to `size` bytes and maps all of it (in place of the old mapping).
    fn map_to(&mut self, size: usize) -> std::io::Result<()> {
        use std::os::unix::io::AsRawFd;
        let had = self.file.metadata()?.len() as usize;
        if had < size {
            // Blocks allocated now, not at each page's first write (on ext4 a write fault that
            // allocates cost the stepper tens of microseconds every few samples).
            // SAFETY: posix_fallocate on our own open descriptor with a valid range.
            let err = unsafe {
                libc::posix_fallocate(
                    self.file.as_raw_fd(),
                    had as libc::off_t,
                    (size - had) as libc::off_t,
                )
            };
            if err != 0 {
                // A file system without it: the size alone will do.
                self.file.set_len(size as u64)?;
            }
        }
        // SAFETY: maps `size` bytes of our file, opened read-write and at least that long;
        // the old mapping (if any) is unmapped only after the new one exists, and nothing
        // refers into it past this call.
        unsafe {
            let p = libc::mmap(
                std::ptr::null_mut(),
                size,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                self.file.as_raw_fd(),
                0,
            );
            if p == libc::MAP_FAILED {
                return Err(std::io::Error::last_os_error());
            }
            if self.mapped > 0 {
                libc::munmap(self.map.as_ptr().cast(), self.mapped);
            }
            self.map = NonNull::new(p.cast()).ok_or_else(|| std::io::Error::other("null map"))?;
        }
        self.mapped = size;
        Ok(())
    }
}

impl Drop for HandLog {
    fn drop(&mut self) {
        if self.mapped > 0 {
            // SAFETY: unmaps our own mapping, once.
            unsafe { libc::munmap(self.map.as_ptr().cast(), self.mapped) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hands_come_back_in_order_across_reopens_and_growth() {
        let dir = std::env::temp_dir().join(format!("hb-handlog-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("stepper.hands");
        let hand = |k: u64| {
            let mut h = HandSample::default();
            h.stamp.seq = k;
            h.wrist.position = [k as f64, 0.5, -1.0];
            h.finger_points[4][4] = [1.0, 2.0, k as f64];
            h
        };
        {
            let (mut log, taken) = HandLog::open(&path).unwrap();
            assert!(taken.is_empty());
            for k in 0..10 {
                log.append(&hand(k)).unwrap();
            }
        }
        let (mut log, taken) = HandLog::open(&path).unwrap();
        assert_eq!(taken, (0..10).map(hand).collect::<Vec<_>>());
        // Past the first chunk: the file grows and the mapping follows.
        for k in 10..(CHUNK as u64 + 20) {
            log.append(&hand(k)).unwrap();
        }
        drop(log);
        let (log, taken) = HandLog::open(&path).unwrap();
        assert_eq!(log.len(), CHUNK as u64 + 20);
        assert!(taken.iter().enumerate().all(|(k, h)| *h == hand(k as u64)));
        drop(log);
        std::fs::remove_dir_all(dir).unwrap();
    }
}
