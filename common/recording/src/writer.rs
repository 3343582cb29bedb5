//! Writing a recording: the MCAP file's header, schemas and channels, then each sample as a
//! message, in LZ4 chunks that are closed by size or age and handed to the operating system
//! whole, so that a recorder killed mid-session loses at most its open chunk.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::mem::size_of;
use std::path::{Path, PathBuf};

use common::bus::Stamped;
use common::samples::MAX_SCENE_BLOCKS;
use common::stamp::Stamp;
use common::topic::{SampleView, Topic};

use crate::codec::{
    encode_sample, encode_slice, encode_view, sample_type, slice_message_bytes, CDR_LE_HEADER,
    MESSAGE_ENCODING,
};
use crate::schema::{layout, SCHEMA_ENCODING};
use crate::{RecordingError, RECORDED_TOPICS};

/// The MCAP profile named in the file header.
pub const PROFILE: &str = "handblocks";
/// By default a chunk is closed once it holds this many uncompressed bytes...
pub const CHUNK_BYTES: usize = 1 << 20;
/// ... or once it is this old, whichever comes first: a crash of the recorder loses at most
/// the open chunk. A session sets both (`[recorder] flush_ms`, `chunk_kib`;
/// [`RecordingWriter::flush_every`]).
pub const CHUNK_SPAN_NS: u64 = 500_000_000;

