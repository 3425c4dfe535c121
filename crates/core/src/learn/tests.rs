//! Tests of the learning law against closed forms: convergence, deadbands, limits, drift,
//! dressing, reverting, and the nanometre step.

use super::*;

fn pe<'a>(error_um: &'a [f64], repeatability_um: &'a [f64], revolutions: u32) -> PartError<'a> {
    PartError {
        error_um,
        repeatability_um,
        revolutions,
        timing_error_deg: 0.0,
        timing_sigma_deg: 0.0,
        part_number: None,
        previous: None,
    }
}

fn grid(n: usize, f: impl Fn(f64) -> f64) -> Vec<f64> {
    (0..n)
        .map(|j| f((j as f64 * 360.0 / n as f64).to_radians()))
        .collect()
}

#[test]
fn low_pass_keeps_low_orders_and_removes_high_ones() {
    let low = grid(360, |p| 3.0 + 2.0 * (5.0 * p).cos() + (12.0 * p).sin());
    let high = grid(360, |p| 0.7 * (90.0 * p).cos());
    let mixed: Vec<f64> = low.iter().zip(&high).map(|(a, b)| a + b).collect();
    let out = low_pass(&mixed, 40, 10);
    for (o, l) in out.iter().zip(&low) {
        assert!((o - l).abs() < 1e-9, "{o} vs {l}");
    }
    // In the taper: order 45 is halfway, gain exactly 0.5.
    let mid = grid(360, |p| (45.0 * p).cos());
    let out = low_pass(&mid, 40, 10);
    for (o, m) in out.iter().zip(&mid) {
        assert!((o - 0.5 * m).abs() < 1e-9);
    }
}

/// A repeatable error with no noise: the correction converges geometrically with rate
/// (1 − L) towards −e when the plant adds the correction 1:1. The correction is kept in
/// whole nanometres: each step rounds by at most half of one, and the plant passes an
/// earlier step's rounding on at the rate (1 − L) = 0.2, so the error stays within
/// 0.5 nm / (1 − 0.2) = 0.625 nm of the exact law; one step (1 nm) is the tolerance.
#[test]
fn converges_on_a_one_to_one_plant() {
    let params = LearningParams {
        deadband_sigmas: 0.0,
        wear_gain: 0.0,
        ..LearningParams::default()
    };
    let machine = grid(360, |p| 8.0 * (2.0 * p).cos() + 3.0);
    let mut state = LearningState::new(360);
    let zeros = vec![0.0; 360];
    let mut last = f64::MAX;
    for k in 0..6 {
        let error: Vec<f64> = machine
            .iter()
            .zip(&state.correction_um)
            .map(|(m, u)| m + u)
            .collect();
        let max_error = error.iter().fold(0.0f64, |a, e| a.max(e.abs()));
        let expected = 11.0 * 0.2f64.powi(k);
        assert!(
            (max_error - expected).abs() <= CORRECTION_STEP_UM,
            "part {k}: {max_error} vs {expected}"
        );
        assert!(max_error < last);
        last = max_error;
        step(&mut state, &pe(&error, &zeros, 4), &params).unwrap();
    }
}

