//! Crankpin analysis against a brute-force oracle: the lift is built as the support
//! function of a dense outline of an off-size, off-throw, mis-indexed, out-of-round pin
//! (max over outline points of p·u(ψ)), not from the formula the analysis inverts.

use camloop::core::analysis::{AnalysisError, PinNominal, analyse_pin};
use camloop::core::measure::AveragedMeasurement;

const N: usize = 360;

fn averaged(mean_lift_mm: Vec<f64>) -> AveragedMeasurement {
    let n = mean_lift_mm.len();
    AveragedMeasurement {
        origin: "pin-test".into(),
        points_per_rev: n as u32,
        mean_lift_mm,
        repeatability_std_um: vec![0.3; n],
        repeatability_range_um: vec![0.6; n],
        revolutions_used: vec![0, 1, 2],
        dropped_revolutions: Vec::new(),
    }
}

/// Form error of the pin as a radial deviation around its own centre, mm.
fn form_mm(alpha_deg: f64) -> f64 {
    0.002 * (3.0 * alpha_deg).to_radians().cos()
        + 0.001 * (2.0 * (alpha_deg - 20.0)).to_radians().cos()
}

/// Support function of the outline `centre + (r + form(α))·u(α)` in direction ψ, by brute
/// force: the touching point of a near-circle lies near α = ψ, so α is searched densely
/// (0.001° steps) over ψ ± 2°. Sampling error: r·(1 − cos 0.0005°) ≈ 1e-9 mm.
fn support_mm(centre: (f64, f64), r: f64, psi_deg: f64) -> f64 {
    let (us, uc) = psi_deg.to_radians().sin_cos();
    (-2000..=2000)
        .map(|i| {
            let alpha = psi_deg + f64::from(i) * 0.001;
            let rho = r + form_mm(alpha);
            let (s, c) = alpha.to_radians().sin_cos();
            (centre.0 + rho * c) * uc + (centre.1 + rho * s) * us
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

#[test]
fn size_throw_index_and_roundness_come_back() {
    let nominal = PinNominal {
        throw_mm: 45.0,
        pin_radius_mm: 30.0,
        index_deg: 120.0,
    };
    // Actual pin: throw +30 µm, radius −5 µm (diameter −10 µm), index +0.3°.
    let (b, r, theta) = (45.030, 29.995, 120.3_f64);
    let centre = (b * theta.to_radians().cos(), b * theta.to_radians().sin());
    let zero_mm = nominal.pin_radius_mm - nominal.throw_mm; // gauge mastered on the nominal
    let lift: Vec<f64> = (0..N)
        .map(|k| support_mm(centre, r, k as f64) - zero_mm)
        .collect();
    let report = analyse_pin(&averaged(lift), &nominal, 50).expect("analysable");

    // Support ≠ radius for a non-round outline only to second order: (f')²/r ≈ 1e-6 mm.
    // So 0.01 µm on lengths and 1e-4° on the index (0.01 µm over 45 mm is 1.3e-5°).
    assert!(
        (report.diameter_error_um + 10.0).abs() < 0.01,
        "{}",
        report.diameter_error_um
    );
    assert!(
        (report.throw_error_um - 30.0).abs() < 0.01,
        "{}",
        report.throw_error_um
    );
    assert!(
        (report.index_angle_deg - 120.3).abs() < 1e-4,
        "{}",
        report.index_angle_deg
    );
    assert!(
        (report.index_error_deg - 0.3).abs() < 1e-4,
        "{}",
        report.index_error_deg
    );
    let form: Vec<f64> = (0..N).map(|k| form_mm(k as f64) * 1000.0).collect();
    let pv = form.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - form.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(
        (report.roundness_um - pv).abs() < 0.01,
        "{} vs {pv}",
        report.roundness_um
    );
    for (k, f) in form.iter().enumerate() {
        assert!((report.residual_um[k] - f).abs() < 0.01, "residual at {k}°");
    }
    // Harmonics of the raw error: order 2 and 3 are the form (1 and 2 µm), order 1 carries
    // throw and index.
    assert!((report.harmonics[1].amplitude_um - 1.0).abs() < 0.01);
    assert!((report.harmonics[2].amplitude_um - 2.0).abs() < 0.01);
    assert!(report.harmonics[3..].iter().all(|h| h.amplitude_um < 0.01));
    assert_eq!(report.revolutions_used, vec![0, 1, 2]);
}

#[test]
fn a_nominal_pin_reads_no_error_and_the_index_wraps() {
    let nominal = PinNominal {
        throw_mm: 40.0,
        pin_radius_mm: 25.0,
        index_deg: 179.9,
    };
    let lift: Vec<f64> = (0..N).map(|k| nominal.lift_mm(k as f64)).collect();
    let report = analyse_pin(&averaged(lift), &nominal, 50).expect("analysable");
    // Exact data: rounding only (lifts up to 80 mm carry ~1e-14 mm).
    assert!(report.error_um.iter().all(|e| e.abs() < 1e-9));
    assert!(report.diameter_error_um.abs() < 1e-9 && report.throw_error_um.abs() < 1e-9);
    assert!(report.roundness_um < 1e-9 && report.index_error_deg.abs() < 1e-9);

    // Measured at −179.9° (= 180.1°): +0.2° across the ±180° seam.
    let moved = PinNominal {
        index_deg: -179.9,
        ..nominal
    };
    let lift: Vec<f64> = (0..N).map(|k| moved.lift_mm(k as f64)).collect();
    let report = analyse_pin(&averaged(lift), &nominal, 50).expect("analysable");
    assert!(
        (report.index_error_deg - 0.2).abs() < 1e-9,
        "{}",
        report.index_error_deg
    );
    assert!(
        (report.index_angle_deg + 179.9).abs() < 1e-9,
        "{}",
        report.index_angle_deg
    );
}

#[test]
fn invalid_pin_nominals_are_refused() {
    let avg = averaged(vec![1.0; N]);
    for (nominal, field) in [
        (
            PinNominal {
                throw_mm: 0.0,
                pin_radius_mm: 25.0,
                index_deg: 0.0,
            },
            "throw_mm",
        ),
        (
            PinNominal {
                throw_mm: 40.0,
                pin_radius_mm: f64::NAN,
                index_deg: 0.0,
            },
            "pin_radius_mm",
        ),
        (
            PinNominal {
                throw_mm: 40.0,
                pin_radius_mm: 25.0,
                index_deg: f64::INFINITY,
            },
            "index_deg",
        ),
    ] {
        let err = analyse_pin(&avg, &nominal, 50).expect_err(field);
        assert!(
            matches!(err, AnalysisError::InvalidParameter { field: f, .. } if f == field),
            "{err:?}"
        );
    }
}
