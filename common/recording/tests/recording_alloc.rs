//! The recorder's write path allocates per chunk, not per sample: MCAP's chunk buffers and
//! message index grow to their size, and closing a chunk starts the next. Counted with a global
//! allocator that tallies per thread.

use common::{Stamp, Topic, TrackerSample, WorldSample};
use recording::{Recording, RecordingWriter};

#[global_allocator]
static GLOBAL: counting_alloc::Counting = counting_alloc::Counting;

#[test]
fn writing_allocates_per_chunk_not_per_sample() {
    let path = std::env::temp_dir().join(format!("hb-alloc-{}.mcap", std::process::id()));
    let mut w = RecordingWriter::create(&path).unwrap();
    let period = 1_000_000u64; // a 1 kHz source
    let mut world = WorldSample::with_blocks(128);
    let mut tracker = TrackerSample::default();
    let mut write = |w: &mut RecordingWriter, k: u64| {
        let stamp = Stamp {
            seq: k,
            source_time_ns: k * period,
            origin_ns: k * period,
            publish_ns: k * period + 1,
        };
        tracker.stamp = stamp;
        world.stamp = stamp;
        world.step = k;
        w.write(Topic::Tracker, &tracker).unwrap();
        w.write_slice(Topic::World, &world.header, &world.blocks)
            .unwrap();
    };
    for k in 0..2_000 {
        write(&mut w, k); // warm-up: buffers grow to their size
    }
    let before = counting_alloc::allocations();
    let messages = 2 * 8_000u64;
    for k in 2_000..10_000 {
        write(&mut w, k);
    }
    let during = counting_alloc::allocations() - before;
    w.finish().unwrap();
    let rec = Recording::open(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    let mut chunks: Vec<u64> = rec.messages.iter().map(|m| m.record_offset).collect();
    chunks.dedup();
    assert!(chunks.len() >= 16, "{} chunks", chunks.len());
    // ~8.5 KB per world sample of 128 blocks: a chunk closes about every 115 samples, so ~140 chunks here.
    let per_chunk = during as f64 / chunks.len() as f64;
    println!(
        "{during} allocations for {messages} messages in {} chunks ({per_chunk:.1} per chunk)",
        chunks.len()
    );
    assert!(
        during * 4 < messages,
        "{during} allocations for {messages} messages: allocating per sample"
    );
}
