//! Recordings: every topic of a session in one MCAP file, and reading them back.
//!
//! The file is the contract between the recorder (which writes it), the replay (which reads
//! the source topics back) and the user's own tools (Foxglove, the `mcap` CLI):
//!
//! * one **channel per topic**, named as the topic (`glove`, `tracker`, `joints`, `hand`,
//!   `world`, `frame`), with message encoding [`MESSAGE_ENCODING`] (`cdr`, as ROS 2 writes):
//!   each message is the 4-byte CDR little-endian header followed by the sample's `#[repr(C)]`
//!   bytes exactly as they travelled. That *is* the sample's CDR serialisation: every field of
//!   every sample type lies at a multiple of its own size, with no implicit padding, which is
//!   CDR's alignment rule, and fixed arrays carry no length. A `world` message is its header's
//!   bytes, then its blocks as a CDR sequence: a uint32 count, 4 bytes of padding (the blocks'
//!   doubles align to 8) and the [`BlockState`]s ([`slice_message_bytes`]);
//! * one **schema per sample type**, a ROS 2 message definition ([`SCHEMA_ENCODING`]
//!   `ros2msg`, named `handblocks/msg/GloveSample`, ...) listing every field with its byte
//!   offset and size in a comment ([`layout`]): Foxglove and the ROS 2 tools decode and plot
//!   every field without knowing handblocks (multi-dimensional arrays appear flattened);
//! * **log time from the stamps**: `log_time` is the sample's `publish_ns`, `publish_time` its
//!   `origin_ns`, both moved from CLOCK_MONOTONIC to Unix time by one offset taken when the
//!   recording starts (kept in the `handblocks` metadata record); the MCAP sequence is the
//!   stamp's `seq` (low 32 bits);
//! * **chunked** (LZ4), each chunk written whole and handed to the operating system as soon as
//!   it is complete ([`RecordingWriter`]): a recorder killed mid-session leaves a file that
//!   [`Recording::open`] reads up to its last complete chunk.

use std::fmt::{self, Write as _};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::mem::{offset_of, size_of, size_of_val};
use std::path::{Path, PathBuf};

use common::bus::Stamped;
use common::samples::*;
use common::stamp::Stamp;
use common::topic::Topic;

/// Message encoding of every channel: CDR (little-endian), which for our layouts is the 4-byte
/// [`CDR_LE_HEADER`] and then the sample's `#[repr(C)]` bytes.
pub const MESSAGE_ENCODING: &str = "cdr";
/// Schema encoding: ROS 2 message definitions, as [`layout`] writes them.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// The CDR encapsulation header of a little-endian plain CDR payload.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// The MCAP profile named in the file header.
pub const PROFILE: &str = "handblocks";
/// The topics a recording holds (the latency reports go into the session report instead).
pub const RECORDED_TOPICS: [Topic; Topic::RECORDED.len()] = Topic::RECORDED;
/// By default a chunk is closed once it holds this many uncompressed bytes...
pub const CHUNK_BYTES: usize = 1 << 20;
/// ... or once it is this old, whichever comes first: a crash of the recorder loses at most
/// the open chunk. A session sets both (`[recorder] flush_ms`, `chunk_kib`;
/// [`RecordingWriter::flush_every`]).
pub const CHUNK_SPAN_NS: u64 = 500_000_000;
/// Largest chunk a reader accepts (uncompressed); a bigger one is damage, not a recording.
pub const MAX_CHUNK_BYTES: u64 = 256 << 20;

/// The largest recording read (it is read whole into memory).
pub const MAX_RECORDING_BYTES: u64 = 64 << 30;

/// The schema (message type) name and the sample's byte size of a topic (of a slice topic, its
/// header's: see [`slice_message_bytes`]).
pub fn sample_type(topic: Topic) -> (&'static str, usize) {
    (topic.schema_name(), topic.sample_size())
}

/// Where a slice topic's elements start in its message (after the CDR header): after the
/// header, the sequence's uint32 count and the padding that aligns the elements to 8 bytes.
pub fn slice_elements_offset(topic: Topic) -> usize {
    (topic.sample_size() + 4).next_multiple_of(8)
}

/// The bytes of a slice topic's message after the CDR header, with `elements` elements; None
/// for a fixed-size topic.
pub fn slice_message_bytes(topic: Topic, elements: usize) -> Option<usize> {
    let element = topic.element_size()?;
    Some(slice_elements_offset(topic) + elements * element)
}

/// A fixed-size sample's message, as a recording holds it and the bridge sends it (issue 17):
/// the CDR header and the sample's bytes, into `out` (cleared first; no allocation once `out`
/// has grown to the size).
pub fn encode_sample<T: Stamped>(sample: &T, out: &mut Vec<u8>) {
    // SAFETY: every sample type is #[repr(C)], Copy, and laid out without implicit padding
    // (explicit `_reserved` fields fill it; `layout` lists them), so all bytes are initialised.
    let bytes =
        unsafe { std::slice::from_raw_parts(sample as *const T as *const u8, size_of::<T>()) };
    out.clear();
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(bytes);
}

