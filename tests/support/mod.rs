//! What the integration tests share: the binary, the repository, scratch folders, and the
//! checks that a session left nothing behind and that two worlds agree bit for bit.
#![allow(dead_code)]

use std::path::PathBuf;

use common::bus::BusConfig;
use common::WorldSample;
use serde_json::Value;

pub const EXE: &str = env!("CARGO_BIN_EXE_handblocks");

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A scratch folder for one test, emptied when made and removed when dropped.
pub struct Scratch(pub PathBuf);

impl Scratch {
    pub fn new(tag: &str) -> Scratch {
        let d = std::env::temp_dir().join(format!("hb-it-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        Scratch(d)
    }
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Nothing of session `bus_id` is left in /dev/shm or its root path.
pub fn assert_nothing_left(bus_id: &str) {
    let bus = BusConfig::for_session(bus_id).unwrap();
    assert!(
        bus.leftover_shm_files().is_empty(),
        "left in /dev/shm: {:?}",
        bus.leftover_shm_files()
    );
    assert!(!bus.root.exists(), "left behind: {}", bus.root.display());
}

/// The blocks of `simulate --json` output have exactly the poses of `world`'s blocks.
pub fn assert_same_poses(simulated: &Value, world: &WorldSample) {
    for (i, block) in simulated["blocks"].as_array().unwrap().iter().enumerate() {
        let nums = |key: &str| -> Vec<f64> {
            block[key]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let live = world.blocks()[i];
        assert_eq!(
            nums("position"),
            live.pose.position.to_vec(),
            "block {i} position differs"
        );
        assert_eq!(
            nums("rotation"),
            live.pose.rotation.to_vec(),
            "block {i} rotation differs"
        );
    }
}
