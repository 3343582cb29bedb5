//! The renderer process loop.
//!
//! It takes every `world` sample as it arrives (so the hop latency is the bus's, not the
//! frame pacing's), keeps only the newest, and at each frame deadline (absolute, at the
//! session's `frame_hz`) draws it with the hand sample it answers (and, in a two-hand session,
//! the newest left hand: the world answers the right one), waits for the GPU to finish
//! ("photon"), and publishes frame statistics. It never blocks upstream: samples that arrive
//! during a frame wait in the bus and are drained, newest kept, before the next one.
//!
//! PNG frames (`--frames-dir`) are encoded on a writer thread with recycled buffers; when the
//! writer falls behind, a frame is not written rather than the loop waiting.

use std::path::PathBuf;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError};
use std::thread::JoinHandle;
use std::time::Duration;

use common::bus::{Bus, Inlet, Outlet, Received, WaitStrategy, Waiter};
use common::config::session::RenderMode;
use common::config::Session;
use common::latency::{Metric, Reporter};
use common::node::{self, Counters, Pass, Task};
use common::{
    monotonic_ns, shutdown, topics, FrameSample, HandSample, HandSide, Stage, Stamp, WorldHeader,
    WorldView, HAND_SLOTS,
};

use crate::error::RenderError;
use crate::image::Image;
use crate::output::write_frame;
use crate::preview::PreviewWriter;
use crate::renderer::Renderer;
use crate::settings::{FramesRequest, OutputMode, RenderSettings};
use crate::window::{WindowHandle, WindowStatus};

/// Hand samples kept to find the one a world sample answers (`hand_seq`): the stepper lags
/// the hand by a step or two, so its fingers and the newest palm would not match.
const HAND_HISTORY: usize = 16;
/// Frames in flight to the PNG writer.
const WRITER_QUEUE: usize = 2;

/// Runs until asked to stop, with the session's renderer settings and no PNG frames.
pub fn run(session: &Session, bus: &Bus) -> Result<(), RenderError> {
    run_with(
        session,
        bus,
        RenderSettings::from_session(&session.renderer),
        None,
    )
}

/// Runs until asked to stop. `frames`: write PNG frames (the launcher's `--frames-dir`).
pub fn run_with(
    session: &Session,
    bus: &Bus,
    settings: RenderSettings,
    frames: Option<FramesRequest>,
) -> Result<(), RenderError> {
    run_with_preview(session, bus, settings, frames, None)
}

/// [`run_with`], and when `preview` names a file, writes the animated preview there when it
/// stops (see [`crate::preview`]).
pub fn run_with_preview(
    session: &Session,
    bus: &Bus,
    settings: RenderSettings,
    frames: Option<FramesRequest>,
    preview: Option<PathBuf>,
) -> Result<(), RenderError> {
    let (mut renderer, window) = match session.renderer.mode {
        RenderMode::Off => (None, None),
        RenderMode::Headless => (
            Some(Renderer::new_headless(&settings, &session.scene)?),
            None,
        ),
        RenderMode::Window => {
            let (r, w) = Renderer::new_window(&settings, &session.scene)?;
            (Some(r), Some(w))
        }
    };
    if let Some(r) = &renderer {
        eprintln!(
            "renderer: {} x {} per eye, {}, on {}",
            settings.width,
            settings.height,
            settings.output.name(),
            r.adapter_name()
        );
    }
    // Set up the GPU and draw one frame (shaders compile on first use) before attaching to the
    // bus: the launcher starts the source once every reader is attached, so no world sample
    // waits behind this.
    if let Some(r) = renderer.as_mut() {
        let empty = WorldHeader::default();
        let nothing = WorldView {
            header: &empty,
            blocks: &[],
        };
        r.render(nothing, &HandSample::default())?;
    }
    let world_in = bus.inlet::<topics::World>()?;
    let hand_in = bus.inlet::<topics::Hand>()?;
    let peer_in = bus.inlet::<topics::PeerHand>()?;
    let frame_out = bus.outlet::<topics::Frame>()?;
    let writer = match (&frames, &renderer) {
        (Some(f), Some(_)) => Some(FrameWriter::start(f.clone(), settings.output)?),
        _ => None,
    };
    let preview = match (preview, &renderer) {
        (Some(p), Some(_)) => Some(PreviewWriter::start(p, &session.scene)?),
        _ => None,
    };
    let period_ns = (1e9 / session.budget.frame_hz) as u64;
    let mut stage = RendererStage {
        renderer,
        window,
        writer,
        preview,
        frames_every: frames.as_ref().map(|f| u64::from(f.every_nth.max(1))),
        world_in,
        hand_in,
        peer_in,
        frame_out,
        period_ns,
        next_frame: monotonic_ns() + period_ns,
        newest: None,
        world: None,
        hands: Box::new([HandSample::default(); HAND_HISTORY]),
        hand_next: 0,
        left: None,
        others: Box::new([None; HAND_SLOTS]),
        others_drawn: Box::new([HandSample::default(); HAND_SLOTS]),
        superseded: 0,
        frame_no: 0,
    };
    // It waits for its frame deadlines, not by the session's wait strategy.
    node::run(Stage::Renderer, bus, WaitStrategy::Event, &mut stage)
}

