//! What the webxr stage does per message allocates nothing: decoding a hands frame (or a
//! refused one), the statistics and the pongs, mapping a hand to the joints the bus carries,
//! and writing a world into the kept buffer the pages are sent from. Counted with a global
//! allocator that tallies per thread.

use common::JointsSample;
use webxr_wire::page::{self, FrameStats, Pong};
use webxr_wire::{decode_into, encode, to_joints, HandsFrame, WEBXR_JOINTS};

#[global_allocator]
static GLOBAL: counting_alloc::Counting = counting_alloc::Counting;

#[test]
fn decoding_mapping_and_writing_worlds_allocate_nothing() {
    let mut frame = HandsFrame {
        seq: 1,
        frame_time_ms: 10.0,
        present: [true, true],
        ..Default::default()
    };
    for h in 0..2 {
        for j in 0..WEBXR_JOINTS {
            frame.hands[h].poses[j].position = [0.01 * j as f64, 1.0, -0.3];
            frame.hands[h].radii[j] = 0.01;
        }
    }
    let (mut hands, mut stats, mut pong) = (Vec::new(), Vec::new(), Vec::new());
    encode(&frame, &mut hands);
    let s = FrameStats {
        seq: 1,
        js_ms: 1.0,
        round_trip_ms: Some(20.0),
    };
    page::encode_stats(&s, &mut stats);
    let p = Pong {
        seq: 1,
        server_ms: 5.0,
        page_ms: 3.0,
    };
    page::encode_pong(&p, &mut pong);
    let mut bad = hands.clone();
    bad[30] = 0xff;
    bad[31] = 0xff;
    bad[32] = 0xff;
    bad[33] = 0x7f;
    let blocks = [common::BlockState {
        pose: common::Pose {
            position: [0.0, 0.04, -0.3],
            rotation: [0.0, 0.0, 0.0, 1.0],
        },
        mode: 1,
        held_by: 0,
    }; 16];
    let mut header = common::WorldHeader {
        block_count: 16,
        finger_count: 5,
        finger_point_count: [4; 5],
        ..Default::default()
    };
    header.finger_points[0][0] = [0.1, 0.2, 0.3];
    let view = common::WorldView {
        header: &header,
        blocks: &blocks,
    };
    let mut world = Vec::with_capacity(page::WORLD_HEADER_BYTES + 32 * 16 + 12 * 20);
    let mut decoded = HandsFrame::default();
    let mut joints = JointsSample::default();
    let mut work = |k: u32| {
        let mut n = 0;
        n += usize::from(decode_into(&hands, &mut decoded).is_ok());
        n += usize::from(decode_into(&bad, &mut decoded).is_err());
        to_joints(&decoded.hands[1], &mut joints);
        n += usize::from(page::decode_stats(&stats).is_ok());
        n += usize::from(page::decode_pong(&pong).is_ok());
        page::encode_world(k, 1.0, &view, &mut world);
        n
    };
    work(0);
    let before = counting_alloc::allocations();
    let mut done = 0;
    for k in 1..1000 {
        done += work(k);
    }
    let made = counting_alloc::allocations() - before;
    assert_eq!(
        done,
        4 * 999,
        "every message decoded or refused as it should be"
    );
    assert_eq!(made, 0, "allocations while handling 5000 messages");
}
