//! Reading a recording back: its messages in file order, per-topic statistics over every
//! message read, and the samples. A damaged or cut-off file is read up to its last complete
//! chunk and the damage kept beside what was read; the MCAP records themselves are walked, with
//! every length checked, by `records`.

mod records;

use std::mem::size_of;
use std::path::{Path, PathBuf};

use common::bus::Stamped;
use common::samples::{BlockState, WorldHeader, WorldSample};
use common::topic::{SampleView, Topic};

use crate::codec::slice_elements_offset;
use crate::{RecordingError, RECORDED_TOPICS};
use records::{Flow, Reader};

/// Largest chunk a reader accepts (uncompressed); a bigger one is damage, not a recording.
pub const MAX_CHUNK_BYTES: u64 = 256 << 20;

/// The largest recording read (it is read whole into memory).
pub const MAX_RECORDING_BYTES: u64 = 64 << 30;

/// One message of a recording, in file order.
#[derive(Debug, Clone, Copy)]
pub struct RecordedMessage {
    pub topic: Topic,
    /// The sample's `publish_ns` (CLOCK_MONOTONIC of the recording machine).
    pub publish_ns: u64,
    /// Byte offset of the record (the chunk) that holds the message.
    pub record_offset: u64,
    start: usize,
    len: usize,
}

/// Per topic: messages, sequence gaps, and the span of publish times.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TopicStats {
    pub messages: u64,
    /// Samples missing between consecutive recorded seqs (what the recorder never received).
    pub gaps: u64,
    pub first_publish_ns: u64,
    pub last_publish_ns: u64,
    /// The first and the last seq read (valid when `messages` > 0).
    pub first_seq: u64,
    pub last_seq: u64,
}

/// A recording read back: its messages in file order, and the damage that ended reading early.
#[derive(Debug)]
pub struct Recording {
    pub path: PathBuf,
    pub messages: Vec<RecordedMessage>,
    /// Messages on channels that are not ours (a file written or edited by other tools).
    pub foreign_messages: u64,
    /// Messages of our topics whose count fields their arrays cannot hold (a file edited by
    /// hand or by a stranger: `finger_point_count` 6 of 5): counted and skipped, the messages
    /// around them kept ([`crate::check_message_counts`]).
    pub refused_messages: u64,
    /// Why the first of them was refused (its topic, seq and field).
    pub first_refused: Option<String>,
    /// Messages of the scene view ([`crate::SCENE_CHANNEL`], the 3D panel's drawing of the
    /// samples): ours, but derived from the topics, so no sample is read from them.
    pub scene_messages: u64,
    /// Messages of the hand's frames ([`crate::TF_CHANNEL`], written with the scene view's):
    /// ours, derived from the topics too.
    pub transform_messages: u64,
    /// Where reading stopped early, if it did: everything before it is in `messages`.
    pub damage: Option<RecordingError>,
    /// True when the file ended with its summary and footer (it was closed properly).
    pub complete: bool,
    /// The `handblocks` metadata record: `unix_offset_ns`, and `session`, `scene` when a
    /// session recorded it.
    pub metadata: std::collections::BTreeMap<String, String>,
    /// Per topic (indexed by `Topic as usize`), over every message read, kept or not.
    pub(crate) stats: [TopicStats; Topic::ALL.len()],
    data: Vec<u8>,
}

impl Recording {
    /// True when `bytes` start like an MCAP file.
    pub fn is_mcap(bytes: &[u8]) -> bool {
        bytes.starts_with(mcap::MAGIC)
    }

    /// Reads `path`. A file that cannot be read or is not MCAP is an error; damage further on
    /// (a cut-off chunk, a bad record, a message whose size does not fit its topic) ends reading
    /// there and is kept in `damage`, with every complete chunk before it read.
    pub fn open(path: &Path) -> Result<Recording, RecordingError> {
        Recording::open_topics(path, &RECORDED_TOPICS)
    }

