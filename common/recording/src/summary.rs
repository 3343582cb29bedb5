//! A recording in figures: per topic its messages, gaps, span and rate, and what the file says
//! about itself (session, scene, completeness, damage). `handblocks inspect` prints this and
//! nothing else, so the figures are computed once, here, beside the format they describe.

use common::topic::Topic;

use crate::codec::sample_type;
use crate::reader::Recording;
use crate::RECORDED_TOPICS;

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
    /// Where reading stopped early, and why, as [`RecordingError`](crate::RecordingError)'s
    /// message.
    pub damage: Option<String>,
    /// Messages on channels that are not ours.
    pub foreign_messages: u64,
    /// Messages of the scene view (`/scene`, for Foxglove's 3D panel).
    pub scene_messages: u64,
    /// Messages of the hand's frames (`/tf`, for Foxglove's 3D panel).
    pub transform_messages: u64,
    /// Messages whose count fields their arrays cannot hold: skipped, and the first's reason.
    pub refused_messages: u64,
    pub first_refused: Option<String>,
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
            scene_messages: self.scene_messages,
            transform_messages: self.transform_messages,
            refused_messages: self.refused_messages,
            first_refused: self.first_refused.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{glove, scratch};
    use crate::RecordingWriter;

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

    /// The scene view's channels (`/scene`, `/tf`) are ours: counted apart, never foreign,
    /// and no sample is read from them.
    #[test]
    fn the_scene_and_the_hands_frames_are_counted_apart() {
        let path = scratch("view-channels");
        let mut w = RecordingWriter::create(&path).unwrap();
        let scene = w
            .add_channel(
                crate::SCENE_CHANNEL,
                ("foxglove.SceneUpdate", "protobuf", b""),
                "protobuf",
            )
            .unwrap();
        let tf = w
            .add_channel(
                crate::TF_CHANNEL,
                ("foxglove.FrameTransforms", "protobuf", b""),
                "protobuf",
            )
            .unwrap();
        let other = w
            .add_channel("/theirs", ("theirs", "protobuf", b""), "protobuf")
            .unwrap();
        for k in 0..3u64 {
            let g = glove(k, 1_000_000_000 + k * 10_000_000);
            w.write(Topic::Glove, &g).unwrap();
            w.write_encoded(scene, &g.stamp, b"scene").unwrap();
            w.write_encoded(tf, &g.stamp, b"tf").unwrap();
        }
        w.write_encoded(tf, &glove(3, 1_100_000_000).stamp, b"tf")
            .unwrap();
        w.write_encoded(other, &glove(3, 1_100_000_000).stamp, b"x")
            .unwrap();
        w.finish().unwrap();
        let rec = Recording::open(&path).unwrap();
        let summary = rec.summary();
        assert_eq!(rec.messages.len(), 3);
        assert_eq!(
            (
                summary.scene_messages,
                summary.transform_messages,
                summary.foreign_messages
            ),
            (3, 4, 1)
        );
        let _ = std::fs::remove_file(&path);
    }
}
