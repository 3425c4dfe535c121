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

mod dressing;
mod grid;
mod outcome;
mod params;

pub use dressing::{
    DresserInfeedError, after_dressing, after_measured_dressing, check_dresser_infeed,
    dressing_size_step_um, size_correction_um,
};
#[cfg(test)]
use grid::CORRECTION_STEP_UM;
use grid::low_pass;
use grid::q_gain;
pub use grid::quantise_correction;
pub use outcome::{Bounded, BoundedQuantity, LearnError, StepOutcome};
pub use params::LearningParams;
use serde::{Deserialize, Serialize};

/// The best correction seen so far, by the max |error| of the part it produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BestCorrection {
    pub iteration: u32,
    pub max_error_um: f64,
    pub correction_um: Vec<f64>,
    #[serde(default)]
    pub timing_correction_deg: f64,
}

/// Everything the loop must remember between parts (persisted by the caller).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LearningState {
    /// The gauge grid the correction lives on: index j at j·360/N degrees of the feature's
    /// own frame.
    pub points_per_rev: u32,
    /// The correction in use (the table currently on the machine was made with it), µm.
    pub correction_um: Vec<f64>,
    /// The timing correction in use: added to the feature's C offset, degrees.
    #[serde(default)]
    pub timing_correction_deg: f64,
    /// Size drift per part (wheel wear: the part grows oversize by this much per part), µm;
    /// the next table anticipates one part of it.
    #[serde(default)]
    pub size_drift_um_per_part: f64,
    /// The size disturbance of the newest part: its size error less the size correction it
    /// was ground with, µm.
    #[serde(default)]
    pub last_size_disturbance_um: Option<f64>,
    /// That part's number, when the gauge gave a number.
    #[serde(default)]
    pub last_size_disturbance_part: Option<u64>,
    /// The size correction a dressing starts from, µm: learned from the first part after
    /// each dressing, so a dresser's systematic error is corrected before it is ground.
    #[serde(default)]
    pub dressing_offset_um: f64,
    /// The wheel was dressed since the last step: the next part's size error is the
    /// dresser's, not drift.
    #[serde(default)]
    pub dressed: bool,
    /// The wheel was dressed since the last step and the dresser measured the radius it
    /// removed, so the correction was moved by the size step already: the next part's size
    /// error is what the infeed reading missed, learned whole, not into the dressing offset
    /// and not as drift.
    #[serde(default)]
    pub dressing_measured: bool,
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
            timing_correction_deg: 0.0,
            size_drift_um_per_part: 0.0,
            last_size_disturbance_um: None,
            last_size_disturbance_part: None,
            dressing_offset_um: 0.0,
            dressed: false,
            dressing_measured: false,
            iteration: 0,
            recent_max_error_um: Vec::new(),
            best: None,
            frozen: None,
        }
    }
}

/// What one measured part tells the learning step.
#[derive(Debug, Clone, Copy)]
pub struct PartError<'a> {
    /// Lift error per gauge angle in the feature's own frame with its timing error taken
    /// out (profile error plus size), µm.
    pub error_um: &'a [f64],
    /// Per-angle standard deviation over the revolutions, µm.
    pub repeatability_um: &'a [f64],
    pub revolutions: u32,
    /// The feature's timing error, degrees, positive when it lags its nominal position.
    pub timing_error_deg: f64,
    /// Standard error of the timing estimate, degrees: the per-angle standard error of the
    /// mean over the root of Σ h′(ψ)² (h′ in mm/°); the timing deadband is
    /// `deadband_sigmas` of it, and never less than `timing_deadband_deg`.
    pub timing_sigma_deg: f64,
    /// The part's number, when the gauge gave a number: the drift is the change of the size
    /// disturbance over the parts since the one the learning state last saw (more than one
    /// after a part not measured, or while the share refused tables and every part was
    /// learned from the same state).
    pub part_number: Option<u64>,
    /// The previous part of this feature, learned from or not: a limit bounds a step only
    /// when this part confirms that part's error (see [`step`]).
    pub previous: Option<PreviousPart>,
}

/// What the previous part of a feature measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PreviousPart {
    pub max_error_um: f64,
    pub timing_error_deg: f64,
    /// Its part number, when the gauge gave a number.
    #[serde(default)]
    pub part_number: Option<u64>,
}

