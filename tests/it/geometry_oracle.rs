//! Self-tests of the wheel-centre oracle (tests/support/oracle.rs) on parts whose envelope is
//! known in closed form, and cross-checks between its independent formulations. The oracle
//! backs the 0.1 µm accuracy tests, so it is held here to 1e-9 mm (five hundred times tighter
//! than anything it is used to judge, and ~10× above what it actually achieves).

use crate::support;

use support::lobes::{PolyLobe, rise_polynomial};
use support::oracle::{
    CamOracle, OracleFollower, crankpin_closed_form_d_mm, crankpin_oracle,
    eccentric_circle_radius_mm, flat_support_d_mm, roller_pitch_oracle,
};

/// The oracle's own tolerance, mm (see the module doc).
const ORACLE_TOL_MM: f64 = 1e-9;

const WHEEL_MM: f64 = 250.0;

/// Wheel directions checked: every `step_deg` from 0° plus a fixed off-grid set, degrees.
fn c_values(step_deg: f64) -> Vec<f64> {
    let n = (360.0 / step_deg).round() as usize;
    let mut cs: Vec<f64> = (0..n).map(|k| k as f64 * step_deg).collect();
    cs.extend([0.013, 17.3, 44.444, 91.07, 179.99, 233.3, 301.7, 359.96]);
    cs
}

/// Largest |oracle − expected| over `cs`, mm, with the worst c (degrees).
fn worst(cs: &[f64], oracle: impl Fn(f64) -> f64, expected: impl Fn(f64) -> f64) -> (f64, f64) {
    cs.iter()
        .map(|&c| ((oracle(c) - expected(c)).abs(), c))
        .fold(
            (f64::NEG_INFINITY, f64::NAN),
            |a, b| if b.0 > a.0 { b } else { a },
        )
}

fn assert_within(what: &str, (err_mm, c_deg): (f64, f64)) {
    println!("{what}: max |Δd| = {:.3e} mm at c = {c_deg}°", err_mm);
    assert!(
        err_mm <= ORACLE_TOL_MM,
        "{what}: oracle off by {err_mm:e} mm at c = {c_deg}°"
    );
}

#[test]
fn rise_polynomial_meets_its_end_conditions() {
    // Derivatives at x = 1 by central differences with one Richardson step (P is a polynomial,
    // so evaluating past x = 1 is fine): truncation O(δ⁴·P⁽⁷⁾) ≈ 1e-12·1e5 and rounding
    // O(ε/δ³) ≈ 2e-6 at δ = 1e-3, so 1e-4 separates right from wrong.
    let richardson = |f: &dyn Fn(f64) -> f64, d: f64| (4.0 * f(d / 2.0) - f(d)) / 3.0;
    for a in [0.0, 4.0, 10.0] {
        let p = |x: f64| rise_polynomial(x, a);
        let d1 = |d: f64| (p(1.0 + d) - p(1.0 - d)) / (2.0 * d);
        let d2 = |d: f64| (p(1.0 + d) - 2.0 * p(1.0) + p(1.0 - d)) / (d * d);
        let d3 = |d: f64| {
            (p(1.0 + 2.0 * d) - 2.0 * p(1.0 + d) + 2.0 * p(1.0 - d) - p(1.0 - 2.0 * d))
                / (2.0 * d * d * d)
        };
        let v1 = richardson(&d1, 1e-3);
        let v2 = richardson(&d2, 1e-3);
        let v3 = richardson(&d3, 1e-3);
        assert!((p(1.0) - 1.0).abs() < 1e-12, "P(1) for a = {a}");
        assert!(v1.abs() < 1e-4, "P'(1) = {v1} for a = {a}");
        assert!((v2 + a).abs() < 1e-4, "P''(1) = {v2} for a = {a}");
        assert!(v3.abs() < 1e-4, "P'''(1) = {v3} for a = {a}");
        // Zero lift, velocity, acceleration and jerk at x = 0: P = O(x⁴).
        assert!(p(1e-3).abs() < 1e-10, "P(0⁺) for a = {a}");
    }
}

#[test]
fn base_circle_alone_gives_base_plus_wheel_for_every_follower() {
    let rb = 20.0;
    let cs = c_values(1.0);
    for follower in [
        OracleFollower::Flat,
        OracleFollower::Roller { radius_mm: 10.0 },
        OracleFollower::Knife,
    ] {
        let oracle = CamOracle::new(|_| 0.0, rb, follower, WHEEL_MM);
        assert_within(
            &format!("base circle, {follower:?}"),
            worst(&cs, |c| oracle.d_mm(c), |_| rb + WHEEL_MM),
        );
    }
}

#[test]
fn crankpin_oracle_matches_the_closed_form() {
    let (throw, pin) = (45.0, 26.0);
    let oracle = crankpin_oracle(throw, pin, WHEEL_MM);
    let cs = c_values(0.5);
    assert_within(
        "crankpin",
        worst(
            &cs,
            |c| oracle.d_mm(c),
            |c| crankpin_closed_form_d_mm(throw, pin, WHEEL_MM, c),
        ),
    );
}