#[test]
fn deadband_keeps_noise_level_errors_out() {
    let params = LearningParams {
        wear_gain: 0.0,
        ..LearningParams::default()
    };
    // σ = 1 µm over 4 revolutions: standard error of one angle's mean 0.5 µm; of the mean
    // over 36 angles 0.5/6 µm, so the size deadband is 2·0.5/6 = 1/6 µm.
    let sigma = vec![1.0; 36];
    let mut state = LearningState::new(36);
    step(&mut state, &pe(&vec![0.15; 36], &sigma, 4), &params).unwrap();
    assert!(state.correction_um.iter().all(|u| u.abs() < 1e-12));
    step(&mut state, &pe(&vec![0.5; 36], &sigma, 4), &params).unwrap();
    // Exactly the law but for the rounding to whole nanometres (half a step at most).
    for u in &state.correction_um {
        assert!(
            (u + 0.8 * (0.5 - 1.0 / 6.0)).abs() <= CORRECTION_STEP_UM / 2.0 + 1e-12,
            "{u}"
        );
    }
    // Shape: with 36 points and the cut-off above the Nyquist order, Q passes all 35
    // degrees of freedom beyond the mean: deadband 2·0.5·√(35/36) µm per angle.
    let band = 2.0 * 0.5 * (35.0f64 / 36.0).sqrt();
    let mut state = LearningState::new(36);
    let below = grid(36, |p| 0.95 * band * (3.0 * p).cos());
    step(&mut state, &pe(&below, &sigma, 4), &params).unwrap();
    assert!(state.correction_um.iter().all(|u| u.abs() < 1e-12));
    let above = grid(36, |p| 2.0 * band * (3.0 * p).cos());
    step(&mut state, &pe(&above, &sigma, 4), &params).unwrap();
    // At the crest the soft deadband leaves 2·band − band = band, times the gain (before Q
    // rounds the clipped shape, which changes the crest by less than 20 %).
    let crest = state.correction_um[0];
    assert!((crest + 0.8 * band).abs() < 0.2 * 0.8 * band, "{crest}");
}

/// A part growing by w per part (wheel wear): proportional learning alone lags by w/L;
/// the drift term takes the lag out.
#[test]
fn wear_drift_is_anticipated() {
    let w = 0.15;
    let run = |wear_gain: f64| {
        let params = LearningParams {
            deadband_sigmas: 0.0,
            wear_gain,
            ..LearningParams::default()
        };
        let mut state = LearningState::new(36);
        let zeros = vec![0.0; 36];
        let mut last = 0.0;
        for k in 0..40 {
            let error: Vec<f64> = state
                .correction_um
                .iter()
                .map(|u| 2.0 + w * f64::from(k) + u)
                .collect();
            last = error[0];
            step(&mut state, &pe(&error, &zeros, 4), &params).unwrap();
        }
        last
    };
    let proportional = run(0.0);
    // Within one nanometre step: the correction is kept in whole ones (see
    // converges_on_a_one_to_one_plant for the bound).
    assert!(
        (proportional - w / 0.8).abs() <= CORRECTION_STEP_UM,
        "{proportional}"
    );
    let with_drift = run(0.2);
    assert!(with_drift.abs() < 1e-3, "{with_drift}");
}

/// While the share refuses tables every part is learned from the same state: the size
/// disturbance's change since that state's part is spread over the parts between, not
/// taken as one part's drift (the release-binary probe found a drift of 3.3 µm/part
/// after a 10 s outage before this).
#[test]
fn drift_is_per_part_over_the_parts_since_the_states_own() {
    let params = LearningParams {
        deadband_sigmas: 0.0,
        ..LearningParams::default()
    };
    let mut base = LearningState::new(36);
    base.last_size_disturbance_um = Some(0.0);
    base.last_size_disturbance_part = Some(10);
    base.size_drift_um_per_part = 0.1;
    let zeros = vec![0.0; 36];
    let error = vec![2.0; 36];
    let drift_after = |part_number: Option<u64>| {
        let mut state = base.clone();
        let part = PartError {
            part_number,
            ..pe(&error, &zeros, 4)
        };
        step(&mut state, &part, &params).unwrap();
        state.size_drift_um_per_part
    };
    // 2 µm over the 20 parts from part 10 to part 30: 0.1 µm a part, as estimated.
    assert!((drift_after(Some(30)) - 0.1).abs() < 1e-12);
    // Without part numbers the gap is one part, and the estimate moves toward 2 µm.
    assert!((drift_after(None) - (0.1 + 0.3 * (2.0 - 0.1))).abs() < 1e-12);
}

