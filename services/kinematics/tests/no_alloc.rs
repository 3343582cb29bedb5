//! Making a hand allocates nothing: the kinematics process turns every glove, tracker and
//! joints sample into a hand through [`HandStream`], so after the first samples not one heap
//! allocation may happen per sample. Counted with a global allocator that tallies per thread.

use common::{GloveSample, JointsSample, TrackerSample};
use kinematics::{HandModel, HandStream};

#[global_allocator]
static GLOBAL: counting_alloc::Counting = counting_alloc::Counting;

#[test]
fn hands_from_gloves_trackers_and_joints_allocate_nothing() {
    let mut stream = HandStream::new(HandModel::default());
    let mut glove = GloveSample::default();
    let mut tracker = TrackerSample::default();
    let mut joints = JointsSample::default();
    let mut feed = |stream: &mut HandStream, k: u64| {
        glove.stamp.source_time_ns = k * 8_000_000;
        glove.angles[k as usize % glove.angles.len()] = k as f64 * 0.01;
        tracker.stamp.source_time_ns = k * 8_000_000 + 1_000;
        tracker.wrist.position[2] = k as f64 * 0.001;
        joints.stamp.source_time_ns = k * 8_000_000 + 2_000;
        stream.glove(&glove);
        let tracked = stream.tracker(&tracker).map_or(0, |h| h.finger_count);
        tracked + stream.joints(&joints).finger_count
    };
    // Warm-up: fill the glove ring once over.
    for k in 0..200 {
        feed(&mut stream, k);
    }
    let before = counting_alloc::allocations();
    let mut fingers = 0;
    for k in 200..1200 {
        fingers += feed(&mut stream, k);
    }
    let made = counting_alloc::allocations() - before;
    assert!(fingers > 0, "hands were made");
    assert_eq!(made, 0, "allocations while making 2000 hands");
}