impl PreviousPart {
    /// This part's error confirms the previous one's: not a jump (no growth beyond the
    /// divergence margin or 25 %).
    fn confirms_lift(&self, max_error_um: f64, params: &LearningParams) -> bool {
        max_error_um
            <= self.max_error_um + params.divergence_margin_um.max(0.25 * self.max_error_um)
    }

    /// The same for timing: within 25 % or five deadbands of the previous timing error.
    fn confirms_timing(&self, timing_error_deg: f64, params: &LearningParams) -> bool {
        let slack = (0.25 * self.timing_error_deg.abs()).max(5.0 * params.timing_deadband_deg);
        (timing_error_deg - self.timing_error_deg).abs() <= slack
    }
}

/// Corrections closer than this everywhere are the same table, µm (and degrees / 1000).
const SAME_CORRECTION_UM: f64 = 0.01;

/// One learning step from the part just measured. On error the state is left exactly as it
/// was.
///
/// - **Size** (order 0, the mean error e₀) has a deadband of `deadband_sigmas` standard
///   errors of a mean over all N angles, and a drift term (wear): the disturbance
///   `d = e₀ − ū` (ū the size correction the part was ground with) changes by the drift each
///   part, so `r ← r + κ·((d − d_prev)/gap − r)` and `u₀ ← u₀ − L·e₀ − r`. An offset (the
///   first part, a dressing) is never taken for drift.
/// - **Shape** (orders ≥ 1) is low-passed by Q first, then a deadband of `deadband_sigmas`
///   standard errors *of the low-passed error* is applied per angle: noise above the
///   cut-off is not what the deadband has to absorb.
/// - **Timing** moves the C offset: `τ ← τ − L·dead(φ)`.
/// - A repeatable error (not a jump: the max error did not grow by more than
///   `divergence_margin_um` or 25 %) that needs more than a limit is learned up to it.
pub fn step(
    state: &mut LearningState,
    part: &PartError<'_>,
    params: &LearningParams,
) -> Result<StepOutcome, LearnError> {
    check_inputs(state, part)?;
    let error_um = part.error_um;
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
            timing_correction_deg: state.timing_correction_deg,
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
        next.timing_correction_deg = best.timing_correction_deg;
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
        learn_correction(state, &mut next, part, params, max_error_um)?
    };
    *state = next;
    Ok(outcome)
}

fn check_inputs(state: &LearningState, part: &PartError<'_>) -> Result<(), LearnError> {
    let n = state.points_per_rev as usize;
    for len in [
        part.error_um.len(),
        part.repeatability_um.len(),
        state.correction_um.len(),
    ] {
        if len != n {
            return Err(LearnError::GridMismatch {
                expected: state.points_per_rev,
                got: len,
            });
        }
    }
    if let Some(j) = part
        .error_um
        .iter()
        .chain(part.repeatability_um)
        .position(|v| !v.is_finite())
    {
        return Err(LearnError::NonFinite {
            angle_deg: (j % n) as f64 * 360.0 / n as f64,
        });
    }
    if !part.timing_error_deg.is_finite() {
        return Err(LearnError::NonFinite { angle_deg: 0.0 });
    }
    Ok(())
}

