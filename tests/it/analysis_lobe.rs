//! Lobe analysis on exact synthetic data: the datum convention (signs), what the fit
//! absorbs (checked against a linear least-squares projection computed here), runout,
//! velocity error, statistics, the JSON field names and the input errors.

use crate::cycloid_cam;
use camloop::core::analysis::{AnalysisError, LobeOptions, ToleranceBand, analyse_lobe};
use camloop::core::measure::{AveragedMeasurement, DroppedRevolution};
use cycloid_cam::cam;

const N: usize = 360;

fn grid() -> Vec<f64> {
    (0..N).map(|k| k as f64 * 360.0 / N as f64).collect()
}

/// An averaged measurement with the given mean lift and a made-up, known spread.
fn averaged(mean_lift_mm: Vec<f64>) -> AveragedMeasurement {
    let n = mean_lift_mm.len();
    AveragedMeasurement {
        origin: "test".into(),
        points_per_rev: n as u32,
        mean_lift_mm,
        repeatability_std_um: (0..n).map(|k| 0.2 + 0.001 * k as f64).collect(),
        repeatability_range_um: vec![0.5; n],
        revolutions_used: vec![0, 2, 3],
        dropped_revolutions: vec![DroppedRevolution {
            revolution: 1,
            max_deviation_um: 20.0,
            at_angle_deg: 30.0,
            reason: "test".into(),
        }],
    }
}

fn measured(f: impl Fn(f64) -> f64) -> AveragedMeasurement {
    averaged(grid().into_iter().map(f).collect())
}

#[test]
fn a_pure_rotation_and_size_change_is_all_datum() {
    // Lags of 1.5°, 12° and −25°: the first-harmonic start must bring even the large ones
    // into Gauss–Newton's basin.
    for phase in [1.5, 12.0, -25.0] {
        let avg = measured(|psi| cam(psi - phase).0 + 0.004);
        let r = analyse_lobe(&avg, &cam, &LobeOptions::default()).expect("analysable");
        // Exact data: limits are rounding (lifts ~9 mm carry ~1e-15 mm).
        assert!(
            (r.phase_error_deg - phase).abs() < 1e-8,
            "{phase}: {}",
            r.phase_error_deg
        );
        assert!(
            (r.base_radius_error_um - 4.0).abs() < 1e-6,
            "{}",
            r.base_radius_error_um
        );
        assert!(r.profile_error_rms_um < 1e-6, "{}", r.profile_error_rms_um);
        for (k, psi) in grid().into_iter().enumerate() {
            let expected = (cam(psi - phase).0 - cam(psi).0) * 1000.0 + 4.0;
            assert!(
                (r.error_um[k] - expected).abs() < 1e-9,
                "error_um at {psi}°"
            );
        }
        assert!(
            r.fit_iterations <= 10,
            "{phase}: {} iterations",
            r.fit_iterations
        );
    }
}

/// φ that a linear least-squares fit of `m − h ≈ δ − φ·h'` gives, computed independently
/// of the library: centred normal equation on the grid.
fn linear_phase(extra_um: &[f64]) -> f64 {
    let slope: Vec<f64> = grid().into_iter().map(|psi| cam(psi).1 * 1000.0).collect();
    let ms = slope.iter().sum::<f64>() / N as f64;
    let me = extra_um.iter().sum::<f64>() / N as f64;
    let num: f64 = slope
        .iter()
        .zip(extra_um)
        .map(|(g, e)| (g - ms) * (e - me))
        .sum();
    let den: f64 = slope.iter().map(|g| (g - ms) * (g - ms)).sum();
    -num / den
}

