//! The control charts' run rules in a real `camloop run` on the simulated machine: quiet on
//! a converged loop (the false alarms per 1,000 parts are printed), firing on a drift the
//! simulated gauge injects.
//!
//! In-control rates per characteristic for independent normal data, per point: 1 beyond 3σ
//! 0.0027, a new run of 7 on one side ≈ 2·(1/2)⁸ = 0.0078, a new run of 6 rising or falling
//! ≈ 0.0023, the EWMA leaving its limits ≈ 0.0018 (average run length about 560): about
//! 0.0146, or 58 per 1,000 parts over a lobe's four characteristics. The bound below, 100,
//! leaves room for the skew of the two largest-|error| characteristics and for the loop's
//! own correlation from part to part.

use crate::cli_support;

use cli_support::run_demo_lobe;
use std::path::Path;

const PARTS: u32 = 200;
const BASELINE_END: u32 = 30; // 5 start-up parts and 25 baseline parts
const DRIFT_FROM: u32 = 130;

fn run(dir: &Path, gauge: &str) -> Vec<(u32, String)> {
    let grinder = format!(
        "[machines.gauge.grinder]\ndress_every_parts = 0\n[machines.gauge.grinder.gauge]\n{gauge}\n"
    );
    let log = run_demo_lobe(dir, PARTS, 1, &grinder);
    let parts = log.lines().filter(|l| l.contains("M7 IN1 part")).count();
    assert!(parts as u32 >= PARTS - 5, "{log}");
    // "run rule: IN1 size: 7 in a row … at part 57 (…"
    log.lines()
        .filter_map(|l| l.split_once("run rule: ").map(|(_, m)| m))
        .map(|m| {
            let part = m
                .split_once(" at part ")
                .and_then(|(_, r)| r.split(' ').next())
                .and_then(|p| p.parse().ok())
                .unwrap_or_else(|| panic!("no part in {m}"));
            (part, m.to_string())
        })
        .collect()
}

#[test]
fn the_rules_stay_quiet_on_a_converged_loop_and_fire_on_a_drift() {
    let quiet_dir = tempfile::tempdir().unwrap();
    let quiet = run(quiet_dir.path(), "");
    assert!(quiet.iter().all(|(p, _)| *p > BASELINE_END), "{quiet:?}");
    let watched = f64::from(PARTS - BASELINE_END);
    let per_1000 = quiet.len() as f64 / watched * 1000.0;
    eprintln!(
        "converged run: {} run-rule events on {watched} parts after the baseline = {per_1000:.0} per 1,000 parts",
        quiet.len()
    );
    for (_, m) in &quiet {
        eprintln!("  {m}");
    }
    assert!(per_1000 < 100.0, "{quiet:?}");

    // The gauge drifts 0.5 µm a part from part 130. The loop learns the drift (a 0.2 µm a
    // part ramp peaks at 0.19 µm, inside the size chart's 3σ of 0.3 µm, and is gone in 8
    // parts), so what the chart sees is the loop's lag: 0.49 µm at the first part. The size
    // chart must say so within 3 parts.
    let drift_dir = tempfile::tempdir().unwrap();
    let drift = run(
        drift_dir.path(),
        &format!("drift_um_per_part = 0.5\ndrift_from_part = {DRIFT_FROM}"),
    );
    let first = drift
        .iter()
        .filter(|(p, m)| *p >= DRIFT_FROM && m.starts_with("IN1 size"))
        .map(|(p, _)| *p)
        .min();
    eprintln!(
        "drift from part {DRIFT_FROM}: first size event at part {first:?}; {} events after it",
        drift.iter().filter(|(p, _)| *p >= DRIFT_FROM).count()
    );
    for (_, m) in drift.iter().filter(|(p, _)| *p >= DRIFT_FROM) {
        eprintln!("  {m}");
    }
    assert!(first.is_some_and(|p| p < DRIFT_FROM + 3), "{drift:?}");
}
