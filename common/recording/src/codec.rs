//! The messages: each sample as CDR bytes (the 4-byte little-endian header, then the sample's
//! `#[repr(C)]` bytes, which for our layouts are its CDR serialisation) and back. A recording's
//! messages and the bridge's (issue 17) are these bytes; every decoder checks a message's
//! length against its topic before it reads a sample from it.

use std::fmt;
use std::mem::{size_of, size_of_val};

use common::bus::Stamped;
use common::stamp::Stamp;
use common::topic::{SampleView, Topic};
use common::Counted;

/// Message encoding of every channel: CDR (little-endian), which for our layouts is the 4-byte
/// [`CDR_LE_HEADER`] and then the sample's `#[repr(C)]` bytes.
pub const MESSAGE_ENCODING: &str = "cdr";
/// The CDR encapsulation header of a little-endian plain CDR payload.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

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
    encode_parts(bytes, None, out);
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
    // (BlockState's `held_by` fills what would be its gap), so every byte is initialised.
    let head =
        unsafe { std::slice::from_raw_parts(header as *const H as *const u8, size_of::<H>()) };
    let body = unsafe {
        std::slice::from_raw_parts(elements.as_ptr() as *const u8, size_of_val(elements))
    };
    let sequence = Sequence {
        count: elements.len(),
        at: slice_elements_offset(topic),
        body,
    };
    encode_parts(head, Some(sequence), out);
}

/// A sample of any topic's message, from its bytes (an inlet's of a topic chosen at run time,
/// `common::bus::AnyInlet`): what [`encode_sample`] or [`encode_slice`] makes of the same
/// sample, into `out` (cleared first; no allocation once `out` has grown to the size).
pub fn encode_view(view: &SampleView<'_>, out: &mut Vec<u8>) {
    let topic = view.topic();
    let sequence = topic.element_size().map(|_| Sequence {
        count: view.len(),
        at: slice_elements_offset(topic),
        body: view.elements(),
    });
    encode_parts(view.sample(), sequence, out);
}

/// A slice topic's elements as the CDR sequence after its header: `count` of them, starting
/// `at` bytes into the message's body.
struct Sequence<'a> {
    count: usize,
    at: usize,
    body: &'a [u8],
}

/// The CDR header, `head` (a sample, or a slice topic's header), then the sequence if any:
/// its count, the padding that aligns its elements, its elements.
fn encode_parts(head: &[u8], sequence: Option<Sequence<'_>>, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(head);
    if let Some(s) = sequence {
        out.extend_from_slice(&(s.count as u32).to_le_bytes());
        let pad = s.at.saturating_sub(head.len() + 4).min(8);
        out.extend_from_slice(&[0u8; 8][..pad]);
        out.extend_from_slice(s.body);
    }
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

/// A `hand` message with its CDR header, as today's samples are.
pub(crate) const WIDENED: usize = CDR_LE_HEADER.len() + size_of::<common::HandSample>();

/// A hand recorded or sent before hands had a `side` (`HandSample::LEGACY_SIZE` bytes) is a
/// prefix of today's: copied into `buf`, the rest zero, it reads as the right hand. Any other
/// message is itself.
pub(crate) fn widen_legacy_hand<'a>(
    topic: Topic,
    data: &'a [u8],
    buf: &'a mut [u8; WIDENED],
) -> &'a [u8] {
    if topic == Topic::Hand && data.len() == CDR_LE_HEADER.len() + common::HandSample::LEGACY_SIZE {
        let (kept, added) = buf.split_at_mut(data.len());
        kept.copy_from_slice(data);
        added.fill(0);
        &buf[..]
    } else {
        data
    }
}

/// The sample of a fixed-size topic's message (`encode_sample`'s inverse): the length must be
/// the CDR header and exactly the sample, and its count fields within its arrays
/// ([`Counted`]: a `finger_point_count` of 6 would index past a finger's 5 points in every
/// viewer). Any other bit pattern of the right length is a sample (only integers and floats);
/// what the values mean is the reader's to check.
pub fn decode_sample<T: Stamped + Counted>(
    topic: Topic,
    message: &[u8],
) -> Result<T, MessageError> {
    // A hand from a peer of before two hands reads as the right hand (on the stack: no
    // allocation per sample).
    let mut widened = [0u8; WIDENED];
    let message = widen_legacy_hand(topic, message, &mut widened);
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
    let sample: T = unsafe { std::ptr::read_unaligned(message[4..].as_ptr() as *const T) };
    sample.check_counts(0).map_err(|e| counts_error(topic, e))?;
    Ok(sample)
}

/// A message whose counts its arrays cannot hold, named by field.
fn counts_error(topic: Topic, e: common::CountError) -> MessageError {
    MessageError(format!("a `{}` sample whose {e}", topic.name()))
}

/// A slice topic's message (`encode_slice`'s inverse): its header and the bytes of its
/// elements, whose count must agree with the message's length, and the header's counts with
/// those elements ([`Counted`]).
pub fn decode_slice<H: Stamped + Counted>(
    topic: Topic,
    message: &[u8],
) -> Result<(H, &[u8]), MessageError> {
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
    let header: H = unsafe { std::ptr::read_unaligned(message[4..].as_ptr() as *const H) };
    header
        .check_counts(count)
        .map_err(|e| counts_error(topic, e))?;
    Ok((header, body))
}

