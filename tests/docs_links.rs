//! The documentation's relative links resolve, and the README stays short (issue 30).
//!
//! The README once cited notes that were never in the repository, and pages move as the docs
//! are reorganised: a link that points nowhere is found here, not by a reader. Every markdown
//! link `](target)` in README.md and in every docs/**/*.md that is not a web address, a mail
//! address or an anchor on the same page must name a file or folder that exists, relative to
//! the page that holds it. Generated pages (docs/bench/) and the preview (docs/preview.gif) are
//! checked like any other target: a link to them is a promise that they exist.
//!
//! Links inside fenced code blocks and inline code spans are not links (a TOML array followed
//! by a parenthesis would otherwise look like one), so they are left out.

use std::path::{Path, PathBuf};

/// The README is where a newcomer starts: the picture, the two commands, a glossary and a
/// short tour. Measurements belong on the pages the benchmarks write, so the README has a
/// length limit to keep them from creeping back.
const README_MAX_LINES: usize = 250;

fn repository() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every markdown file under `dir`, sorted so that failures read in a stable order.
fn markdown_files(dir: &Path, into: &mut Vec<PathBuf>) {
    let entries =
        std::fs::read_dir(dir).unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
    for entry in entries {
        let path = entry
            .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
            .path();
        if path.is_dir() {
            markdown_files(&path, into);
        } else if path.extension().is_some_and(|x| x == "md") {
            into.push(path);
        }
    }
    into.sort();
}

/// The line with its inline code spans (text between backticks) blanked out.
fn without_code_spans(line: &str) -> String {
    let mut inside = false;
    line.chars()
        .map(|c| {
            if c == '`' {
                inside = !inside;
                ' '
            } else if inside {
                ' '
            } else {
                c
            }
        })
        .collect()
}

/// The targets of the markdown links `[text](target)` and `![alt](target)` in `text`, with
/// the line each is on, outside code. A target may carry a title (`](path "title")`) or be
/// written in angle brackets (`](<path>)`); both are reduced to the path.
fn link_targets(text: &str) -> Vec<(usize, String)> {
    let mut targets = Vec::new();
    let mut in_fence = false;
    for (index, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence {
            continue;
        }
        let line = without_code_spans(line);
        let mut rest = line.as_str();
        while let Some(at) = rest.find("](") {
            let after = &rest[at + 2..];
            let Some(end) = after.find(')') else { break };
            let raw = after[..end].trim();
            let target = match raw.strip_prefix('<') {
                Some(bracketed) => bracketed.split('>').next().unwrap_or(""),
                None => raw.split_whitespace().next().unwrap_or(""),
            };
            targets.push((index + 1, target.to_string()));
            rest = &after[end..];
        }
    }
    targets
}

/// Whether a target is a relative path into the repository (not a web or mail address, not
/// an anchor on the same page).
fn is_relative_path(target: &str) -> bool {
    !(target.is_empty()
        || target.starts_with('#')
        || target.starts_with("http://")
        || target.starts_with("https://")
        || target.starts_with("mailto:"))
}

#[test]
fn every_relative_link_in_the_readme_and_docs_resolves() {
    let root = repository();
    let mut pages = vec![root.join("README.md")];
    markdown_files(&root.join("docs"), &mut pages);

    let mut broken = Vec::new();
    let mut checked = 0;
    for page in &pages {
        let text = std::fs::read_to_string(page)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", page.display()));
        let folder = page.parent().unwrap_or(&root);
        for (line, target) in link_targets(&text) {
            if !is_relative_path(&target) {
                continue;
            }
            checked += 1;
            let path = target.split('#').next().unwrap_or("");
            if !folder.join(path).exists() {
                let shown = page.strip_prefix(&root).unwrap_or(page);
                broken.push(format!("{}:{line}: {target}", shown.display()));
            }
        }
    }
    assert!(
        checked > 0,
        "no relative links found: the link extraction is broken"
    );
    assert!(
        broken.is_empty(),
        "{} link(s) point at nothing in the repository:\n  {}",
        broken.len(),
        broken.join("\n  ")
    );
}

#[test]
fn the_readme_stays_under_its_line_limit() {
    let readme = repository().join("README.md");
    let text = std::fs::read_to_string(&readme)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", readme.display()));
    let lines = text.lines().count();
    assert!(
        lines < README_MAX_LINES,
        "README.md has {lines} lines, the limit is under {README_MAX_LINES}: measurements \
         belong on the pages the benchmarks write (docs/bench/), explanations in docs/"
    );
}

#[test]
fn link_extraction_skips_code_and_reads_titles_and_anchors() {
    let text = "see [a](docs/a.md) and ![b](<b c.png>) and [t](x.md \"title\")\n\
                `[not](code.md)` [web](https://example.org) [here](#anchor)\n\
                ```\n[fenced](nothing.md)\n```\n[deep](d.md#part)\n";
    let targets: Vec<String> = link_targets(text).into_iter().map(|(_, t)| t).collect();
    assert_eq!(
        targets,
        [
            "docs/a.md",
            "b c.png",
            "x.md",
            "https://example.org",
            "#anchor",
            "d.md#part"
        ]
    );
    let relative: Vec<&String> = targets.iter().filter(|t| is_relative_path(t)).collect();
    assert_eq!(relative, ["docs/a.md", "b c.png", "x.md", "d.md#part"]);
}
