//! Run-to-run iterative learning control in the lift (follower) domain, with the guards
//! that keep a bad measurement or a diverging loop away from the control.
//!
//! The correction u (µm, one value per gauge angle) is added to the nominal lift; the next
//! X(C) table is regenerated from the corrected lift through the exact geometry. After part
//! k with error e_k (measured − nominal, µm):
//!
//! `u_{k+1} = Q(u_k − L·D(e_k))`
//!
//! - L: learning gain in (0, 1); below 1 so a model mismatch cannot make the loop ring.
//! - D: a soft deadband per angle of `deadband_sigmas · σ(ψ) / √revolutions`, σ the per-angle
//!   repeatability: what the gauge cannot tell from noise is not learned.
//! - Q: a zero-phase low-pass on harmonic orders (full up to `cutoff_order`, a cosine taper
//!   over `rolloff_orders` beyond it): high orders are noise and chatter, not machine.
//! - Order 0 (size) is learned like any other: a base circle ground oversize is corrected.
//!
//! Because the correction lives in the lift domain it is independent of the wheel: after a
//! dressing the same correction regenerates the table for the new wheel radius.

use super::harmonics::DftTable;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Learning parameters (part recipe `[learning]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LearningParams {
    /// Learning gain L, 0 < L < 1.
    pub gain: f64,
    /// Highest harmonic order learned in full.
    pub cutoff_order: u32,
    /// Orders over which Q tapers from 1 to 0 above the cut-off.
    pub rolloff_orders: u32,
    /// Deadband in units of the standard error σ/√revolutions of the per-angle mean.
    pub deadband_sigmas: f64,
    /// Stop learning while the part's max |error| is within this (µm); `None`: always learn.
    pub stop_in_tolerance_um: Option<f64>,
    /// Largest |correction| allowed anywhere (µm): a larger one is refused, never pushed.
    pub max_correction_um: f64,
    /// The max error must grow by more than this on each of two parts in a row to count as
    /// divergence (µm): slow drift such as wheel wear and gauge noise must not raise it.
    pub divergence_margin_um: f64,
}

impl Default for LearningParams {
    fn default() -> Self {
        Self {
            gain: 0.8,
            cutoff_order: 40,
            rolloff_orders: 10,
            deadband_sigmas: 2.0,
            stop_in_tolerance_um: None,
            max_correction_um: 50.0,
            divergence_margin_um: 0.5,
        }
    }
}

impl LearningParams {
    /// Every problem at once, as `field: reason` lines.
    pub fn validate(&self) -> Result<(), Vec<String>> {
        let mut problems = Vec::new();
        if !(self.gain > 0.0 && self.gain < 1.0) {
            problems.push(format!("learning.gain = {}: must be in (0, 1)", self.gain));
        }
        if self.cutoff_order == 0 {
            problems.push("learning.cutoff_order = 0: must be at least 1".to_string());
        }
        if !(self.deadband_sigmas.is_finite() && self.deadband_sigmas >= 0.0) {
            problems.push(format!(
                "learning.deadband_sigmas = {}: must be ≥ 0",
                self.deadband_sigmas
            ));
        }
        if !(self.max_correction_um.is_finite() && self.max_correction_um > 0.0) {
            problems.push(format!(
                "learning.max_correction_um = {}: must be > 0",
                self.max_correction_um
            ));
        }
        if !(self.divergence_margin_um.is_finite() && self.divergence_margin_um >= 0.0) {
            problems.push(format!(
                "learning.divergence_margin_um = {}: must be ≥ 0",
                self.divergence_margin_um
            ));
        }
        if let Some(t) = self.stop_in_tolerance_um
            && !(t.is_finite() && t > 0.0)
        {
            problems.push(format!("learning.stop_in_tolerance_um = {t}: must be > 0"));
        }
        if problems.is_empty() {
            Ok(())
        } else {
            Err(problems)
        }
    }
}

/// The best correction seen so far, by the max |error| of the part it produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BestCorrection {
    pub iteration: u32,
    pub max_error_um: f64,
    pub correction_um: Vec<f64>,
}

/// Everything the loop must remember between parts (persisted by the caller).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LearningState {
    /// The gauge grid the correction lives on: index j at j·360/N degrees.
    pub points_per_rev: u32,
    /// The correction in use (the table currently on the machine was made with it), µm.
    pub correction_um: Vec<f64>,
    /// Parts learned from so far.
    pub iteration: u32,
    /// Max |error| of the parts measured with each recent correction, oldest first (≤ 3).
    pub recent_max_error_um: Vec<f64>,
    pub best: Option<BestCorrection>,
    /// Why learning is frozen (after a revert), if it is.
    pub frozen: Option<String>,
}

impl LearningState {
    /// No correction yet: the nominal table.
    pub fn new(points_per_rev: u32) -> Self {
        Self {
            points_per_rev,
            correction_um: vec![0.0; points_per_rev as usize],
            iteration: 0,
            recent_max_error_um: Vec::new(),
            best: None,
            frozen: None,
        }
    }
}

/// What one learning step decided.
#[derive(Debug, Clone, PartialEq)]
pub enum StepOutcome {
    /// A new correction; the next table must be made from it.
    Updated {
        max_error_um: f64,
        max_correction_um: f64,
    },
    /// The part is within `stop_in_tolerance_um`: the correction is kept as it is.
    InTolerance { max_error_um: f64 },
    /// Learning is frozen; the correction is kept as it is.
    Frozen { max_error_um: f64, reason: String },
    /// The error grew (by more than the divergence margin) on two parts in a row: back to the
    /// best correction, learning frozen.
    /// An operator must look at the machine (alarm).
    Reverted {
        max_error_um: f64,
        to_iteration: u32,
        reason: String,
    },
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LearnError {
    #[error("measurement has {got} points per revolution, the learning state {expected}")]
    GridMismatch { expected: u32, got: usize },
    #[error("error at {angle_deg}° is not a finite number")]
    NonFinite { angle_deg: f64 },
    #[error(
        "correction would reach {max_um:.2} µm at {angle_deg:.1}°, above the limit of {limit_um} µm"
    )]
    CorrectionTooLarge {
        max_um: f64,
        angle_deg: f64,
        limit_um: f64,
    },
}

/// One learning step from the error of the part just measured (µm per gauge angle, no fit
/// removed) and its per-angle repeatability (standard deviation over `revolutions`, µm).
/// On error the state is left exactly as it was.
pub fn step(
    state: &mut LearningState,
    error_um: &[f64],
    repeatability_um: &[f64],
    revolutions: u32,
    params: &LearningParams,
) -> Result<StepOutcome, LearnError> {
    let n = state.points_per_rev as usize;
    for len in [
        error_um.len(),
        repeatability_um.len(),
        state.correction_um.len(),
    ] {
        if len != n {
            return Err(LearnError::GridMismatch {
                expected: state.points_per_rev,
                got: len,
            });
        }
    }
    if let Some(j) = error_um
        .iter()
        .chain(repeatability_um)
        .position(|v| !v.is_finite())
    {
        return Err(LearnError::NonFinite {
            angle_deg: (j % n) as f64 * 360.0 / n as f64,
        });
    }
    let max_error_um = error_um.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    let mut next = state.clone();
    next.iteration += 1;
    if next
        .best
        .as_ref()
        .is_none_or(|b| max_error_um < b.max_error_um)
    {
        next.best = Some(BestCorrection {
            iteration: state.iteration,
            max_error_um,
            correction_um: state.correction_um.clone(),
        });
    }
    next.recent_max_error_um.push(max_error_um);
    if next.recent_max_error_um.len() > 3 {
        next.recent_max_error_um.remove(0);
    }
    let outcome = if let Some(reason) = &state.frozen {
        StepOutcome::Frozen {
            max_error_um,
            reason: reason.clone(),
        }
    } else if let [a, b, c] = next.recent_max_error_um[..]
        && c > b + params.divergence_margin_um
        && b > a + params.divergence_margin_um
    {
        let best = next.best.clone().expect("set above on the first part");
        let reason = format!(
            "max error grew on two parts in a row ({a:.2} → {b:.2} → {c:.2} µm): reverted to the correction of iteration {}, learning frozen",
            best.iteration
        );
        next.correction_um = best.correction_um;
        next.frozen = Some(reason.clone());
        StepOutcome::Reverted {
            max_error_um,
            to_iteration: best.iteration,
            reason,
        }
    } else if params
        .stop_in_tolerance_um
        .is_some_and(|t| max_error_um <= t)
    {
        StepOutcome::InTolerance { max_error_um }
    } else {
        let learned: Vec<f64> = (0..n)
            .map(|j| {
                let band = params.deadband_sigmas * repeatability_um[j]
                    / f64::from(revolutions.max(1)).sqrt();
                let e = error_um[j];
                let e_dead = e.signum() * (e.abs() - band).max(0.0);
                state.correction_um[j] - params.gain * e_dead
            })
            .collect();
        next.correction_um = low_pass(&learned, params.cutoff_order, params.rolloff_orders);
        let (max_um, j) =
            next.correction_um
                .iter()
                .enumerate()
                .fold((0.0f64, 0), |(m, jm), (j, u)| {
                    if u.abs() > m { (u.abs(), j) } else { (m, jm) }
                });
        if max_um > params.max_correction_um {
            return Err(LearnError::CorrectionTooLarge {
                max_um,
                angle_deg: j as f64 * 360.0 / n as f64,
                limit_um: params.max_correction_um,
            });
        }
        StepOutcome::Updated {
            max_error_um,
            max_correction_um: max_um,
        }
    };
    *state = next;
    Ok(outcome)
}

/// After a wheel dressing the control gets a new wheel radius, which replaces everything the
/// loop learned about the wheel's size (the initial radius error and the wear since). So the
/// size part (order 0, the mean) of the correction is dropped and the shape is kept; the error
/// history restarts so the size step after dressing is not taken for divergence.
pub fn after_dressing(state: &mut LearningState) {
    remove_mean(&mut state.correction_um);
    if let Some(best) = state.best.as_mut() {
        remove_mean(&mut best.correction_um);
    }
    state.recent_max_error_um.clear();
}

fn remove_mean(values: &mut [f64]) {
    let mean = values.iter().sum::<f64>() / values.len().max(1) as f64;
    values.iter_mut().for_each(|v| *v -= mean);
}

/// Zero-phase low-pass Q: keeps orders ≤ `cutoff`, tapers with a half cosine over the next
/// `rolloff` orders, drops the rest. Gains are real and non-negative, so no phase shift.
pub fn low_pass(values: &[f64], cutoff: u32, rolloff: u32) -> Vec<f64> {
    let n = values.len();
    let table = DftTable::new(n);
    let top = ((cutoff + rolloff) as usize).min(n / 2);
    let mut out = vec![0.0; n];
    for order in 0..=top {
        let gain = q_gain(order as u32, cutoff, rolloff);
        if gain == 0.0 {
            continue;
        }
        let Some((a, b)) = table.coefficients(values, order) else {
            continue;
        };
        for (k, o) in out.iter_mut().enumerate() {
            let Some((c, s)) = table.cos_sin((k * order) % n) else {
                continue;
            };
            *o += gain * (a * c + b * s);
        }
    }
    out
}

fn q_gain(order: u32, cutoff: u32, rolloff: u32) -> f64 {
    if order <= cutoff {
        1.0
    } else if order < cutoff + rolloff {
        0.5 * (1.0 + (PI * f64::from(order - cutoff) / f64::from(rolloff)).cos())
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    /// (1 − L) towards −e when the plant adds the correction 1:1.
    #[test]
    fn converges_on_a_one_to_one_plant() {
        let params = LearningParams {
            deadband_sigmas: 0.0,
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
                (max_error - expected).abs() < 1e-9 * expected.max(1.0),
                "part {k}: {max_error} vs {expected}"
            );
            assert!(max_error < last);
            last = max_error;
            step(&mut state, &error, &zeros, 4, &params).unwrap();
        }
    }

    #[test]
    fn deadband_keeps_noise_level_errors_out() {
        let params = LearningParams::default();
        let mut state = LearningState::new(36);
        // σ = 1 µm over 4 revolutions: standard error 0.5 µm, deadband 1 µm.
        let error = vec![0.9; 36];
        let sigma = vec![1.0; 36];
        step(&mut state, &error, &sigma, 4, &params).unwrap();
        assert!(state.correction_um.iter().all(|u| u.abs() < 1e-12));
        let error = vec![1.5; 36];
        step(&mut state, &error, &sigma, 4, &params).unwrap();
        for u in &state.correction_um {
            assert!((u + 0.8 * 0.5).abs() < 1e-9, "{u}");
        }
    }

    #[test]
    fn growing_error_twice_reverts_to_the_best_and_freezes() {
        let params = LearningParams {
            deadband_sigmas: 0.0,
            ..LearningParams::default()
        };
        let mut state = LearningState::new(36);
        let zeros = vec![0.0; 36];
        // The nominal table (iteration 0) gives 2 µm; its successors give 3 and then 4 µm:
        // the best correction is the one the 2 µm part was ground with, i.e. none.
        step(&mut state, &vec![2.0; 36], &zeros, 4, &params).unwrap();
        assert!(state.correction_um.iter().all(|u| (u + 1.6).abs() < 1e-9));
        step(&mut state, &vec![3.0; 36], &zeros, 4, &params).unwrap();
        let outcome = step(&mut state, &vec![4.0; 36], &zeros, 4, &params).unwrap();
        match outcome {
            StepOutcome::Reverted { to_iteration, .. } => assert_eq!(to_iteration, 0),
            other => panic!("expected a revert, got {other:?}"),
        }
        assert_eq!(state.correction_um, zeros);
        assert!(state.frozen.is_some());
        let outcome = step(&mut state, &vec![1.0; 36], &zeros, 4, &params).unwrap();
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
        let e = step(&mut state, &vec![10.0; 36], &vec![0.0; 36], 4, &params).unwrap_err();
        assert!(matches!(e, LearnError::CorrectionTooLarge { .. }), "{e}");
        assert_eq!(state, before);
    }

    #[test]
    fn dressing_drops_the_learned_size_and_keeps_the_shape() {
        let mut state = LearningState::new(360);
        state.correction_um = grid(360, |p| -4.0 + 2.0 * (3.0 * p).cos());
        state.recent_max_error_um = vec![1.0, 2.0];
        after_dressing(&mut state);
        let shape = grid(360, |p| 2.0 * (3.0 * p).cos());
        for (u, s) in state.correction_um.iter().zip(&shape) {
            assert!((u - s).abs() < 1e-12);
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
        let outcome = step(&mut state, &vec![0.5; 36], &vec![0.0; 36], 4, &params).unwrap();
        assert!(matches!(outcome, StepOutcome::InTolerance { .. }));
        assert!(state.correction_um.iter().all(|u| *u == 0.0));
    }
}
