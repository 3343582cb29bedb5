//! The catalog of every configuration key: its type, default, allowed values and what it does
//! (docs/config.md, printed by `handblocks config keys`).
//!
//! It comes from the code that checks the keys, so it cannot drift from it: every getter of
//! the readers ([`super::reader::Reader`], the device tables' own) tells [`note`] what it
//! checks (the type, the range or the choices, the default when it holds one) while a catalog
//! is being made, and [`keys`] makes one by loading, with every loader of this module, a set
//! of small files ([`INPUTS`]) that between them take every branch a key hangs on (each kind of
//! source, each shape of block, each form of a hand key). A key's one line of what it does is
//! [`super::key_docs::DOCS`]'s; [`keys`] refuses a key the loaders ask for that has no line, and
//! a line for a key no loader asks for, and the tests check that every key the shipped files
//! and the loaders' source name is in the catalog.

use std::cell::RefCell;
use std::path::Path;

use super::key_docs::{Doc, DOCS};

/// Which kind of file a key is read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum FileKind {
    /// A session file (config/sessions/*.toml).
    Session,
    /// A `[source] kind = "devices"` session's `[source.glove]` and `[source.tracker]`.
    Devices,
    /// A scene file (config/scenes/*.toml).
    Scene,
    /// A hand model file (config/hand.toml).
    HandModel,
}

impl FileKind {
    pub const ALL: [FileKind; 4] = [
        FileKind::Session,
        FileKind::Devices,
        FileKind::Scene,
        FileKind::HandModel,
    ];

    /// Its name in the catalog's JSON (`"file"`).
    pub fn name(self) -> &'static str {
        match self {
            FileKind::Session => "session",
            FileKind::Devices => "devices",
            FileKind::Scene => "scene",
            FileKind::HandModel => "hand model",
        }
    }

    fn heading(self) -> &'static str {
        match self {
            FileKind::Session => "Session files",
            FileKind::Devices => "Device tables of a session",
            FileKind::Scene => "Scene files",
            FileKind::HandModel => "Hand model files",
        }
    }

    fn intro(self) -> &'static str {
        match self {
            FileKind::Session => {
                "`config/sessions/*.toml`: which scene, what feeds the pipeline, the renderer, \
                 the recorder, the budget ([sessions.md](sessions.md)). `handblocks launch \
                 --set KEY=VALUE` sets any of them, checked as in the file; `--set \
                 scene.KEY=VALUE` sets the scene's KEY."
            }
            FileKind::Devices => {
                "`[source.glove]` and `[source.tracker]` of a session whose `[source] kind = \
                 \"devices\"` (a CyberGlove and a Polhemus FASTRAK on serial ports; \
                 `config/devices/emulated-session.toml`, \
                 [config/devices/README.md](../config/devices/README.md)). Checked when the \
                 session loads, before anything starts."
            }
            FileKind::Scene => {
                "`config/scenes/*.toml`: the world's settings, the effects it simulates, its \
                 blocks and the scripted hands ([model.md](model.md) states each rule R1-R14 \
                 and T1-T3 named here). A scene file given to `launch` runs as a session with \
                 the session defaults."
            }
            FileKind::HandModel => {
                "`config/hand.toml`, or the file a session's `hand_model` names: the hand's \
                 bones, radii and palm in its own frame (the wrist at the origin, fingers \
                 along -z, palm facing -y, thumb on the -x side of a right hand), metres. An \
                 absent key keeps the built-in adult hand's value (the default column)."
            }
        }
    }
}

/// What a getter checks of a key (before its line of description is joined to it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Spec {
    /// "number", "whole number", "string", "list of 3 numbers", "table", ...
    pub ty: String,
    /// The range (`0 to 1000`) or the choices (`"a", "b"`); empty when any value of the type.
    pub allowed: String,
    /// The value taken when the key is absent, as it would be written (`120`, `"paper"`,
    /// `[0, 0, 0]`), or `required`; None when the getter does not hold one.
    pub default: Option<String>,
}

