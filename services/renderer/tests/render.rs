//! Renders known scenes on whatever adapter wgpu finds (Mesa's llvmpipe in CI) and asserts
//! facts measured in the pixels: where a block appears in each eye, its disparity against the
//! off-axis stereo formula, its own colour in every mode and its outline by mode, the hand
//! drawn where the world puts it, and the anaglyph's channels.

use std::path::PathBuf;

use common::config::scene::{BlockSpec, Effects, Scene, ShapeSpec, WorldSettings};
use common::{BlockMode, BlockState, HandSample, Pose, WorldSample};
use glam::DVec3;
use renderer::camera::{expected_disparity_px, Eye, Viewer};
use renderer::image::Image;
use renderer::output::write_frame;
use renderer::png::read_png;
use renderer::{CameraSettings, OutputMode, RenderSettings, Renderer};

const W: u32 = 320;
const H: u32 = 240;
const SIZE: f64 = 0.04;

/// Looking horizontally along -z from 10 cm above the floor, 1 m from the origin: depth of a
/// point is 1 - z.
fn camera() -> CameraSettings {
    CameraSettings {
        eye: [0.0, 0.1, 1.0],
        target: [0.0, 0.1, 0.0],
        ..CameraSettings::default()
    }
}

fn settings(output: OutputMode, shadows: bool) -> RenderSettings {
    RenderSettings {
        width: W,
        height: H,
        output,
        camera: camera(),
        shadows,
    }
}

fn scene(n: usize) -> Scene {
    Scene {
        file: PathBuf::from("test.toml"),
        world: WorldSettings::default(),
        effects: Effects::default(),
        blocks: (0..n)
            .map(|i| BlockSpec {
                // Named for their colour (draw_list::color_for_name): the tests find them by it.
                name: format!("red{i}"),
                shape: ShapeSpec::Box {
                    size: [SIZE, SIZE, SIZE],
                },
                position: [0.0; 3],
                rotation: [0.0, 0.0, 0.0, 1.0],
                velocity: [0.0; 3],
            })
            .collect(),
        hand: None,
        left_hand: None,
    }
}

/// A world of blocks at `positions`, all in `mode`.
fn world(positions: &[[f64; 3]], mode: BlockMode) -> WorldSample {
    let mut w = WorldSample::with_blocks(positions.len());
    for (b, p) in w.blocks.iter_mut().zip(positions) {
        *b = BlockState {
            pose: Pose {
                position: *p,
                rotation: [0.0, 0.0, 0.0, 1.0],
            },
            mode: mode as u32,
            held_by: 0,
        };
    }
    w
}

fn renderer(s: &RenderSettings, blocks: usize) -> Renderer {
    match Renderer::new_headless(s, &scene(blocks)) {
        Ok(r) => r,
        Err(e) => panic!("{e}"),
    }
}

fn draw(r: &mut Renderer, w: &WorldSample, h: &HandSample) -> Image {
    r.render(w.view(), h).unwrap();
    r.read_back().unwrap()
}

/// Red-dominant pixels: a block named red (floor, sky, shadows and skin are not).
fn is_red(p: [u8; 4]) -> bool {
    p[0] as i32 > p[1] as i32 + 40 && p[0] as i32 > p[2] as i32 + 40
}

/// Mean position and count of the pixels that pass `f`.
fn centroid(img: &Image, f: impl Fn(u32, u32) -> bool) -> (f64, f64, usize) {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for y in 0..img.height {
        for x in 0..img.width {
            if f(x, y) {
                sx += x as f64 + 0.5;
                sy += y as f64 + 0.5;
                n += 1;
            }
        }
    }
    (sx / n.max(1) as f64, sy / n.max(1) as f64, n)
}

/// The disparities of a box's front and back faces: the measured one must lie between.
fn expected_range(depth: f64) -> (f64, f64) {
    let c = camera();
    let a = expected_disparity_px(&c, W, depth - SIZE / 2.0);
    let b = expected_disparity_px(&c, W, depth + SIZE / 2.0);
    (a.min(b), a.max(b))
}