#[test]
fn an_eccentric_part_shows_as_base_circle_runout() {
    // A part displaced by ε towards θ: a flat probe reads its support function plus
    // ε·cos(ψ − θ), exactly. The part along the flank slope is absorbed as phase (as the
    // linear projection predicts); the base circle, where the nominal is flat, keeps it all.
    let eps_um = 10.0;
    for theta in [0.0_f64, 77.0, 90.0, 180.0, 250.0] {
        let extra: Vec<f64> = grid()
            .into_iter()
            .map(|psi| eps_um * (psi - theta).to_radians().cos())
            .collect();
        let avg = measured(|psi| cam(psi).0 + eps_um / 1000.0 * (psi - theta).to_radians().cos());
        let r = analyse_lobe(&avg, &cam, &LobeOptions::default()).expect("analysable");
        let predicted = linear_phase(&extra);
        // Linearisation error: h''·φ²/2 over φ ≈ 0.05° is ~1e-4 of φ.
        assert!(
            (r.phase_error_deg - predicted).abs() < 1e-3 * predicted.abs() + 1e-7,
            "θ {theta}: phase {} vs linear {predicted}",
            r.phase_error_deg
        );
        let runout = r.runout_um.expect("base circle ≈ 220°");
        // The base circle is where the shifted nominal is ≤ 1 µm; at its two edges (the
        // first ~1.8° of the ramps) the slope is up to 1.7 µm/°, so the fitted φ ≈ 0.03°
        // leaves up to ~0.05 µm there as genuine profile error. That bends the runout by
        // < 0.001 µm (seen: 4e-4) and the direction by < 0.01°, and is all the roundness.
        assert!(
            (runout - 2.0 * eps_um).abs() < 0.005,
            "θ {theta}: runout {runout}"
        );
        let dir = r.runout_phase_deg.expect("present");
        let dir_off = (dir - theta + 540.0).rem_euclid(360.0) - 180.0;
        assert!(dir_off.abs() < 0.01, "θ {theta}: direction {dir}");
        let roundness = r.base_circle_roundness_um.expect("present");
        assert!(roundness < 0.06, "θ {theta}: roundness {roundness}");
        assert!(
            (210..=230).contains(&r.base_circle_points),
            "{}",
            r.base_circle_points
        );
    }
}

#[test]
fn an_error_orthogonal_to_the_datum_stays_whole() {
    // cos(ψ − 180°) is even about the nose at 180° and h' is odd: orthogonal, and its mean
    // over the grid is zero; so the fit leaves it untouched.
    let eps_um = 3.0;
    let avg = measured(|psi| cam(psi).0 + eps_um / 1000.0 * (psi - 180.0).to_radians().cos());
    let r = analyse_lobe(&avg, &cam, &LobeOptions::default()).expect("analysable");
    assert!(r.phase_error_deg.abs() < 1e-9, "{}", r.phase_error_deg);
    assert!(r.base_radius_error_um.abs() < 1e-9);
    let step = 1.0_f64.to_radians();
    for (k, psi) in grid().into_iter().enumerate() {
        let e = eps_um * (psi - 180.0).to_radians().cos();
        assert!(
            (r.profile_error_um[k] - e).abs() < 1e-8,
            "profile at {psi}°"
        );
        // Central difference of A·cos(ψ) over ±Δ, per degree: −A·sin ψ·sin Δ / (1°), which is
        // the exact derivative −A·sin ψ·π/180 times sin(Δ)/Δ (Δ = 1°, relative 5e-5).
        let v = -eps_um * (psi - 180.0).to_radians().sin() * step.sin();
        assert!(
            (r.velocity_error_um_per_deg[k] - v).abs() < 1e-8,
            "velocity at {psi}°"
        );
    }
    assert!((r.profile_error_max_um - 3.0).abs() < 1e-8);
    assert!((r.profile_error_min_um + 3.0).abs() < 1e-8);
    assert!((r.profile_error_peak_to_valley_um - 6.0).abs() < 1e-8);
    assert!((r.profile_error_rms_um - 3.0 / 2.0_f64.sqrt()).abs() < 1e-8);
    assert_eq!(r.harmonics.len(), 50);
    assert!((r.harmonics[0].amplitude_um - 3.0).abs() < 1e-8);
    assert!((r.harmonics[0].phase_deg - 180.0).abs() < 1e-6);
    assert!(r.harmonics[1..].iter().all(|h| h.amplitude_um < 1e-8));
    // Default band ±5 µm: 3 µm passes with 2 µm margin.
    assert!(r.verdict.pass);
    assert!((r.verdict.margin_um - 2.0).abs() < 1e-8);
    assert_eq!(r.verdict.bands, vec![ToleranceBand::everywhere(5.0)]);
}

