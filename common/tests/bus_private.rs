//! Issue 16: a session's iceoryx2 resources are its user's alone (/dev/shm files 0600, the
//! session's folders 0700), and every id the validator accepts works whatever `$TMPDIR` is (a
//! Unix socket's path holds at most 107 bytes).

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::Path;
use std::time::Duration;

use common::bus::{Bus, BusConfig};
use common::{topics, GloveSample};

fn mode(path: &Path) -> u32 {
    std::fs::symlink_metadata(path).unwrap().mode() & 0o777
}

/// Opens the session's bus, sends one glove sample through it (event included), and checks
/// what it made in /dev/shm and under its root while it is open.
fn round_trip_and_check_modes(cfg: &BusConfig) {
    {
        let bus = Bus::open(cfg, "test").unwrap();
        let _services = bus.create_services().unwrap();
        let inlet = bus.inlet::<topics::Glove>().unwrap();
        let mut outlet = bus.outlet::<topics::Glove>().unwrap();
        outlet.publish(&GloveSample::default()).unwrap();
        inlet.wait(Duration::from_millis(500)).unwrap();
        assert!(
            inlet.receive().unwrap().is_some(),
            "the sample came through"
        );
        let shm = cfg.leftover_shm_files();
        assert!(!shm.is_empty());
        for f in &shm {
            assert_eq!(mode(f), 0o600, "{} is {:o}", f.display(), mode(f));
        }
        assert_eq!(mode(&cfg.root), 0o700, "{}", cfg.root.display());
        let base = cfg.root.parent().unwrap();
        assert_eq!(mode(base), 0o700, "{}", base.display());
    }
    cfg.remove_resources().unwrap();
    assert!(cfg.leftover_shm_files().is_empty());
    assert!(!cfg.root.exists());
}

#[test]
fn a_sessions_shared_memory_and_folders_are_its_users_alone() {
    let cfg = BusConfig::for_session(&format!("bp{}", std::process::id())).unwrap();
    round_trip_and_check_modes(&cfg);
}

#[test]
fn the_longest_id_works_and_two_long_ids_do_not_share_resources() {
    let pid = std::process::id().to_string();
    let long = |c: char| format!("{pid}{}", c.to_string().repeat(48 - pid.len()));
    let (a, b) = (long('a'), long('b'));
    let (ca, cb) = (
        BusConfig::for_session(&a).unwrap(),
        BusConfig::for_session(&b).unwrap(),
    );
    assert_ne!(ca.prefix, cb.prefix);
    assert_ne!(ca.root, cb.root);
    round_trip_and_check_modes(&ca);
}

#[test]
fn a_long_tmpdir_falls_back_to_tmp_and_every_socket_path_fits() {
    let tmp = Path::new("/tmp").join("t".repeat(90));
    let cfg = BusConfig::for_session_in(&"z".repeat(48), &tmp).unwrap();
    assert!(
        cfg.root.to_string_lossy().starts_with("/tmp/hb-iox2-"),
        "{}",
        cfg.root.display()
    );
    // Root, prefix and iceoryx2's longest socket name (a u128 in decimal and `.event`).
    let longest = cfg.root.as_os_str().len() + 1 + cfg.prefix.len() + 39 + ".event".len();
    assert!(longest <= 107, "{longest}");
    let short = BusConfig::for_session_in("s1", Path::new("/var/tmp")).unwrap();
    assert!(
        short
            .root
            .to_string_lossy()
            .starts_with("/var/tmp/hb-iox2-"),
        "{}",
        short.root.display()
    );
    assert_eq!(short.prefix, "hb_s1_");
}

#[test]
fn a_session_folder_open_to_others_or_closed_to_its_owner_is_made_0700_again() {
    for (tag, mode) in [("bq", 0o777), ("br", 0o600)] {
        let cfg = BusConfig::for_session(&format!("{tag}{}", std::process::id())).unwrap();
        std::fs::create_dir_all(&cfg.root).unwrap();
        std::fs::set_permissions(&cfg.root, std::fs::Permissions::from_mode(mode)).unwrap();
        round_trip_and_check_modes(&cfg);
    }
}
