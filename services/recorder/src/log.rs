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

/// One record of a log: its topic and the sample's bytes.
pub struct Record<'a> {
    pub topic: Topic,
    pub bytes: &'a [u8],
}

impl Record<'_> {
    /// The record as sample type `T`, if it has exactly `T`'s size.
    pub fn sample<T: Stamped>(&self) -> Option<T> {
        if self.bytes.len() != std::mem::size_of::<T>() {
            return None;
        }
        // SAFETY: the length matches and every sample type is plain old data (#[repr(C)],
        // Copy, only numbers); read_unaligned copes with the byte buffer's alignment.
        Some(unsafe { std::ptr::read_unaligned(self.bytes.as_ptr() as *const T) })
    }
}

/// Splits a log's bytes into records; the error names the offset of the first bad byte.
pub fn records(bytes: &[u8]) -> Result<Vec<Record<'_>>, String> {
    if bytes.len() < 8 || bytes[..8] != MAGIC {
        return Err("not a handblocks sample log (wrong magic)".into());
    }
    let mut out = Vec::new();
    let mut at = 8;
    while at < bytes.len() {
        if at + 8 > bytes.len() {
            return Err(format!("record header cut off at offset {at}"));
        }
        let word =
            |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        let (topic, len) = (word(at), word(at + 4) as usize);
        let Some(topic) = Topic::from_u32(topic) else {
            return Err(format!("unknown topic {topic} at offset {at}"));
        };
        if len > bytes.len() - at - 8 {
            return Err(format!("record of {len} bytes cut off at offset {at}"));
        }
        out.push(Record {
            topic,
            bytes: &bytes[at + 8..at + 8 + len],
        });
        at += 8 + len;
    }
    Ok(out)
}