#[test]
fn a_block_appears_in_both_eyes_with_the_disparity_its_depth_gives() {
    let s = settings(OutputMode::SideBySide, true);
    let mut r = renderer(&s, 1);
    let hand = HandSample::default();
    // Behind the screen plane (0.6 m): uncrossed, right image to the right; in front: crossed.
    for depth in [1.2, 0.4, 0.6] {
        let img = draw(
            &mut r,
            &world(&[[0.0, 0.1, 1.0 - depth]], BlockMode::Resting),
            &hand,
        );
        assert_eq!((img.width, img.height), (2 * W, H));
        let (l, rt) = (img.eye(Eye::Left), img.eye(Eye::Right));
        let (lx, ly, ln) = centroid(&l, |x, y| is_red(l.pixel(x, y)));
        let (rx, ry, rn) = centroid(&rt, |x, y| is_red(rt.pixel(x, y)));
        assert!(
            ln > 50 && rn > 50,
            "depth {depth}: block pixels left {ln}, right {rn}"
        );
        let d = rx - lx;
        let (lo, hi) = expected_range(depth);
        println!(
            "depth {depth} m: {ln}/{rn} px, disparity {d:.2} px, expected {lo:.2}..{hi:.2} px \
             (ipd * (1 - d/z) at the front and back faces)"
        );
        assert!(
            d >= lo - 1.0 && d <= hi + 1.0,
            "depth {depth}: {d} not in {lo}..{hi}"
        );
        assert!((ly - ry).abs() < 0.5, "vertical disparity {}", ly - ry);
        if depth > 0.7 {
            assert!(d > 10.0);
        } else if depth < 0.5 {
            assert!(d < -10.0);
        }
        // And where the camera model puts it: the projected centre, within a few pixels.
        let g = DVec3::new(0.0, 0.1, 1.0 - depth);
        let (px, py) = r.eye_views()[0].project_px(g, W, H).unwrap();
        assert!(
            (px - lx).abs() < 3.0 && (py - ly).abs() < 3.0,
            "{px},{py} vs {lx},{ly}"
        );
    }
}

/// A block keeps its own colour (red, by its name) in every mode, grasped included; its
/// outline shows the mode, differently for each.
#[test]
fn a_block_keeps_its_colour_in_every_mode_and_its_outline_tells_the_mode() {
    let s = settings(OutputMode::SideBySide, true);
    let mut r = renderer(&s, 1);
    let g = DVec3::new(0.0, 0.1, 0.3);
    let (px, py) = r.eye_views()[0].project_px(g, W, H).unwrap();
    // The front face's centre: 5 x 5 pixels around the projected centre of gravity.
    let patch = |img: &Image| -> [f64; 3] {
        let mut sum = [0.0; 3];
        for dy in -2..=2 {
            for dx in -2..=2 {
                let p = img.pixel((px as i32 + dx) as u32, (py as i32 + dy) as u32);
                for c in 0..3 {
                    sum[c] += p[c] as f64 / 25.0;
                }
            }
        }
        sum
    };
    let hand = HandSample::default();
    let mut w = world(&[g.to_array()], BlockMode::Resting);
    let resting_img = draw(&mut r, &w, &hand);
    let resting = patch(&resting_img);
    w.grasped_block = 0;
    let grasped_img = draw(&mut r, &w, &hand);
    let grasped = patch(&grasped_img);
    w.grasped_block = -1;
    w.blocks[0].mode = BlockMode::Grasped as u32;
    let grasped_by_mode_img = draw(&mut r, &w, &hand);
    println!("front face rgb: resting {resting:?}, grasped {grasped:?}");
    assert!(resting[0] > resting[1] + 60.0 && resting[0] > resting[2] + 60.0);
    for c in 0..3 {
        assert!(
            (grasped[c] - resting[c]).abs() < 2.0,
            "the face keeps its colour"
        );
    }
    assert!(grasped_img == grasped_by_mode_img);
    // Around the block: the pixels where two modes' images differ (the outline).
    let differing = |a: &Image, b: &Image| {
        let mut n = 0;
        for y in (py as u32).saturating_sub(40)..(py as u32 + 40).min(H) {
            for x in (px as u32).saturating_sub(40)..(px as u32 + 40).min(W) {
                let (p, q) = (a.pixel(x, y), b.pixel(x, y));
                let d: i32 = (0..3).map(|c| (p[c] as i32 - q[c] as i32).abs()).sum();
                if d > 60 {
                    n += 1;
                }
            }
        }
        n
    };
    let mut seen: Vec<(BlockMode, Image)> = Vec::new();
    for mode in BlockMode::ALL {
        w.blocks[0].mode = mode as u32;
        let img = draw(&mut r, &w, &hand);
        let c = patch(&img);
        for k in 0..3 {
            assert!(
                (c[k] - resting[k]).abs() < 2.0,
                "{mode:?}: the face keeps its colour"
            );
        }
        for (m, o) in &seen {
            let n = differing(&img, o);
            assert!(n > 20, "{mode:?} and {m:?} look alike: {n} px differ");
        }
        seen.push((mode, img));
    }
}

