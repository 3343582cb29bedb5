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
//!
//! The crate holds one concept a file: `codec` the messages' bytes, `schema` the message
//! definitions (from the topic table's field lists), `walk` a message's fields in order for
//! whatever shows them, `writer` and `reader` the file (`error` what goes wrong with it), `summary` its
//! figures and `segments` a recording continued over restarts of its recorder. Everything is
//! used from the crate's root.
//!
//! [`BlockState`]: common::samples::BlockState

mod codec;
mod error;
mod reader;
mod schema;
mod segments;
mod summary;
#[cfg(test)]
mod test_support;
mod walk;
mod writer;

pub use codec::{
    check_message_counts, decode_sample, decode_slice, encode_sample, encode_slice, encode_view,
    message_stamp, sample_type, slice_elements_offset, slice_message_bytes, MessageError,
    CDR_LE_HEADER, MESSAGE_ENCODING,
};
pub use error::RecordingError;
pub use reader::{RecordedMessage, Recording, TopicStats, MAX_CHUNK_BYTES, MAX_RECORDING_BYTES};
pub use schema::{fields, layout, schema, Field, SCHEMA_ENCODING};
pub use segments::{segment_gaps, SegmentChain, SegmentGap};
pub use summary::{RecordingSummary, TopicSummary};
pub use walk::{walk, Group, MessageVisitor, Value, Values};
pub use writer::{RecordingWriter, CHUNK_BYTES, CHUNK_SPAN_NS, PROFILE};

use common::topic::Topic;

/// The channel of the scene view beside the topics (`foxglove.SceneUpdate`, protobuf, written by
/// the session recorder from the world and hand it records), so that a recording opens in
/// Foxglove's 3D panel as the live view does; the live view sends it under the same name.
pub const SCENE_CHANNEL: &str = "/scene";

/// The channel of the hand's frames beside the scene (`foxglove.FrameTransforms`, protobuf:
/// `world` -> the wrist -> each finger's joints, written with each `/scene` message and stamped
/// as it is), so that the 3D panel shows the hand's joints as a frame tree, live and recorded.
pub const TF_CHANNEL: &str = "/tf";

/// The topics a recording holds (the latency reports go into the session report instead).
pub const RECORDED_TOPICS: [Topic; Topic::RECORDED.len()] = Topic::RECORDED;
