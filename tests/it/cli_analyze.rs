//! `camloop analyze` as a user runs it, on the cantools-encoded CAN fixture and on a crankpin
//! CSV: figures checked against the formulas the fixtures were made from.

use crate::cli_support;

use cli_support::{camloop, camloop_ok, crankpin_args, flat_cam_args, json_file, refusal};
use std::fmt::Write as _;
use std::path::Path;

fn fixture(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
        .display()
        .to_string()
}

/// The nominal the CAN fixture was encoded from (tools/encode_candump.py), without its
/// per-revolution ripple and offset: h(ψ) = 6.2·((1 − cos ψ)/2)² mm, at 1° steps.
fn write_fixture_nominal(dir: &Path) -> String {
    let mut s = String::from("angle_deg,lift_mm\n");
    for a in 0..360 {
        let half = (1.0 - f64::from(a).to_radians().cos()) / 2.0;
        let _ = writeln!(s, "{a},{:.9}", 6.2 * half * half);
    }
    std::fs::write(dir.join("nominal.csv"), s).unwrap();
    "nominal.csv".to_string()
}

/// `camloop analyze cam` of `log` against `lift` on the fixture's cam (flat follower,
/// base radius 20 mm, wheel 250 mm), with `extra` arguments.
fn analyze_demo_cam(lift: &str, log: &str, extra: &[&str], dir: &Path) -> std::process::Output {
    let mut args = flat_cam_args("analyze", lift, &["--measurement", log]);
    args.extend_from_slice(extra);
    camloop(&args, dir)
}

#[test]
fn can_log_is_analysed_against_its_nominal() {
    let dir = tempfile::tempdir().unwrap();
    let lift = write_fixture_nominal(dir.path());
    let log = fixture("gauge_3x360.log");
    let out = analyze_demo_cam(&lift, &log, &["--json", "report.json"], dir.path());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = json_file(&dir.path().join("report.json"));
    for field in [
        "error_um",
        "profile_error_um",
        "phase_error_deg",
        "base_radius_error_um",
        "repeatability_um",
        "harmonics",
        "revolutions_used",
        "dropped_revolutions",
        "verdict",
    ] {
        assert!(json.get(field).is_some(), "{field} missing");
    }
    // The fixture adds −0.8 µm to every reading: the base circle reads 0.8 µm undersize. The
    // readings are rounded to 0.1 µm, so the fitted offset is within 0.05 µm of it.
    let delta = json["base_radius_error_um"].as_f64().unwrap();
    assert!((delta + 0.8).abs() < 0.05, "{delta}");
    // Its ripple 1.5 µm·sin(5θ + r) over revolutions r = 0, 1, 2 averages to an order-5
    // harmonic of 1.5·|1 + e^i + e^2i|/3 = 1.5·sin(1.5)/(3·sin(0.5)) = 1.0404 µm; every other
    // order is rounding noise (< 0.05 µm). The nominal's slope has orders 1 and 2 only, so
    // the phase fit leaves order 5 alone and finds no phase error.
    let harmonics = json["harmonics"].as_array().unwrap();
    let amp = |order: u64| {
        harmonics
            .iter()
            .find(|h| h["order"].as_u64() == Some(order))
            .unwrap()["amplitude_um"]
            .as_f64()
            .unwrap()
    };
    let expected = 1.5 * 1.5f64.sin() / (3.0 * 0.5f64.sin());
    assert!((amp(5) - expected).abs() < 0.02, "{} vs {expected}", amp(5));
    for order in (1..=50).filter(|&o| o != 5) {
        assert!(amp(order) < 0.05, "order {order}: {}", amp(order));
    }
    assert!(json["phase_error_deg"].as_f64().unwrap().abs() < 1e-3);
    assert_eq!(json["revolutions_used"].as_array().unwrap().len(), 3);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("PASS"), "{stdout}");
}

#[test]
fn a_log_with_a_cut_off_measurement_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let lift = write_fixture_nominal(dir.path());
    let log = fixture("gauge_cutoff.log");
    let out = analyze_demo_cam(&lift, &log, &[], dir.path());
    let err = refusal(&out);
    assert!(err.contains("gauge_cutoff.log"), "{err}");
}

#[test]
fn crankpin_index_throw_and_diameter_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    // A pin at throw 45.003 mm, radius 30.002 mm, index 0.5°, read as a flat follower from
    // the main axis over 3 revolutions: lift = b·cos(ψ − θ) + r_p − (r_p,nom − b_nom).
    let mut s = String::from("# machine=1 part=2 lobe=3\nrev,angle_deg,lift_mm\n");
    for rev in 0..3 {
        for a in 0..360 {
            let psi = f64::from(a).to_radians();
            let lift = 45.003 * (psi - 0.5f64.to_radians()).cos() + 30.002 - (30.0 - 45.0);
            let _ = writeln!(s, "{rev},{a},{lift:.7}");
        }
    }
    std::fs::write(dir.path().join("pin.csv"), s).unwrap();
    camloop_ok(
        &crankpin_args(
            "analyze",
            &["--measurement", "pin.csv", "--json", "pin.json"],
        ),
        dir.path(),
    );
    let json: serde_json::Value = json_file(&dir.path().join("pin.json"));
    // Written with 1e-7 mm: the figures are exact to well under 0.01 µm and 1e-4°.
    assert!((json["throw_error_um"].as_f64().unwrap() - 3.0).abs() < 0.01);
    assert!((json["diameter_error_um"].as_f64().unwrap() - 4.0).abs() < 0.01);
    assert!((json["index_angle_deg"].as_f64().unwrap() - 0.5).abs() < 1e-4);
    assert!(json["roundness_um"].as_f64().unwrap() < 0.01);
}
