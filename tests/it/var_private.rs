//! The README demo's var folder is its owner's only: `camloop run` on the shipped
//! `config/camloop.toml` (its folders copied beside a fresh `var/`, the listener on port 0)
//! leaves every folder it made 0700 and every file 0600, the machines' journals and the
//! share's programs included.

use crate::cli_support;

use std::os::unix::fs::PermissionsExt;
use std::path::Path;

/// Copies `from` (a folder of the repository) to `to`, files and folders.
fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        match entry.file_type().unwrap().is_dir() {
            true => copy_tree(&entry.path(), &target),
            false => {
                std::fs::copy(entry.path(), &target).unwrap();
            }
        }
    }
}

/// Every path under `root` whose mode is not 0700 (folders) or 0600 (files), with its mode.
fn not_private(root: &Path) -> Vec<String> {
    let mut wrong = Vec::new();
    let mut todo = vec![root.to_path_buf()];
    while let Some(p) = todo.pop() {
        let meta = std::fs::symlink_metadata(&p).unwrap();
        let mode = meta.permissions().mode() & 0o777;
        let want = if meta.is_dir() { 0o700 } else { 0o600 };
        if mode != want {
            wrong.push(format!("{} {mode:o}", p.display()));
        }
        if meta.is_dir() {
            todo.extend(std::fs::read_dir(&p).unwrap().map(|e| e.unwrap().path()));
        }
    }
    wrong
}

#[test]
fn the_demo_run_leaves_var_to_its_owner_alone() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config");
    copy_tree(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("config"),
        &config,
    );
    let shipped = std::fs::read_to_string(config.join("camloop.toml")).unwrap();
    assert!(shipped.contains("listen = \"127.0.0.1:8080\""), "{shipped}");
    let ours = shipped
        .replace("listen = \"127.0.0.1:8080\"", "listen = \"127.0.0.1:0\"")
        .replace("part_interval_ms = 500", "part_interval_ms = 10");
    std::fs::write(config.join("camloop.toml"), ours).unwrap();
    let out = cli_support::camloop(
        &["run", "--config", "config/camloop.toml", "--parts", "1"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", cli_support::stderr(&out));
    let var = dir.path().join("var");
    // What the demo makes, so the walk below cannot pass on an empty folder.
    for made in ["camloop.db", "machines", "share/SIM1", "admin-password"] {
        assert!(var.join(made).exists(), "{made}");
    }
    let wrong = not_private(&var);
    assert!(
        wrong.is_empty(),
        "not the owner's only:\n{}",
        wrong.join("\n")
    );
}