/// A slice topic's message: the CDR header, `header`'s bytes, then `elements` as a CDR
/// sequence (count, padding to 8, elements), into `out` (cleared first).
pub fn encode_slice<H: Stamped, E: Copy>(
    topic: Topic,
    header: &H,
    elements: &[E],
    out: &mut Vec<u8>,
) {
    // SAFETY: as in `encode_sample`: #[repr(C)] plain data without implicit padding
    // (BlockState's `_reserved` fills its gap), so every byte is initialised.
    let head =
        unsafe { std::slice::from_raw_parts(header as *const H as *const u8, size_of::<H>()) };
    let body = unsafe {
        std::slice::from_raw_parts(elements.as_ptr() as *const u8, size_of_val(elements))
    };
    out.clear();
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(head);
    out.extend_from_slice(&(elements.len() as u32).to_le_bytes());
    let pad = slice_elements_offset(topic) - size_of::<H>() - 4;
    out.extend_from_slice(&[0u8; 8][..pad]);
    out.extend_from_slice(body);
}

/// Why a message is not a sample of its topic (bytes from another machine, a damaged file).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MessageError(pub String);

impl fmt::Display for MessageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for MessageError {}

/// The sample of a fixed-size topic's message (`encode_sample`'s inverse): the length must be
/// the CDR header and exactly the sample. Any bit pattern of the right length is a sample (only
/// integers and floats); what the values mean is the reader's to check.
pub fn decode_sample<T: Stamped>(topic: Topic, message: &[u8]) -> Result<T, MessageError> {
    let want = CDR_LE_HEADER.len() + size_of::<T>();
    if topic.element_size().is_some() || size_of::<T>() != topic.sample_size() {
        return Err(MessageError(format!(
            "a {}-byte sample type is not `{}`'s",
            size_of::<T>(),
            topic.name()
        )));
    }
    if message.len() != want || message[..4] != CDR_LE_HEADER {
        return Err(MessageError(format!(
            "a `{}` message is {want} bytes starting with the CDR little-endian header; this \
             one is {} bytes",
            topic.name(),
            message.len()
        )));
    }
    // SAFETY: the length matches; plain old data, read unaligned.
    Ok(unsafe { std::ptr::read_unaligned(message[4..].as_ptr() as *const T) })
}

/// A slice topic's message (`encode_slice`'s inverse): its header and the bytes of its
/// elements, whose count must agree with the message's length.
pub fn decode_slice<H: Stamped>(topic: Topic, message: &[u8]) -> Result<(H, &[u8]), MessageError> {
    let Some(element) = topic.element_size() else {
        return Err(MessageError(format!(
            "`{}` is not a slice topic",
            topic.name()
        )));
    };
    let start = CDR_LE_HEADER.len() + slice_elements_offset(topic);
    let count_at = CDR_LE_HEADER.len() + size_of::<H>();
    if size_of::<H>() != topic.sample_size()
        || message.len() < start
        || message[..4] != CDR_LE_HEADER
    {
        return Err(MessageError(format!(
            "a `{}` message is at least {start} bytes starting with the CDR little-endian \
             header; this one is {} bytes",
            topic.name(),
            message.len()
        )));
    }
    let count = u32::from_le_bytes([
        message[count_at],
        message[count_at + 1],
        message[count_at + 2],
        message[count_at + 3],
    ]) as usize;
    let body = &message[start..];
    if body.len() != count.saturating_mul(element) {
        return Err(MessageError(format!(
            "a `{}` message says {count} elements of {element} bytes but holds {} bytes of them",
            topic.name(),
            body.len()
        )));
    }
    // SAFETY: the length is checked; plain old data, read unaligned.
    let header = unsafe { std::ptr::read_unaligned(message[4..].as_ptr() as *const H) };
    Ok((header, body))
}

/// The stamp at the start of any topic's message (every sample starts with it).
pub fn message_stamp(message: &[u8]) -> Option<Stamp> {
    let bytes = message.get(4..4 + size_of::<Stamp>())?;
    // SAFETY: the length is checked; a stamp is four u64s, any bit pattern valid.
    Some(unsafe { std::ptr::read_unaligned(bytes.as_ptr() as *const Stamp) })
}

/// One field of a sample layout: where it is and what it holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    pub name: &'static str,
    /// The ROS 2 field type: `float64[75]`, or a nested message such as `handblocks/Pose`.
    /// Multi-dimensional arrays are flattened (row-major, as in memory).
    pub ty: &'static str,
    pub offset: usize,
    pub size: usize,
}

fn field_size<T, F>(_: fn(&T) -> &F) -> usize {
    size_of::<F>()
}

macro_rules! fields {
    ($t:ty { $($f:ident : $ty:literal),* $(,)? }) => {
        vec![$(Field {
            name: stringify!($f).trim_start_matches('_'),
            ty: $ty,
            offset: offset_of!($t, $f),
            size: field_size::<$t, _>(|s| &s.$f),
        }),*]
    };
}

