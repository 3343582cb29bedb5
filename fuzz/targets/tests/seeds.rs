//! The checked-in seed corpus (`fuzz/corpus/<target>/`): how it was made, and that it stays
//! small and valid.
//!
//! `seed-*` files are small valid inputs (each must parse); `regression-*` files are inputs
//! that once found a bug (each must be refused without a panic: `stable_fuzz.rs` runs them).
//! Regenerate the generated seeds with
//! `cargo test --release -p fuzz-targets --test seeds -- --ignored write_seeds`
//! (the text seeds are copies of config/ files and hand-written sessions; see `write_seeds`).

use std::path::{Path, PathBuf};

use acquisition::devices::fastrak::{encode_record, item};
use acquisition::devices::{Calibration, FastrakParser, Format, GloveParser};
use common::config::hand::HandModelSpec;
use common::config::{Scene, Session};
use common::{
    FrameSample, GloveSample, HandSample, JointsSample, Pose, Stamp, Topic, TrackerSample,
    WorldSample, MAX_GLOVE_SENSORS,
};
use recording::{Recording, RecordingWriter};
use replay::CarlTrace;

/// The largest seed checked in.
const MAX_SEED_BYTES: usize = 64 * 1024;

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn put(target: &str, name: &str, bytes: &[u8]) {
    assert!(
        bytes.len() < MAX_SEED_BYTES,
        "{target}/{name}: {} bytes",
        bytes.len()
    );
    let dir = corpus().join(target);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(name), bytes).unwrap();
}

fn glove_record(header: u8, k: usize, n: usize) -> Vec<u8> {
    let mut v = vec![header];
    v.extend((0..n).map(|i| 1 + ((k * 37 + i * 11) % 254) as u8));
    v.push(0);
    v
}

fn quat(k: usize) -> [f64; 4] {
    let a = k as f64 * 0.2;
    let (s, c) = (a / 2.0).sin_cos();
    [c, s * 0.6, s * 0.0, s * 0.8]
}

fn fastrak_stream(format: Format, items: &[u8], n: usize) -> Vec<u8> {
    let mut out = Vec::new();
    for k in 0..n {
        encode_record(
            format,
            items,
            1 + (k % 4) as u8,
            [k as f64 * 1.5, -20.25, 33.5],
            [k as f64 * 10.0 - 90.0, 45.0 - k as f64, 170.0],
            quat(k),
            &mut out,
        );
    }
    out
}

/// A CARL file of `n` samples of nothing but times and absent poses, except every third
/// sample, which has the right hand's wrist and joints.
fn carl_sparse(n: usize) -> Vec<u8> {
    let mut out = b"CARL".to_vec();
    out.extend(1u32.to_le_bytes());
    out.extend(1u32.to_le_bytes());
    out.extend((n as u64).to_le_bytes());
    let pose = |out: &mut Vec<u8>, k: usize| {
        for v in [0.0f32, 0.0, 0.0, 1.0, 0.1 * k as f32, 1.0, -0.3] {
            out.extend(v.to_le_bytes());
        }
    };
    for k in 0..n {
        out.extend((k as f64 / 90.0).to_le_bytes());
        out.extend([0, 0]); // head, left wrist
        let right = k % 3 == 2;
        out.push(right as u8);
        if right {
            pose(&mut out, k);
        }
        out.push(0); // left joints
        out.push(right as u8);
        if right {
            for j in 0..26 {
                pose(&mut out, j);
            }
        }
        out.extend([0, 0]); // controllers
    }
    out.extend(0f64.to_le_bytes());
    out.extend(((n - 1) as f64 / 90.0).to_le_bytes());
    out
}

fn stamp(k: u64) -> Stamp {
    Stamp {
        seq: k,
        source_time_ns: k * 8_333_333,
        origin_ns: 1_000_000_000 + k * 8_333_333,
        publish_ns: 1_000_010_000 + k * 8_333_333,
    }
}

