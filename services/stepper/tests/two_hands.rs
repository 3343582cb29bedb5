//! docs/model.md "Two hands": a world that takes both hands of a headset. Each hand's actions
//! are decided as a one-hand world decides them and combined block by block: a two-hand grasp
//! moves by the mean of the two wrists' motions, a block passes from hand to hand without a
//! release, a hand letting go of a two-hand grasp leaves the block with the other (no fling),
//! two pushes move it by their mean; a hand that comes, goes or sends garbage leaves the other
//! hand's work alone. Under both rule sets (paper, tracked) where they differ.

mod support;

use common::{BlockMode, HandSample};
use glam::DVec3;
use stepper::{Event, EventKind, World};
use support::{hand, scene};

const RIGHT: u8 = 0b01;
const LEFT: u8 = 0b10;

/// A floating 10 cm cube at (0, 1, 0) (no gravity, no floor), under `hands` rules.
fn floating_cube(hands: &str) -> World {
    let s = scene(&format!(
        "[world]\nhands = \"{hands}\"\n[effects]\ngravity = false\nfloor = \"none\"\n\
         [[block]]\nname = \"cube\"\nposition = [0.0, 1.0, 0.0]\nsize = [0.1, 0.1, 0.1]\n"
    ));
    World::new(&s).unwrap_or_else(|e| panic!("{e}"))
}

/// The right hand: a pinch across the cube's x faces, each tip `gap` m outside its face
/// (negative: inside), every point moved with the wrist at `wrist`.
fn right_pinch(gap: f64, wrist: DVec3) -> HandSample {
    let p = |x: f64, z: f64| (DVec3::new(x, 1.0, z) + wrist).to_array();
    hand(
        &[
            &[p(-0.05 - gap, -0.01), p(-0.05 - gap, 0.01)],
            &[p(0.05 + gap, -0.01), p(0.05 + gap, 0.01)],
        ],
        wrist.to_array(),
    )
}

/// The left hand: a pinch across the cube's z faces (the right's fingers stay clear of it).
fn left_pinch(gap: f64, wrist: DVec3) -> HandSample {
    let p = |x: f64, z: f64| (DVec3::new(x, 1.0, z) + wrist).to_array();
    hand(
        &[
            &[p(-0.01, -0.05 - gap), p(0.01, -0.05 - gap)],
            &[p(-0.01, 0.05 + gap), p(0.01, 0.05 + gap)],
        ],
        wrist.to_array(),
    )
}

/// An open hand far from the cube.
fn away(wrist: DVec3) -> HandSample {
    right_pinch(0.3, wrist + DVec3::new(0.0, 0.0, 1.0))
}

fn mode(w: &World) -> BlockMode {
    w.block(0).unwrap().mode
}

fn pos(w: &World) -> DVec3 {
    w.block(0).unwrap().position
}

/// The events of kind `kind` in the last step, by their hands.
fn by(w: &World, kind: EventKind) -> Vec<u8> {
    w.events()
        .iter()
        .filter(|e: &&Event| e.kind == kind)
        .map(|e| e.hands)
        .collect()
}

/// Steps `n` times with the same two hands and returns the events of kind `kind` of those
/// steps, by their hands (a hand that opens lets go in the step after R1 last finds it; under
/// tracked rules once its grip has been found open for grip_open_time, 4 steps at 120 Hz).
fn steps(w: &mut World, hands: [Option<&HandSample>; 2], n: usize, kind: EventKind) -> Vec<u8> {
    let mut out = Vec::new();
    for _ in 0..n {
        w.step_hands(hands);
        out.extend(by(w, kind));
    }
    out
}

/// Both hands close on the cube in the same step: a grasp by each.
fn both_grasp(w: &mut World) {
    w.set_previous_hand_of(0, Some(&right_pinch(0.01, DVec3::ZERO)));
    w.set_previous_hand_of(1, Some(&left_pinch(0.01, DVec3::ZERO)));
    w.step_hands([
        Some(&right_pinch(-0.002, DVec3::ZERO)),
        Some(&left_pinch(-0.002, DVec3::ZERO)),
    ]);
    assert_eq!(mode(w), BlockMode::Grasped);
    assert_eq!(
        by(w, EventKind::Grasp),
        vec![RIGHT | LEFT],
        "one grasp by both"
    );
}