/// The fields of a struct the samples are built from, in memory order.
pub fn fields(struct_name: &str) -> Option<Vec<Field>> {
    Some(match struct_name {
        "handblocks/Stamp" => fields!(Stamp {
            seq: "uint64",
            source_time_ns: "uint64",
            origin_ns: "uint64",
            publish_ns: "uint64",
        }),
        "handblocks/Pose" => fields!(Pose {
            position: "float64[3]",
            rotation: "float64[4]",
        }),
        "handblocks/BlockState" => fields!(BlockState {
            pose: "handblocks/Pose",
            mode: "uint32",
            _reserved: "uint32",
        }),
        "handblocks/msg/GloveSample" => fields!(GloveSample {
            stamp: "handblocks/Stamp",
            sensor_count: "uint32",
            _reserved: "uint32",
            angles: "float64[22]",
        }),
        "handblocks/msg/TrackerSample" => fields!(TrackerSample {
            stamp: "handblocks/Stamp",
            station: "uint32",
            _reserved: "uint32",
            wrist: "handblocks/Pose",
        }),
        "handblocks/msg/JointsSample" => fields!(JointsSample {
            stamp: "handblocks/Stamp",
            tracked: "uint32",
            _reserved: "uint32",
            wrist: "handblocks/Pose",
            joints: "handblocks/Pose[26]",
        }),
        "handblocks/msg/HandSample" => fields!(HandSample {
            stamp: "handblocks/Stamp",
            wrist: "handblocks/Pose",
            tracked: "uint32",
            finger_count: "uint32",
            finger_point_count: "uint32[5]",
            palm_vertex_count: "uint32",
            finger_points: "float64[75]",
            finger_radius: "float64[5]",
            palm_vertices: "float64[48]",
        }),
        // The header; `layout` adds the `blocks` sequence that follows it.
        "handblocks/msg/WorldSample" => fields!(WorldHeader {
            stamp: "handblocks/Stamp",
            step: "uint64",
            hand_seq: "uint64",
            block_count: "uint32",
            grasped_block: "int32",
            finger_count: "uint32",
            finger_point_count: "uint32[5]",
            finger_points: "float64[75]",
        }),
        "handblocks/msg/FrameSample" => fields!(FrameSample {
            stamp: "handblocks/Stamp",
            world_seq: "uint64",
            render_ns: "uint64",
            origin_to_photon_ns: "uint64",
            skipped_worlds: "uint64",
        }),
        _ => return None,
    })
}

/// The schema of a topic: a ROS 2 message definition of its sample type, then (after the
/// `====` separators of the format) each nested message it uses. Each field's comment gives its
/// byte offset and size within the sample, so the bytes can be read without a CDR library too.
pub fn layout(topic: Topic) -> String {
    let (name, size) = sample_type(topic);
    let mut out = String::new();
    let mut pending = vec![(name, size)];
    let mut done: Vec<&str> = Vec::new();
    while let Some((name, size)) = pending.pop() {
        if done.contains(&name) {
            continue;
        }
        let Some(fs) = fields(name) else { continue };
        if done.is_empty() {
            let what = match topic.element_size() {
                None => format!("{size} bytes"),
                Some(_) => format!("a {size}-byte header and a sequence of blocks"),
            };
            let _ = writeln!(
                out,
                "# {name}: {what} after the 4-byte CDR header (little-endian; each field at a \
                 multiple of its size, so the CDR bytes are the C layout). Metres, world frame, y \
                 up; rotations as unit quaternions [x, y, z, w]; times in nanoseconds."
            );
        } else {
            let _ = writeln!(out, "{}", "=".repeat(80));
            let _ = writeln!(out, "MSG: {name}");
            let _ = writeln!(out, "# {size} bytes");
        }
        done.push(name);
        for f in &fs {
            let _ = writeln!(
                out,
                "{} {}  # @{}, {} bytes",
                f.ty, f.name, f.offset, f.size
            );
            let base = f.ty.split('[').next().unwrap_or(f.ty);
            let nested = match base {
                "handblocks/Stamp" => Some(size_of::<Stamp>()),
                "handblocks/Pose" => Some(size_of::<Pose>()),
                "handblocks/BlockState" => Some(size_of::<BlockState>()),
                _ => None,
            };
            if let Some(s) = nested {
                pending.insert(0, (base, s));
            }
        }
        // A slice topic's elements follow its header as a CDR sequence.
        if done.len() == 1 && topic.element_size().is_some() {
            let _ = writeln!(
                out,
                "handblocks/BlockState[] blocks  # count: uint32 @{size}; blocks @{}, {} bytes each",
                slice_elements_offset(topic),
                size_of::<BlockState>()
            );
            pending.insert(0, ("handblocks/BlockState", size_of::<BlockState>()));
        }
    }
    out
}

/// What went wrong with a recording; every variant names the file, and damage its byte offset.
#[derive(Debug)]
pub enum RecordingError {
    /// The file could not be created, read or written.
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// The file does not start with MCAP's magic bytes.
    NotMcap { path: PathBuf },
    /// The MCAP library refused a write.
    Write { path: PathBuf, error: String },
    /// The file is damaged at `offset`; what comes before it was read.
    Damaged {
        path: PathBuf,
        offset: u64,
        what: String,
    },
}

impl fmt::Display for RecordingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RecordingError::Io { path, error } => write!(f, "{}: {error}", path.display()),
            RecordingError::NotMcap { path } => write!(
                f,
                "{}: not an MCAP recording (wrong magic at offset 0; expected \\x89MCAP0\\r\\n)",
                path.display()
            ),
            RecordingError::Write { path, error } => {
                write!(f, "{}: cannot write the recording: {error}", path.display())
            }
            RecordingError::Damaged { path, offset, what } => {
                write!(
                    f,
                    "{}: damaged at byte offset {offset}: {what}",
                    path.display()
                )
            }
        }
    }
}

