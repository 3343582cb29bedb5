//! Hard cases other engines test (notes/physics.md), in our terms.

mod support;

use support::{run, scene};

#[test]
fn a_thin_plate_1000_to_1_is_a_solid_that_lands_flat_r8_r9() {
    // 1 m x 0.5 mm x 1 m, dropped tilted: it must not be refused as flat, and must come to
    // rest face down with G at half its thickness.
    let s = scene(
        "[[block]]\nname = \"plate\"\nsize = [1.0, 0.0005, 1.0]\nposition = [0.0, 0.3, 0.0]\n\
         rotation = [0.0998334, 0.0, 0.0, 0.9950042]\n",
    );
    let r = run(&s, 240);
    let b = &r.blocks[0];
    assert_eq!(b.mode.name(), "resting");
    assert!(
        (b.position[1] - 0.00025).abs() < 1e-9,
        "G at y = {}",
        b.position[1]
    );
    let tilt = 2.0
        * b.rotation[0]
            .hypot(b.rotation[2])
            .atan2(b.rotation[3].hypot(b.rotation[1]));
    assert!(tilt < 1e-9, "the plate rests tilted by {tilt} rad");
}

#[test]
fn a_grain_falling_2_m_onto_a_fifth_of_a_millimetre_plate_does_not_pass_through_r12() {
    let s = scene(
        "[world]\nstep_hz = 120\n\
         [[block]]\nname = \"grain\"\nsize = [0.001, 0.001, 0.001]\nposition = [0.0, 2.0, 0.0]\n\
         [[block]]\nname = \"plate\"\nsize = [1.0, 0.0002, 1.0]\nposition = [0.0, 0.0001, 0.0]\n",
    );
    let r = run(&s, 240);
    let grain = &r.blocks[0];
    assert!(
        grain.position[1] >= 0.0002 + 0.0005 - 1e-4,
        "the grain tunnelled to y = {}",
        grain.position[1]
    );
}
