//! The recorder process: sleeps on every topic's event, writes each sample as it comes into
//! the session's MCAP recording, and reports per topic what it received and the gaps in
//! sequence numbers (the launcher puts them in the session report).
//!
//! A chunk of the recording is handed to the operating system as soon as it closes (at
//! `[recorder] chunk_kib` or once `flush_ms` old, 1024 KiB and 500 ms by default; checked on
//! every wake-up, so a quiet topic's samples do not wait for the next), so a crash of any
//! process, this one included, loses at most the open chunk.
//!
//! Beside the topics it writes `/scene` (`scene_view`: the blocks, the floor and the hand in
//! Foxglove's z-up frame, at most `[recorder] scene_hz` times a second, stamped as the world it
//! shows), so a recording opens in Foxglove's 3D panel as the live view does; and with each
//! scene `/tf`, the hand's frames (`scene_view::HandFrames`: `world` -> the wrist -> each
//! finger's joints), stamped with that scene's log time.

use std::time::Duration;

use common::bus::{wait_each, AnyInlet, Bus, BusError, WaitStrategy, Waiter, Wakeable, MAX_WAIT};
use common::config::Session;
use common::latency::{LatencyRecorder, Reporter};
use common::node::{self, Counters, Pass, Task};
use common::{monotonic_ns, Stage, Topic};

use common::samples::{BlockState, HandSample, WorldHeader};
use recording::{RecordingError, RecordingWriter};
use scene_view::SceneView;