impl std::error::Error for RecordingError {}

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
                .add_channel(schema, topic.name(), MESSAGE_ENCODING, &Default::default())
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

    /// Messages written so far.
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

    /// Writes `self.message` on `channel_id`; closes the chunk when it is full or old enough.
    fn write_message(&mut self, stamp: &Stamp, channel_id: u16) -> Result<(), RecordingError> {
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: stamp.seq as u32,
            log_time: stamp.publish_ns + self.unix_offset_ns,
            publish_time: stamp.origin_ns + self.unix_offset_ns,
        };
        self.mcap
            .write_to_known_channel(&header, &self.message)
            .map_err(|e| self.write_error(e))?;
        self.messages += 1;
        self.chunk_bytes += self.message.len() - CDR_LE_HEADER.len();
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
    /// Where reading stopped early, if it did: everything before it is in `messages`.
    pub damage: Option<RecordingError>,
    /// True when the file ended with its summary and footer (it was closed properly).
    pub complete: bool,
    /// The `handblocks` metadata record: `unix_offset_ns`, and `session`, `scene` when a
    /// session recorded it.
    pub metadata: std::collections::BTreeMap<String, String>,
    /// Per topic (indexed by `Topic as usize`), over every message read, kept or not.
    stats: [TopicStats; Topic::ALL.len()],
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
            damage: None,
            complete: false,
            metadata: Default::default(),
            stats: [TopicStats::default(); Topic::ALL.len()],
            data: Vec::new(),
        };
        let mut reader = Reader {
            channels: Vec::new(),
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

const OP_SCHEMA: u8 = 0x03;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;
const OP_METADATA: u8 = 0x0c;
const OP_DATA_END: u8 = 0x0f;
/// The records the reader parses.
const USED_OPCODES: [u8; 6] = [
    OP_SCHEMA,
    OP_CHANNEL,
    OP_MESSAGE,
    OP_CHUNK,
    OP_METADATA,
    OP_DATA_END,
];

/// Checks every length inside a record against the bytes its body holds, before mcap parses
/// it: mcap 0.26 reserves the length a string or map claims before it checks that the record
/// has it (issue 16: a 7 KiB file asked for 1.6 GiB).
fn lengths_fit(opcode: u8, body: &[u8]) -> Result<(), String> {
    /// Reads a record's fields in order, every length checked against what is left.
    struct Cursor<'b> {
        opcode: u8,
        body: &'b [u8],
        at: usize,
        end: usize,
    }
    impl Cursor<'_> {
        fn skip(&mut self, n: u64, what: &str) -> Result<(), String> {
            let left = (self.end - self.at) as u64;
            if n > left {
                return Err(format!(
                    "a record (opcode {:#04x}) claims {n} bytes of {what} at byte {} of its \
                     {}-byte body ({left} left)",
                    self.opcode,
                    self.at,
                    self.body.len()
                ));
            }
            self.at += n as usize;
            Ok(())
        }
        fn int<const N: usize>(&mut self, what: &str) -> Result<u64, String> {
            let start = self.at;
            self.skip(N as u64, what)?;
            let mut b = [0u8; 8];
            b[..N].copy_from_slice(&self.body[start..start + N]);
            Ok(u64::from_le_bytes(b))
        }
        fn string(&mut self, what: &str) -> Result<(), String> {
            let n = self.int::<4>(what)?;
            self.skip(n, what)
        }
        /// A map of strings to strings: its byte length, then its entries within it.
        fn string_map(&mut self, what: &str) -> Result<(), String> {
            let n = self.int::<4>(what)?;
            let start = self.at;
            self.skip(n, what)?;
            let mut inner = Cursor {
                opcode: self.opcode,
                body: self.body,
                at: start,
                end: self.at,
            };
            while inner.at < inner.end {
                inner.string(what)?;
                inner.string(what)?;
            }
            Ok(())
        }
    }
    let mut c = Cursor {
        opcode,
        body,
        at: 0,
        end: body.len(),
    };
    match opcode {
        OP_SCHEMA => {
            c.skip(2, "schema id")?;
            c.string("schema name")?;
            c.string("schema encoding")?;
            c.string("schema data")?;
        }
        OP_CHANNEL => {
            c.skip(4, "channel and schema ids")?;
            c.string("topic")?;
            c.string("message encoding")?;
            c.string_map("channel metadata")?;
        }
        OP_MESSAGE => c.skip(22, "message header")?,
        OP_CHUNK => {
            c.skip(28, "chunk header")?;
            c.string("compression")?;
            let n = c.int::<8>("chunk records")?;
            c.skip(n, "chunk records")?;
        }
        OP_METADATA => {
            c.string("metadata name")?;
            c.string_map("metadata")?;
        }
        _ => {}
    }
    Ok(())
}

/// A chunk's records, decompressed: exactly `uncompressed_size` bytes (the caller has bounded
/// it), checked against the chunk's CRC when it has one.
fn decompress_chunk(header: &mcap::records::ChunkHeader, data: &[u8]) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let size = usize::try_from(header.uncompressed_size)
        .map_err(|_| format!("a chunk of {} bytes", header.uncompressed_size))?;
    let content = match header.compression.as_str() {
        "" => data.to_vec(),
        "lz4" => {
            let decoder =
                lz4::Decoder::new(data).map_err(|e| format!("the chunk's lz4 frame: {e}"))?;
            // lz4 expands at most ~255 times: a stated size beyond that is not reserved.
            let mut out = Vec::with_capacity(size.min(data.len().saturating_mul(256)));
            // One byte more than stated, to tell a chunk that holds more than it says.
            decoder
                .take(size as u64 + 1)
                .read_to_end(&mut out)
                .map_err(|e| format!("the chunk's lz4 data: {e}"))?;
            out
        }
        other => {
            return Err(format!(
                "a chunk compressed with {other:?} (handblocks reads lz4 and uncompressed chunks)"
            ))
        }
    };
    if content.len() != size {
        return Err(format!(
            "the chunk holds {} bytes uncompressed where its header says {size}",
            content.len()
        ));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(&content);
        if crc != header.uncompressed_crc {
            return Err(format!(
                "the chunk's CRC is {crc:#010x} where its header says {:#010x}: its bytes were \
                 changed",
                header.uncompressed_crc
            ));
        }
    }
    Ok(content)
}

