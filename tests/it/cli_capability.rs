//! `camloop capability` and `camloop gauge-study` on the store a real `camloop run` wrote,
//! with master runs of the simulated gauge among the parts: the masters are never learned
//! from nor counted, the capability leaves them out, the gauge study takes only them.

use crate::cli_support;

use cli_support::{camloop_ok, run_demo_lobe};
use serde_json::Value;
use std::path::Path;

const PARTS: usize = 30;
const MASTER_RUNS: usize = 12;

fn run_service(dir: &Path) -> String {
    let gauge = format!(
        "[machines.gauge.grinder.gauge]\nmaster_runs = {MASTER_RUNS}\nmaster_before_part = 3\n"
    );
    run_demo_lobe(dir, PARTS as u32, 10, &gauge)
}

/// `camloop COMMAND --machine M7 EXTRA…` on the run's store, with the limits from its
/// configuration: what it prints.
fn quality(dir: &Path, command: &str, extra: &[&str]) -> String {
    let mut args = vec![
        command,
        "--machine",
        "M7",
        "--database",
        "sqlite://var/camloop.db",
        "--config",
        "camloop.toml",
    ];
    args.extend_from_slice(extra);
    String::from_utf8(camloop_ok(&args, dir).stdout).unwrap()
}

/// [`quality`] with `--format json`, parsed.
fn json(dir: &Path, command: &str, extra: &[&str]) -> Value {
    let text = quality(dir, command, &[extra, &["--format", "json"]].concat());
    serde_json::from_str(&text).unwrap()
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

    let cap = json(dir.path(), "capability", &[]);
    let feature = &cap[0];
    assert_eq!(feature["feature"], "IN1");
    assert_eq!(feature["parts"].as_u64(), Some(PARTS as u64));
    assert_eq!(
        feature["master_runs_left_out"].as_u64(),
        Some(MASTER_RUNS as u64)
    );
    // 30 parts: the figures are there, marked indicative (fewer than 100 values).
    assert_eq!(feature["indicative"], true, "{feature}");
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

    let study = json(dir.path(), "gauge-study", &["--lobe", "IN1"]);
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

/// Below 100 values (the AIAG SPC manual's minimum for a capability study) the figures are
/// shown and marked indicative: a line in the table, a field in the JSON; at 100 neither.
#[test]
fn a_window_under_100_values_is_marked_indicative() {
    let dir = tempfile::tempdir().unwrap();
    // A few more parts than the window, should the loop reject one.
    run_demo_lobe(dir.path(), 110, 1, "");
    let table = |last: &str| quality(dir.path(), "capability", &["--lobe", "IN1", "--last", last]);
    let small = table("7");
    assert!(
        small.lines().nth(1).is_some_and(|l| l
            .starts_with("indicative only: 7 values, fewer than the 100 a capability study needs")),
        "{small}"
    );
    // Marked, not hidden: the timing row still carries its indices.
    let timing = small
        .lines()
        .find(|l| l.starts_with("timing"))
        .unwrap_or("");
    assert!(
        !timing.contains("no statistics") && timing.contains('('),
        "{small}"
    );
    let large = table("100");
    assert!(!large.contains("indicative"), "{large}");
    for (last, indicative) in [("7", true), ("100", false)] {
        let reply = json(dir.path(), "capability", &["--lobe", "IN1", "--last", last]);
        let feature = &reply[0];
        assert_eq!(feature["parts"].to_string(), last, "{feature}");
        assert_eq!(feature["indicative"], indicative, "{feature}");
        assert_eq!(feature["min_values"], 100, "{feature}");
        for c in feature["characteristics"].as_array().unwrap() {
            assert_eq!(c["indicative"], indicative, "{c}");
            assert_eq!(c["capability"]["n"].to_string(), last, "{c}");
            if c["characteristic"] == "timing" {
                assert!(c["capability"]["indices"]["cpk"]["value"].is_f64(), "{c}");
            }
        }
    }
}
