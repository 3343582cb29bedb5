//! Issue 46: a stage the stage table marks `wakes_by: Doorbell` sleeps on one futex word that
//! every publisher of its topics rings, whichever of its inlets is written, and still wakes at
//! its deadline; `[pipeline] wake = "event"` (`Bus::woken_by_events`) puts it back on
//! iceoryx2's event. Another process is played by another thread with its own node: the
//! doorbell is a file of the session's folder, mapped by each.

use std::time::{Duration, Instant};

use common::bus::{Bus, BusConfig, WaitStrategy, Waiter, Wakeable};
use common::topic::WakesBy;
use common::{topics, JointsSample, Stage, TrackerSample};

fn woken_within(
    waiter: &mut Waiter,
    inlets: &[&dyn Wakeable],
    timeout: Duration,
    publish: impl FnOnce() + Send + 'static,
) -> Duration {
    let publisher = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(100));
        publish();
    });
    let t = Instant::now();
    waiter.wait(inlets, timeout).unwrap();
    let woke = t.elapsed();
    publisher.join().unwrap();
    woke
}

#[test]
fn a_doorbell_stage_wakes_for_any_of_its_inlets_and_at_its_deadline() {
    assert_eq!(Stage::Kinematics.wakes_by(), WakesBy::Doorbell);
    assert_eq!(Stage::Stepper.wakes_by(), WakesBy::Doorbell);
    assert_eq!(
        Stage::Bridge.wakes_by(),
        WakesBy::Event,
        "it sleeps on zenoh's eventfd too"
    );
    let id = format!("doorbell{}", std::process::id());
    let config = BusConfig::for_session(&id).unwrap();
    {
        let launcher = Bus::open(&config, "launcher").unwrap();
        let _services = launcher.create_services().unwrap();
        for by_events in [false, true] {
            let mut kinematics = Bus::for_stage(&config, Stage::Kinematics).unwrap();
            if by_events {
                kinematics = kinematics.woken_by_events();
            }
            let tracker_in = kinematics.inlet::<topics::Tracker>().unwrap();
            let joints_in = kinematics.inlet::<topics::Joints>().unwrap();
            assert_eq!(
                common::bus::wake_fd(&tracker_in).is_none(),
                !by_events,
                "a doorbell inlet has no descriptor; an event one has"
            );
            let mut waiter = Waiter::for_stage(WaitStrategy::Event);
            let inlets: [&dyn Wakeable; 2] = [&tracker_in, &joints_in];

            // The deadline, with nothing sent.
            let t = Instant::now();
            waiter.wait(&inlets, Duration::from_millis(50)).unwrap();
            assert!(
                t.elapsed() >= Duration::from_millis(45),
                "{:?}",
                t.elapsed()
            );

            // Each inlet wakes it, long before a 60 s deadline (only a wake-up that never
            // comes reaches it), and what woke it is there to take (the publisher holds it
            // 300 ms more).
            for topic in ["tracker", "joints"] {
                let c = config.clone();
                let woke = woken_within(&mut waiter, &inlets, Duration::from_secs(60), move || {
                    let bus = Bus::open(&c, "source").unwrap();
                    if topic == "tracker" {
                        let mut out = bus.outlet::<topics::Tracker>().unwrap();
                        out.publish(&TrackerSample::default()).unwrap();
                        std::thread::sleep(Duration::from_millis(300));
                    } else {
                        let mut out = bus.outlet::<topics::Joints>().unwrap();
                        out.publish(&JointsSample::default()).unwrap();
                        std::thread::sleep(Duration::from_millis(300));
                    }
                });
                assert!(
                    woke < Duration::from_secs(30),
                    "by events {by_events}: {topic} woke it after {woke:?}"
                );
            }
            // A sample already waiting is not slept on.
            let source = Bus::open(&config, "source").unwrap();
            let mut out = source.outlet::<topics::Joints>().unwrap();
            out.publish(&JointsSample::default()).unwrap();
            let t = Instant::now();
            waiter.wait(&inlets, Duration::from_secs(60)).unwrap();
            assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());
            assert!(
                joints_in.receive().unwrap().is_some(),
                "what woke it is there"
            );
            drop(out);

            // Inlet::wait sleeps on the same doorbell.
            let t = Instant::now();
            joints_in.wait(Duration::from_millis(30)).unwrap();
            assert!(t.elapsed() >= Duration::from_millis(25));
        }
    }
    config.remove_resources().unwrap();
}