impl Spec {
    pub fn of(ty: &str) -> Spec {
        Spec {
            ty: ty.to_string(),
            allowed: String::new(),
            default: None,
        }
    }
}

/// A number as a key's value is written (as the errors say it).
pub(crate) fn num(x: f64) -> String {
    format!("{x}")
}

/// `[a, b, c]`.
pub(crate) fn list(xs: &[f64]) -> String {
    let items: Vec<String> = xs.iter().map(|x| num(*x)).collect();
    format!("[{}]", items.join(", "))
}

/// One key as a getter was asked for it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Asked {
    pub kind: FileKind,
    /// The dotted path, each `[i]` of an array of tables written `[]` (`block[].size`).
    pub path: String,
    pub spec: Spec,
}

thread_local! {
    /// Where the getters' notes go while [`record`] runs; None otherwise.
    static SINK: RefCell<Option<Vec<Asked>>> = const { RefCell::new(None) };
}

/// Notes that a getter of a `kind` file checks `path` by `spec`: kept while [`record`] runs on
/// this thread; otherwise nothing (and neither closure runs).
pub(crate) fn note(kind: FileKind, path: impl FnOnce() -> String, spec: impl FnOnce() -> Spec) {
    SINK.with(|sink| {
        if let Some(asked) = sink.borrow_mut().as_mut() {
            asked.push(Asked {
                kind,
                path: pattern(&path()),
                spec: spec(),
            });
        }
    });
}

/// `block[3].size` -> `block[].size`.
fn pattern(path: &str) -> String {
    let mut out = String::with_capacity(path.len());
    let mut in_index = false;
    for c in path.chars() {
        match c {
            '[' => {
                in_index = true;
                out.push(c);
            }
            ']' => {
                in_index = false;
                out.push(c);
            }
            c if in_index && c.is_ascii_digit() => {}
            c => out.push(c),
        }
    }
    out
}

/// Runs `f`, and returns with what it returned every key a getter was asked for meanwhile on
/// this thread, in order (the same key as often as it was asked).
pub(crate) fn record<T>(f: impl FnOnce() -> T) -> (T, Vec<Asked>) {
    struct Restore(Option<Vec<Asked>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let before = self.0.take();
            SINK.with(|sink| *sink.borrow_mut() = before);
        }
    }
    let before = SINK.with(|sink| sink.borrow_mut().replace(Vec::new()));
    let _restore = Restore(before);
    let out = f();
    let asked = SINK.with(|sink| sink.borrow_mut().replace(Vec::new()).unwrap_or_default());
    (out, asked)
}

/// One key of the catalog.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Key {
    /// The kind of file ([`FileKind::name`]).
    pub file: &'static str,
    /// The dotted path, `[]` for each array of tables (`block[].size`, `hand.key[].t`).
    pub key: String,
    #[serde(rename = "type")]
    pub ty: String,
    /// The value taken when the key is absent, as written in a file, or words (`required`,
    /// `none: ...`); empty for a table.
    pub default: String,
    /// The range or the choices; empty when any value of the type is taken.
    pub allowed: String,
    /// What it does.
    pub what: &'static str,
    /// True when `default` is a value the code holds (shown as code), false for words.
    #[serde(skip)]
    pub default_is_value: bool,
    #[serde(skip)]
    pub kind: FileKind,
}