#[test]
fn a_two_hand_grasp_moves_by_the_mean_of_the_two_wrists_motions() {
    for rules in ["paper", "tracked"] {
        let mut w = floating_cube(rules);
        both_grasp(&mut w);
        // The right wrist moves 1 cm a step along y, the left stays: the block moves 5 mm a
        // step, halfway, and both grips keep it.
        let start = pos(&w);
        for k in 1..=6 {
            let up = DVec3::new(0.0, 0.01 * k as f64, 0.0);
            w.step_hands([
                Some(&right_pinch(-0.002, up)),
                Some(&left_pinch(-0.002, up * 0.0)),
            ]);
            let moved = pos(&w) - start;
            assert!(
                (moved.y - 0.005 * k as f64).abs() < 1e-9,
                "{rules} step {k}: {moved}"
            );
        }
    }
}

#[test]
fn a_block_passed_from_hand_to_hand_is_never_released() {
    for rules in ["paper", "tracked"] {
        let mut w = floating_cube(rules);
        // The right grasps alone.
        w.set_previous_hand_of(0, Some(&right_pinch(0.01, DVec3::ZERO)));
        w.step_hands([
            Some(&right_pinch(-0.002, DVec3::ZERO)),
            Some(&away(DVec3::ZERO)),
        ]);
        assert_eq!(by(&w, EventKind::Grasp), vec![RIGHT], "{rules}");
        // The left closes on it too: it joins the grasp.
        w.step_hands([
            Some(&right_pinch(-0.002, DVec3::ZERO)),
            Some(&left_pinch(0.01, DVec3::ZERO)),
        ]);
        w.step_hands([
            Some(&right_pinch(-0.002, DVec3::ZERO)),
            Some(&left_pinch(-0.002, DVec3::ZERO)),
        ]);
        assert_eq!(
            by(&w, EventKind::Grasp),
            vec![LEFT],
            "{rules}: the left joins"
        );
        // The right opens wide and leaves: the right lets go, the block stays with the left.
        let released = steps(
            &mut w,
            [
                Some(&right_pinch(0.05, DVec3::ZERO)),
                Some(&left_pinch(-0.002, DVec3::ZERO)),
            ],
            6,
            EventKind::Release,
        );
        assert_eq!(released, vec![RIGHT], "{rules}: the right lets go");
        assert_eq!(mode(&w), BlockMode::Grasped, "{rules}");
        // The left carries it away, 1 cm a step.
        let start = pos(&w);
        for k in 1..=5 {
            let to = DVec3::new(0.0, 0.0, -0.01 * k as f64);
            w.step_hands([Some(&away(DVec3::ZERO)), Some(&left_pinch(-0.002, to))]);
            assert!(
                ((pos(&w) - start) - to).length() < 1e-9,
                "{rules} step {k}: the block follows the left"
            );
            assert_eq!(mode(&w), BlockMode::Grasped);
        }
    }
}