/// Why the recorder process stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    #[error("{0}")]
    Bus(#[from] BusError),
    /// The recording could not be created.
    #[error("cannot record: {0}")]
    Create(#[source] RecordingError),
    /// The recording could not be written.
    #[error("{0}")]
    Recording(#[from] RecordingError),
    /// The scene cannot be drawn (a block's shape).
    #[error("cannot draw the scene for the recording's /scene channel: {0}")]
    Scene(#[source] scene_view::SceneViewError),
}

/// The recording, and the scene view written beside the topics.
struct Log {
    writer: RecordingWriter,
    scene: Option<SceneTrack>,
}

/// The `/scene` channel and the `/tf` channel beside it: the view, rewritten in place, and
/// their encoded bytes.
struct SceneTrack {
    channel_id: u16,
    tf_channel_id: u16,
    view: SceneView,
    encoded: Vec<u8>,
    tf_encoded: Vec<u8>,
    period_ns: u64,
    /// When the next scene is due (publish time of the world that brings it).
    next_ns: Option<u64>,
}

impl Log {
    /// After `topic`'s sample was written: a hand updates the scene; a world updates it and,
    /// once a period, writes it. Both are read back from the message just written.
    fn feed_scene(&mut self, topic: Topic, stamp: &common::Stamp) -> Result<(), RecorderError> {
        let Some(track) = &mut self.scene else {
            return Ok(());
        };
        let message = self.writer.last_message();
        match topic {
            Topic::Hand => {
                if let Ok(hand) = recording::decode_sample::<HandSample>(topic, message) {
                    track.view.set_hand(&hand);
                }
            }
            Topic::World => {
                // Due on a grid of the period, not a period after the last one written: the
                // rate is scene_hz on average whatever the worlds' jitter (every 4th of 120 Hz
                // worlds at 30, not every 5th when one came a little early).
                let now = stamp.publish_ns;
                if track.next_ns.is_some_and(|due| now < due) {
                    return Ok(());
                }
                if let Ok((_, body)) = recording::decode_slice::<WorldHeader>(topic, message) {
                    let due = track.next_ns.unwrap_or(now) + track.period_ns;
                    // After a stall, on from now rather than a burst to catch up.
                    track.next_ns = Some(if due <= now {
                        now + track.period_ns
                    } else {
                        due
                    });
                    let size = std::mem::size_of::<BlockState>();
                    // SAFETY: `body` holds `len / size` whole block states (decode_slice
                    // checked its length); plain old data, read unaligned.
                    track.view.set_world(body.len() / size, |i| unsafe {
                        std::ptr::read_unaligned(body[i * size..].as_ptr() as *const BlockState)
                    });
                    track.view.encode_into(&mut track.encoded);
                    self.writer
                        .write_encoded(track.channel_id, stamp, &track.encoded)?;
                    // The hand's frames, once there is a hand, stamped with the message's log
                    // time (the scene's).
                    if !track.view.frames().is_empty() {
                        let log_ns = stamp
                            .publish_ns
                            .saturating_add(self.writer.unix_offset_ns());
                        track.view.frames_mut().stamp(log_ns);
                        track.view.frames().encode_into(&mut track.tf_encoded);
                        self.writer
                            .write_encoded(track.tf_channel_id, stamp, &track.tf_encoded)?;
                    }
                }
            }
            _ => {}
        }
        Ok(())
    }
}

// One `wait_any` sleeps on every recorded topic.
const _: () = assert!(Topic::RECORDED.len() <= MAX_WAIT);

/// Writes every sample waiting in `inlet` (one of the recorded topics', whichever) into `log`
/// and records its latency: the sample's bytes are copied from the publisher's memory into the
/// open chunk, nothing else.
fn drain(
    inlet: &AnyInlet,
    log: &mut Option<Log>,
    recorder: &mut LatencyRecorder,
) -> Result<(), RecorderError> {
    while let Some(s) = inlet.receive()? {
        let view = s.view();
        record_one(view.topic(), s.stamp(), log, recorder, |log| {
            log.write_view(&view)
        })?;
    }
    Ok(())
}

/// One received sample: its hop, `write` into the recording (when there is one), and the
/// recorder's own time and the sample's age.
fn record_one(
    topic: Topic,
    stamp: &common::Stamp,
    log: &mut Option<Log>,
    recorder: &mut LatencyRecorder,
    write: impl FnOnce(&mut RecordingWriter) -> Result<(), RecordingError>,
) -> Result<(), RecorderError> {
    let received = monotonic_ns();
    recorder.hop(stamp, received);
    if let Some(log) = log {
        write(&mut log.writer)?;
        log.feed_scene(topic, stamp)?;
    }
    let done = monotonic_ns();
    recorder.record(common::latency::Metric::Process, done - received);
    recorder.record(
        common::latency::Metric::Origin,
        done.saturating_sub(stamp.origin_ns),
    );
    Ok(())
}

/// The recorder stage: an inlet per recorded topic and the recording.
struct Recorder {
    /// One per recorded topic, in table order.
    inlets: Vec<AnyInlet>,
    log: Option<Log>,
}

impl Task for Recorder {
    type Error = RecorderError;

    fn wait(&mut self, _: &mut Waiter, timeout: Duration) -> Result<(), RecorderError> {
        let wakeables = self.inlets.iter().map(|i| i as &dyn Wakeable);
        Ok(wait_each(wakeables, None, timeout)?)
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), RecorderError> {
        for inlet in &self.inlets {
            drain(inlet, &mut self.log, pass.recorder)?;
        }
        if let Some(log) = &mut self.log {
            log.writer.close_chunk_if_due(monotonic_ns())?;
        }
        Ok(())
    }

    fn counters(&self) -> Counters {
        self.inlets.iter().map(AnyInlet::counter).collect()
    }

    fn stop(&mut self, _: &mut Reporter) -> Result<(), RecorderError> {
        if let Some(log) = self.log.take() {
            log.writer.finish()?;
        }
        Ok(())
    }
}

/// Runs until asked to stop, then drains every input.
pub fn run(session: &Session, bus: &Bus) -> Result<(), RecorderError> {
    let log = match &session.recorder.file {
        Some(path) => {
            // The recording names the session it came from (`handblocks inspect` shows it).
            let name = |p: &std::path::Path| {
                std::fs::canonicalize(p)
                    .unwrap_or_else(|_| p.to_path_buf())
                    .display()
                    .to_string()
            };
            let about = [
                ("session", name(&session.file)),
                ("scene", name(&session.scene_file)),
                ("source", session.source.kind().to_string()),
                // The blocks' names, one a line (a name holds no control character), so that
                // a reader names the world's blocks without the scene file.
                (
                    "blocks",
                    session
                        .scene
                        .blocks
                        .iter()
                        .map(|b| b.name.as_str())
                        .collect::<Vec<_>>()
                        .join("\n"),
                ),
            ];
            let settings = &session.recorder;
            let mut writer = RecordingWriter::create_with(path, &about)
                .map_err(RecorderError::Create)?
                .flush_every(
                    settings.flush_ms * 1_000_000,
                    (settings.chunk_kib * 1024) as usize,
                );
            let scene = if let Some(period_ns) = 1_000_000_000u64.checked_div(settings.scene_hz) {
                let (name, encoding, data) = SceneView::schema();
                let channel_id = writer
                    .add_channel(
                        recording::SCENE_CHANNEL,
                        (&name, &encoding, &data),
                        &SceneView::message_encoding(),
                    )
                    .map_err(RecorderError::Create)?;
                let (name, encoding, data) = scene_view::HandFrames::schema();
                let tf_channel_id = writer
                    .add_channel(
                        recording::TF_CHANNEL,
                        (&name, &encoding, &data),
                        &SceneView::message_encoding(),
                    )
                    .map_err(RecorderError::Create)?;
                Some(SceneTrack {
                    channel_id,
                    tf_channel_id,
                    view: SceneView::new(&session.scene).map_err(RecorderError::Scene)?,
                    encoded: Vec::new(),
                    tf_encoded: Vec::new(),
                    period_ns,
                    next_ns: None,
                })
            } else {
                None
            };
            Some(Log { writer, scene })
        }
        None => None,
    };
    // An inlet on every topic the recorder reads (the table names it their reader).
    let inlets = Topic::RECORDED
        .into_iter()
        .map(|t| bus.any_inlet(t))
        .collect::<Result<_, _>>()?;
    let mut recorder = Recorder { inlets, log };
    // The recorder sleeps on all its inlets at once (`wait_any`), not by the session's
    // strategy: what it writes is not on the latency path.
    node::run(Stage::Recorder, bus, WaitStrategy::Event, &mut recorder)
}