/// A repeatable error larger than the limit is learned up to the limit, never beyond;
/// once there, the step is refused as "at the limit".
#[test]
fn a_repeatable_error_beyond_the_limit_is_learned_up_to_it() {
    let params = LearningParams {
        deadband_sigmas: 0.0,
        wear_gain: 0.0,
        max_correction_um: 20.0,
        ..LearningParams::default()
    };
    let machine = grid(360, |p| 30.0 * (2.0 * p).cos());
    let zeros = vec![0.0; 360];
    let mut state = LearningState::new(360);
    let mut errors: Vec<f64> = Vec::new();
    let mut at_limit = None;
    for k in 0..9 {
        let error: Vec<f64> = machine
            .iter()
            .zip(&state.correction_um)
            .map(|(m, u)| m + u)
            .collect();
        let part = PartError {
            previous: errors.last().map(|&max_error_um| PreviousPart {
                max_error_um,
                timing_error_deg: 0.0,
                part_number: None,
            }),
            ..pe(&error, &zeros, 4)
        };
        errors.push(error.iter().fold(0.0f64, |a, e| a.max(e.abs())));
        match step(&mut state, &part, &params) {
            // Nothing confirms the first part's error yet: refused, as a jump would be.
            Err(LearnError::CorrectionTooLarge { .. }) => assert_eq!(k, 0),
            Ok(StepOutcome::Limited { bound, .. }) => {
                assert_eq!(bound.quantity, BoundedQuantity::Correction);
                assert!(bound.wanted > 20.0);
            }
            Err(LearnError::AtLimit { .. }) => {
                at_limit.get_or_insert(k);
            }
            other => panic!("part {k}: {other:?}"),
        }
        let max_u = state
            .correction_um
            .iter()
            .fold(0.0f64, |a, u| a.max(u.abs()));
        assert!(max_u <= 20.0 + 1e-9, "part {k}: correction {max_u}");
    }
    // 30, 30 (refused), then held to 20 µm of correction: 30 − 20 = 10 µm remain.
    assert!(errors[2] < errors[1]);
    // Q rounds the clipped crest: the last 1 % of the limit is not reached there.
    assert!((10.0 - 1e-9..10.2).contains(&errors[8]), "{errors:?}");
    assert!(
        at_limit.is_some(),
        "the limit must end the learning: {errors:?}"
    );
}

#[test]
fn timing_is_learned_into_the_c_offset_within_its_limit() {
    let params = LearningParams {
        deadband_sigmas: 0.0,
        ..LearningParams::default()
    };
    let zeros = vec![0.0; 36];
    let mut state = LearningState::new(36);
    let lag_deg = 0.081;
    for _ in 0..12 {
        let part = PartError {
            timing_error_deg: lag_deg + state.timing_correction_deg,
            ..pe(&zeros, &zeros, 4)
        };
        step(&mut state, &part, &params).unwrap();
    }
    // The residual timing error ends within the deadband.
    let residual = lag_deg + state.timing_correction_deg;
    assert!(
        residual.abs() <= params.timing_deadband_deg + 1e-9,
        "{residual}"
    );
    // A jump of 2° on a first part is refused, never clamped.
    let mut fresh = LearningState::new(36);
    let jump = PartError {
        timing_error_deg: 2.0,
        ..pe(&zeros, &zeros, 4)
    };
    let e = step(&mut fresh, &jump, &params).unwrap_err();
    assert!(matches!(e, LearnError::TimingTooLarge { .. }), "{e}");
}