/// The files the catalog loads: between them they take every branch a key hangs on. Each is
/// (file name, text); sessions name `scene.toml` and `hand.toml`, and the scenes are loaded on
/// their own too.
pub(crate) const INPUTS: [(&str, &str); 11] = [
    (
        "scene.toml",
        "[world]\n[tracked]\n[precise]\n[effects]\n\
         [[block]]\nposition = [0, 0.05, 0]\n\
         [[block]]\nshape = \"hull\"\nposition = [0.3, 0.05, 0]\n\
         vertices = [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]\n\
         [hand]\n[[hand.key]]\nt = 0\nwrist = [0, 0.3, 0]\n\
         [left_hand]\n[[left_hand.key]]\nt = 0\nwrist = [0, 0.3, 0.3]\n",
    ),
    (
        "bare-hands.toml",
        "[hand]\n[[hand.key]]\nt = 0\nwrist = [0, 0.3, 0]\nfingers = [[[0, 0, 0]]]\n\
         [left_hand]\n[[left_hand.key]]\nt = 0\nwrist = [0, 0.3, 0.3]\nfingers = [[[0, 0, 0]]]\n",
    ),
    (
        "hand.toml",
        "[palm]\n[thumb]\n[index]\n[middle]\n[ring]\n[little]\n",
    ),
    (
        "scripted.session.toml",
        "scene = \"scene.toml\"\nhand_model = \"hand.toml\"\n[source]\n\
         [remote]\nendpoint = \"tls/127.0.0.1:7447\"\n[viewer]\n[renderer]\n[recorder]\n\
         [budget]\n[pipeline]\n[supervise]\n",
    ),
    (
        "devices.session.toml",
        "scene = \"scene.toml\"\n[source]\nkind = \"devices\"\nglove = { port = \"a\" }\n\
         tracker = { port = \"b\" }\n",
    ),
    (
        "replay.session.toml",
        "scene = \"scene.toml\"\n[source]\nkind = \"replay\"\nfile = \"a.mcap\"\n",
    ),
    (
        "remote.session.toml",
        "scene = \"scene.toml\"\n[source]\nkind = \"remote\"\nendpoint = \"tls/127.0.0.1:7447\"\n",
    ),
    (
        "webxr.session.toml",
        "scene = \"scene.toml\"\n[source]\nkind = \"webxr\"\n",
    ),
    (
        "external.session.toml",
        "scene = \"scene.toml\"\n[source]\nkind = \"external\"\ncommand = [\"a\"]\n",
    ),
    (
        "shared-host.session.toml",
        "scene = \"scene.toml\"\n[source]\nkind = \"shared\"\n[shared]\n",
    ),
    (
        "shared-join.session.toml",
        "scene = \"scene.toml\"\n[shared]\nhost = \"tls/127.0.0.1:7460\"\n",
    ),
];

/// Loads `file` with the loader of its kind (by its name: `*.session.toml` a session,
/// `hand.toml` a hand model, else a scene), keeping only whether it loaded.
pub(crate) fn load(file: &Path) -> Result<(), super::ConfigError> {
    let name = file.file_name().map(|n| n.to_string_lossy().into_owned());
    match name.as_deref() {
        Some(n) if n.ends_with(".session.toml") => super::Session::load(file).map(drop),
        Some("hand.toml") => super::hand::HandModelSpec::load(file).map(drop),
        _ => super::Scene::load(file).map(drop),
    }
}

/// Every key the loaders ask for when they load [`INPUTS`] (written to a temporary folder,
/// removed after), each as often as it was asked.
pub(crate) fn asked() -> Result<Vec<Asked>, String> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "handblocks-config-keys-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let result = (|| {
        for (name, text) in INPUTS {
            let f = dir.join(name);
            std::fs::write(&f, text).map_err(|e| format!("{}: {e}", f.display()))?;
        }
        let (loaded, asked) = record(|| {
            INPUTS
                .iter()
                .map(|(name, _)| load(&dir.join(name)))
                .collect::<Result<Vec<()>, _>>()
        });
        loaded.map_err(|e| format!("the catalog's own input does not load: {e}"))?;
        Ok(asked)
    })();
    // Best effort: a folder left in the temporary directory harms nothing.
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Each key once, in the order first asked; an error names a key two getters check
/// differently.
pub(crate) fn merged(asked: Vec<Asked>) -> Result<Vec<Asked>, String> {
    let mut out: Vec<Asked> = Vec::new();
    for a in asked {
        match out.iter().find(|o| o.kind == a.kind && o.path == a.path) {
            None => out.push(a),
            Some(o) if o.spec == a.spec => {}
            Some(o) => {
                return Err(format!(
                    "{} key `{}` is checked two ways: {:?} and {:?}",
                    a.kind.name(),
                    a.path,
                    o.spec,
                    a.spec
                ))
            }
        }
    }
    Ok(out)
}