    /// Like [`Recording::open`], keeping only the messages of `topics` (every message is still
    /// checked): a replay needs the source topics, not the world states that dwarf them.
    pub fn open_topics(path: &Path, topics: &[Topic]) -> Result<Recording, RecordingError> {
        // Only a regular file (issue 16: `/dev/zero` or a pipe was read for ever).
        let bytes = common::config::read_bounded(path, MAX_RECORDING_BYTES).map_err(|e| {
            RecordingError::Io {
                path: path.to_path_buf(),
                error: std::io::Error::other(e),
            }
        })?;
        Recording::parse_topics(path, &bytes, topics)
    }

    /// Reads a recording from bytes already in memory; `path` names it in errors.
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<Recording, RecordingError> {
        Recording::parse_topics(path, bytes, &RECORDED_TOPICS)
    }

    fn parse_topics(
        path: &Path,
        bytes: &[u8],
        topics: &[Topic],
    ) -> Result<Recording, RecordingError> {
        if !Recording::is_mcap(bytes) {
            return Err(RecordingError::NotMcap {
                path: path.to_path_buf(),
            });
        }
        let mut rec = Recording {
            path: path.to_path_buf(),
            messages: Vec::new(),
            foreign_messages: 0,
            refused_messages: 0,
            first_refused: None,
            scene_messages: 0,
            transform_messages: 0,
            damage: None,
            complete: false,
            metadata: Default::default(),
            stats: [TopicStats::default(); Topic::ALL.len()],
            data: Vec::new(),
        };
        let mut reader = Reader {
            channels: Vec::new(),
            scene_channels: Vec::new(),
            tf_channels: Vec::new(),
            schemas: Vec::new(),
            kept: topics,
            last_seq: [None; Topic::ALL.len()],
        };
        let mut at = mcap::MAGIC.len();
        let damage = |offset: usize, what: String| RecordingError::Damaged {
            path: path.to_path_buf(),
            offset: offset as u64,
            what,
        };
        loop {
            if at == bytes.len() {
                rec.damage = Some(damage(
                    at,
                    "the file ends here, without its summary and footer (the recorder did not \
                     finish; every complete chunk before this offset was read)"
                        .into(),
                ));
                break;
            }
            if bytes.len() - at < 9 {
                rec.damage = Some(damage(
                    at,
                    format!(
                        "a record header is cut off ({} of 9 bytes)",
                        bytes.len() - at
                    ),
                ));
                break;
            }
            let opcode = bytes[at];
            let mut len_bytes = [0u8; 8];
            len_bytes.copy_from_slice(&bytes[at + 1..at + 9]);
            let len = u64::from_le_bytes(len_bytes);
            let left = (bytes.len() - at - 9) as u64;
            if len > left {
                rec.damage = Some(damage(
                    at,
                    format!(
                        "a record (opcode {opcode:#04x}) of {len} bytes runs past the end of the \
                         file ({left} bytes left): the file was cut off"
                    ),
                ));
                break;
            }
            let body = &bytes[at + 9..at + 9 + len as usize];
            let kept = rec.messages.len();
            let kept_data = rec.data.len();
            let (kept_stats, kept_seqs) = (rec.stats, reader.last_seq);
            match reader.record(opcode, body, at as u64, &mut rec) {
                Ok(Flow::Go) => {}
                Ok(Flow::DataEnd) => {
                    rec.complete = mcap::read::footer(bytes).is_ok();
                    if !rec.complete {
                        rec.damage = Some(damage(
                            at,
                            "the data section ends here but the summary or footer after it is \
                             damaged (every message was read)"
                                .into(),
                        ));
                    }
                    break;
                }
                Err(what) => {
                    // A damaged chunk counts as a whole: drop what it had added.
                    rec.messages.truncate(kept);
                    rec.data.truncate(kept_data);
                    rec.stats = kept_stats;
                    reader.last_seq = kept_seqs;
                    rec.damage = Some(damage(at, what));
                    break;
                }
            }
            at += 9 + len as usize;
        }
        Ok(rec)
    }