/// The renderer stage: the GPU (none with `mode = "off"`), its ports, the newest world held
/// in place and the recent hands.
struct RendererStage {
    renderer: Option<Renderer>,
    window: Option<WindowHandle>,
    writer: Option<FrameWriter>,
    preview: Option<PreviewWriter>,
    /// Every how many frames a PNG is written (`--frames-dir`).
    frames_every: Option<u64>,
    world_in: Inlet<topics::World>,
    hand_in: Inlet<topics::Hand>,
    /// A shared world's participant: the other participants' hands its bridge took from the
    /// host (on a host they come on `hand`, every participant's).
    peer_in: Inlet<topics::PeerHand>,
    frame_out: Outlet<topics::Frame>,
    period_ns: u64,
    next_frame: u64,
    /// The newest world's stamp, while it is undrawn.
    newest: Option<Stamp>,
    /// The newest world sample, held in place (read from the stepper's memory, not copied).
    world: Option<Received<topics::World>>,
    /// The recent right hands (side 0: a one-hand session's only hand).
    hands: Box<[HandSample; HAND_HISTORY]>,
    hand_next: usize,
    /// A two-hand session's newest left hand (side 1); None until one came.
    left: Option<HandSample>,
    /// A shared world's other people's hands, the newest per slot (participant 1 and up).
    others: Box<[Option<HandSample>; HAND_SLOTS]>,
    /// Where a frame gathers them for drawing (no allocation per frame).
    others_drawn: Box<[HandSample; HAND_SLOTS]>,
    superseded: u64,
    frame_no: u64,
}

impl Task for RendererStage {
    type Error = RenderError;