enum Flow {
    Go,
    DataEnd,
}

/// Channels and schemas seen so far while reading.
struct Reader<'t> {
    /// (channel id, our topic if it is one of ours with the right schema)
    channels: Vec<(u16, Option<Topic>)>,
    /// (schema id, schema name)
    schemas: Vec<(u16, String)>,
    /// The topics whose messages are kept.
    kept: &'t [Topic],
    /// The last seq read per topic, for the gaps.
    last_seq: [Option<u64>; Topic::ALL.len()],
}

impl Reader<'_> {
    fn record(
        &mut self,
        opcode: u8,
        body: &[u8],
        offset: u64,
        rec: &mut Recording,
    ) -> Result<Flow, String> {
        // What the reader uses; any other record (header, indexes, attachments, the summary)
        // is passed over unparsed.
        if !USED_OPCODES.contains(&opcode) {
            return Ok(Flow::Go);
        }
        lengths_fit(opcode, body)?;
        let record = mcap::read::parse_record(opcode, body).map_err(|e| format!("{e}"))?;
        match record {
            mcap::records::Record::Chunk { header, data } => {
                if header.uncompressed_size > MAX_CHUNK_BYTES {
                    return Err(format!(
                        "a chunk claims {} uncompressed bytes (at most {MAX_CHUNK_BYTES} \
                         accepted)",
                        header.uncompressed_size
                    ));
                }
                // Decompressed here, into exactly the size the chunk states (bounded above),
                // and its records walked with every length checked against what is left:
                // mcap's own chunk reader trusts the lengths inside a chunk, so one changed
                // byte there asked for 1e12 bytes (issue 16).
                let content = decompress_chunk(&header, &data)?;
                let mut at = 0usize;
                while at < content.len() {
                    let left = content.len() - at;
                    if left < 9 {
                        return Err(format!(
                            "inside the chunk, at byte {at} of {}: a record header is cut off \
                             ({left} of 9 bytes)",
                            content.len()
                        ));
                    }
                    let opcode = content[at];
                    let mut len_bytes = [0u8; 8];
                    len_bytes.copy_from_slice(&content[at + 1..at + 9]);
                    let len = u64::from_le_bytes(len_bytes);
                    if len > (left - 9) as u64 {
                        return Err(format!(
                            "inside the chunk, at byte {at} of {}: a record (opcode \
                             {opcode:#04x}) of {len} bytes runs past the chunk's end",
                            content.len()
                        ));
                    }
                    let body = &content[at + 9..at + 9 + len as usize];
                    if !USED_OPCODES.contains(&opcode) || opcode == OP_CHUNK {
                        // A chunk inside a chunk is not MCAP; other records are not used.
                        at += 9 + len as usize;
                        continue;
                    }
                    lengths_fit(opcode, body)
                        .map_err(|e| format!("inside the chunk, at byte {at}: {e}"))?;
                    let inner = mcap::read::parse_record(opcode, body)
                        .map_err(|e| format!("inside the chunk, at byte {at}: {e}"))?;
                    self.inner(inner, offset, rec)?;
                    at += 9 + len as usize;
                }
                Ok(Flow::Go)
            }
            mcap::records::Record::DataEnd(_) => Ok(Flow::DataEnd),
            other => {
                self.inner(other, offset, rec)?;
                Ok(Flow::Go)
            }
        }
    }

    fn inner(
        &mut self,
        record: mcap::records::Record<'_>,
        offset: u64,
        rec: &mut Recording,
    ) -> Result<(), String> {
        use mcap::records::Record;
        match record {
            Record::Metadata(m) if m.name == "handblocks" => rec.metadata = m.metadata,
            Record::Schema { header, .. } => {
                self.schemas.retain(|(id, _)| *id != header.id);
                self.schemas.push((header.id, header.name));
            }
            Record::Channel(c) => {
                let schema = self
                    .schemas
                    .iter()
                    .find(|(id, _)| *id == c.schema_id)
                    .map(|(_, name)| name.as_str());
                let topic = RECORDED_TOPICS
                    .into_iter()
                    .find(|t| t.name() == c.topic && c.message_encoding == MESSAGE_ENCODING);
                if let (Some(t), Some(schema)) = (topic, schema) {
                    let (expected, _) = sample_type(t);
                    if schema != expected {
                        return Err(format!(
                            "channel {:?} has schema {schema:?}, expected {expected:?}",
                            c.topic
                        ));
                    }
                }
                self.channels.retain(|(id, _)| *id != c.id);
                self.channels.push((c.id, topic));
            }
            Record::Message { header, data } => {
                let Some(&(_, topic)) = self
                    .channels
                    .iter()
                    .find(|(id, _)| *id == header.channel_id)
                else {
                    return Err(format!(
                        "a message on channel {} which was never declared",
                        header.channel_id
                    ));
                };
                let Some(topic) = topic else {
                    rec.foreign_messages += 1;
                    return Ok(());
                };
                let (type_name, header_size) = sample_type(topic);
                let size = match topic.element_size() {
                    None => header_size,
                    // A slice topic: its sequence's count says how long it is.
                    Some(_) => {
                        let at = CDR_LE_HEADER.len() + header_size;
                        let count = data
                            .get(at..at + 4)
                            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
                        match count {
                            Some(n) if n <= MAX_SCENE_BLOCKS => {
                                slice_message_bytes(topic, n).unwrap_or(0)
                            }
                            Some(n) => {
                                return Err(format!(
                                    "a {} message (seq {}) claims {n} blocks (at most \
                                     {MAX_SCENE_BLOCKS})",
                                    topic.name(),
                                    header.sequence
                                ))
                            }
                            None => header_size + 4,
                        }
                    }
                };
                if data.len() != CDR_LE_HEADER.len() + size {
                    return Err(format!(
                        "a {} message (seq {}) has {} bytes; {type_name} has {} with its CDR \
                         header (a recording from another version of handblocks?)",
                        topic.name(),
                        header.sequence,
                        data.len(),
                        CDR_LE_HEADER.len() + size
                    ));
                }
                if data[..CDR_LE_HEADER.len()] != CDR_LE_HEADER {
                    return Err(format!(
                        "a {} message (seq {}) is not little-endian plain CDR (header {:02x?})",
                        topic.name(),
                        header.sequence,
                        &data[..CDR_LE_HEADER.len()]
                    ));
                }
                let data = &data[CDR_LE_HEADER.len()..];
                // SAFETY: every sample starts with its Stamp (four u64) and `data` is longer.
                let stamp = unsafe { std::ptr::read_unaligned(data.as_ptr() as *const Stamp) };
                let s = &mut rec.stats[topic as usize];
                if s.messages == 0 {
                    s.first_publish_ns = stamp.publish_ns;
                    s.first_seq = stamp.seq;
                }
                s.messages += 1;
                s.last_publish_ns = stamp.publish_ns;
                s.last_seq = stamp.seq;
                if let Some(prev) = self.last_seq[topic as usize] {
                    s.gaps += stamp.seq.saturating_sub(prev + 1);
                }
                self.last_seq[topic as usize] = Some(stamp.seq);
                if !self.kept.contains(&topic) {
                    return Ok(());
                }
                let start = rec.data.len();
                rec.data.extend_from_slice(data);
                rec.messages.push(RecordedMessage {
                    topic,
                    publish_ns: stamp.publish_ns,
                    record_offset: offset,
                    start,
                    len: size,
                });
            }
            _ => {}
        }
        Ok(())
    }
}