/// The learning law proper (see [`step`]), with the limits; writes `next`.
fn learn_correction(
    state: &LearningState,
    next: &mut LearningState,
    part: &PartError<'_>,
    params: &LearningParams,
    max_error_um: f64,
) -> Result<StepOutcome, LearnError> {
    let n = state.points_per_rev as usize;
    let repeatable = part
        .previous
        .is_some_and(|p| p.confirms_lift(max_error_um, params));
    let (size_band, shape_band) = deadbands(part, params);
    let mean = part.error_um.iter().sum::<f64>() / n as f64;
    let shape: Vec<f64> = part.error_um.iter().map(|e| e - mean).collect();
    let shape = low_pass(&shape, params.cutoff_order, params.rolloff_orders);
    let size = soft_dead(mean, size_band);
    learn_size_drift(state, next, part, params, mean, size);
    // Right after a dressing the size step is the dresser's offset (or what its infeed
    // reading missed), measured to a few nm over every angle: taken whole, not by the gain
    // (which guards the shape against model mismatch).
    let size_gain = if state.dressed || state.dressing_measured {
        1.0
    } else {
        params.gain
    };
    let learned: Vec<f64> = (0..n)
        .map(|j| {
            state.correction_um[j]
                - size_gain * size
                - params.gain * soft_dead(shape[j], shape_band)
                - next.size_drift_um_per_part
        })
        .collect();
    let wanted = low_pass(&learned, params.cutoff_order, params.rolloff_orders);
    let (correction_um, bound) = held_to_limit(wanted, repeatable, params)?;
    next.correction_um = correction_um;
    quantise_correction(&mut next.correction_um, params.max_correction_um);
    let timing = learn_timing(state, part, params)?;
    next.timing_correction_deg = timing.0;
    let bound = bound.or(timing.1);
    let unchanged = next
        .correction_um
        .iter()
        .zip(&state.correction_um)
        .all(|(a, b)| (a - b).abs() < SAME_CORRECTION_UM)
        && (next.timing_correction_deg - state.timing_correction_deg).abs()
            < SAME_CORRECTION_UM * 1e-3;
    let max_correction_um = max_abs_at(&next.correction_um).0;
    step_outcome(bound, unchanged, part, max_error_um, max_correction_um)
}

/// Records the size disturbance this part saw and, when neither a dressing nor a measured
/// dressing explains its change, learns the size drift per part from it.
fn learn_size_drift(
    state: &LearningState,
    next: &mut LearningState,
    part: &PartError<'_>,
    params: &LearningParams,
    mean_error_um: f64,
    size_um: f64,
) {
    let n = state.points_per_rev as usize;
    // The size disturbance the part saw: its size error less the size correction it was
    // ground with (the plant is 1:1 in size). Its change from part to part is the drift.
    let in_force_size = state.correction_um.iter().sum::<f64>() / n as f64;
    let disturbance = mean_error_um - in_force_size;
    next.dressed = false;
    next.dressing_measured = false;
    next.last_size_disturbance_um = Some(disturbance);
    next.last_size_disturbance_part = part.part_number;
    if state.dressed {
        // The dresser's error, not drift: the next dressing starts from what this one needed.
        next.dressing_offset_um = state.dressing_offset_um - params.gain * size_um;
    } else if state.dressing_measured {
        // What the dresser's infeed reading missed: an offset, not drift.
    } else if let Some(before) = state.last_size_disturbance_um {
        let parts = match (state.last_size_disturbance_part, part.part_number) {
            (Some(before), Some(now)) if now > before => (now - before) as f64,
            _ => 1.0,
        };
        let observed = (disturbance - before) / parts;
        next.size_drift_um_per_part = state.size_drift_um_per_part
            + params.wear_gain * (observed - state.size_drift_um_per_part);
    }
}

/// The wanted correction within `max_correction_um`: as it is when it fits, held to the
/// limit when a repeated part confirms the error is real, refused otherwise (one part alone
/// may be a bad measurement).
fn held_to_limit(
    wanted: Vec<f64>,
    repeatable: bool,
    params: &LearningParams,
) -> Result<(Vec<f64>, Option<Bounded>), LearnError> {
    let (wanted_um, j) = max_abs_at(&wanted);
    let angle_deg = j as f64 * 360.0 / wanted.len() as f64;
    if wanted_um <= params.max_correction_um {
        Ok((wanted, None))
    } else if !repeatable {
        Err(LearnError::CorrectionTooLarge {
            max_um: wanted_um,
            angle_deg,
            limit_um: params.max_correction_um,
        })
    } else {
        let bound = Bounded {
            wanted: wanted_um,
            limit: params.max_correction_um,
            angle_deg: Some(angle_deg),
            quantity: BoundedQuantity::Correction,
        };
        Ok((within_limit(&wanted, params), Some(bound)))
    }
}

