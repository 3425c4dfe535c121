//! The speed plan against an independent time-optimal solver: TOPP-RA (the `toppra` package,
//! run by the repository's `tests/speed_plan/topp_reference.py`) on the demo intake lobe
//! where the X axis binds (no removal limit, C up to 600 rpm and 36 000 °/s²).
//!
//! The reference has no jerk limit, so its revolution is a lower bound for every plan that
//! keeps the X jerk limit too: a plan within 3 % of it is within 3 % of the jerk-limited
//! optimum, whatever that is. That the plan keeps every limit, jerk included, is proven
//! apart (`speed_plan.rs`: finite differences of the exact geometry; `speed_plan_sampled.rs`:
//! the written tables sampled at the control's interpolation cycle).
//!
//! Skips with a line on stderr when python3 with toppra is missing, unless
//! `CAMLOOP_REQUIRE_TOPPRA=1` (CI sets it and installs toppra).

use camloop_core::geometry::{CamGeometry, Follower, Part};
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::speed_plan::{self, SpeedLimits};
use serde_json::{Value, json};
use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};

const INTAKE: &str = include_str!("../../../config/parts/demo-intake-lobe.csv");

/// How far above the jerk-free optimum the plan may be (the bound).
const WITHIN: f64 = 0.03;
/// How far below it the plan may be: none, but for the two discretisations (the plan's 0.1°
/// grid with its piecewise-constant α, toppra's 0.1° grid on its own spline of X), which
/// differ by under 0.2 % on this lobe.
const DISCRETISATION: f64 = 0.002;

fn lobe() -> Part {
    let table = LiftTable::parse_csv(INTAKE, "demo intake lobe").unwrap();
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    };
    Part::cam(geometry, LiftCurve::new(&table)).unwrap()
}

/// The demo's X limits; no removal limit; C up to 600 rpm and 36 000 °/s².
fn x_bound() -> SpeedLimits {
    SpeedLimits {
        x_velocity_mm_s: 200.0,
        x_acceleration_mm_s2: 10_000.0,
        x_jerk_mm_s3: 10_000_000.0,
        c_max_speed_rpm: 600.0,
        c_max_accel_deg_s2: 36_000.0,
        q_w_max_mm3_mm_s: 1e9,
        stock_mm: 0.02,
    }
}

fn toppra_available() -> bool {
    Command::new("python3")
        .args(["-c", "import toppra, scipy, numpy"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The reference's revolution, s, for `part` under `limits`: X at every 0.05° from the exact
/// geometry, nothing else of the planner's.
fn reference_revolution_s(part: &Part, limits: &SpeedLimits) -> f64 {
    let x_mm: Vec<f64> = (0..7200)
        .map(|k| part.d_at_c_deg(k as f64 * 0.05).unwrap() - part.x_zero_mm())
        .collect();
    let input = json!({
        "x_mm": x_mm,
        "grid_deg": 0.1,
        "limits": {
            "x_velocity_mm_s": limits.x_velocity_mm_s,
            "x_acceleration_mm_s2": limits.x_acceleration_mm_s2,
            "c_max_speed_rad_s": speed_plan::rad_s(limits.c_max_speed_rpm),
            "c_max_accel_rad_s2": limits.c_max_accel_deg_s2.to_radians(),
        },
    });
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/speed_plan/topp_reference.py");
    let mut child = Command::new("python3")
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    child
        .stdin
        .take()
        .expect("piped")
        .write_all(input.to_string().as_bytes())
        .expect("the script reads its input");
    let out = child.wait_with_output().expect("the script ends");
    assert!(out.status.success(), "{} failed", script.display());
    let answer: Value = serde_json::from_slice(&out.stdout).expect("the script prints JSON");
    answer["revolution_s"].as_f64().expect("a revolution time")
}

#[test]
fn x_bound_plan_is_within_three_percent_of_the_independent_optimum() {
    if !toppra_available() {
        assert!(
            std::env::var("CAMLOOP_REQUIRE_TOPPRA").as_deref() != Ok("1"),
            "CAMLOOP_REQUIRE_TOPPRA=1 but python3 with toppra is missing"
        );
        eprintln!("skipped: python3 with toppra is missing (pip install toppra)");
        return;
    }
    let part = lobe();
    let limits = x_bound();
    let optimum = reference_revolution_s(&part, &limits);
    let plan = speed_plan::plan(&part, &limits).unwrap();
    let ratio = plan.revolution_s() / optimum;
    eprintln!(
        "X-bound intake lobe: plan {:.4} s, TOPP-RA {optimum:.4} s, ratio {ratio:.4} ({} rounds)",
        plan.revolution_s(),
        plan.rounds
    );
    assert!(!plan.is_constant, "the plan fell back to constant speed");
    assert!(
        ratio <= 1.0 + WITHIN,
        "plan {:.4} s is more than 3 % over the optimum {optimum:.4} s",
        plan.revolution_s()
    );
    assert!(
        ratio >= 1.0 - DISCRETISATION,
        "plan {:.4} s beats the time-optimal {optimum:.4} s: a limit is not kept",
        plan.revolution_s()
    );
}
