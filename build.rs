//! Names the commit the binary was built from (`handblocks --version`, the session report):
//! `git rev-parse --short HEAD` when it was built; "unknown" when this is not a git checkout or
//! git is missing. And embeds `config/` (the sessions, scenes, hand model and device files), so
//! that the binary finds its default session and scenes wherever it is run from, even installed
//! with `cargo install --path .` away from the repository (`services/handblocks/locate.rs`).

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let commit = match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(c) if !c.is_empty() => c,
        _ => "unknown".to_string(),
    };
    println!("cargo:rustc-env=HANDBLOCKS_COMMIT={commit}");
    // Rebuild when HEAD moves (a commit, a checkout).
    if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
        println!("cargo:rerun-if-changed={dir}/HEAD");
        if let Some(head_ref) = git(&["symbolic-ref", "-q", "HEAD"]) {
            println!("cargo:rerun-if-changed={dir}/{head_ref}");
        }
    }
    println!("cargo:rerun-if-changed=build.rs");
    embed_config();
}

/// Writes `$OUT_DIR/embedded_config.rs`: `&[(path under config/, bytes)]` of every file there.
fn embed_config() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut files = Vec::new();
    let mut dirs = vec![root.clone()];
    while let Some(dir) = dirs.pop() {
        println!("cargo:rerun-if-changed={}", dir.display());
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                dirs.push(path);
            } else if let Ok(rel) = path.strip_prefix(&root) {
                println!("cargo:rerun-if-changed={}", path.display());
                files.push((
                    rel.to_string_lossy().into_owned(),
                    path.display().to_string(),
                ));
            }
        }
    }
    files.sort();
    let mut out = String::from("pub const FILES: &[(&str, &[u8])] = &[\n");
    for (rel, abs) in &files {
        out.push_str(&format!("    ({rel:?}, include_bytes!({abs:?})),\n"));
    }
    out.push_str("];\n");
    let Some(dir) = std::env::var_os("OUT_DIR") else {
        return;
    };
    let _ = std::fs::write(std::path::Path::new(&dir).join("embedded_config.rs"), out);
}