/// A bounded step that changed nothing is stuck at its limit: an error, so an operator
/// looks at the machine instead of the loop pushing the same table forever.
fn step_outcome(
    bound: Option<Bounded>,
    unchanged: bool,
    part: &PartError<'_>,
    max_error_um: f64,
    max_correction_um: f64,
) -> Result<StepOutcome, LearnError> {
    match bound {
        Some(b) if unchanged => Err(match b.quantity {
            BoundedQuantity::Correction => LearnError::AtLimit {
                wanted_um: b.wanted,
                angle_deg: b.angle_deg.unwrap_or(0.0),
                limit_um: b.limit,
            },
            BoundedQuantity::Timing => LearnError::TimingTooLarge {
                wanted_deg: b.wanted,
                limit_deg: b.limit,
                timing_error_deg: part.timing_error_deg,
            },
        }),
        Some(bound) => Ok(StepOutcome::Limited {
            max_error_um,
            max_correction_um,
            bound,
        }),
        None => Ok(StepOutcome::Updated {
            max_error_um,
            max_correction_um,
        }),
    }
}

/// The timing step and the limit that bounded it, if one did.
fn learn_timing(
    state: &LearningState,
    part: &PartError<'_>,
    params: &LearningParams,
) -> Result<(f64, Option<Bounded>), LearnError> {
    let repeatable = part
        .previous
        .is_some_and(|p| p.confirms_timing(part.timing_error_deg, params));
    let band = params
        .timing_deadband_deg
        .max(params.deadband_sigmas * part.timing_sigma_deg);
    let wanted = state.timing_correction_deg - params.gain * soft_dead(part.timing_error_deg, band);
    let limit = params.max_timing_correction_deg;
    if wanted.abs() <= limit {
        return Ok((wanted, None));
    }
    if !repeatable {
        return Err(LearnError::TimingTooLarge {
            wanted_deg: wanted,
            limit_deg: limit,
            timing_error_deg: part.timing_error_deg,
        });
    }
    let bound = Bounded {
        wanted: wanted.abs(),
        limit,
        angle_deg: None,
        quantity: BoundedQuantity::Timing,
    };
    Ok((wanted.clamp(-limit, limit), Some(bound)))
}

/// Deadbands of the size and of the low-passed shape, µm: `deadband_sigmas` standard errors
/// of each. The per-angle standard error of the mean over the revolutions is σ/√revs; the
/// mean over N angles has √N less; a low-pass keeping K_eff of the N degrees of freedom
/// (K_eff = Σ 2·q(k)² over orders ≥ 1) leaves √(K_eff/N) of it per angle.
fn deadbands(part: &PartError<'_>, params: &LearningParams) -> (f64, f64) {
    let n = part.error_um.len();
    let revs = f64::from(part.revolutions.max(1));
    let sigma =
        (part.repeatability_um.iter().map(|s| s * s).sum::<f64>() / n as f64).sqrt() / revs.sqrt();
    let top = ((params.cutoff_order + params.rolloff_orders) as usize).min(n / 2);
    let k_eff: f64 = (1..=top)
        .map(|k| {
            let q = q_gain(k as u32, params.cutoff_order, params.rolloff_orders);
            if 2 * k == n { q * q } else { 2.0 * q * q }
        })
        .sum();
    let d = params.deadband_sigmas;
    (
        d * sigma / (n as f64).sqrt(),
        d * sigma * (k_eff / n as f64).sqrt(),
    )
}

/// The largest correction like `wanted` that stays within the limit: clipped, smoothed by Q
/// (a clipped curve has corners the wheel cannot follow), and scaled back under the limit.
fn within_limit(wanted: &[f64], params: &LearningParams) -> Vec<f64> {
    let limit = params.max_correction_um;
    let clipped: Vec<f64> = wanted.iter().map(|u| u.clamp(-limit, limit)).collect();
    let smooth = low_pass(&clipped, params.cutoff_order, params.rolloff_orders);
    let (max_um, _) = max_abs_at(&smooth);
    let scale = if max_um > limit { limit / max_um } else { 1.0 };
    smooth.iter().map(|u| u * scale).collect()
}

fn soft_dead(value: f64, band: f64) -> f64 {
    value.signum() * (value.abs() - band).max(0.0)
}

/// Largest |value| and its index.
fn max_abs_at(values: &[f64]) -> (f64, usize) {
    values
        .iter()
        .enumerate()
        .fold((0.0f64, 0), |(m, jm), (j, u)| {
            if u.abs() > m { (u.abs(), j) } else { (m, jm) }
        })
}

#[cfg(test)]
mod tests;