#[test]
fn one_hand_letting_go_of_a_two_hand_grasp_does_not_fling_the_block() {
    for rules in ["paper", "tracked"] {
        let mut w = floating_cube(rules);
        both_grasp(&mut w);
        // The right swings fast (4 m/s at 120 Hz) while the left holds still, then opens: the
        // block, moved halfway between them while both held it, stays with the still left
        // hand and stops, with no throw (a slingshot would send it off at the right's speed).
        let mut released = Vec::new();
        for k in 1..=2 {
            let swing = DVec3::new(0.0, 0.0333 * k as f64, 0.0);
            released.extend(steps(
                &mut w,
                [
                    Some(&right_pinch(-0.002, swing)),
                    Some(&left_pinch(-0.002, DVec3::ZERO)),
                ],
                1,
                EventKind::Release,
            ));
        }
        let open = DVec3::new(0.0, 0.0666, 0.0);
        released.extend(steps(
            &mut w,
            [
                Some(&right_pinch(0.06, open)),
                Some(&left_pinch(-0.002, DVec3::ZERO)),
            ],
            6,
            EventKind::Release,
        ));
        assert_eq!(released, vec![RIGHT], "{rules}");
        let at = pos(&w);
        for _ in 0..10 {
            w.step_hands([
                Some(&right_pinch(0.06, open)),
                Some(&left_pinch(-0.002, DVec3::ZERO)),
            ]);
        }
        assert_eq!(mode(&w), BlockMode::Grasped, "{rules}");
        assert!(
            (pos(&w) - at).length() < 1e-9,
            "{rules}: held still by the still left hand, moved {}",
            (pos(&w) - at).length()
        );
    }
}

#[test]
fn both_hands_letting_go_together_throw_with_the_blocks_own_motion() {
    // Both hands move the block up at 1.2 m/s and open together: it leaves at the speed it was
    // moving, not at either hand's speed added to the other's.
    for rules in ["paper", "tracked"] {
        let mut w = floating_cube(rules);
        both_grasp(&mut w);
        let step = DVec3::new(0.0, 0.01, 0.0);
        for k in 1..=20 {
            let at = step * k as f64;
            w.step_hands([
                Some(&right_pinch(-0.002, at)),
                Some(&left_pinch(-0.002, at)),
            ]);
        }
        let at = step * 21.0;
        let released = steps(
            &mut w,
            [Some(&right_pinch(0.06, at)), Some(&left_pinch(0.06, at))],
            6,
            EventKind::Release,
        );
        assert_eq!(released, vec![RIGHT | LEFT], "{rules}: one release by both");
        let v = w.block(0).unwrap().v * 120.0;
        assert!(
            (v - DVec3::new(0.0, 1.2, 0.0)).length() < 0.05,
            "{rules}: thrown at {v} m/s"
        );
    }
}

#[test]
fn two_hands_pushing_one_block_move_it_by_the_mean_of_their_pushes() {
    // Each hand one finger (two points along z) against the -x face, moving +x: the right by
    // 6 mm, the left by 4 mm a step. Each alone pushes by its own; together, by the mean.
    let finger = |x: f64, y: f64| {
        hand(
            &[&[[x, 1.0 + y, -0.01], [x, 1.0 + y, 0.01]]],
            [x - 0.1, 1.0, 0.0],
        )
    };
    let (right_before, right_now) = (finger(-0.052, 0.02), finger(-0.046, 0.02));
    let (left_before, left_now) = (finger(-0.052, -0.02), finger(-0.048, -0.02));
    let alone = |before: &HandSample, now: &HandSample| {
        let mut w = floating_cube("paper");
        w.set_previous_hand(Some(before));
        let start = pos(&w);
        w.step(Some(now));
        assert_eq!(mode(&w), BlockMode::Pushed);
        pos(&w) - start
    };
    let (right, left) = (
        alone(&right_before, &right_now),
        alone(&left_before, &left_now),
    );
    assert!(right.x > left.x && left.x > 0.0, "{right} {left}");
    let mut w = floating_cube("paper");
    w.set_previous_hand_of(0, Some(&right_before));
    w.set_previous_hand_of(1, Some(&left_before));
    let start = pos(&w);
    w.step_hands([Some(&right_now), Some(&left_now)]);
    assert_eq!(mode(&w), BlockMode::Pushed);
    assert_eq!(by(&w, EventKind::Push), vec![RIGHT | LEFT]);
    let moved = pos(&w) - start;
    assert!(
        (moved - (right + left) * 0.5).length() < 1e-12,
        "{moved} against {right} and {left}"
    );
}