fn clock_ns(clock: libc::clockid_t) -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec into the valid pointer we pass.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Appends samples to an MCAP recording in chunks (see the module's description).
///
/// Writing a sample copies its bytes into the open chunk: no allocation once the chunk's
/// buffers have grown to their size.
pub struct RecordingWriter {
    path: PathBuf,
    mcap: mcap::Writer<BufWriter<File>>,
    channel_ids: [u16; Topic::ALL.len()],
    unix_offset_ns: u64,
    chunk_bytes: usize,
    chunk_first_publish_ns: Option<u64>,
    /// The open chunk is closed at this many bytes...
    chunk_limit_bytes: usize,
    /// ... or this old (its first sample's publish time to now, or to a later sample's).
    chunk_span_ns: u64,
    messages: u64,
    /// The CDR header and the sample's bytes, contiguous (sized for the largest sample once).
    message: Vec<u8>,
}

impl RecordingWriter {
    /// Creates `path` (and its folder) new and private (0600: a recording holds a person's hand
    /// motion; an existing file or link there is an error) and writes the header, schemas and
    /// channels.
    pub fn create(path: &Path) -> Result<RecordingWriter, RecordingError> {
        RecordingWriter::create_with(path, &[])
    }

    /// [`Self::create`], with more entries for the `handblocks` metadata record (the session
    /// recorder names the session and scene files: `handblocks inspect` shows them).
    pub fn create_with(
        path: &Path,
        about: &[(&str, String)],
    ) -> Result<RecordingWriter, RecordingError> {
        let io = |error| RecordingError::Io {
            path: path.to_path_buf(),
            error,
        };
        let wr = |e: mcap::McapError| RecordingError::Write {
            path: path.to_path_buf(),
            error: e.to_string(),
        };
        if let Some(dir) = path.parent() {
            if !dir.as_os_str().is_empty() {
                std::fs::create_dir_all(dir).map_err(io)?;
            }
        }
        // New and private: an existing file or a link at `path` is refused, never written
        // through (`common::output`; the launcher's --force removed the entry before).
        let file = BufWriter::with_capacity(1 << 16, common::output::create_new(path).map_err(io)?);
        let mut mcap = mcap::WriteOptions::new()
            .profile(PROFILE)
            .library(concat!("handblocks ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Lz4))
            // Chunks are closed by `write` (size or time span) and written whole: never a
            // half-written chunk header in the file.
            .chunk_size(None)
            .disable_seeking(true)
            .create(file)
            .map_err(wr)?;
        let unix_offset_ns =
            clock_ns(libc::CLOCK_REALTIME).saturating_sub(clock_ns(libc::CLOCK_MONOTONIC));
        let mut metadata = std::collections::BTreeMap::new();
        metadata.insert(
            "log_time".to_string(),
            "stamp.publish_ns + unix_offset_ns (publish_time: stamp.origin_ns + unix_offset_ns)"
                .to_string(),
        );
        metadata.insert("unix_offset_ns".to_string(), unix_offset_ns.to_string());
        for (k, v) in about {
            metadata.insert(k.to_string(), v.clone());
        }
        mcap.write_metadata(&mcap::records::Metadata {
            name: "handblocks".to_string(),
            metadata,
        })
        .map_err(wr)?;
        let mut channel_ids = [0u16; Topic::ALL.len()];
        for topic in RECORDED_TOPICS {
            let (type_name, _) = sample_type(topic);
            let schema = mcap
                .add_schema(type_name, SCHEMA_ENCODING, layout(topic).as_bytes())
                .map_err(wr)?;
            channel_ids[topic as usize] = mcap
                .add_channel(
                    schema,
                    topic.channel(),
                    MESSAGE_ENCODING,
                    &Default::default(),
                )
                .map_err(wr)?;
        }
        Ok(RecordingWriter {
            path: path.to_path_buf(),
            mcap,
            channel_ids,
            unix_offset_ns,
            chunk_bytes: 0,
            chunk_first_publish_ns: None,
            chunk_limit_bytes: CHUNK_BYTES,
            chunk_span_ns: CHUNK_SPAN_NS,
            messages: 0,
            message: Vec::with_capacity(
                CDR_LE_HEADER.len()
                    + RECORDED_TOPICS
                        .iter()
                        .map(|t| {
                            slice_message_bytes(*t, MAX_SCENE_BLOCKS).unwrap_or(t.sample_size())
                        })
                        .max()
                        .unwrap_or(0),
            ),
        })
    }

    /// Closes each chunk once it holds `bytes` uncompressed bytes or is `span_ns` old
    /// (defaults [`CHUNK_BYTES`], [`CHUNK_SPAN_NS`]): the most a crash of the writer loses.
    /// Smaller chunks compress less well and cost a write each.
    pub fn flush_every(mut self, span_ns: u64, bytes: usize) -> RecordingWriter {
        self.chunk_span_ns = span_ns;
        self.chunk_limit_bytes = bytes.max(1);
        self
    }

    /// Closes the open chunk if it is older than the flush interval at `now_ns`
    /// (CLOCK_MONOTONIC): a topic that went quiet does not keep its last samples in memory,
    /// where a crash would lose them. Call it on each wake-up.
    pub fn close_chunk_if_due(&mut self, now_ns: u64) -> Result<(), RecordingError> {
        match self.chunk_first_publish_ns {
            Some(first) if now_ns.saturating_sub(first) >= self.chunk_span_ns => self.close_chunk(),
            _ => Ok(()),
        }
    }

    /// The message (CDR header and sample) the last `write` or `write_slice` wrote.
    pub fn last_message(&self) -> &[u8] {
        &self.message
    }

    /// What moves a stamp's CLOCK_MONOTONIC times to Unix time in this file: a message's log
    /// time is its stamp's `publish_ns` plus this (kept in the `handblocks` metadata record).
    pub fn unix_offset_ns(&self) -> u64 {
        self.unix_offset_ns
    }

    /// Samples written so far (the messages of [`Self::write_encoded`] not counted).
    pub fn messages(&self) -> u64 {
        self.messages
    }

    fn write_error(&self, e: mcap::McapError) -> RecordingError {
        RecordingError::Write {
            path: self.path.clone(),
            error: e.to_string(),
        }
    }

    /// Writes one sample of `topic`; closes the chunk when it is full or old enough.
    pub fn write<T: Stamped>(&mut self, topic: Topic, sample: &T) -> Result<(), RecordingError> {
        if topic.element_size().is_some() || size_of::<T>() != topic.sample_size() {
            return Err(RecordingError::Write {
                path: self.path.clone(),
                error: format!(
                    "a {}-byte sample is not a `{}` sample (a slice topic is written with \
                     `write_slice`)",
                    size_of::<T>(),
                    topic.name()
                ),
            });
        }
        let channel_id = self.channel_ids[topic as usize];
        let stamp = *sample.stamp();
        encode_sample(sample, &mut self.message);
        self.write_message(&stamp, channel_id)
    }

    /// Writes one sample of slice topic `topic`: `header`, then `elements` as a CDR sequence
    /// (count, padding to 8, elements). Copies into the open chunk; allocates nothing for up
    /// to [`MAX_SCENE_BLOCKS`] elements.
    pub fn write_slice<H: Stamped, E: Copy>(
        &mut self,
        topic: Topic,
        header: &H,
        elements: &[E],
    ) -> Result<(), RecordingError> {
        let channel_id = self.channel_ids[topic as usize];
        let stamp = *header.stamp();
        encode_slice(topic, header, elements, &mut self.message);
        self.write_message(&stamp, channel_id)
    }

    /// Writes one sample of any recorded topic from its bytes (what a run-time inlet,
    /// `common::bus::AnyInlet`, receives): the message [`Self::write`] or
    /// [`Self::write_slice`] writes of the same sample. Allocates nothing for up to
    /// [`MAX_SCENE_BLOCKS`] elements.
    pub fn write_view(&mut self, view: &SampleView<'_>) -> Result<(), RecordingError> {
        let topic = view.topic();
        if !topic.is_recorded() {
            return Err(RecordingError::Write {
                path: self.path.clone(),
                error: format!("a recording has no channel for `{}`", topic.name()),
            });
        }
        let channel_id = self.channel_ids[topic as usize];
        let stamp = view.stamp();
        encode_view(view, &mut self.message);
        self.write_message(&stamp, channel_id)
    }

    /// Declares a channel beside the topics' own, for messages encoded elsewhere (the scene
    /// view's [`crate::SCENE_CHANNEL`] and [`crate::TF_CHANNEL`]); [`Self::write_encoded`]
    /// writes on it.
    pub fn add_channel(
        &mut self,
        channel: &str,
        schema: (&str, &str, &[u8]),
        message_encoding: &str,
    ) -> Result<u16, RecordingError> {
        let (name, encoding, data) = schema;
        let schema = self
            .mcap
            .add_schema(name, encoding, data)
            .map_err(|e| self.write_error(e))?;
        self.mcap
            .add_channel(schema, channel, message_encoding, &Default::default())
            .map_err(|e| self.write_error(e))
    }

    /// Writes `message` (already encoded) on a channel of [`Self::add_channel`], stamped as the
    /// sample it was made from: its log and publish times are that sample's.
    pub fn write_encoded(
        &mut self,
        channel_id: u16,
        stamp: &Stamp,
        message: &[u8],
    ) -> Result<(), RecordingError> {
        self.write_data(stamp, channel_id, message)
    }

    /// Writes `self.message` on `channel_id`; closes the chunk when it is full or old enough.
    fn write_message(&mut self, stamp: &Stamp, channel_id: u16) -> Result<(), RecordingError> {
        let message = std::mem::take(&mut self.message);
        let written = self.write_data(stamp, channel_id, &message);
        self.message = message;
        if written.is_ok() {
            self.messages += 1;
        }
        written
    }

    fn write_data(
        &mut self,
        stamp: &Stamp,
        channel_id: u16,
        data: &[u8],
    ) -> Result<(), RecordingError> {
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: stamp.seq as u32,
            log_time: stamp.publish_ns + self.unix_offset_ns,
            publish_time: stamp.origin_ns + self.unix_offset_ns,
        };
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(|e| self.write_error(e))?;
        self.chunk_bytes += data.len();
        let first = *self.chunk_first_publish_ns.get_or_insert(stamp.publish_ns);
        if self.chunk_bytes >= self.chunk_limit_bytes
            || stamp.publish_ns.saturating_sub(first) >= self.chunk_span_ns
        {
            self.close_chunk()?;
        }
        Ok(())
    }

    /// Closes the open chunk and hands it to the operating system: from here on it survives a
    /// crash of this process.
    pub fn close_chunk(&mut self) -> Result<(), RecordingError> {
        self.mcap.flush().map_err(|e| self.write_error(e))?;
        self.chunk_bytes = 0;
        self.chunk_first_publish_ns = None;
        Ok(())
    }

    /// Closes the last chunk and writes the summary (channels, statistics, chunk index).
    pub fn finish(mut self) -> Result<u64, RecordingError> {
        self.mcap.finish().map_err(|e| self.write_error(e))?;
        let messages = self.messages;
        let path = self.path.clone();
        self.mcap
            .into_inner()
            .flush()
            .map_err(|error| RecordingError::Io { path, error })?;
        Ok(messages)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::scratch;

    /// A restart's segment (`NAME.1.mcap`) with a link planted there mid-session: the writer
    /// refuses it, and nothing is written at the link's target (issue 28).
    #[test]
    fn a_link_at_the_path_is_refused_not_written_through() {
        let (target, link) = (scratch("victim"), scratch("planted.1"));
        std::fs::write(&target, b"keep").unwrap();
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let err = RecordingWriter::create(&link).err().expect("refused");
        assert!(err.to_string().contains("planted.1"), "{err}");
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
        let path = scratch("private");
        let _ = std::fs::remove_file(&path);
        RecordingWriter::create(&path).unwrap().finish().unwrap();
        let mode = std::os::unix::fs::PermissionsExt::mode(
            &std::fs::metadata(&path).unwrap().permissions(),
        );
        assert_eq!(mode & 0o777, 0o600);
        for f in [target, link, path] {
            std::fs::remove_file(f).unwrap();
        }
    }
}
