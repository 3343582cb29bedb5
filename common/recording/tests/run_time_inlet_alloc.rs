//! The recorder's and the bridge's hot path through the run-time inlet (`AnyInlet`, a topic
//! chosen at run time): receiving a sample, viewing its bytes and making its message allocate
//! nothing per sample; writing it into a recording allocates per chunk, as the typed path does.
//! Counted with a global allocator that tallies per thread.

use common::bus::{Bus, BusConfig};
use common::{topics, BlockState, HandSample, Topic, WorldHeader};
use recording::{Recording, RecordingWriter};

#[global_allocator]
static GLOBAL: counting_alloc::Counting = counting_alloc::Counting;

#[test]
fn a_run_time_inlet_receives_and_records_without_allocating_per_sample() {
    let config = BusConfig::for_session(&format!("rtalloc{}", std::process::id())).unwrap();
    let path = std::env::temp_dir().join(format!("hb-rt-alloc-{}.mcap", std::process::id()));
    {
        let bus = Bus::open(&config, "test").unwrap();
        let _services = bus.create_services().unwrap();
        let inlets = [
            bus.any_inlet(Topic::Hand).unwrap(),
            bus.any_inlet(Topic::World).unwrap(),
        ];
        let mut hands = bus.outlet::<topics::Hand>().unwrap();
        let mut worlds = bus.slice_outlet::<topics::World>().unwrap();
        let header = WorldHeader {
            block_count: 16,
            ..WorldHeader::default()
        };
        let blocks = [BlockState::default(); 16];
        let mut writer = RecordingWriter::create(&path).unwrap();
        let mut message = Vec::new();
        // Samples in the warm-up (buffers grow to their size), and after it with their allocations.
        let (mut warm_up, mut counted, mut during) = (0u64, 0u64, 0u64);
        for k in 0..3_000u64 {
            hands.publish(&HandSample::default()).unwrap();
            worlds.publish_copy(&header, &blocks).unwrap();
            for inlet in &inlets {
                // The bridge's and `echo`'s path: the message from the sample's bytes.
                let (got, made) = counting_alloc::count(|| {
                    let mut got = 0;
                    while let Some(s) = inlet.receive().unwrap() {
                        recording::encode_view(&s.view(), &mut message);
                        writer.write_view(&s.view()).unwrap();
                        got += 1;
                    }
                    got
                });
                if k >= 500 {
                    counted += got;
                    during += made;
                } else {
                    warm_up += got;
                }
            }
        }
        assert_eq!(warm_up + counted, 6_000);
        println!("{during} allocations for {counted} samples received and recorded");
        // Writing allocates per chunk (MCAP's buffers, its index), a chunk per ~1 MiB.
        assert!(
            during * 4 < counted,
            "{during} allocations for {counted} samples: allocating per sample"
        );
        // Receiving and making the message: none at all.
        let mut receive_only = 0;
        for _ in 0..1_000 {
            hands.publish(&HandSample::default()).unwrap();
            worlds.publish_copy(&header, &blocks).unwrap();
            for inlet in &inlets {
                let ((), made) = counting_alloc::count(|| {
                    while let Some(s) = inlet.receive().unwrap() {
                        recording::encode_view(&s.view(), &mut message);
                    }
                });
                receive_only += made;
            }
        }
        assert_eq!(
            receive_only, 0,
            "receiving through the run-time inlet allocates"
        );
        writer.finish().unwrap();
    }
    let rec = Recording::open(&path).unwrap();
    assert_eq!(rec.views(Topic::World).count(), 3_000);
    assert!(rec.views(Topic::World).all(|v| v.len() == 16));
    let _ = std::fs::remove_file(&path);
    config.remove_resources().unwrap();
}