#[test]
fn a_hand_that_disappears_mid_grasp_leaves_the_block_with_the_other() {
    for rules in ["paper", "tracked"] {
        let mut w = floating_cube(rules);
        both_grasp(&mut w);
        // The left vanishes (no sample at all) for a second: under the paper's rules it lets
        // go at once, under the tracked ones after gap_hold; either way the right keeps it
        // and moves it alone.
        let start = pos(&w);
        for k in 1..=120 {
            let to = DVec3::new(0.001 * k as f64, 0.0, 0.0);
            w.step_hands([Some(&right_pinch(-0.002, to)), None]);
            assert_eq!(mode(&w), BlockMode::Grasped, "{rules} step {k}");
        }
        assert!(
            (pos(&w) - start - DVec3::new(0.12, 0.0, 0.0)).length() < 0.07,
            "{rules}: {}",
            pos(&w) - start
        );
        // It comes back open and far: nothing changes.
        w.step_hands([
            Some(&right_pinch(-0.002, DVec3::new(0.12, 0.0, 0.0))),
            Some(&away(DVec3::ZERO)),
        ]);
        assert_eq!(mode(&w), BlockMode::Grasped, "{rules}");
    }
}

#[test]
fn garbage_on_one_hand_leaves_the_other_hand_unaffected() {
    let mut w = floating_cube("paper");
    w.set_previous_hand_of(0, Some(&right_pinch(0.01, DVec3::ZERO)));
    w.step_hands([
        Some(&right_pinch(-0.002, DVec3::ZERO)),
        Some(&away(DVec3::ZERO)),
    ]);
    assert_eq!(mode(&w), BlockMode::Grasped);
    let mut nan = away(DVec3::ZERO);
    nan.finger_points[0][0] = [f64::NAN, 0.0, 0.0];
    let mut far = away(DVec3::ZERO);
    far.wrist.position = [1e300, 0.0, 0.0];
    let start = pos(&w);
    for (k, bad) in [nan, far, nan].iter().enumerate() {
        let to = DVec3::new(0.0, 0.01 * (k + 1) as f64, 0.0);
        w.step_hands([Some(&right_pinch(-0.002, to)), Some(bad)]);
        assert!(((pos(&w) - start) - to).length() < 1e-9, "step {k}");
    }
    assert_eq!(w.rejected_hand_samples(), 3);
    assert_eq!(mode(&w), BlockMode::Grasped);
}

#[test]
fn hands_that_cross_and_interpenetrate_go_on() {
    // Both hands' fingers through the same block and through each other, every step, with the
    // wrists swapping sides: the world steps, every pose stays finite.
    for rules in ["paper", "tracked"] {
        let mut w = floating_cube(rules);
        for k in 0..200 {
            let s = (k as f64 * 0.1).sin() * 0.08;
            w.step_hands([
                Some(&right_pinch(-0.03 + s * 0.2, DVec3::new(s, 0.0, 0.0))),
                Some(&left_pinch(-0.03 - s * 0.2, DVec3::new(-s, 0.0, 0.0))),
            ]);
            let b = w.block(0).unwrap();
            assert!(
                b.position.is_finite() && b.rotation.is_finite(),
                "{rules} step {k}"
            );
        }
    }
}

#[test]
fn a_one_hand_world_is_step_with_slot_0_and_names_no_hand() {
    let (mut a, mut b) = (floating_cube("tracked"), floating_cube("tracked"));
    a.set_previous_hand(Some(&right_pinch(0.01, DVec3::ZERO)));
    b.set_previous_hand_of(0, Some(&right_pinch(0.01, DVec3::ZERO)));
    for k in 0..30 {
        let h = right_pinch(-0.002, DVec3::new(0.0, 0.003 * k as f64, 0.0));
        a.step(Some(&h));
        b.step_hands([Some(&h), None]);
        assert_eq!(a.events(), b.events());
        assert_eq!(a.block(0), b.block(0));
        assert!(a.events().iter().all(|e| e.hands == 0));
    }
}