/// An eccentric circle (radius `a`, centre `e` from the axis on 0°) read as a cam for each
/// follower: the part is the same circle, so d is the crankpin formula with b = e, r_p = a.
#[test]
fn eccentric_circle_cams_match_the_crankpin_formula() {
    let (e, a, roller) = (6.0, 24.0, 10.0);
    let rb = a - e;
    let expected = |c: f64| crankpin_closed_form_d_mm(e, a, WHEEL_MM, c);
    let cs = c_values(1.0);

    // Knife edge: the lift is the circle's radial function minus the base radius.
    let knife = CamOracle::new(
        |psi| eccentric_circle_radius_mm(e, a, psi) - rb,
        rb,
        OracleFollower::Knife,
        WHEEL_MM,
    );
    assert_within(
        "eccentric circle, knife",
        worst(&cs, |c| knife.d_mm(c), expected),
    );

    // Flat face: the circle's support function is a + e·cos ψ = Rb + (e·cos ψ + e).
    let flat = CamOracle::new(
        |psi: f64| e * psi.cos() + e,
        rb,
        OracleFollower::Flat,
        WHEEL_MM,
    );
    assert_within(
        "eccentric circle, flat",
        worst(&cs, |c| flat.d_mm(c), expected),
    );

    // Roller: the pitch curve is the concentric circle of radius a + r.
    let roller_cam = CamOracle::new(
        |psi| eccentric_circle_radius_mm(e, a + roller, psi) - rb - roller,
        rb,
        OracleFollower::Roller { radius_mm: roller },
        WHEEL_MM,
    );
    assert_within(
        "eccentric circle, roller",
        worst(&cs, |c| roller_cam.d_mm(c), expected),
    );
}

/// The test lobes of the accuracy tests, cross-checked between two formulations that share
/// no code beyond the scan-and-refine search.
#[test]
fn flat_lobe_outline_envelope_matches_the_support_function_formula() {
    let lobe = PolyLobe {
        lift_mm: 8.0,
        nose_deg: 10.0,
        rise_deg: 75.0,
        return_deg: 85.0,
        nose_accel: 4.0,
    };
    let rb = 25.0;
    let lift = |psi| lobe.lift_at_rad(psi);
    let oracle = CamOracle::new(lift, rb, OracleFollower::Flat, WHEEL_MM);
    let cs = c_values(0.5);
    assert_within(
        "flat lobe, outline vs support",
        worst(
            &cs,
            |c| oracle.d_mm(c),
            |c| flat_support_d_mm(lift, rb, WHEEL_MM, c),
        ),
    );
}

#[test]
fn roller_lobe_cam_envelope_matches_the_pitch_curve_envelope() {
    let lobe = PolyLobe {
        lift_mm: 8.0,
        nose_deg: 355.0,
        rise_deg: 70.0,
        return_deg: 80.0,
        nose_accel: 4.0,
    };
    let (rb, roller) = (20.0, 10.0);
    let lift = |psi| lobe.lift_at_rad(psi);
    let oracle = CamOracle::new(
        lift,
        rb,
        OracleFollower::Roller { radius_mm: roller },
        WHEEL_MM,
    );
    let pitch = roller_pitch_oracle(lift, rb, roller, WHEEL_MM);
    let cs = c_values(0.5);
    assert_within(
        "roller lobe, cam vs pitch curve",
        worst(&cs, |c| oracle.d_mm(c), |c| pitch.d_mm(c)),
    );
}

/// A symmetric lobe touches the wheel at the nose and opposite it on the base circle, where
/// the envelope is known exactly for every follower: Rb + L + R and Rb + R.
#[test]
fn symmetric_lobes_reach_nose_and_base_circle_exactly() {
    let lobe = PolyLobe {
        lift_mm: 8.0,
        nose_deg: 200.0,
        rise_deg: 80.0,
        return_deg: 80.0,
        nose_accel: 6.0,
    };
    let rb = 22.0;
    for follower in [
        OracleFollower::Flat,
        OracleFollower::Roller { radius_mm: 10.0 },
        OracleFollower::Knife,
    ] {
        let oracle = CamOracle::new(|psi| lobe.lift_at_rad(psi), rb, follower, WHEEL_MM);
        let nose_err = (oracle.d_mm(lobe.nose_deg) - (rb + lobe.lift_mm + WHEEL_MM)).abs();
        let base_err = (oracle.d_mm(lobe.nose_deg - 180.0) - (rb + WHEEL_MM)).abs();
        assert_within(
            &format!("symmetric lobe nose, {follower:?}"),
            (nose_err, lobe.nose_deg),
        );
        assert_within(
            &format!("symmetric lobe base, {follower:?}"),
            (base_err, lobe.nose_deg - 180.0),
        );
    }
}
