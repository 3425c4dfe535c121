//! `camloop table` as a user runs it: real binary, real files, exit codes and stderr.

use crate::cli_support;

use cli_support::{
    assert_nothing_written, camloop, camloop_ok, crankpin_args, flat_cam_args, refusal, repo,
    stderr,
};
use std::path::{Path, PathBuf};

/// The real engine lift shipped with the project docs; looked for beside the repo.
fn ecn_fixture() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let local = manifest.join("tests/fixtures/ecn-sandia-h2-intake.csv");
    assert!(local.exists(), "fixture missing: {}", local.display());
    local
}

#[test]
fn quantised_engine_lift_is_refused_with_the_angle_range_and_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let fixture = ecn_fixture().display().to_string();
    let out = camloop(
        &flat_cam_args("table", &fixture, &["--csv", "t.csv"]),
        dir.path(),
    );
    let err = refusal(&out);
    assert!(err.contains("ecn-sandia-h2-intake.csv"), "{err}");
    assert!(err.contains("negative radius of curvature"), "{err}");
    assert!(err.contains("between 254.56° and 255.59°"), "{err}");
    assert!(!dir.path().join("t.csv").exists());
    assert_nothing_written(dir.path());
}

#[test]
fn smoothing_makes_it_grindable_and_reports_the_change() {
    let dir = tempfile::tempdir().unwrap();
    let fixture = ecn_fixture().display().to_string();
    let out = camloop_ok(
        &flat_cam_args("table", &fixture, &["--smooth", "--csv", "t.csv"]),
        dir.path(),
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find(|l| l.starts_with("smoothed"))
        .expect("smoothing reported");
    // "lift changed by at most X µm": the 5 µm quantisation means a few µm is expected;
    // the default limit is 10 µm.
    let change: f64 = line
        .split("at most ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(change > 0.5 && change <= 10.0, "{line}");
    assert!(dir.path().join("t.csv").exists());
}

#[test]
fn csv_has_one_row_per_point_on_the_uniform_grid_with_nine_decimals() {
    let dir = tempfile::tempdir().unwrap();
    let lift = repo("config/parts/demo-intake-lobe.csv");
    camloop_ok(
        &flat_cam_args("table", &lift, &["--points", "720", "--csv", "out/t.csv"]),
        dir.path(),
    );
    let csv = std::fs::read_to_string(dir.path().join("out/t.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("c_deg,d_mm,x_mm"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 720);
    for (k, row) in rows.iter().enumerate() {
        let c: f64 = row[0].parse().unwrap();
        assert!((c - k as f64 * 0.5).abs() < 1e-9);
        for v in &row[1..] {
            assert_eq!(v.split('.').nth(1).map(str::len), Some(9), "{v}");
        }
        let (d, x): (f64, f64) = (row[1].parse().unwrap(), row[2].parse().unwrap());
        // X = d − R − Rb exactly (both printed with 9 decimals).
        assert!((x - (d - 270.0)).abs() < 2e-9, "row {k}");
    }
    // Base circle (ψ far from the 100°–260° event): X = 0; nose at 180°: X = 8 mm lift.
    let x_at = |k: usize| rows[k][2].parse::<f64>().unwrap();
    assert!(x_at(0).abs() < 1e-9);
    assert!((x_at(360) - 8.0).abs() < 1e-9);
}

#[test]
fn bad_input_gives_one_clear_line_and_keeps_existing_outputs() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("t.csv"), "previous").unwrap();
    std::fs::write(dir.path().join("short.csv"), "0,0\n10,0\n20,0\n").unwrap();
    let lift = repo("config/parts/demo-intake-lobe.csv");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            flat_cam_args("table", "missing.csv", &["--csv", "t.csv"]),
            "cannot read lift table missing.csv",
        ),
        (
            flat_cam_args("table", "short.csv", &["--csv", "t.csv"]),
            "short.csv: 3 points, at least 36 are needed",
        ),
        (
            flat_cam_args("table", &lift, &["--points", "10", "--csv", "t.csv"]),
            "10 points per revolution is outside 36..=36000",
        ),
        (
            vec![
                "table",
                "cam",
                "--lift",
                &lift,
                "--follower",
                "roller",
                "--base-radius",
                "20",
                "--wheel-radius",
                "250",
                "--csv",
                "t.csv",
            ],
            "--roller-radius is required",
        ),
        (
            vec![
                "table",
                "crankpin",
                "--throw",
                "300",
                "--pin-radius",
                "30",
                "--wheel-radius",
                "250",
                "--csv",
                "t.csv",
            ],
            "throw = 300 is invalid: must be smaller than wheel radius + pin radius",
        ),
        (
            vec![
                "table",
                "cam",
                "--lift",
                &lift,
                "--follower",
                "flat",
                "--base-radius",
                "-5",
                "--wheel-radius",
                "250",
                "--csv",
                "t.csv",
            ],
            "base radius = -5 is invalid",
        ),
    ];
    for (args, expected) in cases {
        let out = camloop(&args, dir.path());
        let err = stderr(&out);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.contains(expected),
            "{args:?}: expected `{expected}` in `{err}`"
        );
        assert_eq!(
            std::fs::read_to_string(dir.path().join("t.csv")).unwrap(),
            "previous"
        );
    }
}