/// A scene's `[left_hand]` of bare check points: the left hand pinches the cube while the
/// scene's `[hand]` (the right) stays clear, so the grasp and the release are the left's; a
/// scene with the same `[hand]` alone is `simulate` of one hand, bit for bit.
#[test]
fn a_scene_scripts_the_left_hand_beside_the_right() {
    let cube = "[effects]\ngravity = false\nfloor = \"none\"\n\
                [[block]]\nname = \"cube\"\nposition = [0.0, 1.0, 0.0]\nsize = [0.1, 0.1, 0.1]\n";
    let right = "[hand]\n[[hand.key]]\nt = 0\nwrist = [1.0, 1.0, 0.0]\n\
                 fingers = [[[0.0, 0.0, -0.01], [0.0, 0.0, 0.01]]]\n";
    // Open 1 cm outside the z faces, closed 0.5 mm inside them, then open again.
    let left_key = |t: f64, inset: f64| {
        let z = 0.05 - inset;
        format!(
            "[[left_hand.key]]\nt = {t}\nwrist = [0.0, 1.0, 0.0]\n\
             fingers = [[[-0.01, 0.0, {}], [0.01, 0.0, {}]], [[-0.01, 0.0, {z}], [0.01, 0.0, {z}]]]\n",
            -z, -z
        )
    };
    let left = format!(
        "[left_hand]\n{}{}{}{}",
        left_key(0.0, -0.01),
        left_key(0.2, 0.0005),
        left_key(0.5, 0.0005),
        left_key(0.7, -0.01)
    );
    let two = scene(&format!("{cube}{right}{left}"));
    assert!(two.left_hand.is_some());
    let mut r = stepper::BareFingersHand::from_scene(&two).unwrap();
    let mut l = stepper::BareFingersHand::left_of_scene(&two).unwrap();
    let report = stepper::simulate_hands_with(
        &two,
        stepper::default_frames(&two),
        [Some(&mut r), Some(&mut l)],
        &mut |_, _| Ok(()),
    )
    .unwrap_or_else(|e| panic!("{e:?}"));
    let named: Vec<(EventKind, Option<common::HandSide>)> = report
        .events
        .iter()
        .filter(|e| matches!(e.kind, EventKind::Grasp | EventKind::Release))
        .map(|e| (e.kind, e.hand))
        .collect();
    assert_eq!(
        named,
        [
            (EventKind::Grasp, Some(common::HandSide::Left)),
            (EventKind::Release, Some(common::HandSide::Left)),
        ]
    );

    // The right hand alone: the one-hand `simulate` and the two-hand run with no left agree.
    let one = scene(&format!("{cube}{right}"));
    let frames = stepper::default_frames(&one);
    let mut a = stepper::BareFingersHand::from_scene(&one).unwrap();
    let mut b = a.clone();
    let alone = stepper::simulate(&one, frames, Some(&mut a)).unwrap();
    let slots =
        stepper::simulate_hands_with(&one, frames, [Some(&mut b), None], &mut |_, _| Ok(()))
            .unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(alone.to_json(), slots.to_json());
}

// ---- Shared worlds (issue 45): several people's hands in one world, slot 2k and 2k + 1 the
// right and left of participant k (`HandSample::slot`), combined by the same rules.

/// A third pinch, across the cube's y faces (clear of the other two pinches' fingers).
fn top_pinch(gap: f64, wrist: DVec3) -> HandSample {
    let p = |y: f64, z: f64| (DVec3::new(0.0, 1.0 + y, z) + wrist).to_array();
    hand(
        &[
            &[p(-0.05 - gap, -0.02), p(-0.05 - gap, 0.02)],
            &[p(0.05 + gap, -0.02), p(0.05 + gap, 0.02)],
        ],
        wrist.to_array(),
    )
}

/// Participants 0, 1 and 2's right hands (slots 0, 2, 4) as a world's slots.
fn three_people<'a>(
    first: &'a HandSample,
    second: Option<&'a HandSample>,
    third: &'a HandSample,
) -> [Option<&'a HandSample>; 5] {
    [Some(first), None, second, None, Some(third)]
}

const PEOPLE: u8 = 0b1_0101;

