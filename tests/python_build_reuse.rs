//! The Python wheel reuses the test build's libraries instead of compiling them a second time.
//!
//! `tests/run` builds the workspace (`cargo test --workspace`), then `pip install ./python`,
//! which makes maturin build the one package `handblocks-python`. Cargo resolves features over
//! the packages a command builds, so that second build saw fewer features for a handful of
//! small crates (libc for build scripts, memchr, smallvec, bytemuck, ...). A crate built with
//! other features is another library, and so is every crate above it: iceoryx2, rapier3d and
//! nalgebra compiled twice, 77 units, minutes of CI and a second copy in target/ (a CI run once
//! ran out of disk on it). `python/Cargo.toml` pins those features; this test fails when a
//! dependency change makes the pins stale, and names the crates to pin.
//!
//! The check reads `cargo tree` (offline, from Cargo.lock): every crate the package builds, with
//! the features it gets on its own, must appear with the same features in the workspace's tree.
//! Two passes, because build scripts and proc macros resolve their features apart from the
//! libraries they build: `-e normal` (what links into the wheel) and `-e normal,build`.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::Command;

fn repository() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `cargo tree` lines `name vX.Y.Z [features]`, deduplicated.
fn tree(selection: &[&str], edges: &str) -> BTreeSet<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = Command::new(cargo)
        .current_dir(repository())
        .args(["tree", "--offline", "--locked", "--prefix", "none"])
        .args(["-e", edges, "-f", "{p} [{f}]"])
        .args(selection)
        .output()
        .expect("cargo tree starts");
    assert!(
        output.status.success(),
        "cargo tree {selection:?} -e {edges} failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|line| line.trim_end_matches(" (*)").to_string())
        .filter(|line| !line.is_empty() && !line.starts_with('['))
        .collect()
}

#[test]
fn the_python_package_builds_with_the_workspaces_features() {
    for edges in ["normal", "normal,build"] {
        let package = tree(&["-p", "handblocks-python"], edges);
        let workspace = tree(&["--workspace"], edges);
        let differing: Vec<&String> = package.difference(&workspace).collect();
        assert!(
            differing.is_empty(),
            "`pip install ./python` would compile these crates (and every crate above them) a \
             second time, with other features than `cargo test --workspace` gave them \
             (-e {edges}):\n  {}\npin the workspace's features for them in python/Cargo.toml \
             (see `cargo tree --workspace -e features -i CRATE`)",
            differing
                .iter()
                .map(|s| s.as_str())
                .collect::<Vec<_>>()
                .join("\n  ")
        );
    }
}
