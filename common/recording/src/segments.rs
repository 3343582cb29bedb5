//! A recording in segments: when a session's recorder is restarted, its file continues in
//! `NAME.1.mcap`, ...; the chain of segments, and between each two the samples no segment
//! holds, counted from the publishers' seqs.

use std::path::{Path, PathBuf};

use common::topic::Topic;

use crate::reader::{Recording, TopicStats};
use crate::summary::RecordingSummary;
use crate::{RecordingError, RECORDED_TOPICS};

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
    use common::samples::TrackerSample;

    use crate::test_support::{glove, scratch};
    use crate::{RecordingWriter, CHUNK_BYTES};

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
}
