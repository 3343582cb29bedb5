//! The scenes in config/scenes behave as their comments say.

mod support;

use support::*;

#[test]
fn drop_blocks_fall_and_rest() {
    let s = scene_file("drop");
    let r = run(&s, 360);
    print!("{}", r.to_text());
    for b in &r.blocks {
        assert_eq!(b.mode, common::BlockMode::Resting, "{}", b.name);
    }
}

#[test]
fn tip_and_balance_print() {
    for name in [
        "tip",
        "balance",
        "push",
        "carry",
        "stack-paper",
        "drop",
        "grasp-throw-fingers",
    ] {
        let s = scene_file(name);
        let r = run(&s, 600);
        print!("{name}: {}", r.to_text());
    }
}