#[test]
fn fingers_are_drawn_where_the_world_relocated_them_and_the_palm_where_the_hand_has_it() {
    let s = settings(OutputMode::SideBySide, false);
    let mut r = renderer(&s, 1);
    let block = [0.0, 0.1, 0.3];
    let base = world(&[block], BlockMode::Grasped);
    let mut hand = HandSample {
        finger_count: 1,
        finger_point_count: [2, 0, 0, 0, 0],
        finger_radius: [0.01, 0.0, 0.0, 0.0, 0.0],
        ..Default::default()
    };
    // The hand's own points: 12 cm to the right of the block; the world's, on its left face.
    hand.finger_points[0][0] = [0.12, 0.09, 0.3];
    hand.finger_points[0][1] = [0.12, 0.11, 0.3];
    let mut w = base.clone();
    w.finger_count = 1;
    w.finger_point_count[0] = 2;
    w.finger_points[0][0] = [-0.03, 0.09, 0.3];
    w.finger_points[0][1] = [-0.03, 0.11, 0.3];
    let without = draw(&mut r, &base, &HandSample::default());
    let with = draw(&mut r, &w, &hand);
    let eye = r.eye_views()[0];
    let changed_near = |p: [f64; 3]| {
        let (x, y) = eye.project_px(DVec3::from_array(p), W, H).unwrap();
        let mut n = 0;
        for dy in -3..=3 {
            for dx in -3..=3 {
                let (xx, yy) = ((x as i32 + dx) as u32, (y as i32 + dy) as u32);
                if with.pixel(xx, yy) != without.pixel(xx, yy) {
                    n += 1;
                }
            }
        }
        n
    };
    let at_world = changed_near([-0.03, 0.1, 0.3]);
    let at_hand = changed_near([0.12, 0.1, 0.3]);
    println!(
        "pixels changed near the relocated fingers {at_world}/49, near the hand's own {at_hand}/49"
    );
    assert!(at_world > 40);
    assert_eq!(at_hand, 0);

    // The palm: the hull of the hand sample's palm box, in skin colour (r > g > b).
    let mut k = 0;
    for x in [-0.14, -0.10] {
        for y in [0.08, 0.12] {
            for z in [0.28, 0.32] {
                hand.palm_vertices[k] = [x, y, z];
                k += 1;
            }
        }
    }
    hand.palm_vertex_count = 8;
    let img = draw(&mut r, &w, &hand);
    let (x, y) = eye.project_px(DVec3::new(-0.12, 0.1, 0.32), W, H).unwrap();
    let p = img.pixel(x as u32, y as u32);
    println!("palm front face {p:?}");
    assert!(p[0] > p[1] && p[1] > p[2] && p[0] > 150, "{p:?}");
}