/// The catalog: every key the loaders ask for, with its line from [`DOCS`], in [`DOCS`]'s
/// order. An error lists every key without a line, every line without a key, and every line
/// that states a default in words where the code holds one.
pub fn keys() -> Result<Vec<Key>, String> {
    let asked = merged(asked()?)?;
    join(&asked, DOCS)
}

fn join(asked: &[Asked], docs: &[Doc]) -> Result<Vec<Key>, String> {
    let mut problems = Vec::new();
    for a in asked {
        if !docs.iter().any(|d| d.kind == a.kind && d.path == a.path) {
            problems.push(format!(
                "{} key `{}` ({}) has no line in common/src/config/key_docs.rs",
                a.kind.name(),
                a.path,
                a.spec.ty
            ));
        }
    }
    let mut keys = Vec::new();
    for (i, d) in docs.iter().enumerate() {
        if docs[..i]
            .iter()
            .any(|o| o.kind == d.kind && o.path == d.path)
        {
            problems.push(format!(
                "{} key `{}` has two lines in common/src/config/key_docs.rs",
                d.kind.name(),
                d.path
            ));
            continue;
        }
        let Some(a) = asked.iter().find(|a| a.kind == d.kind && a.path == d.path) else {
            problems.push(format!(
                "common/src/config/key_docs.rs describes {} key `{}`, which no loader asks for",
                d.kind.name(),
                d.path
            ));
            continue;
        };
        let (default, default_is_value) = match (&a.spec.default, d.default) {
            (Some(v), "") => (v.clone(), v != "required"),
            (Some(v), words) => {
                problems.push(format!(
                    "{} key `{}`: its default is the code's ({v}); remove {words:?} from its \
                     line in common/src/config/key_docs.rs",
                    d.kind.name(),
                    d.path
                ));
                continue;
            }
            (None, words) => (words.to_string(), false),
        };
        keys.push(Key {
            file: d.kind.name(),
            key: d.path.to_string(),
            ty: a.spec.ty.clone(),
            default,
            allowed: a.spec.allowed.clone(),
            what: d.what,
            default_is_value,
            kind: d.kind,
        });
    }
    if problems.is_empty() {
        Ok(keys)
    } else {
        Err(format!(
            "the key catalog does not match the loaders:\n  {}",
            problems.join("\n  ")
        ))
    }
}

/// The command that writes docs/config.md.
pub const MARKDOWN_COMMAND: &str = "handblocks config keys --markdown > docs/config.md";

/// docs/config.md: one table per kind of file.
pub fn markdown(keys: &[Key]) -> String {
    let mut out = String::new();
    out.push_str("# Configuration keys\n\n");
    out.push_str(&format!(
        "Every key of every configuration file: its type, its default (the value taken when \
         the key is absent), what it may be, and what it does. {} keys in all.\n\n\
         Generated from the code that checks the keys (`common/src/config`: each getter \
         reports what it checks; `key_docs.rs` holds each key's line), so it cannot drift \
         from it: do not edit this page; after changing a key run `{MARKDOWN_COMMAND}` \
         (`cargo run --release -- config keys --markdown > docs/config.md` in a checkout). A \
         test of `common` fails until the page is what the code says. `handblocks config \
         keys --json` gives the same as JSON.\n\n\
         Every file is checked before anything starts: an unknown key, a value of the wrong \
         type or outside its range is an error that names the file, the key and what is \
         allowed. `key[]` is a key of each `[[key]]` table (an array of tables).\n",
        keys.len()
    ));
    for kind in FileKind::ALL {
        let rows: Vec<&Key> = keys.iter().filter(|k| k.kind == kind).collect();
        if rows.is_empty() {
            continue;
        }
        out.push_str(&format!("\n## {}\n\n{}\n\n", kind.heading(), kind.intro()));
        out.push_str("| key | type | default | allowed | what it does |\n");
        out.push_str("|---|---|---|---|---|\n");
        for k in rows {
            let default = if k.default_is_value {
                format!("`{}`", k.default)
            } else {
                k.default.clone()
            };
            out.push_str(&format!(
                "| `{}` | {} | {} | {} | {} |\n",
                k.key,
                cell(&k.ty),
                cell(&default),
                cell(&k.allowed),
                cell(k.what)
            ));
        }
    }
    out
}

