//! `handblocks bench tosses` (issue 42, item 1): MuJoCo and PyBullet, driven from Python
//! (`bench/python/toss_engines.py`), run real tosses from their first tracked state and hand
//! back paths the bench scores with the same code as its own models. Needs the engines' venv
//! (`target/toss-engines`, which the bench makes from the package index; `HB_TOSS_PYTHON`
//! names another Python): without it the test says it was skipped.

use std::path::{Path, PathBuf};

use handblocks_bench::tosses::{self, Engine, OutsideEngine, HALF_WIDTH};

#[test]
fn mujoco_and_pybullet_start_each_toss_where_it_starts_and_land_it_on_the_board() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = repo.join("../shared/data/tosses");
    if !dir.is_dir() {
        eprintln!("skipped: {} is missing", dir.display());
        return;
    }
    let (all, refused) = tosses::load_dir(&dir).unwrap_or_else(|e| panic!("{e}"));
    assert!(refused.is_empty(), "{refused:?}");
    let floor = tosses::floor_offset(&all);
    let some: Vec<&tosses::Toss> = all.iter().take(8).collect();
    let fits =
        tosses::load_fit(&repo.join("config/tosses-fit.toml")).unwrap_or_else(|e| panic!("{e}"));
    let python = std::env::var_os("HB_TOSS_PYTHON").map(PathBuf::from);
    let scratch = std::env::temp_dir().join(format!("hb-tosses-test-{}", std::process::id()));
    let outside = match tosses::Outside::prepare(&repo, python.as_deref(), &scratch, &mut |l| {
        eprintln!("{l}")
    }) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("skipped: {e}");
            return;
        }
    };
    let mut seen = Vec::new();
    for c in tosses::contenders(&fits, &OutsideEngine::ALL) {
        let Engine::Outside { engine, .. } = c.engine else {
            continue;
        };
        let what = format!("{} ({})", c.name, c.setting);
        let (paths, ns) = tosses::run_contender(&c, &some, floor, Some(&outside))
            .unwrap_or_else(|e| panic!("{what}: {e}"));
        assert!(ns > 0, "{what}: the engine's loop was timed");
        assert_eq!(paths.len(), some.len(), "{what}");
        let mut errors = Vec::new();
        let mut rest_heights = Vec::new();
        for (toss, path) in some.iter().zip(&paths) {
            assert_eq!(path.len(), toss.samples.len(), "{what}");
            // The first pose is the toss's first sample, through both frame changes and back.
            let first = toss.samples[0];
            assert!(
                (path[0].0 - first.position).length() < 1e-9
                    && path[0].1.angle_between(first.rotation) < 1e-6,
                "{what}: {:?} against {:?}",
                path[0],
                (first.position, first.rotation)
            );
            errors.push(tosses::score(toss, path).position_error);
            rest_heights.push(path[path.len() - 1].0.y - floor);
        }
        errors.sort_by(f64::total_cmp);
        rest_heights.sort_by(f64::total_cmp);
        let median_error = errors[errors.len() / 2];
        let median_rest = rest_heights[rest_heights.len() / 2];
        // A cube that ends on a face rests at its half-width; a frame turned the wrong way
        // would throw it sideways or under the board.
        assert!(
            (median_rest - HALF_WIDTH).abs() < 5e-3,
            "{what}: rests at {median_rest} m"
        );
        if c.setting.contains("fitted") {
            assert!(
                median_error < 0.5,
                "{what}: median error {median_error} edges"
            );
        }
        seen.push(engine);
    }
    assert!(
        seen.contains(&OutsideEngine::MuJoCo) && seen.contains(&OutsideEngine::PyBullet),
        "{seen:?}"
    );
    let _ = std::fs::remove_dir_all(&scratch);
}