/// Reverses the sRGB curve, 0..1.
fn linear(v: u8) -> f64 {
    let c = v as f64 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

#[test]
fn the_anaglyph_carries_the_left_eye_in_red_and_the_right_in_cyan() {
    let mut sbs = renderer(&settings(OutputMode::SideBySide, false), 1);
    let mut ana = renderer(&settings(OutputMode::Anaglyph, false), 1);
    let hand = HandSample::default();
    let empty = world(&[], BlockMode::Resting);
    let bg = draw(&mut ana, &empty, &hand);
    assert_eq!((bg.width, bg.height), (W, H));
    let mut shifts = Vec::new();
    for depth in [1.2, 0.6] {
        let w = world(&[[0.0, 0.1, 1.0 - depth]], BlockMode::Resting);
        let a = draw(&mut ana, &w, &hand);
        let eyes = draw(&mut sbs, &w, &hand);
        let (l, r) = (eyes.eye(Eye::Left), eyes.eye(Eye::Right));
        // Composition: red = the left eye's luminance, green and blue = the right eye's.
        for (x, y) in [
            (W / 2, H / 2),
            (10, 10),
            (W / 3, H - 20),
            (W / 2 + 5, H / 2 + 3),
        ] {
            let (lp, rp, ap) = (l.pixel(x, y), r.pixel(x, y), a.pixel(x, y));
            let lum = 0.299 * linear(lp[0]) + 0.587 * linear(lp[1]) + 0.114 * linear(lp[2]);
            assert!(
                (linear(ap[0]) - lum).abs() < 0.01,
                "{x},{y}: {ap:?} vs {lp:?}"
            );
            assert!(
                (ap[1] as i32 - rp[1] as i32).abs() <= 1
                    && (ap[2] as i32 - rp[2] as i32).abs() <= 1
            );
        }
        // Where the block changes the red channel (left eye) and where it changes green and
        // blue (right eye): shifted by the disparity, so they disagree only off the screen.
        let red = |x: u32, y: u32| (a.pixel(x, y)[0] as i32 - bg.pixel(x, y)[0] as i32).abs() > 25;
        let cyan = |x: u32, y: u32| {
            let (p, q) = (a.pixel(x, y), bg.pixel(x, y));
            (p[1] as i32 - q[1] as i32).abs() + (p[2] as i32 - q[2] as i32).abs() > 25
        };
        let (rx, _, rn) = centroid(&a, red);
        let (cx, _, cn) = centroid(&a, cyan);
        let (_, _, disagree) = centroid(&a, |x, y| red(x, y) != cyan(x, y));
        let (lo, hi) = expected_range(depth);
        println!(
            "anaglyph, depth {depth} m: red {rn} px, cyan {cn} px, shift {:.2} px \
             (expected {lo:.2}..{hi:.2}), channels disagree at {disagree} px",
            cx - rx
        );
        assert!(rn > 50 && cn > 50);
        assert!(cx - rx >= lo - 1.0 && cx - rx <= hi + 1.0);
        shifts.push((cx - rx, disagree));
    }
    // Far from the screen plane the channels disagree along both sides of the block; on it,
    // barely at all.
    assert!(shifts[0].1 > 4 * shifts[1].1.max(1), "{shifts:?}");
}

#[test]
fn output_modes_write_the_files_they_promise() {
    let dir = std::env::temp_dir().join(format!("hb-renderer-out-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let w = world(&[[0.0, 0.1, 0.0]], BlockMode::Resting);
    let hand = HandSample::default();
    let mut scratch = Image::default();
    for (mode, files, width) in [
        (OutputMode::SideBySide, 1, 2 * W + renderer::image::EYE_GAP),
        (OutputMode::Anaglyph, 1, W),
        (OutputMode::Separate, 2, W),
    ] {
        let mut r = renderer(&settings(mode, true), 1);
        let img = draw(&mut r, &w, &hand);
        let dir = dir.join(format!("{mode:?}"));
        std::fs::create_dir_all(&dir).unwrap();
        let paths = write_frame(&dir, 7, mode, &img, &mut scratch).unwrap();
        assert_eq!(paths.len(), files);
        // A frame is a new private file: written again, it is refused, not overwritten.
        assert!(write_frame(&dir, 7, mode, &img, &mut scratch).is_err());
        let private = std::os::unix::fs::PermissionsExt::mode(
            &std::fs::metadata(&paths[0]).unwrap().permissions(),
        );
        assert_eq!(private & 0o777, 0o600);
        for (i, p) in paths.iter().enumerate() {
            let back = read_png(p).unwrap();
            assert_eq!((back.width, back.height), (width, H), "{}", p.display());
            // Side by side: the two eyes with a gap between them.
            let want = match mode {
                OutputMode::Separate => img.eye(if i == 0 { Eye::Left } else { Eye::Right }),
                OutputMode::SideBySide => {
                    let mut g = Image::default();
                    img.with_eye_gap_into(&mut g);
                    g
                }
                OutputMode::Anaglyph => img.clone(),
            };
            assert!(back == want, "{} differs from the frame", p.display());
        }
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bad_poses_skip_that_block_and_bad_settings_are_errors() {
    let s = settings(OutputMode::SideBySide, true);
    let mut r = renderer(&s, 2);
    let mut w = world(&[[f64::NAN, 0.1, 0.0], [0.0, 0.1, 0.0]], BlockMode::Resting);
    let img = draw(&mut r, &w, &HandSample::default());
    let (_, _, n) = centroid(&img, |x, y| is_red(img.pixel(x, y)));
    assert!(n > 50);
    w.blocks[1].pose.rotation = [f64::INFINITY, 0.0, 0.0, 1.0];
    let img = draw(&mut r, &w, &HandSample::default());
    let (_, _, n) = centroid(&img, |x, y| is_red(img.pixel(x, y)));
    assert_eq!(n, 0);

    let mut bad = s.clone();
    bad.camera.target = bad.camera.eye;
    let e = Renderer::new_headless(&bad, &scene(1))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("target"), "{e}");
    let mut flat = scene(1);
    flat.blocks[0].shape = ShapeSpec::Hull {
        vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0]],
    };
    let e = Renderer::new_headless(&s, &flat).err().unwrap().to_string();
    assert!(e.contains("\"red0\"") && e.contains("no volume"), "{e}");
}

#[test]
fn the_default_camera_sees_the_blocks_around_the_origin_and_the_hand_above() {
    let s = RenderSettings {
        width: 160,
        height: 120,
        ..RenderSettings::default()
    };
    let v = Viewer::new(&s.camera);
    let mut r = renderer(&s, 0);
    for p in [
        [0.0, 0.0, 0.0],
        [0.4, 0.0, 0.3],
        [-0.4, 0.0, -0.4],
        [0.0, 0.4, 0.0],
    ] {
        let d = DVec3::from_array(p);
        assert!(v.depth(d) > 0.3);
        for e in r.eye_views() {
            let (x, y) = e.project_px(d, 160, 120).unwrap();
            assert!(
                (0.0..160.0).contains(&x) && (0.0..120.0).contains(&y),
                "{p:?}: {x},{y}"
            );
        }
    }
    let t = r
        .render(WorldSample::default().view(), &HandSample::default())
        .unwrap();
    assert!(t.done_ns >= t.submitted_ns && t.submitted_ns >= t.started_ns);
}

#[test]
fn every_shape_kind_is_drawn_centred_on_its_centre_of_gravity() {
    let s = settings(OutputMode::SideBySide, false);
    let mut sc = scene(4);
    sc.blocks[1].shape = ShapeSpec::Wedge {
        size: [0.05, 0.04, 0.04],
    };
    sc.blocks[2].shape = ShapeSpec::Tetra {
        size: [0.05, 0.05, 0.05],
    };
    // An octahedron given far from its own origin: drawn around G all the same.
    sc.blocks[3].shape = ShapeSpec::Hull {
        vertices: vec![
            [10.03, 5.0, 0.0],
            [9.97, 5.0, 0.0],
            [10.0, 5.03, 0.0],
            [10.0, 4.97, 0.0],
            [10.0, 5.0, 0.03],
            [10.0, 5.0, -0.03],
        ],
    };
    let mut r = Renderer::new_headless(&s, &sc).unwrap();
    let xs = [-0.15, -0.05, 0.05, 0.15];
    let w = world(&xs.map(|x| [x, 0.1, 0.3]), BlockMode::Resting);
    let img = draw(&mut r, &w, &HandSample::default()).eye(Eye::Left);
    let eye = r.eye_views()[0];
    for (i, x) in xs.iter().enumerate() {
        let (px, py) = eye.project_px(DVec3::new(*x, 0.1, 0.3), W, H).unwrap();
        let (cx, cy, n) = centroid(&img, |u, v| {
            (u as f64 - px).abs() < 20.0 && (v as f64 - py).abs() < 20.0 && is_red(img.pixel(u, v))
        });
        println!("shape {i}: {n} px, image centre {cx:.1},{cy:.1}, G at {px:.1},{py:.1}");
        assert!(n > 40, "shape {i}: {n} px");
        // The image's centre is G's projection up to perspective and the shape's asymmetry.
        assert!((cx - px).abs() < 5.0 && (cy - py).abs() < 5.0);
    }
}

/// The shadow pass draws only the projected faces that wind one way as the camera sees the
/// floor (pipeline.rs): for a closed solid they still cover the whole shadow, once. Seen from
/// above, a floating block's shadow (the floor darkened where it is, against the same frame
/// without shadows) is one solid region: no row of it has a hole, for a box and a tetrahedron
/// at several orientations, including faces edge-on to the light.
#[test]
fn a_floating_block_casts_one_whole_shadow_whatever_its_orientation() {
    let above = CameraSettings {
        eye: [0.0, 1.2, 0.3],
        target: [0.0, 0.0, 0.0],
        ..CameraSettings::default()
    };
    let rotations: [[f64; 4]; 4] = [
        [0.0, 0.0, 0.0, 1.0],
        // 45 degrees about y, then tilted: faces at every angle to the light.
        [0.0, 0.382_683_4, 0.0, 0.923_879_5],
        [0.270_598, 0.270_598, 0.653_281_5, 0.653_281_5],
        [0.5, 0.5, 0.5, 0.5],
    ];
    for shape in [
        ShapeSpec::Box {
            size: [0.12, 0.06, 0.09],
        },
        ShapeSpec::Tetra {
            size: [0.12, 0.1, 0.09],
        },
    ] {
        let mut sc = scene(1);
        sc.blocks[0].shape = shape.clone();
        for rotation in rotations {
            let mut w = world(&[[0.0, 0.25, 0.0]], BlockMode::Free);
            w.blocks[0].pose.rotation = rotation;
            let frame = |shadows: bool| {
                let s = RenderSettings {
                    camera: above,
                    ..settings(OutputMode::SideBySide, shadows)
                };
                let mut r = Renderer::new_headless(&s, &sc).unwrap();
                draw(&mut r, &w, &HandSample::default()).eye(Eye::Left)
            };
            let (lit, dark) = (frame(false), frame(true));
            let shadowed = |x: u32, y: u32| {
                let (a, b) = (lit.pixel(x, y), dark.pixel(x, y));
                (a[0] as i32 - b[0] as i32) > 20
            };
            // The bare floor's colour: the commonest pixel without shadows. Grid lines are
            // drawn over shadows (equal in both frames) but are not this colour.
            let floor = {
                let mut px: Vec<[u8; 4]> = (0..lit.height)
                    .flat_map(|y| (0..lit.width).map(move |x| (x, y)))
                    .map(|(x, y)| lit.pixel(x, y))
                    .collect();
                px.sort_unstable();
                let mut best = (0, px[0]);
                for run in px.chunk_by(|a, b| a == b) {
                    if run.len() > best.0 {
                        best = (run.len(), run[0]);
                    }
                }
                best.1
            };
            let bare_floor =
                |p: [u8; 4]| (0..3).all(|c| (p[c] as i32 - floor[c] as i32).abs() <= 6);
            let mut rows = 0;
            for y in 0..dark.height {
                let xs: Vec<u32> = (0..dark.width).filter(|&x| shadowed(x, y)).collect();
                let (Some(&first), Some(&last)) = (xs.first(), xs.last()) else {
                    continue;
                };
                rows += 1;
                // A block or a grid line over the shadow hides part of a row; a face culled
                // wrongly would leave bare floor inside it.
                let holes = (first..=last)
                    .filter(|&x| bare_floor(dark.pixel(x, y)))
                    .count();
                assert_eq!(holes, 0, "{shape:?} at {rotation:?}: row {y} has a hole");
            }
            assert!(
                rows > 10,
                "{shape:?} at {rotation:?}: no shadow ({rows} rows)"
            );
        }
    }
}

/// The static layer (`static_layer.rs`) changes what a frame costs, never what it shows: a
/// frame started from the layer's image has the bytes of the same frame drawn by a renderer
/// that never saw an earlier one, whether a live block moved (the image is reused), a block of
/// the layer moved (it is redrawn), a resting block was grasped, or blocks came to rest; and
/// with blocks clear of the floor (no 0.8 mm shadow plane between a side and the floor, where
/// the two layers' order shows) it is also the frame drawn whole, the layer off.
#[test]
fn a_frame_from_the_static_layer_is_the_frame_drawn_from_scratch() {
    let above = CameraSettings {
        eye: [0.0, 0.6, 0.5],
        target: [0.0, 0.0, 0.0],
        ..CameraSettings::default()
    };
    let s = RenderSettings {
        camera: above,
        ..settings(OutputMode::SideBySide, true)
    };
    let positions: Vec<[f64; 3]> = (0..16)
        .map(|i| {
            [
                0.08 * (i % 4) as f64 - 0.12,
                0.02,
                0.08 * (i / 4) as f64 - 0.12,
            ]
        })
        .collect();
    let mut w = world(&positions, BlockMode::Resting);
    let hand = HandSample::default();
    let fresh = |w: &WorldSample, layer: bool| {
        let mut r = renderer(&s, 16);
        r.set_static_layer(layer);
        draw(&mut r, w, &hand)
    };
    let mut r = renderer(&s, 16);
    let first = draw(&mut r, &w, &hand);
    assert_eq!(r.static_layer_blocks(), 16);
    assert!(first.rgba == fresh(&w, true).rgba);
    // A block is pushed out of the layer (redrawn without it), then moves live (reused).
    w.blocks[5].mode = BlockMode::Pushed as u32;
    w.blocks[5].pose.position[0] += 0.01;
    assert!(draw(&mut r, &w, &hand).rgba == fresh(&w, true).rgba);
    assert_eq!(r.static_layer_blocks(), 15);
    for step in 0..3 {
        w.blocks[5].pose.position[0] += 0.01;
        w.blocks[5].pose.rotation = [
            0.0,
            (0.1 * step as f64).sin(),
            0.0,
            (0.1 * step as f64).cos(),
        ];
        assert!(
            draw(&mut r, &w, &hand).rgba == fresh(&w, true).rgba,
            "live step {step}"
        );
        assert_eq!(r.static_layer_blocks(), 15);
    }
    // A block of the layer moves without leaving rest (a nudge): redrawn.
    w.blocks[10].pose.position[2] += 0.005;
    assert!(draw(&mut r, &w, &hand).rgba == fresh(&w, true).rgba);
    // Grasped: out of the layer, in the grasp colour.
    w.header.grasped_block = 0;
    assert!(draw(&mut r, &w, &hand).rgba == fresh(&w, true).rgba);
    assert_eq!(r.static_layer_blocks(), 14);
    // Blocks clear of the floor: the layered frame is the frame drawn whole.
    let mut high = world(&positions, BlockMode::Resting);
    for b in &mut high.blocks {
        b.pose.position[1] = 0.1;
    }
    high.blocks[3].mode = BlockMode::Free as u32;
    let mut r = renderer(&s, 16);
    draw(&mut r, &high, &hand);
    high.blocks[3].pose.position[1] = 0.09;
    let layered = draw(&mut r, &high, &hand);
    assert_eq!(r.static_layer_blocks(), 15);
    let whole = fresh(&high, false);
    let differ = layered
        .rgba
        .chunks(4)
        .zip(whole.rgba.chunks(4))
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(
        differ, 0,
        "{differ} pixels differ from the frame drawn whole"
    );
}