/// A small recording of every recorded topic, finished properly.
fn mcap_recording(samples: u64, world_blocks: usize) -> Vec<u8> {
    let dir = std::env::temp_dir().join(format!("hb-fuzz-seeds-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("seed.mcap");
    let mut w = RecordingWriter::create_with(&path, &[("session", "seed.toml".into())]).unwrap();
    for k in 0..samples {
        let mut g = GloveSample {
            stamp: stamp(k),
            ..GloveSample::default()
        };
        for (i, a) in g.angles.iter_mut().enumerate() {
            *a = 0.01 * (k as f64 + i as f64);
        }
        w.write(Topic::Glove, &g).unwrap();
        let wrist = Pose {
            position: [0.1 * k as f64, 0.3, -0.2],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        w.write(
            Topic::Tracker,
            &TrackerSample {
                stamp: stamp(k),
                station: 1,
                side: 0,
                wrist,
            },
        )
        .unwrap();
        w.write(
            Topic::Joints,
            &JointsSample {
                stamp: stamp(k),
                tracked: 1,
                wrist,
                ..JointsSample::default()
            },
        )
        .unwrap();
        let mut hand: HandSample = unsafe_zeroed_hand();
        hand.stamp = stamp(k);
        hand.wrist = wrist;
        hand.tracked = 1;
        w.write(Topic::Hand, &hand).unwrap();
        let mut world = WorldSample::with_blocks(world_blocks);
        world.header.stamp = stamp(k);
        world.header.step = k;
        world.header.hand_seq = k;
        for (i, b) in world.blocks.iter_mut().enumerate() {
            b.pose = Pose {
                position: [i as f64 * 0.2, 0.05, 0.0],
                rotation: [0.0, 0.0, 0.0, 1.0],
            };
        }
        w.write_slice(Topic::World, &world.header, &world.blocks)
            .unwrap();
        w.write(
            Topic::Frame,
            &FrameSample {
                stamp: stamp(k),
                ..FrameSample::default()
            },
        )
        .unwrap();
        if k % 4 == 3 {
            w.close_chunk().unwrap();
        }
    }
    w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    bytes
}

/// A hand sample of zeros (every sample type is plain old data: zero is a valid value).
fn unsafe_zeroed_hand() -> HandSample {
    // SAFETY: HandSample is #[repr(C)] plain old data of integers and floats.
    unsafe { std::mem::zeroed() }
}

/// The `stepper_hand` seeds and the inputs of issue 28 that once hung the stepper (byte 0:
/// bit 0 the precise model, bit 1 the grasp scene, bit 2 tracked hand rules, bit 3 "no hand"
/// records mark the hand lost, bit 4 a second hand; then records of step, kind, index, value:
/// `fuzz_targets::stepper_hand`).
#[test]
#[ignore = "writes fuzz/corpus/stepper_hand: run it by hand to regenerate those inputs"]
fn write_stepper_hand_seeds() {
    let record = |step: u8, kind: u8, index: u16, value: f64| {
        let mut r = vec![step, kind];
        r.extend(index.to_le_bytes());
        r.extend(value.to_le_bytes());
        r
    };
    let input = |pick: u8, records: &[Vec<u8>]| [vec![pick], records.concat()].concat();
    let h = "stepper_hand";
    put(h, "seed-paper-push", &input(0, &[record(5, 0, 1, 0.3)]));
    // Issue 41: a tracked hand lost mid-grasp for a while, then a NaN wrist and a check point
    // far off while it holds.
    let lost: Vec<Vec<u8>> = (40..70).map(|s| record(s, 7, 0, 0.0)).collect();
    put(h, "seed-tracked-grasp-lost", &input(2 | 4 | 8, &lost));
    put(
        h,
        "regression-tracked-grasp-nan-wrist-far-point",
        &input(
            2 | 4,
            &[
                record(45, 1, 1, f64::NAN),
                record(50, 0, 7, 1e9),
                record(55, 7, 0, 0.0),
            ],
        ),
    );
    // Issue 41, two hands (bit 4; kind bit 3 puts a record on the second hand): both grasp
    // the thrown block, the second is lost for a while (tracked rules), then turns its wrist
    // half over and disappears while the first still holds; and under the paper's rules the
    // second's check points jump through the block.
    let mut two: Vec<Vec<u8>> = (30..40).map(|s| record(s, 8 | 7, 0, 0.0)).collect();
    two.extend([record(42, 8 | 1, 3, 0.7), record(44, 8 | 7, 0, 0.0)]);
    put(
        h,
        "seed-two-hands-tracked-lost",
        &input(16 | 8 | 4 | 2, &two),
    );
    put(
        h,
        "seed-two-hands-paper-jump",
        &input(
            16 | 2,
            &[
                record(20, 8, 0, 0.5),
                record(21, 8, 4, -0.5),
                record(22, 8 | 1, 0, 0.9),
            ],
        ),
    );
    put(
        h,
        "seed-precise-grasp",
        &input(3, &[record(20, 4, 0, 0.01)]),
    );
    put(
        h,
        "seed-precise-push-no-hand",
        &input(1, &[record(9, 7, 0, 0.0)]),
    );
    put(
        h,
        "regression-check-point-at-1e20-paper",
        &input(0, &[record(10, 0, 0, 1e20)]),
    );
    put(
        h,
        "regression-wrist-at-5e14-paper-grasp",
        &input(2, &[record(10, 1, 0, 5e14)]),
    );
    put(
        h,
        "regression-nan-radius-precise",
        &input(3, &[record(10, 4, 0, f64::NAN)]),
    );
    put(
        h,
        "regression-palm-vertex-at-1e300-precise",
        &input(
            3,
            &[record(10, 5, 0, f64::from_bits(4)), record(10, 6, 0, 1e300)],
        ),
    );
}

/// The `link` seeds: a hand and a world of 3 blocks as the bridge sends them (the topic's
/// index among the recorded topics, then the recording's message).
#[test]
#[ignore = "writes fuzz/corpus/link: run it by hand to regenerate those seeds"]
fn write_link_seeds() {
    let index = |t: Topic| Topic::RECORDED.iter().position(|r| *r == t).unwrap() as u8;
    let mut hand = unsafe_zeroed_hand();
    hand.stamp = stamp(7);
    hand.finger_count = 1;
    hand.finger_point_count[0] = 2;
    hand.finger_points[0][1] = [0.01, 0.02, 0.03];
    let mut msg = Vec::new();
    recording::encode_sample(&hand, &mut msg);
    put(
        "link",
        "seed-hand",
        &[&[index(Topic::Hand)][..], &msg].concat(),
    );
    let mut world = WorldSample::with_blocks(3);
    world.header.stamp = stamp(8);
    world.blocks[1].pose.position = [0.1, 0.05, 0.0];
    recording::encode_slice(Topic::World, &world.header, &world.blocks, &mut msg);
    put(
        "link",
        "seed-world",
        &[&[index(Topic::World)][..], &msg].concat(),
    );
    // Issue 40: one count its array cannot hold crashed a viewer (the recorder, the renderer
    // and the Foxglove view indexed past a finger's 5 points or the palm's 16 vertices).
    let mut put_hand = |name: &str, set: &dyn Fn(&mut HandSample)| {
        let mut h = hand;
        set(&mut h);
        recording::encode_sample(&h, &mut msg);
        put("link", name, &[&[index(Topic::Hand)][..], &msg].concat());
    };
    put_hand("regression-hand-finger-point-count-6", &|h| {
        h.finger_point_count[0] = 6
    });
    put_hand("regression-hand-palm-vertex-count-17", &|h| {
        h.palm_vertex_count = 17
    });
    put_hand("regression-hand-finger-count-1000", &|h| {
        h.finger_count = 1000
    });
    let mut put_world = |name: &str, set: &dyn Fn(&mut WorldSample)| {
        let mut w = world.clone();
        set(&mut w);
        recording::encode_slice(Topic::World, &w.header, &w.blocks, &mut msg);
        put("link", name, &[&[index(Topic::World)][..], &msg].concat());
    };
    put_world("regression-world-finger-point-count-6", &|w| {
        w.header.finger_point_count[0] = 6
    });
    put_world("regression-world-block-count-4000", &|w| {
        w.header.block_count = 4000
    });
    put_world("regression-world-grasped-block-3", &|w| {
        w.header.grasped_block = 3
    });
}

#[test]
#[ignore = "writes fuzz/corpus/webxr: run it by hand to regenerate those seeds"]
fn write_webxr_seeds() {
    use webxr_wire::{encode, HandsFrame, WEBXR_JOINTS};
    let mut frame = HandsFrame {
        seq: 41,
        frame_time_ms: 16_683.3,
        present: [false, true],
        ..Default::default()
    };
    for j in 0..WEBXR_JOINTS {
        for h in 0..2 {
            let side = if h == 0 { -0.2 } else { 0.2 };
            frame.hands[h].poses[j].position =
                [side + 0.004 * j as f64, 1.1, -0.35 - 0.01 * j as f64];
            frame.hands[h].radii[j] = 0.008;
        }
    }
    let mut bytes = Vec::new();
    encode(&frame, &mut bytes);
    put("webxr", "seed-right-hand", &bytes);
    frame.present = [true, true];
    frame.seq = 42;
    encode(&frame, &mut bytes);
    put("webxr", "seed-both-hands", &bytes);
    frame.present = [false, false];
    frame.seq = 43;
    encode(&frame, &mut bytes);
    put("webxr", "seed-no-hand", &bytes);
    let stats = webxr_wire::page::FrameStats {
        seq: 7,
        js_ms: 1.5,
        round_trip_ms: Some(40.0),
    };
    webxr_wire::page::encode_stats(&stats, &mut bytes);
    put("webxr", "seed-stats", &bytes);
    let pong = webxr_wire::page::Pong {
        seq: 3,
        server_ms: 10.0,
        page_ms: 2.0,
    };
    webxr_wire::page::encode_pong(&pong, &mut bytes);
    put("webxr", "seed-pong", &bytes);
}

/// Writes the generated seeds and copies the text ones from config/.
#[test]
#[ignore = "writes fuzz/corpus: run it by hand to regenerate the seeds"]
fn write_seeds() {
    write_link_seeds();
    write_webxr_seeds();
    write_stepper_hand_seeds();
    // cyberglove: byte 0 = size (0 -> 18, 1 -> 22), byte 1 = chunk size (0 = all at once).
    let mut s = vec![1, 0];
    for k in 0..5 {
        s.extend(glove_record(b'S', k, 22));
    }
    s.extend(b"?S\x16\0eg");
    put("cyberglove", "seed-22-streamed", &s);
    let mut s = vec![0, 1];
    s.extend(b"?S\x12\0");
    for k in 0..4 {
        s.extend(glove_record(b'G', k, 18));
    }
    s.extend(b"es");
    put("cyberglove", "seed-18-polled-byte-by-byte", &s);
    let mut s = vec![1, 7];
    s.extend(b"\xff\x00 G\x01\x02");
    s.extend(glove_record(b'S', 1, 22));
    s.extend(&glove_record(b'S', 2, 22)[..9]);
    s.extend(glove_record(b'S', 3, 22));
    s.extend(b"S\x05\x06\x00?S\x16");
    s.extend(glove_record(b'S', 4, 22));
    put("cyberglove", "seed-22-noise-and-cut-records", &s);

    // fastrak: byte 0 bit 0 = ascii, bit 1 = raw item list, bits 2.. = chunk; byte 1 = list.
    let lists: [&[u8]; 3] = [
        &[item::POSITION, item::QUATERNION, item::CRLF],
        &[item::POSITION, item::EULER, item::CRLF],
        &[
            item::SPACE,
            item::POSITION,
            item::SPACE,
            item::QUATERNION,
            item::CRLF,
        ],
    ];
    let mut s = vec![0, 0];
    s.extend(fastrak_stream(Format::Binary, lists[0], 8));
    put("fastrak", "seed-binary-quaternion", &s);
    let mut s = vec![1 | (9 << 2), 1];
    s.extend(fastrak_stream(Format::Ascii, lists[1], 8));
    put("fastrak", "seed-ascii-euler-chunks-of-9", &s);
    let mut s = vec![1, 0];
    s.extend(fastrak_stream(Format::Ascii, lists[0], 6));
    put("fastrak", "seed-ascii-quaternion", &s);
    let mut s = vec![2 | (5 << 2), lists[2].len() as u8];
    s.extend(lists[2]);
    let mut stream = fastrak_stream(Format::Binary, lists[2], 6);
    stream.splice(40..40, b"\x00\xff01 junk\r\n".iter().copied());
    s.extend(stream);
    put("fastrak", "seed-binary-spaces-raw-list-with-noise", &s);

    // carl: generated ones only (the real recordings in ../shared/data/carl are not ours to
    // check in: stable_fuzz reads them from there, cut short, as extra seeds).
    put("carl", "seed-sparse-right-hand", &carl_sparse(12));
    let mut cut = carl_sparse(30);
    cut.truncate(cut.len() - 1000);
    put("carl", "seed-sparse-cut-off", &cut);

    // mcap: our own recordings, small.
    put("mcap", "seed-every-topic", &mcap_recording(6, 3));
    put("mcap", "seed-one-sample-no-blocks", &mcap_recording(1, 0));
    let full = mcap_recording(8, 2);
    put("mcap", "seed-cut-off", &full[..full.len() * 2 / 3]);

    // Text seeds: copies of config/ files (scenes, hand, calibrations).
    for (target, from, name) in [
        (
            "scene",
            "config/scenes/grasp-throw.toml",
            "seed-grasp-throw.toml",
        ),
        (
            "scene",
            "config/scenes/grasp-throw-fingers.toml",
            "seed-grasp-throw-fingers.toml",
        ),
        (
            "scene",
            "config/scenes/wedge-tetra.toml",
            "seed-wedge-tetra.toml",
        ),
        (
            "scene",
            "config/scenes/field-1024.toml",
            "seed-field-1024.toml",
        ),
        ("scene", "config/scenes/balance.toml", "seed-balance.toml"),
        ("hand", "config/hand.toml", "seed-hand.toml"),
        (
            "calibration",
            "config/devices/glove-22.cal",
            "seed-glove-22.cal",
        ),
        (
            "calibration",
            "config/devices/glove-18.cal",
            "seed-glove-18.cal",
        ),
    ] {
        put(target, name, &std::fs::read(repo().join(from)).unwrap());
    }
}

/// Every seed is small; every `seed-*` parses (so fuzzing starts from valid inputs); every
/// file is a seed or a regression.
/// Issue 40: the payloads that crashed a viewer from the zenoh link (a count its array cannot
/// hold: `finger_point_count[0]` 6, `palm_vertex_count` 17, ...) are the link target's
/// `regression-*` inputs: each is refused where it comes in, naming the field.
#[test]
fn issue40_link_payloads_are_refused_naming_the_count() {
    let folder = corpus().join("link");
    let mut refused = 0;
    for entry in std::fs::read_dir(&folder).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if !name.starts_with("regression-") {
            continue;
        }
        let bytes = std::fs::read(&path).unwrap();
        let topic = Topic::RECORDED[usize::from(bytes[0]) % Topic::RECORDED.len()];
        let e = match topic {
            Topic::World => {
                recording::decode_slice::<common::WorldHeader>(topic, &bytes[1..]).map(|_| ())
            }
            _ => recording::decode_sample::<HandSample>(topic, &bytes[1..]).map(|_| ()),
        }
        .expect_err(&name)
        .to_string();
        let field = [
            "finger_point_count",
            "palm_vertex_count",
            "finger_count",
            "block_count",
            "grasped_block",
        ]
        .into_iter()
        .find(|f| name.contains(&f.replace('_', "-")))
        .unwrap_or_else(|| panic!("{name}: which field?"));
        assert!(e.contains(field), "{name}: {e}");
        fuzz_targets::link(&bytes);
        refused += 1;
    }
    assert_eq!(refused, 6);
}

#[test]
fn seeds_are_small_and_valid() {
    let dir = std::env::temp_dir().join(format!("hb-fuzz-seed-check-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("s.toml"), fuzz_targets::SESSION_SCENE).unwrap();
    std::fs::write(dir.join("hand.toml"), fuzz_targets::SESSION_HAND).unwrap();
    let mut seen = 0;
    for (target, _) in fuzz_targets::TARGETS {
        let mut seeds = 0;
        let folder = corpus().join(target);
        for entry in std::fs::read_dir(&folder).unwrap_or_else(|e| panic!("{folder:?}: {e}")) {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            let bytes = std::fs::read(&path).unwrap();
            assert!(
                bytes.len() < MAX_SEED_BYTES,
                "{target}/{name}: {} bytes",
                bytes.len()
            );
            assert!(
                name.starts_with("seed-") || name.starts_with("regression-"),
                "{target}/{name}: name it seed-... or regression-..."
            );
            if name.starts_with("seed-") {
                seeds += 1;
                check_valid(target, &name, &bytes, &dir);
            }
            seen += 1;
        }
        assert!(seeds >= 2, "{target}: {seeds} seeds");
    }
    assert!(seen >= 16);
    std::fs::remove_dir_all(&dir).unwrap();
}

fn check_valid(target: &str, name: &str, bytes: &[u8], dir: &Path) {
    let what = format!("{target}/{name}");
    match target {
        "cyberglove" => {
            let sensors = if bytes[0] & 1 == 0 { 18 } else { 22 };
            let mut p = GloveParser::new(sensors);
            let mut raw = [0u8; MAX_GLOVE_SENSORS];
            let mut events = 0;
            for chunk in bytes[2..].chunks(64) {
                p.push(chunk);
                while p.next(&mut raw).is_some() {
                    events += 1;
                }
            }
            assert!(events >= 3, "{what}: {events} events");
        }
        "fastrak" => {
            let format = if bytes[0] & 1 == 0 {
                Format::Binary
            } else {
                Format::Ascii
            };
            let (items, stream) = if bytes[0] & 2 == 0 {
                let lists: [&[u8]; 2] = [&[2, 11, 1], &[2, 4, 1]];
                (lists[usize::from(bytes[1])], &bytes[2..])
            } else {
                bytes[2..].split_at(usize::from(bytes[1]))
            };
            let mut p = FastrakParser::new(format, items).unwrap();
            let mut r = Default::default();
            let mut records = 0;
            for chunk in stream.chunks(64) {
                p.push(chunk);
                while p.next(&mut r) {
                    records += 1;
                }
            }
            assert!(records >= 5, "{what}: {records} records");
        }
        "carl" => {
            let t = CarlTrace::parse(Path::new(name), bytes).unwrap_or_else(|e| panic!("{e}"));
            assert!(!t.samples.is_empty(), "{what}");
            assert_eq!(t.damage.is_some(), name.contains("cut-off"), "{what}");
        }
        "link" => {
            let topic = Topic::RECORDED[usize::from(bytes[0]) % Topic::RECORDED.len()];
            let ok = match topic {
                Topic::World => {
                    recording::decode_slice::<common::WorldHeader>(topic, &bytes[1..]).is_ok()
                }
                Topic::Hand => recording::decode_sample::<HandSample>(topic, &bytes[1..]).is_ok(),
                t => panic!("{what}: no seed of {t:?} expected"),
            };
            assert!(ok, "{what} does not decode");
        }
        "webxr" => {
            use webxr_wire::page;
            match page::kind_of(bytes).unwrap_or_else(|e| panic!("{what}: {e}")) {
                page::KIND_STATS => drop(page::decode_stats(bytes).unwrap()),
                page::KIND_PONG => drop(page::decode_pong(bytes).unwrap()),
                _ => {
                    let mut frame = webxr_wire::HandsFrame::default();
                    webxr_wire::decode_into(bytes, &mut frame)
                        .unwrap_or_else(|e| panic!("{what}: {e}"));
                }
            }
            fuzz_targets::webxr(bytes);
        }
        "mcap" => {
            let r = Recording::parse(Path::new(name), bytes).unwrap_or_else(|e| panic!("{e}"));
            assert!(!r.messages.is_empty(), "{what}");
            assert_eq!(
                r.complete,
                !name.contains("cut-off"),
                "{what}: {:?}",
                r.damage
            );
        }
        "stepper_hand" => {
            // Whole records, each a modest value: the scripted hand, slightly changed.
            let records = &bytes[1..];
            assert_eq!(records.len() % fuzz_targets::STEPPER_RECORD, 0, "{what}");
            for r in records.chunks_exact(fuzz_targets::STEPPER_RECORD) {
                let v = f64::from_le_bytes(r[4..12].try_into().unwrap());
                assert!(v.is_finite() && v.abs() < 1.0, "{what}: {v}");
            }
            fuzz_targets::stepper_hand(bytes);
        }
        _ => {
            let file = dir.join(format!("{target}-{name}"));
            std::fs::write(&file, bytes).unwrap();
            let ok = match target {
                "scene" => Scene::load(&file).map(|_| ()),
                "session" => Session::load(&file).map(|_| ()),
                "hand" => HandModelSpec::load(&file).map(|_| ()),
                "calibration" => Calibration::parse(&file, &String::from_utf8_lossy(bytes))
                    .map(|_| ())
                    .map_err(|e| common::config::ConfigError::new(&file, "", e.to_string())),
                t => panic!("no check for target {t}"),
            };
            if let Err(e) = ok {
                panic!("{what} does not load: {e}");
            }
        }
    }
}
