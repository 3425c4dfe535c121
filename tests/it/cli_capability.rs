//! `camloop capability` and `camloop gauge-study` on the store a real `camloop run` wrote,
//! with master runs of the simulated gauge among the parts: the masters are never learned
//! from nor counted, the capability leaves them out, the gauge study takes only them.

use crate::cli_support;

use cli_support::{camloop, stderr};
use serde_json::Value;
use std::path::Path;

const PARTS: usize = 30;
const MASTER_RUNS: usize = 12;

fn run_service(dir: &Path) -> String {
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let config = format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n[http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"M7\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share/M7\"\n[machines.gauge]\nkind = \"sim\"\npart_interval_ms = 10\n\
         [machines.gauge.grinder.gauge]\nmaster_runs = {MASTER_RUNS}\nmaster_before_part = 3\n",
        recipe.display()
    );
    std::fs::write(dir.join("camloop.toml"), config).unwrap();
    let out = camloop(
        &[
            "run",
            "--config",
            "camloop.toml",
            "--parts",
            &PARTS.to_string(),
        ],
        dir,
    );
    let log = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{log}\n{}", stderr(&out));
    log
}

fn json(dir: &Path, args: &[&str]) -> Value {
    let out = camloop(args, dir);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn masters_feed_the_gauge_study_and_never_the_loop_or_the_capability() {
    let dir = tempfile::tempdir().unwrap();
    let log = run_service(dir.path());
    // Every master run is recorded, and the loop's own count of parts never sees one: the
    // 30th production part is its part 30 (a master counted would make it 42).
    assert_eq!(
        log.matches("master run recorded").count(),
        MASTER_RUNS,
        "{log}"
    );
    let parts: Vec<&str> = log.lines().filter(|l| l.contains("M7 IN1 part")).collect();
    assert_eq!(parts.len(), PARTS, "{log}");
    assert!(
        parts[PARTS - 1].contains(&format!("M7 IN1 part {PARTS}:")),
        "{}",
        parts[PARTS - 1]
    );

    let db = "sqlite://var/camloop.db";
    let cap = json(
        dir.path(),
        &[
            "capability",
            "--machine",
            "M7",
            "--format",
            "json",
            "--database",
            db,
            "--config",
            "camloop.toml",
        ],
    );
    let feature = &cap[0];
    assert_eq!(feature["feature"], "IN1");
    assert_eq!(feature["parts"].as_u64(), Some(PARTS as u64));
    assert_eq!(
        feature["master_runs_left_out"].as_u64(),
        Some(MASTER_RUNS as u64)
    );
    let by = |name: &str| {
        feature["characteristics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["characteristic"] == name)
            .unwrap()
            .clone()
    };
    // The demo lobe's recipe gives timing and size tolerances and one symmetric band, no
    // max-error tolerance: indices for the others, and the reply says why not for that one.
    let timing = by("timing");
    assert_eq!(timing["capability"]["n"].as_u64(), Some(PARTS as u64));
    assert!(
        timing["capability"]["indices"]["cp"]["value"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    let profile = by("profile_error");
    assert_eq!(profile["capability"]["indices"]["sides"], "upper");
    assert!(
        profile["capability"]["model"]["candidates"]
            .as_array()
            .unwrap()
            .len()
            >= 2
    );
    let max = by("max_error");
    assert!(max["capability"]["indices"].is_null());
    let note = max["note"].as_str().unwrap();
    assert!(note.contains("no max_error_tolerance_um"), "{max}");
    assert!(
        by("size")["capability"]["indices"]["cp"]["value"]
            .as_f64()
            .unwrap()
            > 0.0
    );

    let study = json(
        dir.path(),
        &[
            "gauge-study",
            "--machine",
            "M7",
            "--lobe",
            "IN1",
            "--format",
            "json",
            "--database",
            db,
            "--config",
            "camloop.toml",
        ],
    );
    assert_eq!(study["runs"].as_u64(), Some(MASTER_RUNS as u64));
    let items = study["characteristics"].as_array().unwrap();
    let timing = items
        .iter()
        .find(|c| c["characteristic"] == "timing")
        .unwrap();
    // The master is the nominal read with 0.3 µm of noise: timing bias within noise, and the
    // gauge capable against ±0.05°.
    assert_eq!(timing["study"]["n"].as_u64(), Some(MASTER_RUNS as u64));
    assert!(timing["study"]["cg"].as_f64().unwrap() > 1.33, "{timing}");
    assert_eq!(timing["study"]["capable"], true);
    let size = items
        .iter()
        .find(|c| c["characteristic"] == "size")
        .unwrap();
    assert_eq!(size["study"]["capable"], true, "{size}");
    let max = items
        .iter()
        .find(|c| c["characteristic"] == "max_error")
        .unwrap();
    let note = max["note"].as_str().unwrap();
    assert!(
        max["study"].is_null() && note.contains("does not apply"),
        "{max}"
    );
}
