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

/// Runs `camloop` with `args` in `cwd`, which must succeed (its stderr is the failure
/// message).
pub fn camloop_ok(args: &[&str], cwd: &Path) -> Output {
    let out = camloop(args, cwd);
    assert!(out.status.success(), "camloop {args:?}: {}", stderr(&out));
    out
}

/// The JSON file at `path`, as the command wrote it.
pub fn json_file(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// What a refused command says: it must have failed, with one line on stderr, returned.
pub fn refusal(out: &Output) -> String {
    assert!(
        !out.status.success(),
        "succeeded: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    let err = stderr(out);
    assert_eq!(err.lines().count(), 1, "one line on stderr: {err}");
    err
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `COMMAND cam --lift LIFT --follower flat --base-radius 20 --wheel-radius 250 EXTRA…`: the
/// flat-follower cam on a 20 mm base circle and a 250 mm wheel that the command-line tests
/// take, with the options under test after it.
pub fn flat_cam_args<'a>(command: &'a str, lift: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        command,
        "cam",
        "--lift",
        lift,
        "--follower",
        "flat",
        "--base-radius",
        "20",
        "--wheel-radius",
        "250",
    ];
    args.extend_from_slice(extra);
    args
}

/// `COMMAND crankpin --throw 45 --pin-radius 30 --wheel-radius 300 EXTRA…`: the crankpin of
/// the command-line tests (45 mm throw, 30 mm pin, 300 mm wheel).
pub fn crankpin_args<'a>(command: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        command,
        "crankpin",
        "--throw",
        "45",
        "--pin-radius",
        "30",
        "--wheel-radius",
        "300",
    ];
    args.extend_from_slice(extra);
    args
}

/// Asserts that `dir` holds nothing: a refused command wrote no output and left no
/// temporary behind.
pub fn assert_nothing_written(dir: &Path) {
    let left: Vec<_> = std::fs::read_dir(dir)
        .expect("the test's folder")
        .map(|e| e.expect("an entry").file_name())
        .collect();
    assert!(left.is_empty(), "written in {}: {left:?}", dir.display());
}

/// A path inside the repository, as a string for the command line.
pub fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(path)
        .display()
        .to_string()
}

/// Runs `camloop run --parts PARTS` in `dir` on one simulated machine, M7, grinding the demo
/// lobe IN1 into `var/camloop.db`, one part every `part_interval_ms`. `grinder` is TOML added
/// to the simulated gauge's section (`[machines.gauge.grinder]`, `[machines.gauge.grinder.gauge]`
/// tables). Returns the log (stdout) of a run that must succeed.
pub fn run_demo_lobe(dir: &Path, parts: u32, part_interval_ms: u32, grinder: &str) -> String {
    let config = format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n[[machines]]\nname = \"M7\"\nrecipe = \"{}\"\n\
         lobe = \"IN1\"\nshare = \"share/M7\"\n[machines.gauge]\nkind = \"sim\"\n\
         part_interval_ms = {part_interval_ms}\n{grinder}",
        repo("config/parts/demo-lobe.toml")
    );
    std::fs::write(dir.join("camloop.toml"), config).expect("the test writes its config");
    let out = camloop(
        &[
            "run",
            "--config",
            "camloop.toml",
            "--parts",
            &parts.to_string(),
        ],
        dir,
    );
    let log = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{log}\n{}", stderr(&out));
    log
}