    /// The message's sample as type `T`, if `T` is its topic's type.
    pub fn sample<T: Stamped>(&self, m: &RecordedMessage) -> Option<T> {
        if m.len != size_of::<T>() {
            return None;
        }
        let bytes = self.data.get(m.start..m.start + m.len)?;
        // SAFETY: the length matches and every sample type is plain old data (#[repr(C)],
        // Copy, only integers and floats, any bit pattern valid); read_unaligned copes with the
        // buffer's alignment.
        Some(unsafe { std::ptr::read_unaligned(bytes.as_ptr() as *const T) })
    }

    /// A `world` message's sample: its header and blocks (None for another topic's message).
    pub fn world(&self, m: &RecordedMessage) -> Option<WorldSample> {
        if m.topic != Topic::World || m.len < slice_elements_offset(Topic::World) {
            return None;
        }
        let bytes = self.data.get(m.start..m.start + m.len)?;
        // SAFETY: the reader checked the size against the sequence's count; plain old data,
        // read unaligned.
        let header = unsafe { std::ptr::read_unaligned(bytes.as_ptr() as *const WorldHeader) };
        let blocks = bytes[slice_elements_offset(Topic::World)..]
            .chunks_exact(size_of::<BlockState>())
            .map(|b| unsafe { std::ptr::read_unaligned(b.as_ptr() as *const BlockState) })
            .collect();
        Some(WorldSample { header, blocks })
    }

