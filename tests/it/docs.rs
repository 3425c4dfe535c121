//! The docs match the tree: the README stays short and holds the two set-up commands, every
//! chapter of the manual is in its summary, every relative link and anchor resolves, and every
//! repository path the docs name in backticks exists.

use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The book's chapters, sorted.
pub(crate) fn chapters() -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(root().join("docs/src"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    out.sort();
    out
}

/// Every Markdown file the docs are made of.
fn documents() -> Vec<PathBuf> {
    let mut docs = vec![root().join("README.md"), root().join("ARCHITECTURE.md")];
    docs.extend(chapters());
    docs
}

/// Heading anchors as the renderers make them: lower case, punctuation dropped, spaces to
/// hyphens. Lines inside code fences are not headings.
fn anchors(text: &str) -> Vec<String> {
    let mut fenced = false;
    let mut out = Vec::new();
    for line in text.lines() {
        if line.starts_with("```") {
            fenced = !fenced;
        } else if !fenced && line.starts_with('#') {
            let title = line.trim_start_matches('#').trim().to_lowercase();
            let kept: String = title
                .chars()
                .filter(|c| c.is_alphanumeric() || *c == '-' || *c == ' ' || *c == '_')
                .collect();
            out.push(kept.replace(' ', "-"));
        }
    }
    out
}

/// The targets of the Markdown links in `text` that are not web addresses.
fn relative_links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find("](") {
        rest = &rest[at + 2..];
        let Some(end) = rest.find(')') else { break };
        let target = &rest[..end];
        if !target.starts_with("http") && !target.starts_with("mailto:") {
            out.push(target.to_string());
        }
        rest = &rest[end..];
    }
    out
}

#[test]
fn the_readme_is_short_and_holds_the_two_set_up_commands() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = readme.lines().count();
    assert!(
        lines <= 200,
        "README.md has {lines} lines: the manual belongs in docs/"
    );
    for command in ["cargo run --release -- run --parts 12", "cargo test"] {
        assert!(
            readme.contains(&format!("```sh\n{command}\n```")),
            "README.md lacks the set-up command `{command}` in a sh block"
        );
    }
}

#[test]
fn every_chapter_is_in_the_summary_and_every_summary_entry_exists() {
    let summary = std::fs::read_to_string(root().join("docs/src/SUMMARY.md")).unwrap();
    let listed = relative_links(&summary);
    for chapter in chapters() {
        let name = chapter.file_name().unwrap().to_string_lossy().to_string();
        if name != "SUMMARY.md" {
            assert!(
                listed.contains(&name),
                "docs/src/{name} is not in SUMMARY.md"
            );
        }
    }
    for entry in &listed {
        assert!(
            root().join("docs/src").join(entry).exists(),
            "SUMMARY.md lists {entry}, which does not exist"
        );
    }
    assert!(listed.len() >= 8, "only {} chapters listed", listed.len());
}

#[test]
fn every_relative_link_and_anchor_resolves() {
    let mut broken = Vec::new();
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        for link in relative_links(&text) {
            let (file, anchor) = link.split_once('#').unwrap_or((&link, ""));
            let target = match file {
                "" => doc.clone(),
                f => doc.parent().unwrap().join(f),
            };
            if !target.exists() {
                broken.push(format!("{}: {link} (no such file)", doc.display()));
                continue;
            }
            if !anchor.is_empty() {
                let text = std::fs::read_to_string(&target).unwrap();
                if !anchors(&text).iter().any(|a| a == anchor) {
                    broken.push(format!("{}: {link} (no such heading)", doc.display()));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn every_repository_path_the_docs_name_exists() {
    let prefixes = [
        "src/", "crates/", "tests/", "config/", "tools/", "docker/", "benches/",
    ];
    let mut missing = Vec::new();
    let mut named = 0;
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        for quoted in text.split('`').skip(1).step_by(2) {
            let is_path = prefixes.iter().any(|p| quoted.starts_with(p))
                && !quoted.contains(|c: char| c.is_whitespace() || "*<>{}…".contains(c));
            if !is_path {
                continue;
            }
            named += 1;
            let path = quoted.trim_end_matches(['/', '.', ',', ';', ':']);
            if !root().join(path).exists() {
                missing.push(format!("{}: {quoted}", doc.display()));
            }
        }
    }
    assert!(
        named > 30,
        "only {named} paths found: is the scan reading the docs?"
    );
    assert!(
        missing.is_empty(),
        "paths named in the docs that do not exist:\n{}",
        missing.join("\n")
    );
}
