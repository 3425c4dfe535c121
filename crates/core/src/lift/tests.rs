//! Lift table parsing and validation, table-driven.

use super::*;

fn grid_csv(step_deg: usize, lift: impl Fn(f64) -> f64) -> String {
    let mut s = String::from("angle_deg,lift_mm\n");
    for a in (0..360).step_by(step_deg) {
        s.push_str(&format!("{a},{:.6}\n", lift(a as f64)));
    }
    s
}

fn err(text: &str) -> String {
    match LiftTable::parse_csv(text, "lobe.csv") {
        Ok(_) => panic!("table was accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn accepts_header_comments_and_closing_point() {
    let mut text = String::from("# exported by a gauge\n");
    text += &grid_csv(5, |a| if a > 100.0 { 1.0 } else { 0.0 });
    text += "360,0.0 # closes the period\n";
    let t = LiftTable::parse_csv(&text, "lobe.csv").unwrap();
    assert_eq!(t.angles_deg().len(), 72);
    assert_eq!(t.lifts_mm()[21], 1.0);
}

#[test]
fn refuses_bad_tables_naming_file_and_place() {
    let good = grid_csv(5, |_| 0.0);
    let cases: Vec<(String, &str)> = vec![
        (
            good.replace("\n10,", "\n5,"),
            "lobe.csv:4: duplicate angle 5°",
        ),
        (
            good.replace("\n15,", "\n8,"),
            "lobe.csv:5: angle 8° comes after 10°",
        ),
        (
            good.replace("15,0.000000\n20,0.000000\n25,0.000000\n", ""),
            "lobe.csv: gap of 20.000° between 10° and 30°",
        ),
        (
            grid_csv(10, |_| 0.0).replace("350,0.000000\n", ""),
            "lobe.csv: 35 points, at least 36",
        ),
        (
            good.replace("\n20,0.000000", "\n20,NaN"),
            "lobe.csv:6: lift at 20° is not a finite number",
        ),
        (
            good.replace("\n20,0.000000", "\n20,-0.002"),
            "lobe.csv:6: negative lift -0.002 mm at 20°",
        ),
        (
            good.replace("\n20,0.000000", "\n20,abc"),
            "lobe.csv:6: lift `abc` is not a number",
        ),
        (
            good.replace("\n20,0.000000", "\n20,0,1"),
            "lobe.csv:6: expected 2 fields",
        ),
        (
            good + "361,0\n",
            "lobe.csv:74: angle 361° is more than one revolution",
        ),
        (
            grid_csv(5, |_| 0.0) + "360,0.5\n",
            "lobe.csv:74: closing point at 360° has lift 0.5 mm",
        ),
    ];
    for (text, expected) in cases {
        let message = err(&text);
        assert!(
            message.starts_with(expected),
            "expected `{expected}…`, got `{message}`"
        );
    }
}

#[test]
fn wrap_around_gap_is_checked() {
    let text: String = (0..=340).step_by(5).map(|a| format!("{a},0\n")).collect();
    assert!(err(&text).contains("gap of 20.000° between 340° and 360°"));
}

#[test]
fn small_negative_lift_within_tolerance_is_kept() {
    let t =
        LiftTable::parse_csv(&grid_csv(5, |a| if a == 20.0 { -0.0005 } else { 0.0 }), "x").unwrap();
    assert_eq!(t.lifts_mm()[4], -0.0005);
}

#[test]
fn parses_opticline_and_checks_step_count() {
    let mut text = String::from("3.0000\n72\n");
    for a in (0..360).step_by(5) {
        text += &format!("{a:.2}  {:.4}  0\n", (a as f64).to_radians().sin() + 1.0);
    }
    let t = LiftTable::parse_opticline(&text, "nominal.txt").unwrap();
    assert_eq!(t.probe_radius_mm(), Some(3.0));
    assert_eq!(t.angles_deg().len(), 72);
    assert!((t.lifts_mm()[18] - 2.0).abs() < 1e-12);

    let short = text.replacen("72\n", "73\n", 1);
    let e = LiftTable::parse_opticline(&short, "nominal.txt")
        .unwrap_err()
        .to_string();
    assert!(e.contains("72 rows, but line 2 announced 73 steps"), "{e}");
    let bad = text.replacen("3.0000", "three", 1);
    let e = LiftTable::parse_opticline(&bad, "nominal.txt")
        .unwrap_err()
        .to_string();
    assert_eq!(e, "nominal.txt:1: probe radius `three` is not a number");
}

#[test]
fn curve_interpolates_the_table_and_is_periodic() {
    let t =
        LiftTable::parse_csv(&grid_csv(1, |a| 4.0 * (1.0 - a.to_radians().cos())), "x").unwrap();
    let c = LiftCurve::new(&t);
    for (a, l) in t.angles_deg().iter().zip(t.lifts_mm()) {
        assert!((c.lift_mm(*a) - l).abs() < 1e-12);
        assert!((c.lift_mm(*a + 360.0) - l).abs() < 1e-12);
    }
    // h = 4(1 − cos ψ): h' = 4 sin ψ exactly; the spline's slope at 1° knots is O(h³)
    // accurate (≈ 4·(0.01745)³/24 ≈ 9e-7 mm/rad), and rounding to 1e-6 mm adds < 1e-4.
    let s = c.eval(1.0);
    assert!((s.dh_mm - 4.0 * 1.0f64.sin()).abs() < 2e-4, "{}", s.dh_mm);
}
