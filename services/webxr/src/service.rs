//! The webxr stage: a headset's page as the session's source. Its loop is
//! [`common::node::run`]'s; this is its [`Task`]: it takes what the pages send from the server
//! ([`crate::server`]), lets [`crate::driving`] decide which page drives and what each frame
//! publishes, publishes that as `joints`, and sends every world the stepper publishes back
//! to every page ([`webxr_wire::page::encode_world`]) with the seq of the driving page's frame
//! it answers; in a shared world, the other participants' hands too ([`crate::peers`]). The
//! page's timing comes back as statistics, recorded here as the webxr
//! stage's `sent->drawn` and `page js` latencies.

use std::time::Duration;

use common::bus::{wait_each, Bus, BusError, Inlet, Outlet, WaitStrategy, Waiter, Wakeable};
use common::config::session::Source;
use common::config::Session;
use common::latency::{Metric, Reporter};
use common::node::{self, Counters, Pass, Task};
use common::{monotonic_ns, shutdown, topics, DeviceCounters, HandsUsed, Stage, WorldView};

use crate::address;
use crate::certificate::{self, CertificateError};
use crate::console;
use crate::driving::{driver_silence_ns, Driving, Hands};
use crate::peers::Peers;
use crate::scene::{self, SceneError};
use crate::server::{Inbound, Server, ServerError, ServerSettings};

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
    #[error(transparent)]
    Scene(#[from] SceneError),
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
    let scene_json = scene::scene(session, settings)?.encode();
    let server = Server::start(ServerSettings {
        listen: settings.listen,
        tls: certificate.as_ref().map(|c| c.config.clone()),
        token: token.clone(),
        scene_json,
    })?;
    let url = address::url(settings.tls, host, server.local_addr.port(), &token);
    console::tell_the_user(
        &url,
        settings,
        server.local_addr,
        &token,
        certificate.as_ref(),
    );

    let mut headset = Headset {
        joints_out: bus.outlet()?,
        world_in: bus.inlet()?,
        peer_in: bus.inlet()?,
        peers: Peers::default(),
        peers_message: Vec::with_capacity(
            webxr_wire::page::PEERS_HEADER_BYTES
                + webxr_wire::page::MAX_PEER_HANDS
                    * (webxr_wire::page::PEER_HAND_HEAD_BYTES
                        + webxr_wire::page::WORLD_POINT_BYTES * webxr_wire::page::PEER_HAND_POINTS),
        ),
        hands: settings.hand,
        server,
        driving: Driving::new(
            settings.hand,
            settings.offset,
            driver_silence_ns(session.budget.source_silence_ms),
        ),
        step_s: 1.0 / session.scene.world.step_hz,
        world_message: Vec::with_capacity(
            webxr_wire::page::WORLD_HEADER_BYTES + 32 * session.scene.blocks.len() + 12 * 64,
        ),
        worlds_sent: 0,
        refusals_file: bus.session_folder().join("refused.headset.json"),
    };
    node::run(Stage::Webxr, bus, WaitStrategy::Event, &mut headset)?;
    Ok(())
}

struct Headset {
    joints_out: Outlet<topics::Joints>,
    world_in: Inlet<topics::World>,
    /// The other participants' hands, in a shared world (published by this machine's bridge).
    peer_in: Inlet<topics::PeerHand>,
    peers: Peers,
    peers_message: Vec<u8>,
    hands: HandsUsed,
    server: Server,
    driving: Driving,
    /// The world's step, seconds (a world's time is its step count times it).
    step_s: f64,
    world_message: Vec<u8>,
    worlds_sent: u64,
    /// `refused.headset.json` in the session folder: what was refused, by kind, for the
    /// session report (issue 40: its JSON gave only a total).
    refusals_file: std::path::PathBuf,
}

