//! What the modules' tests share: a scratch path per test, and a glove sample to write.

use std::path::PathBuf;

use common::samples::GloveSample;
use common::stamp::Stamp;

pub(crate) fn scratch(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("hb-recording-{}-{name}.mcap", std::process::id()))
}

pub(crate) fn glove(seq: u64, publish_ns: u64) -> GloveSample {
    let mut g = GloveSample {
        stamp: Stamp {
            seq,
            source_time_ns: seq * 1000,
            origin_ns: publish_ns - 10,
            publish_ns,
        },
        ..Default::default()
    };
    g.angles[3] = seq as f64 * 0.01;
    g
}