#[test]
fn growing_error_twice_reverts_to_the_best_and_freezes() {
    let params = LearningParams {
        deadband_sigmas: 0.0,
        wear_gain: 0.0,
        ..LearningParams::default()
    };
    let mut state = LearningState::new(36);
    let zeros = vec![0.0; 36];
    // The nominal table (iteration 0) gives 2 µm; its successors give 3 and then 4 µm:
    // the best correction is the one the 2 µm part was ground with, i.e. none.
    step(&mut state, &pe(&vec![2.0; 36], &zeros, 4), &params).unwrap();
    assert!(state.correction_um.iter().all(|u| (u + 1.6).abs() < 1e-9));
    step(&mut state, &pe(&vec![3.0; 36], &zeros, 4), &params).unwrap();
    let outcome = step(&mut state, &pe(&vec![4.0; 36], &zeros, 4), &params).unwrap();
    match outcome {
        StepOutcome::Reverted { to_iteration, .. } => assert_eq!(to_iteration, 0),
        other => panic!("expected a revert, got {other:?}"),
    }
    assert_eq!(state.correction_um, zeros);
    assert!(state.frozen.is_some());
    let outcome = step(&mut state, &pe(&vec![1.0; 36], &zeros, 4), &params).unwrap();
    assert!(matches!(outcome, StepOutcome::Frozen { .. }));
    assert_eq!(state.correction_um, zeros);
}

#[test]
fn too_large_a_correction_is_refused_and_the_state_kept() {
    let params = LearningParams {
        deadband_sigmas: 0.0,
        max_correction_um: 5.0,
        ..LearningParams::default()
    };
    let mut state = LearningState::new(36);
    let before = state.clone();
    let e = step(&mut state, &pe(&vec![10.0; 36], &vec![0.0; 36], 4), &params).unwrap_err();
    assert!(matches!(e, LearnError::CorrectionTooLarge { .. }), "{e}");
    assert_eq!(state, before);
}

/// A learned correction is in whole nanometres (its JSON has at most three decimals, the
/// point of keeping it so), within half a step of the exact value, and never beyond the
/// limit even where rounding to nearest would cross it.
#[test]
fn corrections_are_kept_in_whole_nanometres_within_the_limit() {
    let exact = vec![1.23449, -1.23451, 4.99979, -4.9999999, 0.0, 1e-4];
    let mut u = exact.clone();
    quantise_correction(&mut u, 4.9999);
    assert_eq!(u, vec![1.234, -1.235, 4.999, -4.999, 0.0, 0.0]);
    let params = LearningParams {
        deadband_sigmas: 0.0,
        ..LearningParams::default()
    };
    let mut state = LearningState::new(360);
    let error = grid(360, |p| {
        3.1 * (2.0 * p).cos() + 0.77 * (5.0 * p).sin() + 0.3
    });
    step(&mut state, &pe(&error, &vec![0.0; 360], 4), &params).unwrap();
    for u in &state.correction_um {
        assert!((u * 1000.0 - (u * 1000.0).round()).abs() < 1e-6, "{u}");
        let text = serde_json::to_string(u).unwrap();
        let decimals = text.split('.').nth(1).map_or(0, str::len);
        assert!(decimals <= 3, "{text}");
    }
}

#[test]
fn dressing_drops_the_learned_size_and_keeps_the_shape() {
    let mut state = LearningState::new(360);
    state.correction_um = grid(360, |p| -4.0 + 2.0 * (3.0 * p).cos());
    state.recent_max_error_um = vec![1.0, 2.0];
    let own = size_correction_um(&state);
    after_dressing(&mut state, own);
    let shape = grid(360, |p| 2.0 * (3.0 * p).cos());
    // The shape to within the rounding to whole nanometres.
    for (u, s) in state.correction_um.iter().zip(&shape) {
        assert!(
            (u - s).abs() <= CORRECTION_STEP_UM / 2.0 + 1e-12,
            "{u} vs {s}"
        );
    }
    assert!(state.recent_max_error_um.is_empty());
}

#[test]
fn stop_in_tolerance_keeps_the_correction() {
    let params = LearningParams {
        stop_in_tolerance_um: Some(1.0),
        ..LearningParams::default()
    };
    let mut state = LearningState::new(36);
    let outcome = step(&mut state, &pe(&vec![0.5; 36], &vec![0.0; 36], 4), &params).unwrap();
    assert!(matches!(outcome, StepOutcome::InTolerance { .. }));
    assert!(state.correction_um.iter().all(|u| *u == 0.0));
}

