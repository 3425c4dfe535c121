//! Running the real `camloop` binary from the command-line tests.
// Each test crate uses the part it needs.

use std::path::Path;
use std::process::{Command, Output};

/// Runs `camloop` with `args` in `cwd`.
pub fn camloop(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_camloop"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("the camloop binary runs")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A path inside the repository, as a string for the command line.
pub fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(path)
        .display()
        .to_string()
}