#[test]
fn tolerance_bands_decide_the_verdict() {
    let eps_um = 3.0;
    let avg = measured(|psi| cam(psi).0 + eps_um / 1000.0 * (psi - 180.0).to_radians().cos());
    // Tight band over the nose (170°–190°), loose elsewhere: the nose reads +3 µm.
    let options = LobeOptions {
        bands: vec![
            ToleranceBand {
                from_deg: 0.0,
                to_deg: 360.0,
                lower_um: -4.0,
                upper_um: 4.0,
            },
            ToleranceBand {
                from_deg: 170.0,
                to_deg: 190.0,
                lower_um: -2.0,
                upper_um: 2.5,
            },
        ],
        ..LobeOptions::default()
    };
    let r = analyse_lobe(&avg, &cam, &options).expect("analysable");
    assert!(!r.verdict.pass);
    let worst = r.verdict.worst_violation.expect("fails");
    assert_eq!(worst.angle_index, 180);
    assert!((worst.value_um - 3.0).abs() < 1e-8);
    assert!((worst.excess_um - 0.5).abs() < 1e-8);
    assert_eq!(worst.band, options.bands[1]);
    assert!((r.verdict.margin_um + 0.5).abs() < 1e-8);

    // A band wrapping through 0° (350° → 10°) around the −3 µm valley at 0°.
    let options = LobeOptions {
        bands: vec![ToleranceBand {
            from_deg: 350.0,
            to_deg: 10.0,
            lower_um: -2.9,
            upper_um: 1.0,
        }],
        ..LobeOptions::default()
    };
    let r = analyse_lobe(&avg, &cam, &options).expect("analysable");
    let worst = r.verdict.worst_violation.expect("fails at 0°");
    assert_eq!(worst.angle_index, 0);
    assert!((worst.excess_um - 0.1).abs() < 1e-8);
    assert_eq!(r.verdict.unchecked_points, 360 - 21);

    // Default band as a parameter.
    let options = LobeOptions {
        default_band_um: 2.0,
        ..LobeOptions::default()
    };
    let r = analyse_lobe(&avg, &cam, &options).expect("analysable");
    assert!(!r.verdict.pass);
    assert!((r.verdict.margin_um + 1.0).abs() < 1e-8);
}

#[test]
fn bad_bands_and_inputs_are_reported() {
    let avg = measured(|psi| cam(psi).0);
    let band = |from_deg, to_deg, lower_um, upper_um| LobeOptions {
        bands: vec![ToleranceBand {
            from_deg,
            to_deg,
            lower_um,
            upper_um,
        }],
        ..LobeOptions::default()
    };
    for (options, reason) in [
        (band(0.0, 360.0, 3.0, -3.0), "lower limit above upper limit"),
        (band(0.0, f64::NAN, -3.0, 3.0), "finite"),
        (band(20.0, 20.0, -3.0, 3.0), "covers no angle"),
        (band(0.0, 400.0, -3.0, 3.0), "longer than one revolution"),
    ] {
        let err = analyse_lobe(&avg, &cam, &options).expect_err(reason);
        assert!(
            matches!(err, AnalysisError::InvalidBand { index: 0, reason: r, .. } if r.contains(reason)),
            "{err:?}"
        );
    }
    // A band between two grid points judges nothing: an error, not a silent pass.
    let err = analyse_lobe(&avg, &cam, &band(10.2, 10.8, -1.0, 1.0)).expect_err("no point");
    assert_eq!(err, AnalysisError::BandsCoverNoPoint { points: 360 });

    let flat = |_: f64| (0.0, 0.0);
    let err = analyse_lobe(&avg, &flat, &LobeOptions::default()).expect_err("round nominal");
    assert!(
        matches!(err, AnalysisError::PhaseUnobservable { .. }),
        "{err:?}"
    );

    let broken = |psi: f64| {
        if psi > 200.0 {
            (f64::NAN, 0.0)
        } else {
            cam(psi)
        }
    };
    let err = analyse_lobe(&avg, &broken, &LobeOptions::default()).expect_err("NaN nominal");
    assert!(matches!(err, AnalysisError::NonFiniteNominal { angle_deg, .. } if angle_deg > 200.0));

    let mut short = avg.clone();
    short.mean_lift_mm.pop();
    let err = analyse_lobe(&short, &cam, &LobeOptions::default()).expect_err("359 values");
    assert!(
        err.to_string()
            .contains("mean_lift_mm has 359 values for 360 points"),
        "{err}"
    );

    let mut nan = avg.clone();
    nan.mean_lift_mm[90] = f64::NAN;
    let err = analyse_lobe(&nan, &cam, &LobeOptions::default()).expect_err("NaN lift");
    assert!(err.to_string().contains("angle index 90 (90°)"), "{err}");

    let tiny = averaged(vec![0.0; 4]);
    let err = analyse_lobe(&tiny, &cam, &LobeOptions::default()).expect_err("4 points");
    assert!(matches!(
        err,
        AnalysisError::TooFewPoints {
            points_per_rev: 4,
            minimum: 8,
            ..
        }
    ));

    let shifted = measured(|psi| cam(psi - 2.0).0 + 0.00123 * (3.0 * psi).to_radians().sin());
    let options = LobeOptions {
        max_fit_iterations: 1,
        ..LobeOptions::default()
    };
    let err = analyse_lobe(&shifted, &cam, &options).expect_err("one iteration is not enough");
    assert!(
        matches!(err, AnalysisError::FitNotConverged { iterations: 1, .. }),
        "{err:?}"
    );
}