    fn wait(&mut self, _: &mut Waiter, _: Duration) -> Result<(), RenderError> {
        let now = monotonic_ns();
        if now < self.next_frame {
            // A window needs its events handled; wake at least every 10 ms for them.
            let wait = self.next_frame - now;
            let wait = if self.window.is_some() {
                wait.min(10_000_000)
            } else {
                wait
            };
            self.world_in.wait(Duration::from_nanos(wait))?;
        }
        Ok(())
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), RenderError> {
        while let Some(s) = self.world_in.receive()? {
            let received = monotonic_ns();
            let stamp = s.user_header().stamp;
            pass.recorder.hop(&stamp, received);
            if self.newest.is_some() {
                self.superseded += 1;
            }
            self.newest = Some(stamp);
            // The one it replaces goes back to the stepper.
            self.world = Some(s);
        }
        while let Some(s) = self.hand_in.receive()? {
            pass.recorder.hop(&s.stamp, monotonic_ns());
            keep_hand(
                &mut self.hands,
                &mut self.hand_next,
                &mut self.left,
                &mut self.others,
                s.payload(),
            );
        }
        while let Some(s) = self.peer_in.receive()? {
            keep_peer(&mut self.others, &s.hand);
        }
        if let (Some(w), Some(r)) = (&mut self.window, &mut self.renderer) {
            if w.pump(r) == WindowStatus::Closed {
                eprintln!("renderer: the window was closed; stopping the session");
                shutdown::request();
            }
        }
        let now = monotonic_ns();
        if now < self.next_frame && !pass.stopping {
            return Ok(());
        }
        // Pace on absolute deadlines; after a long stall, start afresh instead of bursting.
        self.next_frame = if now > self.next_frame + self.period_ns {
            now + self.period_ns
        } else {
            self.next_frame + self.period_ns
        };
        let (Some(stamp), Some(world)) = (self.newest.take(), &self.world) else {
            return Ok(());
        };
        let started = monotonic_ns();
        let mut done = started;
        if let Some(r) = &mut self.renderer {
            let view = WorldView {
                header: world.user_header(),
                blocks: world.payload(),
            };
            let hand = matching_hand(&self.hands[..self.hand_next.min(HAND_HISTORY)], view.header);
            let left = self.left.as_ref();
            let mut drawn_others = 0;
            for h in self.others.iter().flatten() {
                self.others_drawn[drawn_others] = *h;
                drawn_others += 1;
            }
            let others = &self.others_drawn[..drawn_others];
            let times = r.render_people(view, hand, left, others)?;
            done = times.done_ns;
            if let (Some(w), Some(every)) = (&mut self.writer, self.frames_every) {
                if self.frame_no.is_multiple_of(every) {
                    w.offer(r, self.frame_no)?;
                }
            }
            if let Some(p) = &mut self.preview {
                p.after_frame(view, hand, left);
            }
            self.frame_no += 1;
        }
        let frame = FrameSample {
            stamp: Stamp::derived(0, &stamp),
            world_seq: stamp.seq,
            render_ns: done.saturating_sub(started),
            origin_to_photon_ns: done.saturating_sub(stamp.origin_ns),
            skipped_worlds: std::mem::take(&mut self.superseded),
        };
        pass.recorder
            .record(Metric::Photon, frame.origin_to_photon_ns);
        let sent = self.frame_out.publish(&frame)?;
        // The renderer's own work is the frame, not the wait for its deadline.
        pass.recorder
            .record(Metric::Process, sent.publish_ns.saturating_sub(started));
        pass.recorder.record(
            Metric::Origin,
            sent.publish_ns.saturating_sub(sent.origin_ns),
        );
        Ok(())
    }

    fn counters(&self) -> Counters {
        Counters::of([
            self.world_in.counter(),
            self.hand_in.counter(),
            self.peer_in.counter(),
            self.frame_out.counter(),
        ])
    }

    fn stop(&mut self, _: &mut Reporter) -> Result<(), RenderError> {
        if let Some(w) = self.writer.take() {
            w.finish();
        }
        Ok(())
    }

    /// The preview is drawn again with its own camera and encoded only now: on a loaded
    /// machine that takes seconds, which must not delay the final report past the launcher's
    /// wait for it (the launcher waits for the process to exit, `PREVIEW_EXIT_WAIT`).
    fn after_final_report(&mut self) {
        if let Some(p) = self.preview.take() {
            p.finish(self.renderer.as_mut());
        }
    }
}

/// Keeps `hand`: another person's of a shared world (participant 1 and up: on the host,
/// whose bridge publishes every participant's hands) as the newest of its slot in `others`;
/// this person's left hand (side 1) as the newest `left`, any other into the right hands'
/// ring (`hands`, `next` the count so far). Allocates nothing.
fn keep_hand(
    hands: &mut [HandSample; HAND_HISTORY],
    next: &mut usize,
    left: &mut Option<HandSample>,
    others: &mut [Option<HandSample>; HAND_SLOTS],
    hand: &HandSample,
) {
    if hand.participant != 0 {
        keep_peer(others, hand);
    } else if HandSide::from_code(hand.side) == HandSide::Left {
        *left = Some(*hand);
    } else {
        hands[*next % HAND_HISTORY] = *hand;
        *next += 1;
    }
}

