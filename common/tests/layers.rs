//! The contract imports only downwards (issue 29): each module of `common/src` names, through
//! `crate::`, only modules of the layers below it, so there is no import circle and the bus
//! (transport) never holds a config value or a sample trait. Read file by file, as a reviewer
//! would: `cargo test --release -p common --test layers -- --nocapture` prints the edges.

use std::collections::BTreeSet;
use std::path::Path;

/// The modules of `common/src`, lowest layer first. A module may import those before it.
const LAYERS: [&str; 10] = [
    "stamp", "samples", "glove", "topic", "config", "output", "shutdown", "bus", "latency", "node",
];

/// Every `crate::MODULE` a source file names outside its comments.
fn imports(text: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or("");
        let mut rest = code;
        while let Some(at) = rest.find("crate::") {
            rest = &rest[at + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            found.insert(name);
        }
    }
    found
}

fn walk(dir: &Path, files: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            walk(&path, files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
}

#[test]
fn the_contract_imports_only_downwards() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    walk(&src, &mut files);
    let rank = |m: &str| LAYERS.iter().position(|l| *l == m);
    let mut edges = BTreeSet::new();
    let mut upwards = Vec::new();
    for file in &files {
        let rel = file.strip_prefix(&src).unwrap();
        let first = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let module = first.trim_end_matches(".rs").to_string();
        if module == "lib" {
            continue;
        }
        let Some(from) = rank(&module) else {
            panic!(
                "{}: module `{module}` is in no layer of LAYERS",
                rel.display()
            );
        };
        let text = std::fs::read_to_string(file).unwrap();
        for to in imports(&text) {
            // Names re-exported at the crate root (`crate::GloveSample`) are not modules.
            let Some(to_rank) = rank(&to) else { continue };
            if to == module {
                continue;
            }
            edges.insert((module.clone(), to.clone()));
            if to_rank > from {
                upwards.push(format!("{} imports crate::{to}", rel.display()));
            }
        }
    }
    println!("{} module edges in common/src:", edges.len());
    for (a, b) in &edges {
        println!("  {a} -> {b}");
    }
    let circles: Vec<_> = edges
        .iter()
        .filter(|(a, b)| edges.contains(&(b.clone(), a.clone())))
        .collect();
    println!("import circles (2-cycles): {}", circles.len() / 2);
    assert!(
        upwards.is_empty(),
        "imports that run up a layer: {upwards:#?}"
    );
    assert!(circles.is_empty(), "{circles:?}");
}
