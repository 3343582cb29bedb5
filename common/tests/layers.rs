//! The contract imports only downwards (issue 29): each module of `common/src` names, through
//! `crate::`, only modules of the layers below it, so there is no import circle and the bus
//! (transport) never holds a config value or a sample trait. Read file by file, as a reviewer
//! would: `cargo test --release -p common --test layers -- --nocapture` prints the edges.

use std::collections::BTreeSet;
use std::path::Path;

/// The modules of `common/src`, lowest layer first. A module may import those before it.
const LAYERS: [&str; 12] = [
    "stamp",
    "samples",
    "world_hash",
    "glove",
    "stage",
    "topic",
    "config",
    "output",
    "shutdown",
    "bus",
    "latency",
    "node",
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

/// The package names a manifest depends on (every dependency table: normal, dev and build).
fn dependencies(manifest: &toml::Table) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for key in ["dependencies", "dev-dependencies", "build-dependencies"] {
        if let Some(table) = manifest.get(key).and_then(|t| t.as_table()) {
            names.extend(table.keys().cloned());
        }
    }
    names
}

/// The tree's packages import downwards too (issue 44): read from every manifest of the
/// workspace, no package of the shared layer (`common/`) depends on a service, and no service
/// depends on another, but for the compositions named here (a scene run in one process is the
/// services' libraries put together). `cargo test --release -p common --test layers --
/// --nocapture` prints the arrows between packages.
#[test]
fn no_shared_package_imports_a_service() {
    /// Services whose job is to put other services' libraries together.
    const COMPOSITIONS: [&str; 1] = ["simulation"];
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let read = |path: &Path| -> toml::Table {
        let text =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        text.parse()
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    };
    let workspace = read(&root.join("Cargo.toml"));
    let members: Vec<String> = workspace["workspace"]["members"]
        .as_array()
        .expect("workspace.members")
        .iter()
        .filter_map(|m| m.as_str().map(String::from))
        .collect();
    // A package's name -> its folder, from the members' own manifests.
    let mut folder_of = std::collections::BTreeMap::new();
    let mut manifests = Vec::new();
    for member in &members {
        let manifest = read(&root.join(member).join("Cargo.toml"));
        let name = manifest["package"]["name"].as_str().expect("package.name");
        folder_of.insert(name.to_string(), member.clone());
        manifests.push((member.clone(), manifest));
    }
    assert!(folder_of.contains_key("simulation"), "{folder_of:?}");
    let mut wrong = Vec::new();
    let mut arrows = 0;
    for (member, manifest) in &manifests {
        for dep in dependencies(manifest) {
            let Some(to) = folder_of.get(&dep) else {
                continue;
            };
            arrows += 1;
            println!("  {member} -> {to}");
            let shared = member.starts_with("common");
            let service = member.starts_with("services/");
            let composition = COMPOSITIONS.iter().any(|c| member.ends_with(c));
            if to.starts_with("services/") && (shared || (service && !composition)) {
                wrong.push(format!("{member} depends on the service {to}"));
            }
        }
    }
    println!("{arrows} arrows between the workspace's packages");
    assert!(wrong.is_empty(), "arrows that run up a layer: {wrong:#?}");
}