/// What `handblocks inspect` says about one recorded topic.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TopicSummary {
    pub topic: Topic,
    pub messages: u64,
    /// Samples missing between consecutive recorded seqs.
    pub gaps: u64,
    /// From the topic's first publish time to its last.
    pub seconds: f64,
    /// Messages per second over that span; 0 with fewer than two messages or no span.
    pub rate_hz: f64,
    /// The schema (message type) name, as [`sample_type`] gives it.
    pub schema: &'static str,
    /// One sample's size in bytes (without the CDR header); of a slice topic (`world`), its
    /// header's, with `element_bytes` more per element.
    pub sample_bytes: usize,
    /// A slice topic's bytes per element (a `world` block); None for a fixed-size topic.
    pub element_bytes: Option<usize>,
}

/// What a recording holds, in figures: `handblocks inspect` prints this (as text or JSON) and
/// nothing else, so the figures are computed once, here, beside the format they describe.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingSummary {
    /// One row per recorded topic, in [`RECORDED_TOPICS`] order, empty topics included.
    pub topics: [TopicSummary; RECORDED_TOPICS.len()],
    /// Messages of every topic together.
    pub messages: u64,
    /// The first and the last publish time of any topic, in Unix nanoseconds (publish times
    /// moved by the recorder's `unix_offset_ns`); `None` without messages or without the offset.
    pub span_unix_ns: Option<(u64, u64)>,
    /// The session that recorded the file, if the file names one.
    pub session: Option<String>,
    /// The scene that session ran, if the file names one.
    pub scene: Option<String>,
    /// True when the file ended with its summary and footer.
    pub complete: bool,
    /// Where reading stopped early, and why, as [`RecordingError`]'s message.
    pub damage: Option<String>,
    /// Messages on channels that are not ours.
    pub foreign_messages: u64,
}

impl Recording {
    /// Counts, gaps, spans and rates per topic, and what the file says about itself. Computed
    /// from the statistics of every message read, so a recording opened with no topics kept
    /// ([`Recording::open_topics`] with `&[]`) summarises as well as a full one.
    pub fn summary(&self) -> RecordingSummary {
        let topics = RECORDED_TOPICS.map(|topic| {
            let s = self.stats[topic as usize];
            let seconds = s.last_publish_ns.saturating_sub(s.first_publish_ns) as f64 * 1e-9;
            let rate_hz = if s.messages > 1 && seconds > 0.0 {
                (s.messages - 1) as f64 / seconds
            } else {
                0.0
            };
            let (schema, sample_bytes) = sample_type(topic);
            TopicSummary {
                topic,
                messages: s.messages,
                gaps: s.gaps,
                seconds,
                rate_hz,
                schema,
                sample_bytes,
                element_bytes: topic.element_size(),
            }
        });
        // Log times are publish times on the recorder's Unix offset: the span of the recording.
        let offset: Option<u64> = self
            .metadata
            .get("unix_offset_ns")
            .and_then(|v| v.parse().ok());
        let span = self
            .stats
            .iter()
            .filter(|s| s.messages > 0)
            .fold(None, |acc, s| {
                let (a, b) = acc.unwrap_or((u64::MAX, 0));
                Some((a.min(s.first_publish_ns), b.max(s.last_publish_ns)))
            });
        // An offset that would carry past u64 nanoseconds (the year 2554) names no time.
        let span_unix_ns = match (offset, span) {
            (Some(o), Some((a, b))) => a.checked_add(o).zip(b.checked_add(o)),
            _ => None,
        };
        RecordingSummary {
            topics,
            messages: self.stats.iter().map(|s| s.messages).sum(),
            span_unix_ns,
            session: self.metadata.get("session").cloned(),
            scene: self.metadata.get("scene").cloned(),
            complete: self.complete,
            damage: self.damage.as_ref().map(|d| d.to_string()),
            foreign_messages: self.foreign_messages,
        }
    }
}