/// Keeps another participant's hand (a shared world's participant, from its bridge's
/// `peer_hand`) as the newest of its slot in `others`: every participant's, whatever its number,
/// since this participant's own hands come on `hand`, not here. A slot out of range (no bridge
/// sends one) is not drawn.
fn keep_peer(others: &mut [Option<HandSample>; HAND_SLOTS], hand: &HandSample) {
    if let Some(slot) = hand.slot().and_then(|k| others.get_mut(k)) {
        *slot = Some(*hand);
    }
}

/// The hand sample the world answers (its `hand_seq`), else the newest one.
pub fn matching_hand<'a>(hands: &'a [HandSample], world: &WorldHeader) -> &'a HandSample {
    static EMPTY: std::sync::OnceLock<HandSample> = std::sync::OnceLock::new();
    hands
        .iter()
        .find(|h| h.stamp.seq == world.hand_seq)
        .or_else(|| hands.iter().max_by_key(|h| h.stamp.seq))
        .unwrap_or_else(|| EMPTY.get_or_init(HandSample::default))
}

/// Writes PNG frames on its own thread; frames travel in recycled images.
pub struct FrameWriter {
    to_writer: Option<SyncSender<(u64, Image)>>,
    free: Receiver<Image>,
    thread: Option<JoinHandle<()>>,
    /// Frames not written because the writer was still busy.
    pub dropped: u64,
}

impl FrameWriter {
    pub fn start(req: FramesRequest, mode: OutputMode) -> Result<FrameWriter, RenderError> {
        std::fs::create_dir_all(&req.dir)
            .map_err(|e| RenderError::Io(format!("--frames-dir {}: {e}", req.dir.display())))?;
        let (to_writer, from_loop) = sync_channel::<(u64, Image)>(WRITER_QUEUE);
        let (to_free, free) = sync_channel::<Image>(WRITER_QUEUE + 1);
        for _ in 0..WRITER_QUEUE + 1 {
            let _ = to_free.try_send(Image::default());
        }
        let dir: PathBuf = req.dir;
        let thread = std::thread::Builder::new()
            .name("png-writer".into())
            .spawn(move || {
                let mut scratch = Image::default();
                while let Ok((n, img)) = from_loop.recv() {
                    if let Err(e) = write_frame(&dir, n, mode, &img, &mut scratch) {
                        eprintln!("renderer: {e}");
                    }
                    let _ = to_free.try_send(img);
                }
            })
            .map_err(|e| RenderError::Io(format!("starting the PNG writer: {e}")))?;
        Ok(FrameWriter {
            to_writer: Some(to_writer),
            free,
            thread: Some(thread),
            dropped: 0,
        })
    }

    /// Reads frame `n` back and hands it to the writer, unless no buffer is free.
    pub fn offer(&mut self, r: &mut Renderer, n: u64) -> Result<(), RenderError> {
        let mut img = match self.free.try_recv() {
            Ok(img) => img,
            Err(TryRecvError::Empty) | Err(TryRecvError::Disconnected) => {
                self.dropped += 1;
                return Ok(());
            }
        };
        r.read_back_into(&mut img)?;
        if let Some(tx) = &self.to_writer {
            if tx.try_send((n, img)).is_err() {
                self.dropped += 1;
            }
        }
        Ok(())
    }

