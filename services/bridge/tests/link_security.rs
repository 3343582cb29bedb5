//! Issue 40: the zenoh link was open and in clear. A peer with no credentials read 600 hands
//! and 600 worlds in 5 s, and an impostor on a viewer's endpoint fed it 1,180 invented ones.
//! Here a `tls/` link carries a live side's hands to its viewer while strangers try to read,
//! join, inject and impersonate; each is refused, and the refusal is counted by name.

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use bridge::identity::{certificate_names, Identity};
use bridge::link::{peer_config, Link};
use common::config::remote::LinkSecurity;
use common::config::session::{LinkRole, RemoteLink};
use common::{HandSample, Topic};
use zenoh::Wait;

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hb-link-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

fn tls(key_dir: &std::path::Path, peer: Option<PathBuf>) -> LinkSecurity {
    LinkSecurity::Tls {
        key_dir: key_dir.to_path_buf(),
        peer_certificate: peer,
        names: Vec::new(),
    }
}

fn side(endpoint: &str, key: &str, role: LinkRole, security: LinkSecurity) -> RemoteLink {
    let (publish, subscribe) = match role {
        LinkRole::Listen => (vec![Topic::Hand], vec![]),
        LinkRole::Connect => (vec![], vec![Topic::Hand]),
    };
    RemoteLink {
        endpoint: endpoint.to_string(),
        security,
        role,
        key: key.to_string(),
        publish,
        subscribe,
        wait_for_viewer_s: 0,
    }
}

/// A hand message as the bridge sends it, its seq `seq`.
fn hand_message(seq: u64) -> Vec<u8> {
    let mut h = HandSample {
        finger_count: 1,
        ..HandSample::default()
    };
    h.stamp.seq = seq;
    h.finger_point_count[0] = 2;
    let mut m = Vec::new();
    recording::encode_sample(&h, &mut m);
    m
}

/// Puts hands on `live` for `span`, one every 5 ms, from seq `from`; returns the next seq.
fn send_for(live: &Link, span: Duration, from: u64) -> u64 {
    let until = Instant::now() + span;
    let mut seq = from;
    while Instant::now() < until {
        let _ = live.put(Topic::Hand, &hand_message(seq));
        seq += 1;
        std::thread::sleep(Duration::from_millis(5));
    }
    seq
}