/// Seqs of one topic that no segment of a recording holds, between two segments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SegmentGap {
    pub topic: Topic,
    /// The first seq missing: one past the last seq any earlier segment holds (0 when none
    /// holds the topic: the session's publishers start at 0).
    pub from_seq: u64,
    /// The first seq the later segment holds.
    pub next_seq: u64,
}

impl SegmentGap {
    /// Samples missing: `next_seq - from_seq`.
    pub fn lost(&self) -> u64 {
        self.next_seq - self.from_seq
    }
}

/// A session's recording whose recorder was restarted (`[supervise]`): the file (segment 0)
/// and each segment after it (`NAME.1.mcap`, ...; see `recording_segment`), and between each
/// two the samples no segment holds, counted from the publishers' seqs. A restarted
/// recorder's loss is the open chunk of the dead one (at most `[recorder] flush_ms` of
/// samples) and what was published while none ran; a source restarted meanwhile may also
/// have skipped seqs it never sent (its own restart line counts those).
#[derive(Debug)]
pub struct SegmentChain {
    pub files: Vec<PathBuf>,
    /// Per file, its summary.
    pub summaries: Vec<RecordingSummary>,
    /// `gaps[k]`: what no segment holds between `files[k]` and `files[k + 1]`, per topic
    /// with a gap.
    pub gaps: Vec<Vec<SegmentGap>>,
}

impl SegmentChain {
    /// Reads `first` and the segments after it that exist, up to `at_most` segments in all;
    /// only counts are kept, no sample.
    pub fn open(first: &Path, at_most: u32) -> Result<SegmentChain, RecordingError> {
        let mut files = vec![first.to_path_buf()];
        for n in 1..at_most {
            let next = common::config::session::recording_segment(first, n);
            if std::fs::symlink_metadata(&next).is_err() {
                break;
            }
            files.push(next);
        }
        let mut summaries = Vec::with_capacity(files.len());
        let mut stats = Vec::with_capacity(files.len());
        for f in &files {
            let rec = Recording::open_topics(f, &[])?;
            summaries.push(rec.summary());
            stats.push(rec.stats());
        }
        Ok(SegmentChain {
            gaps: segment_gaps(&stats),
            files,
            summaries,
        })
    }
}