    /// Writes what is queued and stops the thread.
    pub fn finish(mut self) {
        self.to_writer = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if self.dropped > 0 {
            eprintln!(
                "renderer: {} frames not written (the PNG writer was busy)",
                self.dropped
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Left hands are kept apart, the newest one; the right hands' ring and the match by
    /// `hand_seq` see only right hands, as in a one-hand session.
    #[test]
    fn left_hands_are_kept_apart_from_the_right_ones() {
        let mut hands = Box::new([HandSample::default(); HAND_HISTORY]);
        let mut others = [None; HAND_SLOTS];
        let (mut next, mut left) = (0, None);
        for seq in 1..=6u64 {
            let mut h = HandSample::default();
            h.stamp.seq = seq;
            // Per frame, the right hand then the left (odd seq the right).
            h.side = if seq % 2 == 0 { 1 } else { 0 };
            keep_hand(&mut hands, &mut next, &mut left, &mut others, &h);
        }
        assert_eq!(next, 3);
        assert_eq!(left.map(|h| h.stamp.seq), Some(6));
        let kept = &hands[..next];
        assert!(kept.iter().all(|h| h.side == 0));
        let world = WorldHeader {
            hand_seq: 3,
            ..Default::default()
        };
        assert_eq!(matching_hand(kept, &world).stamp.seq, 3);
        // A world that answers no kept hand: the newest right hand, never the left.
        let world = WorldHeader {
            hand_seq: 6,
            ..Default::default()
        };
        assert_eq!(matching_hand(kept, &world).stamp.seq, 5);
        // A one-hand session has no left hand.
        let (mut next, mut left) = (0, None);
        keep_hand(
            &mut hands,
            &mut next,
            &mut left,
            &mut others,
            &HandSample::default(),
        );
        assert!(left.is_none());
        assert_eq!(next, 1);
    }

    /// On a shared world's host every participant's hands arrive on one topic: participant
    /// 0's go to the ring and `left` as before, each other one's to its own slot, newest kept,
    /// so that no two people's hands are ever drawn as one hand flickering between them.
    #[test]
    fn other_peoples_hands_are_kept_per_slot_apart_from_this_ones() {
        let mut hands = Box::new([HandSample::default(); HAND_HISTORY]);
        let mut others = [None; HAND_SLOTS];
        let (mut next, mut left) = (0, None);
        for seq in 1..=12u64 {
            let h = HandSample {
                participant: (seq % 3) as u32,
                side: ((seq / 3) % 2) as u32,
                stamp: common::Stamp {
                    seq,
                    ..Default::default()
                },
                ..HandSample::default()
            };
            keep_hand(&mut hands, &mut next, &mut left, &mut others, &h);
        }
        // Participant 0: seqs 3, 6, 9, 12 (sides 1, 0, 1, 0).
        assert_eq!(next, 2);
        assert!(hands[..next]
            .iter()
            .all(|h| h.participant == 0 && h.side == 0));
        assert_eq!(left.map(|h| h.stamp.seq), Some(9));
        let kept: Vec<(usize, u64)> = others
            .iter()
            .enumerate()
            .filter_map(|(k, h)| h.map(|h| (k, h.stamp.seq)))
            .collect();
        // Participant 1 (slots 2, 3) and 2 (slots 4, 5), the newest of each side.
        assert_eq!(kept, vec![(2, 7), (3, 10), (4, 8), (5, 11)]);
        // A participant past the slots is not kept.
        let stray = HandSample {
            participant: 99,
            ..HandSample::default()
        };
        keep_hand(&mut hands, &mut next, &mut left, &mut others, &stray);
        assert_eq!(others.iter().flatten().count(), 4);
    }

    /// On a participant, the others' hands come on `peer_hand` with the host's numbers, the
    /// host's first participant (0) among them: each kept in its own slot, apart from this
    /// participant's own hands (on `hand`, participant 0 on its own bus).
    #[test]
    fn a_participants_peers_are_kept_per_slot_even_participant_zero() {
        let mut hands = Box::new([HandSample::default(); HAND_HISTORY]);
        let mut others = [None; HAND_SLOTS];
        let (mut next, mut left) = (0, None);
        let own = HandSample::default();
        keep_hand(&mut hands, &mut next, &mut left, &mut others, &own);
        for (participant, side) in [(0, 0), (0, 1), (2, 0), (99, 0)] {
            let peer = HandSample {
                participant,
                side,
                ..HandSample::default()
            };
            keep_peer(&mut others, &peer);
        }
        assert_eq!(next, 1);
        let kept: Vec<usize> = (0..HAND_SLOTS).filter(|&k| others[k].is_some()).collect();
        assert_eq!(kept, vec![0, 1, 4]);
    }
}