#[test]
fn json_field_names_are_the_interface() {
    let avg = measured(|psi| cam(psi - 0.2).0 + 0.001);
    let r = analyse_lobe(&avg, &cam, &LobeOptions::default()).expect("analysable");
    let json = serde_json::to_value(&r).expect("serialisable");
    let keys: Vec<&str> = json
        .as_object()
        .expect("object")
        .keys()
        .map(String::as_str)
        .collect();
    let mut expected = vec![
        "angle_deg",
        "base_circle_points",
        "base_circle_roundness_um",
        "base_radius_error_um",
        "dropped_revolutions",
        "error_um",
        "fit_iterations",
        "harmonics",
        "origin",
        "phase_error_deg",
        "profile_error_max_um",
        "profile_error_min_um",
        "profile_error_peak_to_valley_um",
        "profile_error_rms_um",
        "profile_error_um",
        "repeatability_max_um",
        "repeatability_range_um",
        "repeatability_um",
        "revolutions_used",
        "runout_phase_deg",
        "runout_um",
        "velocity_error_um_per_deg",
        "verdict",
    ];
    expected.sort_unstable();
    let mut keys = keys;
    keys.sort_unstable();
    assert_eq!(keys, expected);
    let h = &json["harmonics"][0];
    assert!(h["order"] == 1 && h["amplitude_um"].is_number() && h["phase_deg"].is_number());
    let d = &json["dropped_revolutions"][0];
    assert_eq!(d["revolution"], 1);
    assert_eq!(d["reason"], "test");
    assert!(d["max_deviation_um"].is_number() && d["at_angle_deg"].is_number());
    assert_eq!(json["verdict"]["pass"], true);
    assert!(json["verdict"]["worst_violation"].is_null());
    assert_eq!(json["revolutions_used"], serde_json::json!([0, 2, 3]));
    assert_eq!(json["repeatability_um"].as_array().map(Vec::len), Some(360));
    assert!((json["repeatability_max_um"].as_f64().expect("number") - 0.559).abs() < 1e-12);
}

#[test]
fn judge_fails_a_non_finite_value_and_counts_unchecked_angles() {
    use camloop::core::analysis::judge;
    let band = ToleranceBand {
        from_deg: 90.0,
        to_deg: 180.0,
        lower_um: -1.0,
        upper_um: 1.0,
    };
    let angles = [0.0, 90.0, 135.0, 180.0, 270.0];
    let verdict = judge(&angles, &[9.0, 0.5, f64::NAN, -0.25, 9.0], &[band]).expect("valid");
    assert!(!verdict.pass);
    let worst = verdict.worst_violation.expect("NaN is outside");
    assert_eq!(worst.angle_index, 2);
    assert_eq!(
        verdict.unchecked_points, 2,
        "0° and 270° lie outside 90°–180°"
    );

    let verdict = judge(&angles, &[9.0, 0.5, 0.0, -0.25, 9.0], &[band]).expect("valid");
    assert!(verdict.pass && verdict.worst_violation.is_none());
    assert!(
        (verdict.margin_um - 0.5).abs() < 1e-12,
        "0.5 µm at 90° is 0.5 from +1"
    );
}

#[test]
fn band_coverage_wraps_and_includes_both_ends() {
    let band = ToleranceBand {
        from_deg: 300.0,
        to_deg: 60.0,
        lower_um: -1.0,
        upper_um: 1.0,
    };
    for angle in [
        300.0,
        0.0,
        60.0,
        -30.0,
        420.0,
        360.0,
        299.999_999_999_9,
        60.000_000_000_1,
    ] {
        assert!(band.contains(angle), "{angle}° lies in 300° → 60°");
    }
    for angle in [299.9, 60.1, 180.0, -61.0] {
        assert!(!band.contains(angle), "{angle}° lies outside 300° → 60°");
    }
    let whole = ToleranceBand::everywhere(5.0);
    assert!(
        [0.0, 359.999, 360.0, -720.0]
            .iter()
            .all(|&a| whole.contains(a))
    );
}
