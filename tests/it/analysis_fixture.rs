//! The analysis wired to the real nominal: the ECN Sandia H2 intake lift table through the
//! periodic cubic spline (`LiftCurve`), as the service will do it. Checks the wiring (the
//! spline's slope is per radian; the analysis wants per degree) and that a pure rotation
//! plus size change of a real, asymmetric, 5 µm-quantised lobe is recovered.

use camloop::core::analysis::{LobeOptions, analyse_lobe};
use camloop::core::lift::{LiftCurve, LiftTable};
use camloop::core::measure::AveragedMeasurement;

fn intake() -> LiftCurve {
    let text = include_str!("../fixtures/ecn-sandia-h2-intake.csv");
    let table = LiftTable::parse_csv(text, "ecn-sandia-h2-intake.csv").expect("fixture parses");
    LiftCurve::new(&table)
}

/// The nominal in the analysis' terms: (lift mm, mm per degree).
fn nominal_of(curve: &LiftCurve) -> impl Fn(f64) -> (f64, f64) + '_ {
    |psi_deg: f64| {
        let s = curve.eval(psi_deg.to_radians());
        (s.h_mm, s.dh_mm.to_radians())
    }
}

fn averaged(mean_lift_mm: Vec<f64>) -> AveragedMeasurement {
    AveragedMeasurement {
        origin: "fixture".into(),
        points_per_rev: 360,
        mean_lift_mm,
        repeatability_std_um: vec![0.3; 360],
        repeatability_range_um: vec![0.6; 360],
        revolutions_used: vec![0, 1, 2],
        dropped_revolutions: Vec::new(),
    }
}

#[test]
fn a_rotated_oversize_intake_lobe_is_all_datum() {
    let curve = intake();
    let nominal = nominal_of(&curve);
    for (phase, offset_um) in [(0.4, 2.0), (-1.3, -6.5), (7.0, 0.0)] {
        let mean_lift_mm = (0..360)
            .map(|k| nominal(f64::from(k) - phase).0 + offset_um / 1000.0)
            .collect();
        let avg = averaged(mean_lift_mm);
        let r = analyse_lobe(&avg, &nominal, &LobeOptions::default()).expect("analysable");
        // Exact synthetic data through the same spline: limits are rounding and the
        // 1e-9° stopping rule (1e-9° × max slope ~0.2 mm/° is 2e-7 µm).
        assert!(
            (r.phase_error_deg - phase).abs() < 1e-7,
            "{phase}: {}",
            r.phase_error_deg
        );
        assert!((r.base_radius_error_um - offset_um).abs() < 1e-6);
        assert!(r.profile_error_rms_um < 1e-5, "{}", r.profile_error_rms_um);
        assert!(r.verdict.pass);
        // The base circle of this lobe spans more than 90°.
        assert!(r.runout_um.expect("base circle found") < 1e-5);
    }
}

#[test]
fn an_eccentric_intake_lobe_converges_fast_and_shows_its_runout() {
    // 10 µm eccentricity towards 300° (on the base circle side). Its flank part moves the
    // first-harmonic start away from the optimum, so Gauss–Newton has real work to do: with
    // the slope in the right unit it converges quadratically (a slope per radian, 57× too
    // large, shrinks every step 57-fold and runs out of the 50 iterations).
    let curve = intake();
    let nominal = nominal_of(&curve);
    let mean_lift_mm = (0..360)
        .map(|k| {
            let psi = f64::from(k);
            nominal(psi - 0.5).0 + 0.010 * (psi - 300.0).to_radians().cos()
        })
        .collect();
    let r = analyse_lobe(&averaged(mean_lift_mm), &nominal, &LobeOptions::default())
        .expect("analysable");
    assert!(r.fit_iterations <= 8, "{} iterations", r.fit_iterations);
    let runout = r.runout_um.expect("base circle found");
    eprintln!(
        "DBG it {} phase {} runout {runout} dir {:?} round {:?} pts {}",
        r.fit_iterations,
        r.phase_error_deg,
        r.runout_phase_deg,
        r.base_circle_roundness_um,
        r.base_circle_points
    );
}
