//! The manual's shell examples are commands that work: every `camloop …` (or
//! `cargo run --release -- …`) line in a `sh` block of the README and the book parses with
//! the binary's own command-line definition, and those that need neither a service, a
//! database nor hardware are run for real in a scratch folder, where each file they name
//! as an output must then exist.

use std::path::{Path, PathBuf};

use clap::Parser;

/// One documented command: where it is written and its arguments after the program name.
#[derive(Debug)]
struct Example {
    place: String,
    args: Vec<String>,
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn documents() -> Vec<PathBuf> {
    let mut docs = vec![root().join("README.md")];
    docs.extend(crate::docs::chapters());
    docs
}

/// The command lines of the shell blocks in `text`, continuation lines (`\`) joined, with
/// the line each starts on (1-based).
fn shell_lines(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut in_shell = false;
    let mut pending: Option<(usize, String)> = None;
    for (i, line) in text.lines().enumerate() {
        if let Some(lang) = line.strip_prefix("```") {
            in_shell = !in_shell && matches!(lang.trim(), "sh" | "bash" | "shell" | "console");
            continue;
        }
        if !in_shell {
            continue;
        }
        let (start, mut joined) = pending.take().unwrap_or((i + 1, String::new()));
        let line = line.trim().trim_start_matches("$ ");
        match line.strip_suffix('\\') {
            Some(head) => {
                joined.push_str(head);
                joined.push(' ');
                pending = Some((start, joined));
            }
            None => {
                joined.push_str(line);
                out.push((start, joined));
            }
        }
    }
    out
}

/// The documented camloop invocations, with comments and redirections dropped.
fn examples() -> Vec<Example> {
    let mut out = Vec::new();
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        let name = doc.strip_prefix(root()).unwrap().display().to_string();
        for (line, command) in shell_lines(&text) {
            let place = format!("{name}:{line}");
            let words = shlex::split(&command)
                .unwrap_or_else(|| panic!("{place}: unbalanced quotes in `{command}`"));
            let args: Vec<String> = match words.first().map(String::as_str) {
                Some("camloop") => words[1..].to_vec(),
                Some("cargo") if words.starts_with(&cargo_run()) => {
                    words[cargo_run().len()..].to_vec()
                }
                _ => continue,
            };
            let args = args
                .into_iter()
                .take_while(|w| !w.starts_with('#') && w != "<" && w != ">" && w != "|")
                .collect();
            out.push(Example { place, args });
        }
    }
    out
}

fn cargo_run() -> Vec<String> {
    ["cargo", "run", "--release", "--"]
        .map(String::from)
        .to_vec()
}

#[test]
fn every_documented_command_parses_with_the_binarys_own_definition() {
    let examples = examples();
    // The README's main job, the getting-started table, the tools of the other machines, the
    // speed plan, users, tokens and TLS are all in the book: fewer means the extraction broke.
    assert!(
        examples.len() >= 20,
        "only {} documented commands found",
        examples.len()
    );
    let refused: Vec<String> = examples
        .iter()
        .filter_map(|e| {
            let argv = std::iter::once("camloop".to_string()).chain(e.args.iter().cloned());
            camloop::cli::Cli::try_parse_from(argv)
                .err()
                .map(|err| format!("{}: camloop {}\n{err}", e.place, e.args.join(" ")))
        })
        .collect();
    assert!(refused.is_empty(), "{}", refused.join("\n"));
}

/// Subcommands that only read repository files and write their outputs: safe to run here.
const OFFLINE: &[&str] = &[
    "table",
    "speed-plan",
    "contour",
    "turnmill",
    "planing",
    "tls",
];

/// Options whose value is a file the command writes.
const OUTPUT_FLAGS: &[&str] = &["--out", "--program", "--main-program", "--csv", "--svg"];

#[test]
fn the_offline_examples_run_and_write_what_they_name() {
    let offline: Vec<Example> = examples()
        .into_iter()
        .filter(|e| {
            e.args
                .first()
                .is_some_and(|c| OFFLINE.contains(&c.as_str()))
        })
        .collect();
    assert!(
        offline.len() >= 8,
        "only {} offline examples",
        offline.len()
    );
    let scratch = tempfile::tempdir().unwrap();
    // The examples name repository inputs by relative path: the scratch folder gets its own
    // copy of `config` (the TLS example writes into it) and sees the test fixtures.
    copy_dir(&root().join("config"), &scratch.path().join("config"));
    std::fs::create_dir_all(scratch.path().join("tests")).unwrap();
    std::os::unix::fs::symlink(
        root().join("tests/fixtures"),
        scratch.path().join("tests/fixtures"),
    )
    .unwrap();
    std::fs::create_dir_all(scratch.path().join("var")).unwrap();
    for e in &offline {
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_camloop"))
            .args(&e.args)
            .current_dir(scratch.path())
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{}: camloop {} failed ({}):\n{}",
            e.place,
            e.args.join(" "),
            run.status,
            String::from_utf8_lossy(&run.stderr)
        );
        for pair in e.args.windows(2) {
            if OUTPUT_FLAGS.contains(&pair[0].as_str()) {
                let written = scratch.path().join(&pair[1]);
                assert!(
                    written.exists(),
                    "{}: `{} {}` was not written",
                    e.place,
                    pair[0],
                    pair[1]
                );
            }
        }
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

#[test]
fn shell_lines_join_continuations_and_skip_other_blocks() {
    let text =
        "```toml\ncamloop not = 1\n```\n```sh\ncamloop a \\\n  --b c # note\n$ camloop d\n```\n";
    let lines = shell_lines(text);
    assert_eq!(
        lines,
        vec![
            (5, "camloop a  --b c # note".to_string()),
            (7, "camloop d".to_string())
        ]
    );
}