#[test]
fn h3_three_people_grasping_one_block_hold_it_together_moved_by_the_mean_of_their_wrists() {
    for rules in ["paper", "tracked"] {
        let mut w = floating_cube(rules);
        w.set_previous_hand_of(0, Some(&right_pinch(0.01, DVec3::ZERO)));
        w.set_previous_hand_of(2, Some(&left_pinch(0.01, DVec3::ZERO)));
        w.set_previous_hand_of(4, Some(&top_pinch(0.01, DVec3::ZERO)));
        w.step_hands(three_people(
            &right_pinch(-0.002, DVec3::ZERO),
            Some(&left_pinch(-0.002, DVec3::ZERO)),
            &top_pinch(-0.002, DVec3::ZERO),
        ));
        assert_eq!(mode(&w), BlockMode::Grasped, "{rules}");
        assert_eq!(
            by(&w, EventKind::Grasp),
            vec![PEOPLE],
            "{rules}: one grasp by all three"
        );
        // Each moves 3 mm along its own axis: the block moves 1 mm along each, the mean of the
        // three motions; nobody's hand has authority over another's.
        let start = pos(&w);
        let d = 0.003;
        w.step_hands(three_people(
            &right_pinch(-0.002, DVec3::new(d, 0.0, 0.0)),
            Some(&left_pinch(-0.002, DVec3::new(0.0, 0.0, d))),
            &top_pinch(-0.002, DVec3::new(0.0, d, 0.0)),
        ));
        let moved = pos(&w) - start;
        assert!(
            (moved - DVec3::splat(d / 3.0)).length() < 1e-12,
            "{rules}: {moved}"
        );
        assert_eq!(w.block_state(0).held_by, u32::from(PEOPLE), "{rules}");
    }
}

#[test]
fn a_participant_that_leaves_mid_grasp_releases_as_a_lost_hand_does_and_the_others_keep_it() {
    for rules in ["paper", "tracked"] {
        let mut w = floating_cube(rules);
        w.set_previous_hand_of(0, Some(&right_pinch(0.01, DVec3::ZERO)));
        w.set_previous_hand_of(2, Some(&left_pinch(0.01, DVec3::ZERO)));
        w.set_previous_hand_of(4, Some(&top_pinch(0.01, DVec3::ZERO)));
        w.step_hands(three_people(
            &right_pinch(-0.002, DVec3::ZERO),
            Some(&left_pinch(-0.002, DVec3::ZERO)),
            &top_pinch(-0.002, DVec3::ZERO),
        ));
        // Participant 1 leaves: its host sends its hand no more (as a hand a headset lost).
        // Under the paper's rules it lets go at once, under the tracked ones after gap_hold;
        // the block never drops, and stays with the two who hold it.
        let mut released = Vec::new();
        for _ in 0..120 {
            w.step_hands(three_people(
                &right_pinch(-0.002, DVec3::ZERO),
                None,
                &top_pinch(-0.002, DVec3::ZERO),
            ));
            assert_eq!(mode(&w), BlockMode::Grasped, "{rules}");
            released.extend(by(&w, EventKind::Release));
        }
        assert_eq!(
            released,
            vec![0b100],
            "{rules}: participant 1's release, once"
        );
        assert_eq!(w.block_state(0).held_by, 0b1_0001, "{rules}");
    }
}

#[test]
fn a_world_of_one_person_steps_the_same_given_one_or_all_slots() {
    // The slots past a person's two cost nothing and change nothing: a one-hand world given
    // [hand] and [hand, None, None, ...] is the same world, bit for bit.
    let (mut a, mut b) = (floating_cube("tracked"), floating_cube("tracked"));
    for k in 0..40 {
        let h = right_pinch(
            0.01 - 0.0005 * k as f64,
            DVec3::new(0.0, 0.002 * k as f64, 0.0),
        );
        a.step_hands([Some(&h)]);
        b.step_hands([Some(&h), None, None, None, None, None, None, None]);
        let (mut sa, mut sb) = (Default::default(), Default::default());
        a.write_sample(&mut sa);
        b.write_sample(&mut sb);
        assert_eq!(sa, sb, "step {k}");
    }
}
