mod support;
use glam::DVec3;
use stepper::*;
use support::*;
#[test]
fn dbg() {
    let s = scene_file("push");
    let mut hand = BareFingersHand::from_scene(&s).unwrap();
    let mut w = World::new(&s).unwrap();
    let dt = 1.0 / 120.0;
    w.set_previous_hand(hand.hand_at(0, 0.0).as_ref());
    for n in 1..=125u64 {
        let h = hand.hand_at(n, n as f64 * dt).unwrap();
        w.step(Some(&h));
        let b = w.block(0).unwrap();
        let p = DVec3::from_array(h.finger_points[0][0]);
        let local = b.rotation.conjugate() * (p - b.position);
        if n > 95 {
            println!(
                "{n} {:?} local {:.5} {:.5} {:.5} ang {:.3} ev {:?}",
                b.mode,
                local.x,
                local.y,
                local.z,
                b.rotation.to_axis_angle().1.to_degrees(),
                w.events()
            );
        }
    }
}