fn wait_until(what: &str, limit: Duration, mut done: impl FnMut() -> bool) {
    let until = Instant::now() + limit;
    while !done() {
        assert!(Instant::now() < until, "{what}: not within {limit:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_stranger_can_neither_read_nor_join_nor_inject_and_is_counted() {
    bridge::refusals::install();
    let keys = scratch("ours");
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let key = format!("hbtest/sec{}", std::process::id());
    let live = Link::open(&side(&endpoint, &key, LinkRole::Listen, tls(&keys, None))).unwrap();
    let viewer = Link::open(&side(&endpoint, &key, LinkRole::Connect, tls(&keys, None))).unwrap();
    assert!(live.protection.contains("TLS 1.3"), "{}", live.protection);
    wait_until(
        "the viewer joins and knows the clock",
        Duration::from_secs(20),
        || viewer.peers() == 1 && viewer.clock.offset_ns().is_some(),
    );

    // A stranger with no certificate, on plain TCP, and one with its own authority's.
    let plain = zenoh::open(
        peer_config(&endpoint.replace("tls/", "tcp/"), LinkRole::Connect, None).unwrap(),
    )
    .wait()
    .unwrap();
    let stolen = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let counter = stolen.clone();
    let _spy = plain
        .declare_subscriber(format!("{key}/**"))
        .callback(move |sample| {
            // Its own invented hands (seq 9999) come back to it; the live side's would not.
            let bytes = sample.payload().to_bytes();
            if recording::message_stamp(&bytes).is_none_or(|s| s.seq != 9_999) {
                counter.fetch_add(1, Ordering::Relaxed);
            }
        })
        .wait()
        .unwrap();
    let other_keys = scratch("theirs");
    let stranger = Link::open(&side(
        &endpoint,
        &key,
        LinkRole::Connect,
        tls(&other_keys, None),
    ))
    .unwrap();

    // Both try for two seconds while the live side sends 400 hands; the plain one also puts
    // an invented hand on the viewer's key.
    let mut seq = 0;
    for _ in 0..4 {
        seq = send_for(&live, Duration::from_millis(500), seq);
        let _ = plain.put(format!("{key}/hand"), hand_message(9_999)).wait();
    }
    let mut taken = 0;
    while let Ok(item) = viewer.incoming.try_recv() {
        let bytes = item.bytes.to_bytes();
        let stamp = recording::message_stamp(&bytes).unwrap();
        assert!(
            stamp.seq < seq,
            "an invented hand came in: seq {}",
            stamp.seq
        );
        taken += 1;
    }
    assert!(taken > seq / 2, "the viewer took {taken} of {seq}");
    assert_eq!(
        stolen.load(Ordering::Relaxed),
        0,
        "a stranger read the link"
    );
    assert_eq!(
        stranger.incoming.len(),
        0,
        "a stranger's authority read the link"
    );
    assert_eq!(stranger.peers(), 0);
    assert_eq!(live.peers(), 1, "only the viewer joined");
    let refused = bridge::refusals::counts();
    let handshakes: u64 = refused
        .iter()
        .filter(|(name, _)| name.starts_with("a connecting peer's TLS handshake"))
        .map(|(_, n)| n)
        .sum();
    assert!(handshakes >= 2, "{refused:?}");
    eprintln!("refused: {refused:#?}");
    drop(plain);
    stranger.close();
    viewer.close();
    live.close();
    let _ = std::fs::remove_dir_all(&keys);
    let _ = std::fs::remove_dir_all(&other_keys);
}

/// An impostor on the viewer's endpoint: first one whose certificate no trusted authority
/// issued (TLS refuses it), then one whose TLS certificate the viewer's side accepts (as it
/// would a public web authority's for that host) but who does not hold the trusted authority's
/// key: its clock answers are refused, so the viewer publishes nothing it sends.
#[test]
fn a_viewer_takes_nothing_from_an_impostor() {
    let ours = scratch("viewer");
    let theirs = scratch("impostor");
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let key = format!("hbtest/imp{}", std::process::id());
    let impostor =
        Link::open(&side(&endpoint, &key, LinkRole::Listen, tls(&theirs, None))).unwrap();
    let viewer = Link::open(&side(&endpoint, &key, LinkRole::Connect, tls(&ours, None))).unwrap();
    send_for(&impostor, Duration::from_millis(1500), 0);
    assert_eq!(viewer.peers(), 0, "TLS let an untrusted certificate in");
    assert_eq!(viewer.incoming.len(), 0);
    impostor.close();

    // An impostor holding a certificate our authority issued, but not our authority's key.
    let authority = keyfile::authority(&ours, "handblocks link authority").unwrap();
    let issued = authority.issue(&certificate_names(&endpoint, &[])).unwrap();
    let stranger = keyfile::authority(&theirs, "handblocks link authority").unwrap();
    let fake = Identity {
        authority: stranger,
        chain_pem: issued.chain_pem,
        key_pem: issued.key_pem,
        peer_pem: authority.certificate_pem.clone(),
        peer_file: None,
        names: Vec::new(),
    };
    let impostor = Link::open_with(
        &side(&endpoint, &key, LinkRole::Listen, LinkSecurity::Plain),
        Some(fake),
    )
    .unwrap();
    wait_until("TLS lets the impostor in", Duration::from_secs(20), || {
        viewer.peers() == 1
    });
    send_for(&impostor, Duration::from_millis(1500), 0);
    assert!(
        viewer.clock.unsigned_answers() > 0,
        "no clock answer was refused"
    );
    assert_eq!(
        viewer.clock.offset_ns(),
        None,
        "an impostor's clock was taken: what it sends would be published"
    );
    impostor.close();
    viewer.close();
    let _ = std::fs::remove_dir_all(&ours);
    let _ = std::fs::remove_dir_all(&theirs);
}

/// A trusted peer that is not this side's own: `peer_certificate` names the other side's
/// authority.pem, and only that side gets in.
#[test]
fn two_machines_trust_each_other_by_their_authority_files() {
    let a = scratch("machine-a");
    let b = scratch("machine-b");
    let a_cert = keyfile::authority(&a, "handblocks link authority")
        .unwrap()
        .certificate_file;
    let b_cert = keyfile::authority(&b, "handblocks link authority")
        .unwrap()
        .certificate_file;
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let key = format!("hbtest/two{}", std::process::id());
    let live = Link::open(&side(
        &endpoint,
        &key,
        LinkRole::Listen,
        tls(&a, Some(b_cert)),
    ))
    .unwrap();
    let viewer = Link::open(&side(
        &endpoint,
        &key,
        LinkRole::Connect,
        tls(&b, Some(a_cert.clone())),
    ))
    .unwrap();
    wait_until(
        "the viewer joins and knows the clock",
        Duration::from_secs(20),
        || viewer.peers() == 1 && viewer.clock.offset_ns().is_some(),
    );
    send_for(&live, Duration::from_millis(300), 0);
    wait_until("a hand crosses", Duration::from_secs(5), || {
        !viewer.incoming.is_empty()
    });
    // A third machine trusting a, but whose own authority a does not trust: refused.
    let c = scratch("machine-c");
    let third = Link::open(&side(
        &endpoint,
        &key,
        LinkRole::Connect,
        tls(&c, Some(a_cert)),
    ))
    .unwrap();
    send_for(&live, Duration::from_millis(1500), 100);
    assert_eq!(third.peers(), 0);
    assert_eq!(third.incoming.len(), 0);
    third.close();
    viewer.close();
    live.close();
    for d in [a, b, c] {
        let _ = std::fs::remove_dir_all(d);
    }
}

#[test]
fn a_missing_peer_certificate_is_named_with_what_to_do() {
    let keys = scratch("missing");
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let missing = keys.join("nope.pem");
    let e = Link::open(&side(
        &endpoint,
        "hbtest/m",
        LinkRole::Listen,
        tls(&keys, Some(missing)),
    ))
    .err()
    .unwrap()
    .to_string();
    assert!(
        e.contains("nope.pem") && e.contains("peer_certificate"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&keys);
}