    /// The message's sample as bytes, for a reader of any topic (by its field list): the
    /// sample (a slice topic's header) and its elements.
    pub fn view(&self, m: &RecordedMessage) -> Option<SampleView<'_>> {
        let bytes = self.data.get(m.start..m.start + m.len)?;
        match m.topic.element_size() {
            None => SampleView::new(m.topic, bytes, &[]),
            Some(_) => SampleView::new(
                m.topic,
                bytes.get(..m.topic.sample_size())?,
                bytes.get(slice_elements_offset(m.topic)..)?,
            ),
        }
    }

    /// The samples of one topic as bytes ([`Recording::view`]), in file order.
    pub fn views(&self, topic: Topic) -> impl Iterator<Item = SampleView<'_>> + '_ {
        self.messages
            .iter()
            .filter(move |m| m.topic == topic)
            .filter_map(|m| self.view(m))
    }

    /// The `world` samples, in file order.
    pub fn worlds(&self) -> impl Iterator<Item = WorldSample> + '_ {
        self.messages
            .iter()
            .filter(|m| m.topic == Topic::World)
            .filter_map(|m| self.world(m))
    }

    /// The samples of one fixed-size topic, in file order (`world`: [`Recording::worlds`]).
    pub fn samples<T: Stamped>(&self, topic: Topic) -> impl Iterator<Item = T> + '_ {
        self.messages
            .iter()
            .filter(move |m| m.topic == topic)
            .filter_map(|m| self.sample::<T>(m))
    }

    /// Messages, gaps in seq and time span per topic (indexed by `Topic as usize`), over
    /// every message read, whether its topic was kept or not.
    pub fn stats(&self) -> [TopicStats; Topic::ALL.len()] {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::samples::GloveSample;

    use crate::test_support::{glove, scratch};
    use crate::RecordingWriter;

    #[test]
    fn round_trip_and_stats() {
        let path = scratch("round-trip");
        let mut w = RecordingWriter::create(&path).unwrap();
        for k in 0..2000u64 {
            if k == 700 {
                continue; // a gap
            }
            w.write(Topic::Glove, &glove(k, 1_000_000 + k * 1_000_000))
                .unwrap();
        }
        let mut world = WorldSample::with_blocks(3);
        world.stamp.publish_ns = 5;
        world.blocks[2].pose.position = [1.0, 2.0, 3.0];
        w.write_slice(Topic::World, &world.header, &world.blocks)
            .unwrap();
        assert_eq!(w.finish().unwrap(), 2000);
        let rec = Recording::open(&path).unwrap();
        assert!(rec.complete, "{:?}", rec.damage);
        assert!(rec.damage.is_none());
        let gloves: Vec<GloveSample> = rec.samples(Topic::Glove).collect();
        assert_eq!(gloves.len(), 1999);
        assert_eq!(gloves[700], glove(701, 1_000_000 + 701 * 1_000_000));
        let stats = rec.stats();
        assert_eq!(stats[Topic::Glove as usize].messages, 1999);
        assert_eq!(stats[Topic::Glove as usize].gaps, 1);
        assert_eq!(stats[Topic::World as usize].messages, 1);
        // Two seconds of publish time at most 0.5 s per chunk: several chunks.
        let chunks: std::collections::BTreeSet<u64> =
            rec.messages.iter().map(|m| m.record_offset).collect();
        assert!(chunks.len() >= 4, "{} chunks", chunks.len());
        // Only the topics asked for are kept.
        let worlds = Recording::open_topics(&path, &[Topic::World]).unwrap();
        assert_eq!(worlds.messages.len(), 1);
        assert_eq!(
            worlds.stats(),
            stats,
            "stats count every message, kept or not"
        );
        let back: Vec<WorldSample> = worlds.worlds().collect();
        assert_eq!(back, [world], "a world sample reads back as it was written");
        let _ = std::fs::remove_file(&path);
    }

    /// A file cut anywhere reads back up to its last complete chunk, and says where it broke.
    #[test]
    fn cut_off_file_reads_to_its_last_complete_chunk() {
        let path = scratch("cut");
        let mut w = RecordingWriter::create(&path).unwrap();
        for k in 0..3000u64 {
            w.write(Topic::Glove, &glove(k, 1 + k * 1_000_000)).unwrap();
        }
        w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let whole = Recording::parse(&path, &bytes).unwrap();
        let chunk_starts: Vec<u64> = {
            let mut v: Vec<u64> = whole.messages.iter().map(|m| m.record_offset).collect();
            v.dedup();
            v
        };
        assert!(chunk_starts.len() >= 5);
        let before = |offset: u64| {
            whole
                .messages
                .iter()
                .filter(|m| m.record_offset < offset)
                .count()
        };
        // (cut, messages expected): inside chunk 3; inside the footer; inside the header.
        let cuts = [
            (chunk_starts[3] as usize + 100, before(chunk_starts[3])),
            (bytes.len() - 30, whole.messages.len()),
            (20, 0),
        ];
        for (cut, expected) in cuts {
            let rec = Recording::parse(&path, &bytes[..cut]).unwrap();
            let msg = rec
                .damage
                .as_ref()
                .map(|d| d.to_string())
                .unwrap_or_default();
            assert!(!rec.complete);
            assert!(msg.contains("damaged at byte offset"), "{msg}");
            assert!(msg.contains(&path.display().to_string()), "{msg}");
            assert_eq!(rec.messages.len(), expected, "cut at {cut}: {msg}");
            for (a, b) in rec.messages.iter().zip(&whole.messages) {
                assert_eq!(rec.sample::<GloveSample>(a), whole.sample::<GloveSample>(b));
            }
        }
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn wrong_magic_and_absurd_sizes_are_named() {
        let path = scratch("bad");
        let e = Recording::parse(&path, b"HBLOG\0\x01\0 and more").unwrap_err();
        assert!(e.to_string().contains("not an MCAP recording"), "{e}");
        assert!(e.to_string().contains("offset 0"), "{e}");
        // A record claiming 2^60 bytes.
        let mut bytes = mcap::MAGIC.to_vec();
        bytes.push(0x06);
        bytes.extend_from_slice(&(1u64 << 60).to_le_bytes());
        bytes.extend_from_slice(&[0u8; 64]);
        let rec = Recording::parse(&path, &bytes).unwrap();
        let d = rec.damage.unwrap().to_string();
        assert!(
            d.contains("offset 8") && d.contains("runs past the end"),
            "{d}"
        );
    }

    /// Issue 16: one changed byte inside a chunk crashed the reader ("capacity overflow", an
    /// abort allocating 1e12 bytes): lengths inside chunks were trusted. Thousands of changes
    /// of one, four or eight bytes anywhere in a real recording: each reads back as a
    /// recording (damage named) or an error, never a panic, and never takes more memory than
    /// the file's size allows.
    #[test]
    fn changed_bytes_anywhere_read_back_as_damage_never_a_panic() {
        let path = scratch("mutated");
        let mut w = RecordingWriter::create(&path).unwrap();
        let mut world = WorldSample::with_blocks(5);
        for k in 0..600u64 {
            w.write(Topic::Glove, &glove(k, 1_000_000 + k * 1_000_000))
                .unwrap();
            if k % 10 == 0 {
                world.stamp.seq = k / 10;
                world.stamp.publish_ns = 1_000_000 + k * 1_000_000;
                w.write_slice(Topic::World, &world.header, &world.blocks)
                    .unwrap();
            }
        }
        w.finish().unwrap();
        let good = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let extremes: [u64; 6] = [
            u64::MAX,
            u32::MAX as u64,
            1_000_000_000_000,
            1 << 40,
            0,
            1 << 63,
        ];
        for trial in 0..10_000 {
            let mut bytes = good.clone();
            let at = (next() % bytes.len() as u64) as usize;
            match trial % 3 {
                0 => bytes[at] ^= 1 << (next() % 8),
                1 => {
                    let v = extremes[(next() % 6) as usize].to_le_bytes();
                    let n = (bytes.len() - at).min(4);
                    bytes[at..at + n].copy_from_slice(&v[..n]);
                }
                _ => {
                    let v = extremes[(next() % 6) as usize].to_le_bytes();
                    let n = (bytes.len() - at).min(8);
                    bytes[at..at + n].copy_from_slice(&v[..n]);
                }
            }
            let outcome = std::panic::catch_unwind(|| {
                if let Ok(rec) = Recording::parse(&path, &bytes) {
                    let _ = rec.worlds().count();
                    let _ = rec.summary();
                }
            });
            assert!(
                outcome.is_ok(),
                "trial {trial}: a change at byte {at} panicked the reader"
            );
        }
    }

    /// Issue 16 (fuzzing, fuzz/corpus/mcap/regression-metadata-string-length): mcap 0.26
    /// reserved a string's claimed length before checking the record held it, so a 7 KiB file
    /// asked for 1.6 GiB. Every length is checked first, and the damage is named.
    #[test]
    fn a_string_longer_than_its_record_is_damage_not_an_allocation() {
        let path = scratch("long-string");
        for opcode in [0x0cu8, 0x03, 0x04] {
            let mut body = Vec::new();
            if opcode != 0x0c {
                body.extend_from_slice(&[0u8; 4][..if opcode == 0x03 { 2 } else { 4 }]);
            }
            body.extend_from_slice(&0xffff_fff0u32.to_le_bytes());
            body.extend_from_slice(b"handblocks");
            let mut bytes = mcap::MAGIC.to_vec();
            bytes.push(opcode);
            bytes.extend_from_slice(&(body.len() as u64).to_le_bytes());
            bytes.extend_from_slice(&body);
            let rec = Recording::parse(&path, &bytes).unwrap();
            let d = rec.damage.unwrap().to_string();
            assert!(
                d.contains("offset 8") && d.contains("claims 4294967280 bytes"),
                "{opcode:#04x}: {d}"
            );
        }
        // Whatever the regression input holds, it reads as damage, bounded.
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fuzz/corpus/mcap/regression-metadata-string-length");
        let rec = Recording::open(&file).unwrap();
        assert!(rec.damage.is_some());
    }

    #[test]
    fn a_recording_that_is_a_device_is_refused() {
        let e = Recording::open(std::path::Path::new("/dev/zero"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/dev/zero") && e.contains("not a regular file"),
            "{e}"
        );
    }
}