impl Headset {
    fn inbound(&mut self, message: Inbound, pass: &mut Pass<'_>) -> Result<(), BusError> {
        match message {
            Inbound::Clock {
                page,
                offset_ns,
                round_trip_ns,
                pongs,
            } => self.driving.clock(page, offset_ns, round_trip_ns, pongs),
            Inbound::Stats { page, stats } => {
                if self.driving.drives(page) {
                    pass.recorder
                        .record(Metric::Page, (stats.js_ms * 1e6).round() as u64);
                    if let Some(rt) = stats.round_trip_ms {
                        pass.recorder
                            .record(Metric::Photon, (rt * 1e6).round() as u64);
                    }
                }
            }
            Inbound::Closed { page } => self.driving.closed(page),
            Inbound::Hands {
                page,
                arrived_ns,
                frame,
            } => {
                let hands = self.driving.frame(page, arrived_ns, &frame);
                self.publish(&hands, pass)?;
            }
        }
        Ok(())
    }

    /// Publishes the hands [`Driving`] gave, the right (slot 0) first.
    fn publish(&mut self, hands: &Hands, pass: &mut Pass<'_>) -> Result<(), BusError> {
        for joints in hands.iter().flatten() {
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
        }
        Ok(())
    }

    fn worlds(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        while let Some(s) = self.world_in.receive()? {
            let header = s.user_header();
            pass.arrived(&header.stamp);
            let world = WorldView {
                header,
                blocks: s.payload(),
            };
            webxr_wire::page::encode_world(
                self.driving.answers(header.stamp.origin_ns),
                header.step as f64 * self.step_s,
                &world,
                &mut self.world_message,
            );
            self.server.send_world(&self.world_message);
            self.worlds_sent += 1;
        }
        Ok(())
    }

    /// Keeps the other participants' hands and sends the page them when they changed.
    fn peers(&mut self) -> Result<(), BusError> {
        let now = monotonic_ns();
        while let Some(s) = self.peer_in.receive()? {
            self.peers.take(&s.hand, now);
        }
        self.peers.forget_silent(now);
        if self.peers.encode(&mut self.peers_message) {
            self.server.send_peers(&self.peers_message);
        }
        Ok(())
    }
}

impl Task for Headset {
    type Error = BusError;

    fn wait(&mut self, _: &mut Waiter, timeout: Duration) -> Result<(), BusError> {
        let look_again = Duration::from_nanos(self.driving.look_again_in_ns(monotonic_ns()));
        let inlets: [&dyn Wakeable; 2] = [&self.world_in, &self.peer_in];
        wait_each(
            inlets.into_iter(),
            Some(self.server.wake_fd()),
            timeout.min(look_again),
        )
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        self.server.clear_wake();
        if !(pass.stopping || shutdown::requested()) {
            while let Ok(m) = self.server.inbound.try_recv() {
                self.inbound(m, pass)?;
            }
            let gap = self.driving.keep_time(monotonic_ns());
            self.publish(&gap, pass)?;
        }
        self.peers()?;
        self.worlds(pass)
    }

    fn counters(&self) -> Counters {
        Counters::of([
            self.joints_out.counter(),
            self.world_in.counter(),
            self.peer_in.counter(),
        ])
    }

    fn stop(&mut self, reporter: &mut Reporter) -> Result<(), BusError> {
        self.server.stop();
        let c = self.driving.counts();
        let tally = &self.server.tally;
        reporter.set_devices([
            DeviceCounters {
                device: common::samples::DeviceKind::Headset as u32,
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
        if let Err(e) = std::fs::write(&self.refusals_file, console::refusals_json(tally, c)) {
            eprintln!(
                "handblocks webxr: cannot write {}: {e}",
                self.refusals_file.display()
            );
        }
        if c.published == 0 {
            let pages = tally.sockets.load(std::sync::atomic::Ordering::Relaxed);
            eprintln!("{}", console::no_headset(pages));
        }
        eprintln!(
            "{}",
            console::summary(c, self.worlds_sent, tally, self.hands)
        );
        Ok(())
    }
}