/// A one-feature size plant in closed form: the part's size error is the size correction
/// plus the station's own oversize plus (told − true) wheel radius; the wheel wears 0.1 µm
/// per part. A 20 µm dressing tells the control the new radius 2.3 µm off while the dresser
/// reads its infeed 0.1 µm long. With the infeed the first part after the dressing is off by
/// the reading's error (−0.1 µm) plus what the wear anticipation missed; with the radius
/// alone it is off by the station's share and the dresser's error (1.5 + 2.3 µm).
#[test]
fn a_measured_dressing_moves_the_correction_by_the_size_step() {
    const N: usize = 36;
    const STATION_UM: f64 = 1.5;
    const WEAR_MM: f64 = 0.1e-3;
    let params = LearningParams::default();
    let (mut told_mm, mut wheel_mm) = (250.0, 250.003);
    let size_error = |s: &LearningState, told: f64, wheel: f64| {
        size_correction_um(s) + STATION_UM + (told - wheel) * 1000.0
    };
    let mut state = LearningState::new(N as u32);
    let mut before_um = 0.0;
    for _ in 0..30 {
        before_um = size_error(&state, told_mm, wheel_mm);
        step(&mut state, &pe(&[before_um; N], &[0.0; N], 4), &params).unwrap();
        wheel_mm -= WEAR_MM;
    }
    // Converged, wear rate learned: the loop anticipates the next part's wear.
    assert!(before_um.abs() < 0.01, "{before_um}");
    assert!(
        (state.size_drift_um_per_part - 0.1).abs() < 0.01,
        "{state:?}"
    );
    let shape_before = state.correction_um.clone();

    wheel_mm -= 0.020;
    let told_after_mm = wheel_mm + 2.3e-3;
    let step_um = dressing_size_step_um(told_mm, told_after_mm, 20.1);
    let mut radius_only = state.clone();
    let wheel_share_um = size_correction_um(&radius_only);
    after_dressing(&mut radius_only, wheel_share_um);
    after_measured_dressing(&mut state, step_um);
    told_mm = told_after_mm;
    // The whole correction moved by the step (to the nanometre rounding), shape kept.
    for (a, b) in state.correction_um.iter().zip(&shape_before) {
        assert!(
            (a - b + step_um).abs() <= CORRECTION_STEP_UM,
            "{a} {b} {step_um}"
        );
    }
    let first_um = size_error(&state, told_mm, wheel_mm);
    let without_um = size_error(&radius_only, told_mm, wheel_mm);
    // The reading 0.1 µm long moved the correction 0.1 µm too far: the part is 0.1 µm
    // small, ±0.01 µm of the wear anticipation.
    assert!((first_um + 0.1).abs() < 0.02, "{first_um}");
    assert!(
        (without_um - (STATION_UM + 2.3)).abs() < 0.2,
        "{without_um}"
    );
    // The residual is learned whole and not taken for wear; the loop goes on as before.
    step(&mut state, &pe(&[first_um; N], &[0.0; N], 4), &params).unwrap();
    wheel_mm -= WEAR_MM;
    assert!(
        (state.size_drift_um_per_part - 0.1).abs() < 0.01,
        "{state:?}"
    );
    let second_um = size_error(&state, told_mm, wheel_mm);
    assert!(second_um.abs() < 0.02, "{second_um}");
    assert!(!state.dressing_measured && state.dressing_offset_um == 0.0);
}

#[test]
fn the_dresser_infeed_is_checked() {
    assert_eq!(check_dresser_infeed(20.0), Ok(20.0));
    assert_eq!(check_dresser_infeed(0.0), Ok(0.0));
    for bad in [-0.1, 1000.5, f64::NAN, f64::INFINITY] {
        let e = check_dresser_infeed(bad).unwrap_err();
        assert!(e.to_string().contains("dresser infeed"), "{e}");
    }
    // Told 17.7 µm smaller, 20 µm removed: the part grows by 2.3 µm.
    assert!((dressing_size_step_um(250.0, 249.9823, 20.0) - 2.3).abs() < 1e-9);
}
