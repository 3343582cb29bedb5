//! The `world` topic as a slice topic over a real iceoryx2 bus: samples sized from the scene,
//! written in place and read in place, the capacity enforced, the buffer depth from its byte
//! budget, and nothing left in /dev/shm.

use std::time::Duration;

use common::bus::{Bus, BusConfig, MIN_SLICE_BUFFER};
use common::{topics, BlockMode, BlockState, Pose, WorldHeader};

fn config(tag: &str, blocks: usize) -> BusConfig {
    BusConfig::for_session(&format!("st{tag}{}", std::process::id()))
        .unwrap()
        .with_world_blocks(blocks)
        .unwrap()
}

fn block(i: usize) -> BlockState {
    BlockState {
        pose: Pose {
            position: [i as f64, 0.02, -(i as f64)],
            rotation: [0.0, 0.0, 0.0, 1.0],
        },
        mode: BlockMode::Resting as u32,
        held_by: 0,
    }
}

#[test]
fn world_samples_carry_the_scenes_blocks_in_place_and_refuse_more() {
    let cfg = config("rw", 300);
    {
        let bus = Bus::open(&cfg, "test").unwrap();
        let _services = bus.create_services().unwrap();
        let inlet = bus.inlet::<topics::World>().unwrap();
        let mut outlet = bus.slice_outlet::<topics::World>().unwrap();
        assert_eq!(outlet.capacity(), 300);
        let sent = outlet
            .publish_with(
                300,
                |h| {
                    h.step = 7;
                    h.block_count = 300;
                    h.grasped_block = 12;
                },
                block,
            )
            .unwrap();
        // A smaller sample on the same topic: the slice's length is the sample's own.
        outlet
            .publish_copy(
                &WorldHeader {
                    block_count: 2,
                    ..Default::default()
                },
                &[block(0), block(1)],
            )
            .unwrap();
        inlet.wait(Duration::from_millis(500)).unwrap();
        let first = inlet.receive().unwrap().expect("a world sample");
        assert_eq!(first.user_header().stamp.seq, sent.seq);
        assert_eq!(first.user_header().step, 7);
        assert_eq!(first.user_header().grasped_block, 12);
        assert_eq!(first.payload().len(), 300);
        assert!(first
            .payload()
            .iter()
            .enumerate()
            .all(|(i, b)| *b == block(i)));
        let second = inlet.receive().unwrap().expect("the second sample");
        assert_eq!(second.payload().len(), 2);
        assert_eq!(inlet.counter().gaps, 0);
        // More than the session's scene holds is refused, naming the capacity.
        let e = outlet
            .publish_with(301, |_| {}, block)
            .unwrap_err()
            .to_string();
        assert!(e.contains("301") && e.contains("at most 300"), "{e}");
    }
    cfg.remove_resources().unwrap();
    assert!(cfg.leftover_shm_files().is_empty());
}

/// The depth is 16 MiB over the sample size, between 64 and the table's 1024: a fixed depth
/// would have a 4096-block world pin over 1 GiB of /dev/shm (iceoryx2 zeroes the segment).
#[test]
fn the_world_buffer_depth_follows_the_sample_size() {
    let depth = |blocks: usize| {
        let cfg = config(&format!("d{blocks}_"), blocks);
        let d = Bus::open(&cfg, "test")
            .unwrap()
            .slice_buffer::<topics::World>();
        cfg.remove_resources().unwrap();
        d
    };
    assert_eq!(depth(128), 1024);
    assert_eq!(depth(1024), 253);
    assert_eq!(depth(4096), MIN_SLICE_BUFFER);
    let e = BusConfig::for_session("x")
        .unwrap()
        .with_world_blocks(4097)
        .unwrap_err()
        .to_string();
    assert!(e.contains("4097") && e.contains("1 to 4096"), "{e}");
}