#[test]
fn program_main_program_and_svg_are_written_together() {
    let dir = tempfile::tempdir().unwrap();
    let lift = repo("config/parts/demo-intake-lobe.csv");
    camloop_ok(
        &flat_cam_args(
            "table",
            &lift,
            &[
                "--form",
                "poly",
                "--program",
                "nc/CAM_T2.SPF",
                "--table-number",
                "2",
                "--main-program",
                "nc/CAM_GRIND.MPF",
                "--svg",
                "setup.svg",
            ],
        ),
        dir.path(),
    );
    let spf = std::fs::read_to_string(dir.path().join("nc/CAM_T2.SPF")).unwrap();
    let lines: Vec<&str> = spf.lines().collect();
    assert_eq!(lines[0], "%_N_CAM_T2_SPF");
    assert_eq!(lines[1], ";$PATH=/_N_SPF_DIR");
    assert!(lines.contains(&"PROC CAM_T2(VAR INT CL_TNO) SAVE"));
    assert!(lines.contains(&"CTABDEF(X,C,2,1)"));
    assert!(lines.iter().any(|l| l.starts_with("CL_TNO=2 ")));
    // The demo lobe needs no refinement: one POLY block per table point, the last one
    // closing the period at 360°.
    let blocks: Vec<&&str> = lines.iter().filter(|l| l.starts_with("PO[C]=")).collect();
    assert_eq!(blocks.len(), 360);
    assert!(
        blocks[359].starts_with("PO[C]=(360.0000) PO[X]=(0.0000,"),
        "{}",
        blocks[359]
    );
    let mpf = std::fs::read_to_string(dir.path().join("nc/CAM_GRIND.MPF")).unwrap();
    assert!(mpf.starts_with("%_N_CAM_GRIND_MPF\n"));
    // The main program couples the number the table program returns, never a literal.
    assert!(mpf.contains("\nCAM_T2(CL_TNO) ;") && mpf.contains("\nLEADON(X,C,CL_TNO)\n"));
    assert!(mpf.contains("LEADOF(X,C)") && !mpf.contains("LEADON(X,C,2)"));
    let svg = std::fs::read_to_string(dir.path().join("setup.svg")).unwrap();
    assert!(
        svg.starts_with("<?xml") || svg.starts_with("<svg"),
        "{}",
        &svg[..40]
    );
}

#[test]
fn invalid_program_name_writes_nothing_at_all() {
    let dir = tempfile::tempdir().unwrap();
    let lift = repo("config/parts/demo-intake-lobe.csv");
    let out = camloop(
        &flat_cam_args(
            "table",
            &lift,
            &["--csv", "t.csv", "--program", "CYCLE_CAM.SPF"],
        ),
        dir.path(),
    );
    let err = refusal(&out);
    assert!(
        err.contains("CYCLE_CAM.SPF") && err.contains("CYCLE"),
        "{err}"
    );
    assert_nothing_written(dir.path());
}

#[test]
fn plot_draws_the_crankpin_with_four_wheels() {
    let dir = tempfile::tempdir().unwrap();
    camloop_ok(&crankpin_args("plot", &["--svg", "pin.svg"]), dir.path());
    let svg = std::fs::read_to_string(dir.path().join("pin.svg")).unwrap();
    for label in ["c = 0°", "c = 90°", "c = 180°", "c = 270°"] {
        assert!(svg.contains(label), "{label} missing");
    }
}
