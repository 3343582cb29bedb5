//! The MCAP records a reader walks: each record's lengths checked against the bytes it holds
//! before mcap parses it, each chunk decompressed into exactly its stated (bounded) size and
//! checked against its CRC, and the schemas, channels, metadata and messages inside taken into
//! the [`Recording`]. mcap's own readers trust these lengths (issue 16); this one never does.

use common::samples::MAX_SCENE_BLOCKS;
use common::stamp::Stamp;
use common::topic::Topic;

use super::{RecordedMessage, Recording, MAX_CHUNK_BYTES};
use crate::codec::{
    sample_type, slice_message_bytes, widen_legacy_hand, CDR_LE_HEADER, MESSAGE_ENCODING, WIDENED,
};
use crate::{RECORDED_TOPICS, SCENE_CHANNEL, TF_CHANNEL};

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

pub(super) enum Flow {
    Go,
    DataEnd,
}

/// Channels and schemas seen so far while reading.
pub(super) struct Reader<'t> {
    /// (channel id, our topic if it is one of ours with the right schema)
    pub(super) channels: Vec<(u16, Option<Topic>)>,
    /// The channels of the scene view ([`SCENE_CHANNEL`]): ours, but not a topic.
    pub(super) scene_channels: Vec<u16>,
    /// The channels of the hand's frames ([`TF_CHANNEL`]): ours, but not a topic.
    pub(super) tf_channels: Vec<u16>,
    /// (schema id, schema name)
    pub(super) schemas: Vec<(u16, String)>,
    /// The topics whose messages are kept.
    pub(super) kept: &'t [Topic],
    /// The last seq read per topic, for the gaps.
    pub(super) last_seq: [Option<u64>; Topic::ALL.len()],
}

impl Reader<'_> {
    pub(super) fn record(
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
                // `/world` names the topic (a bare `world` in recordings made before the live
                // view and the recordings shared their names).
                let topic = Topic::from_channel(&c.topic).filter(|t| {
                    RECORDED_TOPICS.contains(t) && c.message_encoding == MESSAGE_ENCODING
                });
                self.scene_channels.retain(|id| *id != c.id);
                if c.topic == SCENE_CHANNEL {
                    self.scene_channels.push(c.id);
                }
                self.tf_channels.retain(|id| *id != c.id);
                if c.topic == TF_CHANNEL {
                    self.tf_channels.push(c.id);
                }
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
                    if self.scene_channels.contains(&header.channel_id) {
                        rec.scene_messages += 1;
                        return Ok(());
                    }
                    if self.tf_channels.contains(&header.channel_id) {
                        rec.transform_messages += 1;
                        return Ok(());
                    }
                    rec.foreign_messages += 1;
                    return Ok(());
                };
                let mut widened = [0u8; WIDENED];
                let data = widen_legacy_hand(topic, &data, &mut widened);
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
                if let Err(why) = crate::check_message_counts(topic, data) {
                    rec.refused_messages += 1;
                    if rec.first_refused.is_none() {
                        rec.first_refused = Some(format!(
                            "at byte offset {offset} (seq {}): {why}",
                            stamp.seq
                        ));
                    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use common::HandSample;

    /// A hand recorded before two hands (1148 bytes with its CDR header) reads as the right
    /// hand, every field it had kept; other lengths and topics pass as they are.
    #[test]
    fn a_hand_recorded_before_sides_reads_as_the_right_hand() {
        let mut hand = HandSample {
            finger_count: 2,
            tracked: 1,
            ..HandSample::default()
        };
        hand.finger_points[1][0] = [0.5, 1.5, -2.0];
        let mut message = Vec::new();
        crate::codec::encode_sample(&hand, &mut message);
        assert_eq!(message.len(), WIDENED);
        let legacy = &message[..CDR_LE_HEADER.len() + HandSample::LEGACY_SIZE];
        assert_eq!(legacy.len(), 1148);
        let mut buf = [7u8; WIDENED];
        let widened = widen_legacy_hand(Topic::Hand, legacy, &mut buf);
        assert_eq!(widened, &message[..]);
        let back: HandSample = crate::codec::decode_sample(Topic::Hand, widened).unwrap();
        assert_eq!(back, hand);
        assert_eq!(
            common::HandSide::from_code(back.side),
            common::HandSide::Right
        );
        let mut buf = [0u8; WIDENED];
        assert_eq!(widen_legacy_hand(Topic::Joints, legacy, &mut buf), legacy);
        assert_eq!(
            widen_legacy_hand(Topic::Hand, &message[..100], &mut buf),
            &message[..100]
        );
    }
}
