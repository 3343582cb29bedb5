//! The webxr stage: a headset's page as the session's source.
//!
//! **Which page drives.** The first page that sends a hands frame drives the hand until its
//! socket closes; frames of any other page meanwhile are counted and dropped (a second headset,
//! or the same one reloaded before the old socket timed out, cannot make the hand jump between
//! two people). Any number of pages may watch.
//!
//! **Time.** A frame's source time is its `predictedDisplayTime` mapped to this machine's
//! CLOCK_MONOTONIC by the page's clock offset ([`crate::server`]), which is held fixed from
//! a driving page's first frame on: the stepper's simulated time follows source time, and an
//! offset that moved under it would stretch or shrink the world's time. Frames whose seq or
//! source time does not increase are refused (`order`: replayed, reordered). Order is the
//! driver's own: a new driver's timeline is put after what was published (its held offset
//! shifted when its first frame would come before it), so no page is held to the times of
//! another, a page that sent a time far ahead included (the server refuses frames far ahead of
//! their page's clock, `clock`, and this keeps any that got through from outliving their page).
//!
//! **Hands.** `hand = "right"` or `"left"`: that hand of each frame is published as a one-hand
//! source's only hand (side 0). `hand = "both"`: each frame publishes the right hand, then the
//! left (side 1), with the same source time (docs/model.md "Two hands"); a hand not seen yet
//! is not sent.
//!
//! **Tracking.** A frame without a driving hand publishes that hand's last joints marked
//! untracked, in the frame's time; kinematics holds the grasp through such a gap up to
//! [`common::TRACKING_HOLD_NS`] (100 ms) and then lets go. A driving page whose socket
//! closes (or that sends nothing for [`driver_silence_ns`]) is a gap too: untracked samples go on,
//! every [`GAP_PERIOD_NS`] of this machine's time, in the driver's timeline continued from its
//! last frame, so that the world goes on and what the hand held falls, until a page drives
//! again. While a page drives, only its frames make samples: the world is a function of what
//! it sent, however slowly it came.
//!
//! **Back to the page.** Every world goes to every page ([`webxr_wire::page::encode_world`]),
//! with the seq of the driving page's frame it answers (looked up by the world's origin, which
//! is that frame's arrival), so the page measures its round trip. The page's timing comes back
//! as statistics, recorded here as the webxr stage's `sent->drawn` and `page js` latencies.

use std::time::Duration;

use common::bus::{wait_each, Bus, BusError, Inlet, Outlet, WaitStrategy, Waiter, Wakeable};
use common::config::session::{Source, WebxrSource};
use common::config::Session;
use common::latency::{Metric, Reporter};
use common::node::{self, Counters, Pass, Task};
use common::{
    monotonic_ns, shutdown, topics, DeviceCounters, HandSide, HandsUsed, JointsSample, Stage,
    Stamp, WorldView, TRACKING_HOLD_NS,
};
use webxr_wire::page::NO_FRAME;
use webxr_wire::{Handedness, HandsFrame};

use crate::address;
use crate::certificate::{self, CertificateError};
use crate::server::{Inbound, Server, ServerError, ServerSettings};

/// A driving page that sends no frame for this long (this machine's time) is taken as gone:
/// it left its XR session, or its browser hid it. A page in XR sends a frame every display
/// frame, a hand or not, so only a page that stopped drawing is this silent; a slow one (a
/// loaded machine's emulated headset stalls for a few hundred milliseconds) is not. Less where
/// the session's budget allows less silence ([`driver_silence_ns`]).
pub const SILENCE_NS: u64 = 2_000_000_000;
/// What the gap samples that follow a silent driver leave of the session's
/// `source_silence_ms`: time for the stage to wake and publish on a loaded machine.
pub const SILENCE_MARGIN_NS: u64 = 250_000_000;

