//! The framed sample log: an 8-byte header `HBLOG\0\x01\0`, then per sample a little-endian
//! `u32` topic, a `u32` byte length and the sample's `#[repr(C)]` bytes.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use common::bus::Stamped;
use common::Topic;

pub const MAGIC: [u8; 8] = *b"HBLOG\0\x01\0";

/// Appends samples to a log file through a buffer (no allocation per sample).
pub struct LogWriter {
    out: BufWriter<File>,
    pub samples: u64,
}

impl LogWriter {
    pub fn create(path: &Path) -> std::io::Result<LogWriter> {
        if let Some(dir) = path.parent() {
            if !dir.as_os_str().is_empty() {
                std::fs::create_dir_all(dir)?;
            }
        }
        let mut out = BufWriter::with_capacity(1 << 20, File::create(path)?);
        out.write_all(&MAGIC)?;
        Ok(LogWriter { out, samples: 0 })
    }

    pub fn write<T: Stamped>(&mut self, topic: Topic, sample: &T) -> std::io::Result<()> {
        // SAFETY: every sample type is #[repr(C)], Copy, and laid out without implicit padding
        // (explicit `_reserved` fields fill it), so all its bytes are initialised.
        let bytes = unsafe {
            std::slice::from_raw_parts(sample as *const T as *const u8, std::mem::size_of::<T>())
        };
        self.out.write_all(&(topic as u32).to_le_bytes())?;
        self.out.write_all(&(bytes.len() as u32).to_le_bytes())?;
        self.out.write_all(bytes)?;
        self.samples += 1;
        Ok(())
    }

    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Counts the samples per topic in a log file (for tests and `handblocks` tooling).
pub fn count_samples(path: &Path) -> std::io::Result<[u64; Topic::ALL.len()]> {
    let bytes = std::fs::read(path)?;
    let bad = |what: String| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{}: {what}", path.display()),
        )
    };
    if bytes.len() < 8 || bytes[..8] != MAGIC {
        return Err(bad("not a handblocks sample log (wrong magic)".into()));
    }
    let mut counts = [0u64; Topic::ALL.len()];
    let mut at = 8;
    while at < bytes.len() {
        if at + 8 > bytes.len() {
            return Err(bad(format!("record header cut off at offset {at}")));
        }
        let topic = u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
        let len = u32::from_le_bytes([bytes[at + 4], bytes[at + 5], bytes[at + 6], bytes[at + 7]])
            as usize;
        let Some(t) = Topic::from_u32(topic) else {
            return Err(bad(format!("unknown topic {topic} at offset {at}")));
        };
        if at + 8 + len > bytes.len() {
            return Err(bad(format!("record of {len} bytes cut off at offset {at}")));
        }
        counts[t as usize] += 1;
        at += 8 + len;
    }
    Ok(counts)
}
