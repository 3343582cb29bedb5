//! Measures origin -> photon through the renderer's real process loop
//! (`renderer::service::run_with`) over a real bus: a feeder publishes world samples at a
//! source rate with `origin_ns` = their publish time (as if upstream took no time), the
//! renderer draws at the session's frame rate, and each frame's `origin_to_photon_ns` (the
//! value its latency histogram records) is collected from the `frame` topic.
//!
//! So the numbers are what the renderer adds: waiting for its frame deadline with the newest
//! world, drawing both eyes, and the GPU finishing. A live session adds the stages upstream.
//!
//! `cargo run -p renderer --release --example photon -- [SECONDS] [WIDTH HEIGHT] [FRAME_HZ] [SOURCE_HZ]`
//! (defaults: 10 s, 640 x 480 per eye, 90 Hz, 120 Hz)

use std::path::PathBuf;
use std::time::{Duration, Instant};

use common::bus::{Bus, BusConfig};
use common::config::hand::HandModelSpec;
use common::config::scene::{BlockSpec, Effects, Scene, ShapeSpec, WorldSettings};
use common::config::session::{
    Budget, RecorderSettings, RenderMode, RendererSettings, Session, Source,
};
use common::{shutdown, topics, BlockMode, HandSample, Stamp, WorldSample};
use renderer::RenderSettings;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<f64> = std::env::args()
        .skip(1)
        .map(|s| s.parse::<f64>())
        .collect::<Result<_, _>>()?;
    let seconds = a.first().copied().unwrap_or(10.0);
    let (w, h) = (
        a.get(1).copied().unwrap_or(640.0) as u32,
        a.get(2).copied().unwrap_or(480.0) as u32,
    );
    let frame_hz = a.get(3).copied().unwrap_or(90.0);
    let source_hz = a.get(4).copied().unwrap_or(120.0);

    let blocks = 8;
    let scene = Scene {
        file: PathBuf::from("photon"),
        world: WorldSettings::default(),
        effects: Effects::default(),
        blocks: (0..blocks)
            .map(|i| BlockSpec {
                name: format!("b{i}"),
                shape: if i % 2 == 0 {
                    ShapeSpec::Box { size: [0.06; 3] }
                } else {
                    ShapeSpec::Wedge {
                        size: [0.08, 0.05, 0.06],
                    }
                },
                position: [0.0; 3],
                rotation: [0.0, 0.0, 0.0, 1.0],
                velocity: [0.0; 3],
            })
            .collect(),
        hand: None,
        left_hand: None,
    };
    let session = Session {
        file: PathBuf::from("photon.toml"),
        scene_file: PathBuf::from("photon"),
        scene,
        source: Source::Scripted { rate_hz: source_hz },
        renderer: RendererSettings {
            mode: RenderMode::Headless,
            width: w,
            height: h,
            ..RendererSettings::default()
        },
        recorder: RecorderSettings::off(),
        budget: Budget {
            frame_hz,
            ..Budget::default()
        },
        hand_model: HandModelSpec::default(),
        wait: common::bus::WaitStrategy::Event,
        wake: common::config::session::WakeUp::Doorbell,
        supervise: Default::default(),
        bridge: Default::default(),
    };
    let config = BusConfig::for_session(&BusConfig::fresh_id())?;
    let bus = Bus::open(&config, "photon")?;
    let services = bus.create_services()?;
    let cfg = config.clone();
    let s = session.clone();
    let service = std::thread::spawn(move || {
        let bus = Bus::open(&cfg, "renderer").map_err(|e| e.to_string())?;
        let settings = RenderSettings::from_session(&s.renderer);
        renderer::service::run_with(&s, &bus, settings, None).map_err(|e| e.to_string())
    });
    let frames_in = bus.inlet::<topics::Frame>()?;
    let mut world_out = bus.slice_outlet::<topics::World>()?;
    let mut hand_out = bus.outlet::<topics::Hand>()?;

    // Blocks moving on the floor and a hand above them: a typical frame's content.
    let mut world = WorldSample::with_blocks(blocks);
    let mut hand = HandSample {
        finger_count: 5,
        finger_point_count: [4; 5],
        finger_radius: [0.009; 5],
        palm_vertex_count: 8,
        ..Default::default()
    };
    let period = Duration::from_secs_f64(1.0 / source_hz);
    let start = Instant::now();
    let warmup = Duration::from_secs(1);
    let mut photon = Vec::new();
    let mut render = Vec::new();
    let mut n = 0u64;
    let mut next = Instant::now();
    while start.elapsed() < Duration::from_secs_f64(seconds) + warmup {
        let t = n as f64 / source_hz;
        for (i, b) in world.blocks[..blocks].iter_mut().enumerate() {
            let a = i as f64 / blocks as f64 * std::f64::consts::TAU + t * 0.5;
            b.pose.position = [0.3 * a.cos(), 0.03, 0.3 * a.sin()];
            b.pose.rotation = [0.0, (a / 2.0).sin(), 0.0, (a / 2.0).cos()];
            b.mode = BlockMode::ALL[i % BlockMode::ALL.len()] as u32;
        }
        for f in 0..5 {
            for k in 0..4 {
                hand.finger_points[f][k] = [
                    -0.04 + 0.02 * f as f64,
                    0.2 - 0.01 * k as f64,
                    -0.02 - 0.025 * k as f64,
                ];
            }
        }
        for (k, v) in hand.palm_vertices[..8].iter_mut().enumerate() {
            *v = [
                if k & 1 == 0 { -0.045 } else { 0.045 },
                if k & 2 == 0 { 0.2 } else { 0.225 },
                if k & 4 == 0 { 0.0 } else { 0.09 },
            ];
        }
        hand.stamp = Stamp::at_origin(0, n);
        let sent = hand_out.publish(&hand)?;
        world.hand_seq = sent.seq;
        world.stamp = Stamp::at_origin(0, n);
        world_out.publish_copy(&world.header, &world.blocks)?;
        n += 1;
        while let Some(f) = frames_in.receive()? {
            if start.elapsed() > warmup {
                photon.push(f.origin_to_photon_ns);
                render.push(f.render_ns);
            }
        }
        next += period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
    }
    shutdown::request();
    let result = service.join().map_err(|_| "the renderer thread panicked")?;
    drop((frames_in, world_out, hand_out, services, bus));
    let _ = config.remove_resources();
    let _ = std::fs::remove_dir_all(&config.root);
    result?;

    let pct = |v: &mut Vec<u64>, q: f64| {
        v.sort_unstable();
        v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1e6
    };
    if photon.is_empty() {
        return Err("no frames".into());
    }
    println!(
        "{w} x {h} per eye, frame_hz {frame_hz}, worlds at {source_hz} Hz, {seconds} s after 1 s warm-up, {} frames ({:.1} Hz)",
        photon.len(),
        photon.len() as f64 / seconds,
    );
    println!(
        "origin -> photon: p50 {:.2} ms, p90 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        pct(&mut photon, 0.5),
        pct(&mut photon, 0.9),
        pct(&mut photon, 0.99),
        pct(&mut photon, 1.0)
    );
    println!(
        "render (draw both eyes + GPU complete): p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        pct(&mut render, 0.5),
        pct(&mut render, 0.99),
        pct(&mut render, 1.0)
    );
    Ok(())
}