/// Checks the count fields of `sample` (a message of `topic` after its CDR header, whose
/// length the caller checked against the topic) by the topic's own [`Counted`] impl: the
/// recording reader's check of every message it keeps, so that a file a stranger edited
/// cannot make a reader index past a sample's arrays. The topic table drives it, so a topic
/// added later is checked too.
pub fn check_message_counts(topic: Topic, sample: &[u8]) -> Result<(), MessageError> {
    use common::topic::{SliceTopicSpec, TopicSpec, TopicVisitor};
    struct Check<'a> {
        topic: Topic,
        bytes: &'a [u8],
        found: Result<(), common::CountError>,
    }
    impl TopicVisitor for Check<'_> {
        type Error = std::convert::Infallible;
        fn visit<P: TopicSpec>(&mut self) -> Result<(), Self::Error> {
            if P::TOPIC == self.topic && self.bytes.len() >= size_of::<P::Sample>() {
                // SAFETY: the length is checked; plain old data, read unaligned.
                let s: P::Sample =
                    unsafe { std::ptr::read_unaligned(self.bytes.as_ptr() as *const P::Sample) };
                self.found = s.check_counts(0);
            }
            Ok(())
        }
        fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), Self::Error> {
            let start = slice_elements_offset(P::TOPIC);
            if P::TOPIC == self.topic && self.bytes.len() >= start {
                // SAFETY: the length is checked; plain old data, read unaligned.
                let h: P::Header =
                    unsafe { std::ptr::read_unaligned(self.bytes.as_ptr() as *const P::Header) };
                let elements = (self.bytes.len() - start) / size_of::<P::Element>().max(1);
                self.found = h.check_counts(elements);
            }
            Ok(())
        }
    }
    let mut check = Check {
        topic,
        bytes: sample,
        found: Ok(()),
    };
    let Ok(()) = Topic::visit_each(&mut check);
    check.found.map_err(|e| counts_error(topic, e))
}

/// The stamp at the start of any topic's message (every sample starts with it).
pub fn message_stamp(message: &[u8]) -> Option<Stamp> {
    let bytes = message.get(4..4 + size_of::<Stamp>())?;
    // SAFETY: the length is checked; a stamp is four u64s, any bit pattern valid.
    Some(unsafe { std::ptr::read_unaligned(bytes.as_ptr() as *const Stamp) })
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::{HandSample, WorldSample};

    /// Issue 40: one hand from the zenoh link with `finger_point_count[0] = 6` (bytes 100..103
    /// of its 1156-byte message) crashed the recorder, the renderer and the Foxglove view. It
    /// is refused where it comes in, naming the field; a recording's reader skips it the same.
    #[test]
    fn a_hand_whose_counts_overrun_its_arrays_is_refused_by_name() {
        let mut hand = HandSample {
            finger_count: 1,
            ..HandSample::default()
        };
        hand.finger_point_count[0] = 2;
        let mut message = Vec::new();
        encode_sample(&hand, &mut message);
        assert_eq!(message.len(), 1156);
        assert!(decode_sample::<HandSample>(Topic::Hand, &message).is_ok());
        message[100..104].copy_from_slice(&6u32.to_le_bytes());
        let e = decode_sample::<HandSample>(Topic::Hand, &message).unwrap_err();
        assert_eq!(
            e.to_string(),
            "a `hand` sample whose finger_point_count[0] is 6; at most 5 fit"
        );
        assert_eq!(
            check_message_counts(Topic::Hand, &message[4..]).unwrap_err(),
            e
        );
        // The palm: 17 of 16 vertices.
        encode_sample(&hand, &mut message);
        message[120..124].copy_from_slice(&17u32.to_le_bytes());
        let e = decode_sample::<HandSample>(Topic::Hand, &message).unwrap_err();
        assert!(e.to_string().contains("palm_vertex_count is 17"), "{e}");
    }

    /// A sample's bytes make the message its typed value makes: a recording written from a
    /// run-time inlet is the one written from a typed one, byte for byte.
    #[test]
    fn a_view_encodes_as_its_typed_sample() {
        let mut world = WorldSample::with_blocks(3);
        world.header.step = 9;
        world.blocks[1].mode = 4;
        let (mut typed, mut viewed) = (Vec::new(), Vec::new());
        encode_slice(Topic::World, &world.header, &world.blocks, &mut typed);
        let view = SampleView::new(
            Topic::World,
            &typed[4..4 + Topic::World.sample_size()],
            &typed[4 + slice_elements_offset(Topic::World)..],
        )
        .unwrap();
        assert_eq!(view.len(), 3);
        encode_view(&view, &mut viewed);
        assert_eq!(typed, viewed);
        let hand = HandSample {
            finger_count: 2,
            ..HandSample::default()
        };
        encode_sample(&hand, &mut typed);
        let view = SampleView::new(Topic::Hand, &typed[4..], &[]).unwrap();
        assert_eq!(view.stamp(), hand.stamp);
        encode_view(&view, &mut viewed);
        assert_eq!(typed, viewed);
        assert!(SampleView::new(Topic::Hand, &typed[5..], &[]).is_none());
        assert!(SampleView::new(Topic::World, &typed[..32], &[1]).is_none());
    }

    #[test]
    fn a_world_whose_counts_overrun_its_blocks_is_refused_by_name() {
        let world = WorldSample::with_blocks(3);
        let mut message = Vec::new();
        encode_slice(Topic::World, &world.header, &world.blocks, &mut message);
        assert!(decode_slice::<common::WorldHeader>(Topic::World, &message).is_ok());
        assert!(check_message_counts(Topic::World, &message[4..]).is_ok());
        let mut bad = world.clone();
        bad.header.block_count = 4;
        encode_slice(Topic::World, &bad.header, &bad.blocks, &mut message);
        let e = decode_slice::<common::WorldHeader>(Topic::World, &message).unwrap_err();
        assert!(
            e.to_string().contains("block_count is 4; at most 3 fit"),
            "{e}"
        );
        assert!(check_message_counts(Topic::World, &message[4..]).is_err());
    }
}