/// Between each two consecutive segments (their per-topic stats, in order), the seqs that
/// none of them holds.
pub fn segment_gaps(segments: &[[TopicStats; Topic::ALL.len()]]) -> Vec<Vec<SegmentGap>> {
    // Per topic, one past the last seq written so far.
    let mut next_expected = [0u64; Topic::ALL.len()];
    let mut gaps = Vec::with_capacity(segments.len().saturating_sub(1));
    for (k, seg) in segments.iter().enumerate() {
        let mut here = Vec::new();
        for t in RECORDED_TOPICS {
            let s = &seg[t as usize];
            if s.messages == 0 {
                continue;
            }
            let from = next_expected[t as usize];
            if k > 0 && s.first_seq > from {
                here.push(SegmentGap {
                    topic: t,
                    from_seq: from,
                    next_seq: s.first_seq,
                });
            }
            next_expected[t as usize] = from.max(s.last_seq.saturating_add(1));
        }
        if k > 0 {
            gaps.push(here);
        }
    }
    gaps
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every layout lists every byte of its struct once, in order: no field forgotten, no gap.
    #[test]
    fn layouts_cover_every_byte() {
        for (name, size) in [
            ("handblocks/Stamp", size_of::<Stamp>()),
            ("handblocks/Pose", size_of::<Pose>()),
            ("handblocks/BlockState", size_of::<BlockState>()),
        ]
        .into_iter()
        .chain(RECORDED_TOPICS.into_iter().map(sample_type))
        {
            let fs = fields(name).unwrap();
            let mut at = 0;
            for f in &fs {
                assert_eq!(
                    f.offset, at,
                    "{name}.{} starts where the last ended",
                    f.name
                );
                // CDR aligns each primitive to its own size: so does our layout.
                let element = match f.ty.split('[').next().unwrap() {
                    "uint64"
                    | "float64"
                    | "handblocks/Stamp"
                    | "handblocks/Pose"
                    | "handblocks/BlockState" => 8,
                    "uint32" | "int32" => 4,
                    other => panic!("{name}.{}: unexpected type {other}", f.name),
                };
                assert_eq!(f.offset % element, 0, "{name}.{} is CDR-aligned", f.name);
                at += f.size;
            }
            assert_eq!(at, size, "{name}: the fields cover all {size} bytes");
        }
        let text = layout(Topic::World);
        assert!(
            text.contains(
                "handblocks/BlockState[] blocks  # count: uint32 @680; blocks @688, 64 bytes each"
            ),
            "{text}"
        );
        assert!(text.contains("MSG: handblocks/BlockState"));
        assert!(text.contains("MSG: handblocks/Pose"));
        assert!(text.contains("MSG: handblocks/Stamp"));
        assert!(text.contains("uint32 reserved"));
    }

    fn scratch(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("hb-recording-{}-{name}.mcap", std::process::id()))
    }

    fn glove(seq: u64, publish_ns: u64) -> GloveSample {
        let mut g = GloveSample {
            stamp: Stamp {
                seq,
                source_time_ns: seq * 1000,
                origin_ns: publish_ns - 10,
                publish_ns,
            },
            ..Default::default()
        };
        g.angles[3] = seq as f64 * 0.01;
        g
    }

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

    /// Issue 28: what no segment holds between a killed recorder's file and its restart's,
    /// from the seqs: the dead writer's open chunk is lost with it; a topic the earlier
    /// segment never held counts from seq 0.
    #[test]
    fn the_samples_between_two_segments_are_counted_from_their_seqs() {
        let first = scratch("chain");
        let second = common::config::session::recording_segment(&first, 1);
        let _ = std::fs::remove_file(&second);
        // The dead recorder: glove 0..300 written, a chunk closed every 100 ms of publish
        // time; it dies with 0.25 s in the open chunk (never closed, never finished).
        let mut w = RecordingWriter::create(&first)
            .unwrap()
            .flush_every(100_000_000, CHUNK_BYTES);
        for k in 0..300u64 {
            w.write(Topic::Glove, &glove(k, k * 1_000_000)).unwrap();
        }
        std::mem::forget(w);
        let mut w = RecordingWriter::create(&second).unwrap();
        for k in 340..400u64 {
            w.write(Topic::Glove, &glove(k, k * 1_000_000)).unwrap();
        }
        let mut t = TrackerSample::default();
        t.stamp.seq = 7;
        w.write(Topic::Tracker, &t).unwrap();
        w.finish().unwrap();
        let chain = SegmentChain::open(&first, 8).unwrap();
        assert_eq!(chain.files, [first.clone(), second.clone()]);
        let written = chain.summaries[0].topics[0];
        assert_eq!(written.topic, Topic::Glove);
        assert!(!chain.summaries[0].complete);
        // Chunks close on the sample 100 ms after a chunk's first: the last closed one ends
        // at seq 201, so 202..340 are in no segment.
        assert_eq!(written.messages, 202);
        assert_eq!(
            chain.gaps,
            [vec![
                SegmentGap {
                    topic: Topic::Glove,
                    from_seq: 202,
                    next_seq: 340
                },
                SegmentGap {
                    topic: Topic::Tracker,
                    from_seq: 0,
                    next_seq: 7
                },
            ]]
        );
        let lost: Vec<(Topic, u64)> = chain.gaps[0].iter().map(|g| (g.topic, g.lost())).collect();
        assert_eq!(lost, [(Topic::Glove, 138), (Topic::Tracker, 7)]);
        // An idle writer closes its chunk once it is due, without a later sample.
        let idle = scratch("idle");
        let mut w = RecordingWriter::create(&idle)
            .unwrap()
            .flush_every(100_000_000, CHUNK_BYTES);
        w.write(Topic::Glove, &glove(0, 1_000_000_000)).unwrap();
        w.close_chunk_if_due(1_050_000_000).unwrap();
        std::mem::forget(w);
        assert_eq!(Recording::open(&idle).unwrap().stats()[0].messages, 0);
        let mut w = RecordingWriter::create(&idle.with_extension("2.mcap"))
            .unwrap()
            .flush_every(100_000_000, CHUNK_BYTES);
        w.write(Topic::Glove, &glove(0, 1_000_000_000)).unwrap();
        w.close_chunk_if_due(1_100_000_000).unwrap();
        std::mem::forget(w);
        let closed = Recording::open(&idle.with_extension("2.mcap")).unwrap();
        assert_eq!(closed.stats()[Topic::Glove as usize].messages, 1);
        for f in [first, second, idle.clone(), idle.with_extension("2.mcap")] {
            let _ = std::fs::remove_file(f);
        }
    }

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

    #[test]
    fn summary_counts_gaps_spans_and_rates() {
        let path = scratch("summary");
        let mut w = RecordingWriter::create(&path).unwrap();
        for k in 0..11u64 {
            if k == 4 {
                continue; // a gap
            }
            w.write(Topic::Glove, &glove(k, 1_000_000_000 + k * 100_000_000))
                .unwrap();
        }
        w.finish().unwrap();
        let rec = Recording::open_topics(&path, &[]).unwrap();
        let summary = rec.summary();
        assert!(summary.complete && summary.damage.is_none());
        assert_eq!(summary.messages, 10);
        let g = summary.topics[0];
        assert_eq!((g.topic, g.messages, g.gaps), (Topic::Glove, 10, 1));
        assert!((g.seconds - 1.0).abs() < 1e-12, "{}", g.seconds);
        assert!((g.rate_hz - 9.0).abs() < 1e-9, "{}", g.rate_hz);
        assert_eq!(
            (g.schema, g.sample_bytes),
            sample_type(Topic::Glove),
            "the schema row"
        );
        let w = summary.topics[4];
        assert_eq!((w.topic, w.messages, w.rate_hz), (Topic::World, 0, 0.0));
        let offset: u64 = rec.metadata["unix_offset_ns"].parse().unwrap();
        assert_eq!(
            summary.span_unix_ns,
            Some((1_000_000_000 + offset, 2_000_000_000 + offset))
        );
        let _ = std::fs::remove_file(&path);
    }
}
