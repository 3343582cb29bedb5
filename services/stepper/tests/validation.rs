//! Scene validation: what the loader checks (form, ranges) and what the stepper adds
//! (geometry, options not implemented), each error naming the file, the block or key and the
//! problem; and the `simulate` output format.

mod support;

use common::config::Scene;
use stepper::{simulate, World};
use support::*;

fn load_err(text: &str) -> String {
    let dir = std::env::temp_dir().join(format!("stepper-validation-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join(format!("bad{}.toml", text.len()));
    std::fs::write(&file, text).unwrap();
    let e = Scene::load(&file).unwrap_err().to_string();
    let _ = std::fs::remove_file(&file);
    e
}

#[test]
fn loader_errors_name_file_key_and_range() {
    let e = load_err("[[block]]\nposition = [0, 0.05, 0]\nsize = [0.1, 0.1, 5000]\n");
    assert!(
        e.contains("bad") && e.contains("block[0].size") && e.contains("allowed"),
        "{e}"
    );
    let e = load_err("[effects]\nfloor = \"bouncy\"\n");
    assert!(e.contains("effects.floor") && e.contains("tipping"), "{e}");
    let e = load_err("[[block]]\nposition = [0, 0.05, 0]\nmass = 1\n");
    assert!(
        e.contains("block[0].mass") && e.contains("unknown key"),
        "{e}"
    );
    let e = load_err("[world]\ngravity = \"down\"\n");
    assert!(e.contains("world.gravity"), "{e}");
}

#[test]
fn a_block_inside_another_is_reported_with_both_names() {
    let s = scene(
        "[[block]]\nname = \"a\"\nposition = [0, 0.05, 0]\n[[block]]\nname = \"b\"\nposition = [0.05, 0.05, 0]\n",
    );
    let e = World::new(&s).err().unwrap().to_string();
    assert!(e.contains(&*s.file.to_string_lossy()), "{e}");
    assert!(
        e.contains("\"b\"") && e.contains("inside block \"a\""),
        "{e}"
    );
    // Touching is allowed.
    let s = scene(
        "[[block]]\nname = \"a\"\nposition = [0, 0.05, 0]\n[[block]]\nname = \"b\"\nposition = [0.1, 0.05, 0]\n",
    );
    assert!(World::new(&s).is_ok());
}

#[test]
fn a_block_below_the_floor_is_reported() {
    let s = scene("[[block]]\nname = \"low\"\nposition = [0, 0.04, 0]\n");
    let e = World::new(&s).err().unwrap().to_string();
    assert!(
        e.contains("\"low\"") && e.contains("below the floor"),
        "{e}"
    );
    // Without a floor it is fine.
    let s =
        scene("[effects]\nfloor = \"none\"\n[[block]]\nname = \"low\"\nposition = [0, -3, 0]\n");
    assert!(World::new(&s).is_ok());
}

#[test]
fn a_flat_hull_is_reported() {
    let s = scene(
        "[[block]]\nname = \"sheet\"\nshape = \"hull\"\nvertices = [[0,0,0],[1,0,0],[0,0,1],[1,0,1]]\nposition = [0, 1, 0]\n",
    );
    let e = World::new(&s).err().unwrap().to_string();
    assert!(e.contains("\"sheet\"") && e.contains("flat"), "{e}");
}

#[test]
fn options_of_later_issues_are_clear_errors() {
    // R14 is implemented (issue 13): accepted.
    let s = scene("[effects]\nstacking = \"supported\"\n");
    assert!(World::new(&s).is_ok());
}

/// `model = "precise"` is no longer refused: the dispatch builds the rapier3d reference, and
/// it refuses what the paper model refuses (here: a block inside another), with the same words.
#[test]
fn the_precise_model_is_built_by_the_dispatch_and_checked_as_the_paper_model() {
    let s = scene("[world]\nmodel = \"precise\"\n[[block]]\nposition = [0.0, 0.05, 0.0]\n");
    let m = stepper::Model::new(&s).unwrap();
    assert_eq!(m.kind(), common::config::scene::ModelKind::Precise);
    let s = scene(
        "[world]\nmodel = \"precise\"\n[[block]]\nname = \"a\"\nposition = [0.0, 0.05, 0.0]\n\
         [[block]]\nname = \"b\"\nposition = [0.05, 0.05, 0.0]\n",
    );
    let e = stepper::Model::new(&s).err().unwrap().to_string();
    assert!(e.contains("starts inside block \"a\""), "{e}");
}

#[test]
fn json_report_has_design_md_shape() {
    let s = scene_file("grasp-throw-fingers");
    let r = run(&s, 300);
    let j = r.to_json();
    assert!(
        j.starts_with("{\"frames\": 300, \"blocks\": [{\"name\": \"cube\", \"position\": ["),
        "{j}"
    );
    assert!(
        j.contains("\"rotation\": [") && j.contains("\"mode\": \"resting\""),
        "{j}"
    );
    assert!(
        j.contains("{\"step\": 48, \"kind\": \"grasp\", \"block\": \"cube\"}"),
        "{j}"
    );
    assert!(j.contains("\"kind\": \"release\""), "{j}");
    // Valid JSON: balanced, and parseable numbers.
    assert_eq!(j.matches('{').count(), j.matches('}').count());
    let t = r.to_text();
    assert!(
        t.contains("cube") && t.contains("resting") && t.contains("grasp"),
        "{t}"
    );
}

#[test]
fn simulate_without_hand_on_a_hand_scene_ignores_the_hand() {
    let s = scene_file("push");
    let r = simulate(&s, 60, None).unwrap();
    assert_eq!(r.blocks[0].position, [0.0, 0.05, 0.0]);
}

#[test]
fn world_sample_carries_poses_modes_and_no_grasp() {
    let s = scene_file("tip");
    let mut w = World::new(&s).unwrap();
    for _ in 0..100 {
        w.step(None);
    }
    let mut out = common::WorldSample {
        header: common::WorldHeader {
            hand_seq: 77,
            ..Default::default()
        },
        blocks: Vec::new(),
    };
    out.stamp.seq = 5;
    w.write_sample(&mut out);
    assert_eq!(out.hand_seq, 77);
    assert_eq!(out.stamp.seq, 5);
    assert_eq!(out.step, 100);
    assert_eq!(out.block_count, 2);
    assert_eq!(out.grasped_block, -1);
    assert_eq!(out.blocks.len(), 2);
    assert_eq!(out.blocks[0].mode(), common::BlockMode::Resting);
    assert_eq!(out.blocks[0], w.block_state(0));
    assert_eq!(w.block_names().collect::<Vec<_>>(), ["cube", "post"]);
    assert_eq!(w.steps(), 100);
}

/// Issue 13, bad input: what cannot be simulated is refused with the file, the block and the
/// reason, whether the scene comes from a file (the loader) or is built in code (the world
/// repeats the checks the model relies on).
#[test]
fn degenerate_and_zero_size_blocks_are_refused_with_file_block_and_reason() {
    // Zero size: the loader names the file, the block's key and the range.
    let e = load_err("[[block]]\nname = \"dot\"\nposition = [0, 1, 0]\nsize = [0.1, 0.0, 0.1]\n");
    assert!(
        e.contains("bad") && e.contains("block[0].size") && e.contains("allowed"),
        "{e}"
    );
    // Built in code: the world refuses it by name.
    let mut s = scene("[[block]]\nname = \"dot\"\nposition = [0, 1, 0]\n");
    s.blocks[0].shape = common::config::scene::ShapeSpec::Box {
        size: [0.1, 0.0, 0.1],
    };
    let e = World::new(&s).err().unwrap().to_string();
    assert!(
        e.contains(&*s.file.to_string_lossy()) && e.contains("\"dot\"") && e.contains("flat"),
        "{e}"
    );
    s.blocks[0].shape = common::config::scene::ShapeSpec::Box {
        size: [0.1, f64::NAN, 0.1],
    };
    let e = World::new(&s).err().unwrap().to_string();
    assert!(e.contains("\"dot\"") && e.contains("finite"), "{e}");
    // Degenerate hulls: all points equal, or on one line.
    for vertices in [
        "[[0,0,0],[0,0,0],[0,0,0],[0,0,0]]",
        "[[0,0,0],[0.1,0.1,0.1],[0.2,0.2,0.2],[0.3,0.3,0.3]]",
    ] {
        let s = scene(&format!(
            "[[block]]\nname = \"needle\"\nshape = \"hull\"\nvertices = {vertices}\nposition = [0, 1, 0]\n"
        ));
        let e = World::new(&s).err().unwrap().to_string();
        assert!(
            e.contains(&*s.file.to_string_lossy()) && e.contains("\"needle\""),
            "{e}"
        );
        assert!(
            e.contains("flat") || e.contains("solid") || e.contains("degenerate"),
            "{e}"
        );
    }
}

/// Overlapping spawns are refused under R14 too (supported stacking could otherwise start from
/// an interpenetrating stack), naming both blocks and the depth.
#[test]
fn an_overlapping_spawn_is_refused_under_supported_stacking() {
    let s = scene(
        "[effects]\nstacking = \"supported\"\n[[block]]\nname = \"low\"\nposition = [0, 0.05, 0]\n\
         [[block]]\nname = \"high\"\nposition = [0, 0.14, 0]\n",
    );
    let e = World::new(&s).err().unwrap().to_string();
    assert!(
        e.contains("\"high\"") && e.contains("inside block \"low\"") && e.contains("0.010000 m"),
        "{e}"
    );
}