/// How long a driving page may send nothing before it is taken as gone and untracked samples
/// go on: [`SILENCE_NS`], or less where the session's `[budget] source_silence_ms` is shorter
/// (that budget less [`SILENCE_MARGIN_NS`], or half of it, whichever is longer), so that a user
/// who leaves XR for a while is a pause within the budget, not a violated one.
pub fn driver_silence_ns(source_silence_ms: f64) -> u64 {
    let budget_ns = (source_silence_ms * 1e6).max(0.0) as u64;
    (budget_ns.saturating_sub(SILENCE_MARGIN_NS))
        .max(budget_ns / 2)
        .min(SILENCE_NS)
}
/// While no page drives after one did: an untracked sample this often (60 Hz).
pub const GAP_PERIOD_NS: u64 = 16_666_667;
/// Frames remembered to answer a world with the frame it answers.
const ORIGINS: usize = 256;
/// Pages whose clock offsets are kept (more than the server admits at once).
const CLOCKS: usize = 16;

/// Why the webxr process stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum WebxrError {
    #[error("{0}")]
    Bus(#[from] BusError),
    #[error("{0}")]
    NotThisSource(String),
    #[error("{0}")]
    Certificate(#[from] CertificateError),
    #[error("{0}")]
    Server(#[from] ServerError),
    #[error("cannot make the session's token: {0}")]
    Token(#[source] std::io::Error),
    #[error("{0}")]
    Scene(String),
}

/// Runs until asked to stop.
pub fn run(session: &Session, bus: &Bus) -> Result<(), WebxrError> {
    let Source::Webxr(settings) = &session.source else {
        return Err(WebxrError::NotThisSource(format!(
            "{}: source kind \"{}\" is not run by the webxr process",
            session.file.display(),
            session.source.kind()
        )));
    };
    let token = match &settings.token {
        Some(t) => t.clone(),
        None => address::random_token().map_err(WebxrError::Token)?,
    };
    let host = address::public_host(settings.listen);
    let certificate = if settings.tls {
        let dir = settings
            .certificate_dir
            .clone()
            .unwrap_or_else(certificate::default_dir);
        let mut hosts = vec!["localhost".to_string(), "127.0.0.1".to_string()];
        if !host.is_loopback() {
            hosts.push(host.to_string());
        }
        Some(certificate::load_or_make(&dir, &hosts)?)
    } else {
        None
    };
    if let Some(c) = &certificate {
        if let Some(why) = &c.renewed {
            eprintln!(
                "handblocks webxr: the certificate in {} was made anew: {why}. The headset's \
                 browser will ask to trust the new one once.",
                c.file.display()
            );
        }
    }
    let scene_json = scene_message(session, settings)?;
    let server = Server::start(ServerSettings {
        listen: settings.listen,
        tls: certificate.as_ref().map(|c| c.config.clone()),
        token: token.clone(),
        scene_json,
    })?;
    let url = address::url(settings.tls, host, server.local_addr.port(), &token);
    tell_the_user(
        &url,
        settings,
        server.local_addr,
        &token,
        certificate.as_ref(),
    );

    let mut headset = Headset {
        joints_out: bus.outlet()?,
        world_in: bus.inlet()?,
        settings: settings.clone(),
        server,
        driver: None,
        clocks: [(0, 0, 0); CLOCKS],
        held_offset_ns: None,
        last_seq: None,
        last_source_ns: 0,
        last_frame_arrival_ns: 0,
        last_frame_source_ns: 0,
        last_gap_ns: 0,
        silence_ns: driver_silence_ns(session.budget.source_silence_ms),
        joints: [None; 2],
        origins: [(0, NO_FRAME, 0); ORIGINS],
        origin_next: 0,
        step_s: 1.0 / session.scene.world.step_hz,
        world_message: Vec::with_capacity(
            webxr_wire::page::WORLD_HEADER_BYTES + 32 * session.scene.blocks.len() + 12 * 64,
        ),
        counts: Counts::default(),
        refusals_file: bus.session_folder().join("refused.headset.json"),
    };
    node::run(Stage::Webxr, bus, WaitStrategy::Event, &mut headset)?;
    Ok(())
}

/// The URL, its QR code, the certificate's fingerprint, the other route, where the server
/// listens, and a warning when the token would cross a network in clear.
fn tell_the_user(
    url: &str,
    settings: &WebxrSource,
    local: std::net::SocketAddr,
    token: &str,
    certificate: Option<&certificate::Certificate>,
) {
    let port = local.port();
    let mut s = String::new();
    s.push_str(&listening(
        local,
        settings.tls,
        &address::interface_addresses(),
    ));
    s.push_str(&format!(
        "handblocks webxr: open this in the headset's browser:\n\n    {url}\n\n"
    ));
    if let Some(qr) = address::qr(url) {
        s.push_str(&qr);
        s.push('\n');
    }
    if let Some(c) = certificate {
        s.push_str(&format!(
            "  The certificate ({}{}) is this machine's own: the browser warns once; accept it\n  \
             (Advanced -> Proceed) after checking its SHA-256 fingerprint:\n  {}\n",
            c.file.display(),
            if c.made { ", made now" } else { "" },
            c.fingerprint
        ));
    }
    s.push_str(&format!(
        "  Or, a Quest on USB: `adb reverse tcp:{port} tcp:{port}` and open \
         {}://localhost:{port}/?token={token}\n",
        if settings.tls { "https" } else { "http" }
    ));
    eprintln!("{s}");
}

/// Where the server listens (every interface's address when it listens on all), and, when it
/// serves plain HTTP beyond this machine, a warning: the token in the URL and every hand
/// frame cross the network in clear, so anyone on it can read the token and drive the hand.
pub fn listening(
    local: std::net::SocketAddr,
    tls: bool,
    interfaces: &[std::net::IpAddr],
) -> String {
    let scheme = if tls { "HTTPS" } else { "plain HTTP" };
    let ip = local.ip();
    let mut s = if ip.is_loopback() {
        format!(
            "handblocks webxr: listening on {local} ({scheme}): this machine only; a headset \
             reaches it through `adb reverse`\n"
        )
    } else if ip.is_unspecified() {
        let list: Vec<String> = interfaces
            .iter()
            .filter(|a| a.is_ipv4() == ip.is_ipv4() || ip.is_ipv6())
            .map(|a| a.to_string())
            .collect();
        format!(
            "handblocks webxr: listening on {local} ({scheme}): every interface ({})\n",
            if list.is_empty() {
                "none found".to_string()
            } else {
                list.join(", ")
            }
        )
    } else {
        format!("handblocks webxr: listening on {local} ({scheme}): that interface only\n")
    };
    if !tls && !ip.is_loopback() {
        s.push_str(
            "handblocks webxr: WARNING: tls = false on a network interface: the token and the \
             hands cross the network in clear, and anyone on it can read the token and drive \
             the hand. Set tls = true, or leave listen out (tls = false then listens on \
             127.0.0.1) and use `adb reverse`.\n",
        );
    }
    s
}

/// The scene as the page draws it: each block's hull (its own frame, about its centre of
/// gravity, as the world's poses place it), its name and colour; the floor; the driving hand.
fn scene_message(session: &Session, settings: &WebxrSource) -> Result<String, WebxrError> {
    let colours = common::config::colors::block_colors(&session.scene);
    let mut blocks = Vec::with_capacity(session.scene.blocks.len());
    for (b, colour) in session.scene.blocks.iter().zip(colours) {
        let solid = shapes::Solid::from_spec(&b.shape).map_err(|problem| {
            WebxrError::Scene(format!(
                "{}: block {:?}: {problem}",
                session.scene_file.display(),
                b.name
            ))
        })?;
        let vertices: Vec<f64> = solid.vertices.iter().flat_map(|v| v.to_array()).collect();
        let indices: Vec<u32> = solid.triangles.iter().flatten().copied().collect();
        blocks.push(serde_json::json!({
            "name": b.name,
            "color": colour,
            "vertices": vertices,
            "indices": indices,
        }));
    }
    Ok(serde_json::json!({
        "op": "scene",
        "session": session.file.display().to_string(),
        "hand": settings.hand.name(),
        "floor_y": 0.0,
        "step_hz": session.scene.world.step_hz,
        "offset": settings.offset,
        "blocks": blocks,
    })
    .to_string())
}

/// The offset a new driver's frames are mapped by: its clock's `offset_ns`, shifted later where
/// its first frame (`frame_ns`, its clock) would not come after `last_source_ns`, the last
/// source time published, so a new driver is never held to an earlier one's times.
fn follow_on_offset(frame_ns: i128, offset_ns: i64, last_source_ns: u64) -> i64 {
    let behind = i128::from(last_source_ns) + 1 - (frame_ns + i128::from(offset_ns));
    offset_ns.saturating_add(behind.clamp(0, i128::from(i64::MAX)) as i64)
}

/// The hands a session's frames publish: (slot, the page's hand), slot being the `joints`
/// sample's side ([`HandSide::code`]): one hand as side 0, or the right (0) then the left (1).
fn slots(hands: HandsUsed) -> &'static [(usize, Handedness)] {
    match hands {
        HandsUsed::One(HandSide::Right) => &[(0, Handedness::Right)],
        HandsUsed::One(HandSide::Left) => &[(0, Handedness::Left)],
        HandsUsed::Both => &[(0, Handedness::Right), (1, Handedness::Left)],
    }
}

/// What the stage counted, for its report.
#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    /// Frames published as joints (tracked or not; with both hands, one frame is two samples).
    published: u64,
    /// Per slot ([`slots`]): hands published untracked (frames without that hand, and samples
    /// sent while no page drove).
    untracked: [u64; 2],
    /// Frames of a page that was not driving.
    other_page: u64,
    /// Frames before the page's clock was known.
    before_clock: u64,
    /// Frames whose seq or time did not increase.
    order: u64,
    /// Frames the driving page numbered that never came (lost on the way, or refused).
    seq_gaps: u64,
    /// Driving sockets lost (closed or silent).
    drops: u64,
    /// Pages that took over driving after the first.
    takeovers: u64,
    /// Drivers whose timeline was moved on to follow what was published.
    shifted: u64,
    /// Gaps of a hand (frames without it, or no page) longer than the hold time, both hands'.
    long_gaps: u64,
    /// Per slot: start of the hand's current gap (source time), when in one.
    gap_from_ns: [Option<u64>; 2],
    gap_counted: [bool; 2],
    worlds_sent: u64,
    offset_ns: i64,
    offset_round_trip_ns: u64,
    offset_pongs: u32,
}

struct Headset {
    joints_out: Outlet<topics::Joints>,
    world_in: Inlet<topics::World>,
    settings: WebxrSource,
    server: Server,
    /// The page driving the hand.
    driver: Option<u64>,
    /// Each page's clock: (page, offset ns, round trip ns).
    clocks: [(u64, i64, u64); CLOCKS],
    /// The offset in force since the first driving frame.
    held_offset_ns: Option<i64>,
    last_seq: Option<u32>,
    last_source_ns: u64,
    last_frame_arrival_ns: u64,
    /// The source time of the driving page's last frame.
    last_frame_source_ns: u64,
    /// When the last untracked sample was sent while no page drove (this machine's time).
    last_gap_ns: u64,
    /// How long a driver may be silent ([`driver_silence_ns`] of the session's budget).
    silence_ns: u64,
    /// Per slot ([`slots`]), the last joints published (what a gap repeats, untracked).
    joints: [Option<JointsSample>; 2],
    /// (origin ns, page seq) of the frames published, to answer worlds with their frame,
    /// and how many hand samples the frame was.
    origins: [(u64, u32, u8); ORIGINS],
    origin_next: usize,
    /// The world's step, seconds (a world's time is its step count times it).
    step_s: f64,
    world_message: Vec<u8>,
    counts: Counts,
    /// `refused.headset.json` in the session folder: what was refused, by kind, for the
    /// session report (issue 40: its JSON gave only a total).
    refusals_file: std::path::PathBuf,
}

impl Headset {
    fn clock_of(&self, page: u64) -> Option<(i64, u64)> {
        self.clocks
            .iter()
            .find(|c| c.0 == page)
            .map(|&(_, offset, rt)| (offset, rt))
    }

    fn inbound(&mut self, message: Inbound, pass: &mut Pass<'_>) -> Result<(), BusError> {
        match message {
            Inbound::Clock {
                page,
                offset_ns,
                round_trip_ns,
                pongs,
            } => {
                let slot = match self.clocks.iter().position(|c| c.0 == page) {
                    Some(i) => i,
                    // The oldest page's slot (pages are numbered in connection order).
                    None => (0..CLOCKS).min_by_key(|&i| self.clocks[i].0).unwrap_or(0),
                };
                self.clocks[slot] = (page, offset_ns, round_trip_ns);
                if self.driver == Some(page) || self.driver.is_none() {
                    self.counts.offset_pongs = pongs;
                }
            }
            Inbound::Stats { page, stats } => {
                if self.driver == Some(page) {
                    pass.recorder
                        .record(Metric::Page, (stats.js_ms * 1e6).round() as u64);
                    if let Some(rt) = stats.round_trip_ms {
                        pass.recorder
                            .record(Metric::Photon, (rt * 1e6).round() as u64);
                    }
                }
            }
            Inbound::Closed { page } => {
                if self.driver == Some(page) {
                    self.driver = None;
                    self.counts.drops += 1;
                }
            }
            Inbound::Hands {
                page,
                arrived_ns,
                frame,
            } => self.frame(page, arrived_ns, &frame, pass)?,
        }
        Ok(())
    }

    fn frame(
        &mut self,
        page: u64,
        arrived_ns: u64,
        frame: &HandsFrame,
        pass: &mut Pass<'_>,
    ) -> Result<(), BusError> {
        match self.driver {
            Some(d) if d != page => {
                self.counts.other_page += 1;
                return Ok(());
            }
            _ => {}
        }
        let Some((offset_ns, round_trip_ns)) = self.clock_of(page) else {
            self.counts.before_clock += 1;
            return Ok(());
        };
        let frame_ns = (frame.frame_time_ms * 1e6).round() as i128;
        if self.driver.is_none() {
            // A new driver: its seqs start over; its clock is its own, held from now on, and
            // its timeline follows what was published (whatever times an earlier driver sent).
            if self.published_any() {
                self.counts.takeovers += 1;
            }
            self.driver = Some(page);
            self.last_seq = None;
            if self.held_offset_ns.is_none() {
                self.counts.offset_ns = offset_ns;
                self.counts.offset_round_trip_ns = round_trip_ns;
            }
            let held = follow_on_offset(frame_ns, offset_ns, self.last_source_ns);
            if held != offset_ns {
                self.counts.shifted += 1;
            }
            self.held_offset_ns = Some(held);
        }
        let offset_ns = self.held_offset_ns.unwrap_or(offset_ns);
        let source_ns = frame_ns + i128::from(offset_ns);
        let in_order = self.last_seq.is_none_or(|s| frame.seq > s)
            && source_ns > i128::from(self.last_source_ns)
            && source_ns <= i128::from(u64::MAX);
        if !in_order {
            self.counts.order += 1;
            return Ok(());
        }
        if let Some(last) = self.last_seq {
            self.counts.seq_gaps += u64::from(frame.seq - last - 1);
        }
        self.last_seq = Some(frame.seq);
        self.last_frame_arrival_ns = arrived_ns;
        self.last_frame_source_ns = source_ns as u64;
        let stamp = Stamp {
            seq: 0,
            source_time_ns: source_ns as u64,
            origin_ns: arrived_ns,
            publish_ns: 0,
        };
        let mut out = [None; 2];
        for &(slot, which) in slots(self.settings.hand) {
            out[slot] = match (frame.hand(which), self.joints[slot]) {
                (Some(hand), _) => {
                    let mut j = JointsSample::default();
                    webxr_wire::to_joints(hand, &mut j);
                    let moved = |p: &mut [f64; 3]| {
                        for (v, o) in p.iter_mut().zip(self.settings.offset) {
                            *v += o;
                        }
                    };
                    moved(&mut j.wrist.position);
                    for p in j.joints.iter_mut() {
                        moved(&mut p.position);
                    }
                    Some(j)
                }
                (None, Some(last)) => {
                    let mut j = last;
                    j.tracked = 0;
                    Some(j)
                }
                // Not seen yet: nothing to hold.
                (None, None) => None,
            }
            .map(|mut j| {
                j.side = slot as u32;
                j.stamp = stamp;
                j
            });
        }
        self.publish(&out, frame.seq, pass)
    }

    /// Whether any hand was published yet.
    fn published_any(&self) -> bool {
        self.joints.iter().any(Option::is_some)
    }

    /// Publishes one frame's hands, the right (slot 0) first, each with its source time and
    /// origin set, remembering which page frame they were; nothing when `hands` holds none.
    fn publish(
        &mut self,
        hands: &[Option<JointsSample>; 2],
        frame_seq: u32,
        pass: &mut Pass<'_>,
    ) -> Result<(), BusError> {
        let mut origin = None;
        let mut samples = 0u8;
        for (slot, joints) in hands.iter().enumerate() {
            let Some(joints) = joints else { continue };
            let t = joints.stamp.source_time_ns;
            if joints.tracked == 0 {
                self.counts.untracked[slot] += 1;
                let from = *self.counts.gap_from_ns[slot].get_or_insert(t);
                if !self.counts.gap_counted[slot] && t - from > TRACKING_HOLD_NS {
                    self.counts.gap_counted[slot] = true;
                    self.counts.long_gaps += 1;
                }
            } else {
                self.counts.gap_from_ns[slot] = None;
                self.counts.gap_counted[slot] = false;
            }
            let sent = self.joints_out.publish(joints)?;
            // A headset session waits for its user: silence counts from the first sample on
            // (told before the first output is recorded, which ends the waiting).
            pass.recorder.delivered_after_waiting(sent.publish_ns);
            pass.recorder.record(
                Metric::Process,
                sent.publish_ns.saturating_sub(sent.origin_ns),
            );
            pass.recorder.record(
                Metric::Origin,
                sent.publish_ns.saturating_sub(sent.origin_ns),
            );
            origin = Some(sent.origin_ns);
            samples += 1;
            self.last_source_ns = t;
            self.joints[slot] = Some(*joints);
        }
        let Some(origin) = origin else {
            return Ok(());
        };
        self.origins[self.origin_next] = (origin, frame_seq, samples);
        self.origin_next = (self.origin_next + 1) % ORIGINS;
        self.counts.published += 1;
        Ok(())
    }

    /// No page drives (after one did): the hand, untracked, every [`GAP_PERIOD_NS`].
    fn keep_time(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        let now = monotonic_ns();
        if self.driver.is_some() {
            if now.saturating_sub(self.last_frame_arrival_ns) > self.silence_ns {
                // Silent: a page in the background, a socket that died without a close. Should
                // it come back, it drives again as a new driver (its seqs start over).
                self.driver = None;
                self.counts.drops += 1;
            } else {
                return Ok(());
            }
        }
        if !self.published_any() || now.saturating_sub(self.last_gap_ns) < GAP_PERIOD_NS {
            return Ok(());
        }
        self.last_gap_ns = now;
        // The driver's timeline goes on at this machine's pace from its last frame (a page
        // that drives again maps its frames by the same offset, so they follow on).
        let since_last = now.saturating_sub(self.last_frame_arrival_ns);
        let stamp = Stamp {
            seq: 0,
            source_time_ns: (self.last_frame_source_ns + since_last).max(self.last_source_ns + 1),
            origin_ns: now,
            publish_ns: 0,
        };
        // Every hand seen so far, untracked, at one time.
        let hands = self.joints.map(|last| {
            last.map(|mut j| {
                j.tracked = 0;
                j.stamp = stamp;
                j
            })
        });
        self.publish(&hands, NO_FRAME, pass)
    }

    fn worlds(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        while let Some(s) = self.world_in.receive()? {
            let header = s.user_header();
            pass.arrived(&header.stamp);
            let origin = header.stamp.origin_ns;
            // The frame it answers is almost always among the newest published: look back
            // from the newest.
            // (A frame of two hands is answered by one world: the stepper publishes once the
            // frame is whole.)
            let frame_seq = (1..=ORIGINS)
                .map(|back| self.origins[(self.origin_next + ORIGINS - back) % ORIGINS])
                .find(|&(o, _, _)| o == origin && origin != 0)
                .map_or(NO_FRAME, |(_, seq, _)| seq);
            let world = WorldView {
                header,
                blocks: s.payload(),
            };
            webxr_wire::page::encode_world(
                frame_seq,
                header.step as f64 * self.step_s,
                &world,
                &mut self.world_message,
            );
            self.server.send_world(&self.world_message);
            self.counts.worlds_sent += 1;
        }
        Ok(())
    }
}

impl Task for Headset {
    type Error = BusError;

    fn wait(&mut self, _: &mut Waiter, timeout: Duration) -> Result<(), BusError> {
        // While no page drives after one did, wake at the gap's period to keep time; while one
        // drives, when its silence would end (so the gap begins on time, not a period late).
        let timeout = if self.driver.is_some() {
            let due = self.last_frame_arrival_ns.saturating_add(self.silence_ns);
            let left = due.saturating_sub(monotonic_ns()).saturating_add(1_000_000);
            timeout.min(Duration::from_nanos(left))
        } else if self.published_any() {
            timeout.min(Duration::from_nanos(GAP_PERIOD_NS))
        } else {
            timeout.min(Duration::from_nanos(SILENCE_NS))
        };
        let inlets: [&dyn Wakeable; 1] = [&self.world_in];
        wait_each(inlets.into_iter(), Some(self.server.wake_fd()), timeout)
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        self.server.clear_wake();
        if !(pass.stopping || shutdown::requested()) {
            while let Ok(m) = self.server.inbound.try_recv() {
                self.inbound(m, pass)?;
            }
            self.keep_time(pass)?;
        }
        self.worlds(pass)
    }

    fn counters(&self) -> Counters {
        Counters::of([self.joints_out.counter(), self.world_in.counter()])
    }

    fn stop(&mut self, reporter: &mut Reporter) -> Result<(), BusError> {
        self.server.stop();
        let c = self.counts;
        let tally = &self.server.tally;
        let refused: Vec<String> = tally.refusals().map(|(k, n)| format!("{k} {n}")).collect();
        reporter.set_devices([
            DeviceCounters {
                device: 3,
                samples: c.published,
                rejected_records: tally.refused_total() + c.order + c.before_clock,
                other_station_records: c.other_page,
                link_losses: c.drops,
                reconnects: c.takeovers,
                device_errors: c.long_gaps,
                ..DeviceCounters::default()
            },
            DeviceCounters::default(),
        ]);
        // By kind, for the session report: the server's refusals and this stage's own (frames
        // out of order, or before the page's clock), adding up to `rejected_records`.
        let mut by_kind: serde_json::Map<String, serde_json::Value> = tally
            .refusals()
            .map(|(k, n)| (k.to_string(), n.into()))
            .collect();
        for (kind, n) in [("order", c.order), ("before_clock", c.before_clock)] {
            if n > 0 {
                by_kind.insert(kind.into(), n.into());
            }
        }
        if let Err(e) = std::fs::write(
            &self.refusals_file,
            serde_json::Value::Object(by_kind).to_string(),
        ) {
            eprintln!(
                "handblocks webxr: cannot write {}: {e}",
                self.refusals_file.display()
            );
        }
        let pages = tally.sockets.load(std::sync::atomic::Ordering::Relaxed);
        if c.published == 0 {
            // Said plainly, before the budget's verdict (source_silence_ms: the source
            // delivered no sample), which is what a session without a hand gets: exit 1.
            eprintln!(
                "handblocks webxr: no headset joined this session: no page sent a hand ({pages} \
                 pages opened the URL). The session fails its budget (source_silence_ms) and \
                 exits with status 1, as any session whose source delivered nothing does."
            );
        }
        eprintln!(
            "handblocks webxr: {} pages connected; {} frames published ({}), {} worlds \
             sent; refused: {}{}{}; frames missing from the driver's seqs {}; frames of a page \
             not driving {}; driving sockets lost {}; pages dropped for not answering pings {}; \
             drivers whose time was moved on to follow the published {}; \
             tracking gaps over 100 ms (the hand let go) {}; clock offset {:.3} ms from the best \
             of {} pings (round trip {:.3} ms), held for the session",
            pages,
            c.published,
            match self.settings.hand {
                HandsUsed::Both => format!(
                    "untracked: the right hand {}, the left {}",
                    c.untracked[0], c.untracked[1]
                ),
                HandsUsed::One(_) => format!("{} untracked", c.untracked[0]),
            },
            c.worlds_sent,
            if refused.is_empty() {
                "none".to_string()
            } else {
                refused.join(", ")
            },
            if c.order > 0 {
                format!(", order {}", c.order)
            } else {
                String::new()
            },
            if c.before_clock > 0 {
                format!(", before the clock {}", c.before_clock)
            } else {
                String::new()
            },
            c.seq_gaps,
            c.other_page,
            c.drops,
            tally.unanswered.load(std::sync::atomic::Ordering::Relaxed),
            c.shifted,
            c.long_gaps,
            c.offset_ns as f64 / 1e6,
            c.offset_pongs,
            c.offset_round_trip_ns as f64 / 1e6,
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn a_new_driver_follows_what_was_published_whatever_time_came_before() {
        // Nothing published yet: the page's own offset.
        assert_eq!(follow_on_offset(1_000, 5_000, 0), 5_000);
        // Its first frame after what was published: its own offset.
        assert_eq!(follow_on_offset(1_000, 5_000, 5_999), 5_000);
        // An earlier driver's time ran 1e9 ms ahead: the new driver's first frame comes just
        // after it, not refused as out of order until our clock catches up with it.
        let poisoned = 1_000_000_000_000_000_u64;
        let held = follow_on_offset(1_000, 5_000, poisoned);
        assert_eq!(1_000 + i128::from(held), i128::from(poisoned) + 1);
    }

    #[test]
    fn one_hand_is_published_as_side_0_and_both_as_the_right_then_the_left() {
        assert_eq!(
            slots(HandsUsed::One(HandSide::Left)),
            &[(0, Handedness::Left)]
        );
        assert_eq!(
            slots(HandsUsed::One(HandSide::Right)),
            &[(0, Handedness::Right)]
        );
        assert_eq!(
            slots(HandsUsed::Both),
            &[(0, Handedness::Right), (1, Handedness::Left)]
        );
        assert_eq!(HandSide::Left.code(), 1);
    }

    #[test]
    fn gap_samples_begin_within_the_sessions_silence_budget() {
        // The default budget (1 s): the gap begins 250 ms before it ends.
        assert_eq!(driver_silence_ns(1000.0), 750_000_000);
        assert!(driver_silence_ns(1000.0) + GAP_PERIOD_NS < 1_000_000_000);
        // webxr.toml's (2.5 s) and larger: at most SILENCE_NS.
        assert_eq!(driver_silence_ns(2500.0), SILENCE_NS);
        assert_eq!(driver_silence_ns(600_000.0), SILENCE_NS);
        // A short one: half of it.
        assert_eq!(driver_silence_ns(100.0), 50_000_000);
        let session = Session::load(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/sessions/webxr.toml"),
        )
        .unwrap();
        let silence_ns = driver_silence_ns(session.budget.source_silence_ms);
        assert!(
            (silence_ns + SILENCE_MARGIN_NS) as f64 <= session.budget.source_silence_ms * 1e6,
            "webxr.toml's gap begins after {silence_ns} ns of its {} ms budget",
            session.budget.source_silence_ms
        );
    }

    #[test]
    fn the_terminal_says_where_the_server_listens_and_warns_of_plain_http_on_a_network() {
        let lan = [
            std::net::IpAddr::from([192, 168, 1, 5]),
            std::net::IpAddr::from([127, 0, 0, 1]),
        ];
        let local = listening("127.0.0.1:8443".parse().unwrap(), false, &lan);
        assert!(
            local.contains("127.0.0.1:8443") && local.contains("this machine only"),
            "{local}"
        );
        assert!(!local.contains("WARNING"), "{local}");
        let all = listening("0.0.0.0:8443".parse().unwrap(), true, &lan);
        assert!(
            all.contains("every interface (192.168.1.5, 127.0.0.1)"),
            "{all}"
        );
        assert!(!all.contains("WARNING"), "{all}");
        let clear = listening("0.0.0.0:8443".parse().unwrap(), false, &lan);
        assert!(
            clear.contains("WARNING") && clear.contains("in clear"),
            "{clear}"
        );
    }
}
