//! Issue 16, supervision: what a restarted stage finds of its dead incarnation on the bus —
//! its outlets' seq goes on, its inlets count gaps from their first sample, and its source
//! epoch is kept — and that an unsupervised bus behaves as before.

use std::time::Duration;

use common::bus::{Bus, BusConfig};
use common::{topics, GloveSample};

fn config(tag: &str) -> BusConfig {
    BusConfig::for_session(&format!("sv{tag}{}", std::process::id())).unwrap()
}

fn received_seqs(inlet: &common::bus::Inlet<topics::Glove>) -> Vec<u64> {
    let _ = inlet.wait(Duration::from_millis(200));
    let mut seqs = Vec::new();
    while let Some(s) = inlet.receive().unwrap() {
        seqs.push(s.payload().stamp.seq);
    }
    seqs
}

#[test]
fn a_restarted_stage_goes_on_with_its_seq_and_epoch() {
    let cfg = config("seq");
    {
        let launcher = Bus::open(&cfg, "launcher").unwrap();
        let _services = launcher.create_services().unwrap();
        let reader = Bus::open(&cfg, "kinematics").unwrap();
        let inlet = reader.inlet::<topics::Glove>().unwrap();
        let (epoch, kept) = {
            let first = Bus::open(&cfg, "acquisition").unwrap().supervised(0);
            let (epoch, kept) = first.session_epoch_ns("acquisition");
            let mut out = first.outlet::<topics::Glove>().unwrap();
            for _ in 0..3 {
                out.publish(&GloveSample::default()).unwrap();
            }
            // Read while the publisher lives (its samples go with it).
            assert_eq!(received_seqs(&inlet), [0, 1, 2]);
            (epoch, kept)
        };
        assert!(!kept, "the first start makes the epoch");
        // The same stage started again: seq goes on, the epoch is the first one's.
        let again = Bus::open(&cfg, "acquisition").unwrap().supervised(1);
        assert_eq!(again.restart(), 1);
        assert_eq!(again.session_epoch_ns("acquisition"), (epoch, true));
        let mut out = again.outlet::<topics::Glove>().unwrap();
        assert_eq!(out.counter().count, 3, "the count goes on too");
        // A reader restarted meanwhile counts from its first sample: the 3 before it were not
        // its to miss.
        let restarted_reader = Bus::open(&cfg, "recorder").unwrap().supervised(1);
        let late = restarted_reader.inlet::<topics::Glove>().unwrap();
        let fresh_reader = Bus::open(&cfg, "renderer").unwrap();
        let fresh = fresh_reader.inlet::<topics::Glove>().unwrap();
        for _ in 0..2 {
            out.publish(&GloveSample::default()).unwrap();
        }
        assert_eq!(received_seqs(&inlet), [3, 4]);
        assert_eq!(received_seqs(&late), [3, 4]);
        assert_eq!((late.counter().count, late.counter().gaps), (2, 0));
        let _ = received_seqs(&fresh);
        assert_eq!(
            fresh.counter().gaps,
            3,
            "an unsupervised reader counts from seq 0"
        );
        // A restarted source skips the seqs of the deadlines it missed: readers count them as
        // gaps, its counter as skipped, and the next restart still knows.
        out.skip_to(8);
        out.publish(&GloveSample::default()).unwrap();
        assert_eq!(received_seqs(&inlet), [8]);
        assert_eq!(inlet.counter().gaps, 3);
        let c = out.counter();
        assert_eq!((c.count, c.gaps, c.last_seq), (6, 3, 8));
        drop(out);
        let third = Bus::open(&cfg, "acquisition").unwrap().supervised(2);
        let c = third.outlet::<topics::Glove>().unwrap().counter();
        assert_eq!((c.count, c.gaps, c.last_seq), (6, 3, 8));
        // An unsupervised outlet of the same name starts at 0, as it always did.
        let plain = Bus::open(&cfg, "acquisition").unwrap();
        assert_eq!(
            plain.outlet::<topics::Tracker>().unwrap().counter().count,
            0
        );
        assert!(!plain.session_epoch_ns("acquisition").1);
    }
    cfg.remove_resources().unwrap();
    assert!(cfg.leftover_shm_files().is_empty());
}

/// Issue 28: a reader that has not received since a lossless publisher appeared is not yet
/// connected to it, and iceoryx2 skips such a reader once its buffer is full rather than wait
/// for it; a speed-0 replay lost 33 glove and 32 tracker samples at a recorder that was
/// descheduled as the replay started. A lossless outlet now fills at most half a reader's
/// buffer until every reader has taken its first sample: a reader that sleeps through the
/// start still gets every sample.
#[test]
fn a_lossless_publisher_waits_for_a_reader_that_has_not_yet_received() {
    let cfg = config("gate").with_lossless(true);
    {
        let launcher = Bus::open(&cfg, "launcher").unwrap();
        let _services = launcher.create_services().unwrap();
        let reader = Bus::open(&cfg, "recorder").unwrap();
        let inlet = reader.inlet::<topics::Glove>().unwrap();
        let n = 3 * common::Topic::Glove.subscriber_buffer() as u64;
        let source = cfg.clone();
        let publisher = std::thread::spawn(move || {
            let bus = Bus::open(&source, "replay").unwrap();
            let mut out = bus.outlet::<topics::Glove>().unwrap();
            for _ in 0..n {
                out.publish(&GloveSample::default()).unwrap();
            }
            out.counter().count
        });
        // The reader does not run while the source starts (a descheduled process).
        std::thread::sleep(Duration::from_millis(300));
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        while inlet.received() < n && std::time::Instant::now() < deadline {
            let _ = inlet.wait(Duration::from_millis(20));
            while inlet.receive().unwrap().is_some() {}
        }
        assert_eq!(publisher.join().unwrap(), n);
        let c = inlet.counter();
        assert_eq!((c.count, c.gaps), (n, 0), "every sample, none skipped");
    }
    cfg.remove_resources().unwrap();
    assert!(cfg.leftover_shm_files().is_empty());
}