/// A table cell: `|` escaped.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}

/// The catalog as plain text, for a terminal: per kind of file, each key with its type,
/// default and range on one line and what it does under it.
pub fn text(keys: &[Key]) -> String {
    let mut out = String::new();
    for kind in FileKind::ALL {
        let rows: Vec<&Key> = keys.iter().filter(|k| k.kind == kind).collect();
        if rows.is_empty() {
            continue;
        }
        if !out.is_empty() {
            out.push('\n');
        }
        out.push_str(&format!("{}:\n", kind.heading()));
        for k in rows {
            let mut facts = vec![k.ty.clone()];
            if !k.default.is_empty() {
                facts.push(format!("default {}", k.default));
            }
            if !k.allowed.is_empty() {
                facts.push(format!("allowed {}", k.allowed));
            }
            out.push_str(&format!(
                "  {} ({})\n      {}\n",
                k.key,
                facts.join("; "),
                k.what
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repo() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
    }

    /// Every key the loaders ask for has its line, every line names a key they ask for, and
    /// each key is checked one way wherever it is read.
    #[test]
    fn every_key_has_a_line_and_every_line_a_key() {
        let keys = keys().unwrap_or_else(|e| panic!("{e}"));
        assert!(keys.len() > 150, "{}", keys.len());
        for k in &keys {
            assert!(!k.what.is_empty() && !k.ty.is_empty(), "{k:?}");
            assert!(
                !k.default.is_empty() || k.ty == "table" || k.ty == "array of tables",
                "{} key `{}`: say its default (words in key_docs.rs when the code holds none)",
                k.file,
                k.key
            );
        }
    }

    /// Every file under config/ loads, and asks for no key the catalog lacks, checked the
    /// same way: a branch the catalog's inputs miss shows here.
    #[test]
    fn the_shipped_config_files_ask_for_no_key_the_catalog_lacks() {
        let catalog = merged(asked().unwrap()).unwrap();
        let mut files = Vec::new();
        let config = repo().join("config");
        for sub in ["sessions", "scenes", "scenes/hard", "devices"] {
            let Ok(dir) = std::fs::read_dir(config.join(sub)) else {
                continue;
            };
            for e in dir.flatten() {
                let p = e.path();
                if p.extension().is_some_and(|x| x == "toml") {
                    files.push((sub, p));
                }
            }
        }
        files.sort();
        assert!(files.len() > 20, "{files:?}");
        for (sub, file) in &files {
            let (loaded, asked) = record(|| match *sub {
                "scenes" | "scenes/hard" => super::super::Scene::load(file).map(drop),
                _ => super::super::Session::load(file).map(drop),
            });
            loaded.unwrap_or_else(|e| panic!("{e}"));
            for a in asked {
                let c = catalog
                    .iter()
                    .find(|c| c.kind == a.kind && c.path == a.path)
                    .unwrap_or_else(|| {
                        panic!(
                            "{}: {} key `{}` is not in the catalog: add a file that asks for \
                             it to catalog::INPUTS",
                            file.display(),
                            a.kind.name(),
                            a.path
                        )
                    });
                assert_eq!(c.spec, a.spec, "{}: `{}`", file.display(), a.path);
            }
        }
        let (loaded, _) =
            record(|| super::super::hand::HandModelSpec::load(&config.join("hand.toml")));
        loaded.unwrap();
    }

    /// Every key name a loader's getters are called with in its source is in the catalog:
    /// a getter on a branch no input takes shows here.
    #[test]
    fn every_key_a_loader_names_is_in_the_catalog() {
        let catalog = merged(asked().unwrap()).unwrap();
        let last = |path: &str| -> String {
            let last = path.rsplit('.').next().unwrap_or(path);
            last.trim_end_matches("[]").to_string()
        };
        let names: Vec<String> = catalog.iter().map(|a| last(&a.path)).collect();
        const GETTERS: [&str; 19] = [
            "table",
            "tables",
            "string",
            "choice",
            "bool",
            "f64_in",
            "f64_required",
            "u64_in",
            "array",
            "array_or",
            "numbers",
            "raw",
            "has",
            "number",
            "integer",
            "integer_or",
            "millis",
            "pose",
            "get",
        ];
        let sources = [
            ("session.rs", include_str!("session.rs")),
            ("scene.rs", include_str!("scene.rs")),
            ("hand.rs", include_str!("hand.rs")),
            ("remote.rs", include_str!("remote.rs")),
            ("shared.rs", include_str!("shared.rs")),
            ("devices.rs", include_str!("devices.rs")),
        ];
        let mut seen = 0;
        for (file, text) in sources {
            let code = text.split("#[cfg(test)]").next().unwrap_or(text);
            for (at, _) in code.match_indices("(\"") {
                let before = &code[..at];
                // `.array::<3>("eye"`: the method's name, its turbofish left out.
                let before = match before.rfind("::<") {
                    Some(i) if !before[i..].contains(['(', ' ', '\n']) => &before[..i],
                    _ => before,
                };
                let method: String = before
                    .chars()
                    .rev()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect::<Vec<_>>()
                    .into_iter()
                    .rev()
                    .collect();
                let dotted = before[..before.len() - method.len()].ends_with('.');
                if !dotted || !GETTERS.contains(&method.as_str()) {
                    continue;
                }
                let rest = &code[at + 2..];
                let key = &rest[..rest.find('"').unwrap_or(0)];
                seen += 1;
                assert!(
                    names.iter().any(|n| n == key),
                    "{file}: `.{method}(\"{key}\"...)` asks for a key no catalog input \
                     reaches: add a file that takes that branch to catalog::INPUTS"
                );
            }
        }
        assert!(seen > 100, "{seen}");
    }

    /// docs/config.md is what `handblocks config keys --markdown` prints.
    #[test]
    fn docs_config_md_is_what_the_code_says() {
        let page = markdown(&keys().unwrap_or_else(|e| panic!("{e}")));
        let file = repo().join("docs/config.md");
        if std::env::var_os("HANDBLOCKS_WRITE_CONFIG_MD").is_some() {
            std::fs::write(&file, &page).unwrap();
        }
        let on_disk = std::fs::read_to_string(&file).unwrap_or_default();
        if on_disk != page {
            let line = on_disk
                .lines()
                .zip(page.lines())
                .position(|(a, b)| a != b)
                .unwrap_or(on_disk.lines().count().min(page.lines().count()));
            panic!(
                "docs/config.md is not what the code says (first difference at line {}): \
                 run `{MARKDOWN_COMMAND}` (or HANDBLOCKS_WRITE_CONFIG_MD=1 cargo test \
                 --release -p common docs_config_md) and commit it",
                line + 1
            );
        }
    }

    #[test]
    fn an_index_becomes_brackets_and_a_missing_line_is_named() {
        assert_eq!(pattern("hand.key[12].t"), "hand.key[].t");
        let asked = vec![Asked {
            kind: FileKind::Scene,
            path: "world.nope".into(),
            spec: Spec::of("number"),
        }];
        let e = join(&asked, &[]).unwrap_err();
        assert!(
            e.contains("scene key `world.nope` (number) has no line"),
            "{e}"
        );
        let e = merged(vec![
            asked[0].clone(),
            Asked {
                spec: Spec::of("string"),
                ..asked[0].clone()
            },
        ])
        .unwrap_err();
        assert!(e.contains("checked two ways"), "{e}");
        // Nothing is kept when no catalog is being made.
        note(FileKind::Scene, || unreachable!(), || unreachable!());
    }
}
