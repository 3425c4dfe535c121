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
    /// Learning gain L, 0 < L < 1 (lift correction and timing alike).
    pub gain: f64,
    /// Highest harmonic order learned in full.
    pub cutoff_order: u32,
    /// Orders over which Q tapers from 1 to 0 above the cut-off.
    pub rolloff_orders: u32,
    /// Deadband in units of the standard error of what is learned: of the part's mean for
    /// the size, of the low-passed error for the shape (see [`step`]).
    pub deadband_sigmas: f64,
    /// Stop learning while the part's max |error| is within this (µm); `None`: always learn.
    pub stop_in_tolerance_um: Option<f64>,
    /// Largest |correction| allowed anywhere (µm): never exceeded. A repeatable error that
    /// needs more is learned up to it (bounded steps); a jump that needs more is refused.
    pub max_correction_um: f64,
    /// The max error must grow by more than this on each of two parts in a row to count as
    /// divergence (µm): slow drift such as wheel wear and gauge noise must not raise it.
    pub divergence_margin_um: f64,
    /// Gain of the size-drift estimate (wheel wear between dressings), 0 ≤ κ < 1: the change
    /// of the size disturbance from part to part, averaged with this weight into a drift per
    /// part that the next table anticipates. 0: off.
    pub wear_gain: f64,
    /// Timing errors within this are never corrected, degrees; the deadband is otherwise
    /// `deadband_sigmas` standard errors of the timing estimate (which a steep feature, such
    /// as a crankpin, measures far better than a cam lobe).
    pub timing_deadband_deg: f64,
    /// Largest |timing correction| (the feature's C offset), degrees; never exceeded.
    pub max_timing_correction_deg: f64,
    /// Parts in a row that the same guard may refuse or limit before it becomes an alarm.
    pub blocked_alarm_after_parts: u32,
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
            wear_gain: 0.3,
            timing_deadband_deg: 0.0001,
            max_timing_correction_deg: 0.5,
            blocked_alarm_after_parts: 3,
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
        let mut at_least_zero = |field: &str, v: f64| {
            if !(v.is_finite() && v >= 0.0) {
                problems.push(format!("learning.{field} = {v}: must be ≥ 0"));
            }
        };
        at_least_zero("deadband_sigmas", self.deadband_sigmas);
        at_least_zero("divergence_margin_um", self.divergence_margin_um);
        at_least_zero("timing_deadband_deg", self.timing_deadband_deg);
        for (field, v) in [
            ("max_correction_um", self.max_correction_um),
            ("max_timing_correction_deg", self.max_timing_correction_deg),
        ] {
            if !(v.is_finite() && v > 0.0) {
                problems.push(format!("learning.{field} = {v}: must be > 0"));
            }
        }
        if !(self.wear_gain.is_finite() && (0.0..1.0).contains(&self.wear_gain)) {
            problems.push(format!(
                "learning.wear_gain = {}: must be in [0, 1)",
                self.wear_gain
            ));
        }
        if self.blocked_alarm_after_parts == 0 {
            problems.push("learning.blocked_alarm_after_parts = 0: must be at least 1".into());
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

/// A limit that bounded a step.
#[derive(Debug, Clone, PartialEq)]
pub struct Bounded {
    /// What the step wanted, µm (lift) or degrees (timing), and the limit it was held to.
    pub wanted: f64,
    pub limit: f64,
    /// Where the lift correction wanted the most, degrees of the feature (lift only).
    pub angle_deg: Option<f64>,
    pub quantity: BoundedQuantity,
}

impl std::fmt::Display for Bounded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.quantity, self.angle_deg) {
            (BoundedQuantity::Correction, Some(a)) => write!(
                f,
                "correction held to its limit of {} µm (it wanted {:.2} µm at {a:.1}°)",
                self.limit, self.wanted
            ),
            (BoundedQuantity::Correction, None) => write!(
                f,
                "correction held to its limit of {} µm (it wanted {:.2} µm)",
                self.limit, self.wanted
            ),
            (BoundedQuantity::Timing, _) => write!(
                f,
                "timing correction held to its limit of {}° (it wanted {:.4}°)",
                self.limit, self.wanted
            ),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoundedQuantity {
    /// The lift correction, µm (`max_correction_um`).
    Correction,
    /// The timing correction, degrees (`max_timing_correction_deg`).
    Timing,
}

/// What one learning step decided.
#[derive(Debug, Clone, PartialEq)]
pub enum StepOutcome {
    /// A new correction; the next table must be made from it.
    Updated {
        max_error_um: f64,
        max_correction_um: f64,
    },
    /// A repeatable error needed more than a limit allows: the new correction goes as far as
    /// the limit, and no further.
    Limited {
        max_error_um: f64,
        max_correction_um: f64,
        bound: Bounded,
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
    #[error(
        "timing correction would reach {wanted_deg:.4}°, above the limit of {limit_deg}° (timing error {timing_error_deg:.4}°)"
    )]
    TimingTooLarge {
        wanted_deg: f64,
        limit_deg: f64,
        timing_error_deg: f64,
    },
    #[error(
        "the correction is at its limit of {limit_um} µm at {angle_deg:.1}° (it would need {wanted_um:.2} µm): nothing more can be learned until the machine is checked or the limit raised"
    )]
    AtLimit {
        wanted_um: f64,
        angle_deg: f64,
        limit_um: f64,
    },
}

/// Corrections closer than this everywhere are the same table, µm (and degrees / 1000).
const SAME_CORRECTION_UM: f64 = 0.01;

/// The step a learned correction is kept in, µm: 1 nm. The table writes X to 0.1 µm and the
/// gauge reads 0.1 µm, so digits below a nanometre change no table (but at a rounding tie)
/// and carry nothing the next part could confirm; kept at whole nanometres, a correction
/// prints with at most three decimals, and its history (every table version and learning
/// snapshot keeps it exactly) takes a fraction of the bytes of full f64 digits.
pub const CORRECTION_STEP_UM: f64 = 0.001;

/// Rounds a correction to whole [`CORRECTION_STEP_UM`], never beyond `±limit_um`.
pub fn quantise_correction(correction_um: &mut [f64], limit_um: f64) {
    let steps = 1.0 / CORRECTION_STEP_UM;
    let limit = (limit_um * steps).floor() / steps;
    for u in correction_um {
        *u = ((*u * steps).round() / steps).clamp(-limit, limit);
    }
}

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
    // The size disturbance the part saw: its size error less the size correction it was
    // ground with (the plant is 1:1 in size). Its change from part to part is the drift.
    let in_force_size = state.correction_um.iter().sum::<f64>() / n as f64;
    let disturbance = mean - in_force_size;
    next.dressed = false;
    next.last_size_disturbance_um = Some(disturbance);
    next.last_size_disturbance_part = part.part_number;
    if state.dressed {
        // The dresser's error, not drift: the next dressing starts from what this one needed.
        next.dressing_offset_um = state.dressing_offset_um - params.gain * size;
    } else if let Some(before) = state.last_size_disturbance_um {
        let parts = match (state.last_size_disturbance_part, part.part_number) {
            (Some(before), Some(now)) if now > before => (now - before) as f64,
            _ => 1.0,
        };
        let observed = (disturbance - before) / parts;
        next.size_drift_um_per_part = state.size_drift_um_per_part
            + params.wear_gain * (observed - state.size_drift_um_per_part);
    }
    // Right after a dressing the size step is the dresser's offset, measured to a few nm
    // over every angle: taken whole, not by the gain (which guards the shape against model
    // mismatch).
    let size_gain = if state.dressed { 1.0 } else { params.gain };
    let learned: Vec<f64> = (0..n)
        .map(|j| {
            state.correction_um[j]
                - size_gain * size
                - params.gain * soft_dead(shape[j], shape_band)
                - next.size_drift_um_per_part
        })
        .collect();
    let wanted = low_pass(&learned, params.cutoff_order, params.rolloff_orders);
    let (wanted_um, j) = max_abs_at(&wanted);
    let angle_deg = j as f64 * 360.0 / n as f64;
    let mut bound = None;
    next.correction_um = if wanted_um <= params.max_correction_um {
        wanted
    } else if !repeatable {
        return Err(LearnError::CorrectionTooLarge {
            max_um: wanted_um,
            angle_deg,
            limit_um: params.max_correction_um,
        });
    } else {
        bound = Some(Bounded {
            wanted: wanted_um,
            limit: params.max_correction_um,
            angle_deg: Some(angle_deg),
            quantity: BoundedQuantity::Correction,
        });
        within_limit(&wanted, params)
    };
    quantise_correction(&mut next.correction_um, params.max_correction_um);
    let timing = learn_timing(state, part, params)?;
    next.timing_correction_deg = timing.0;
    bound = bound.or(timing.1);
    let unchanged = next
        .correction_um
        .iter()
        .zip(&state.correction_um)
        .all(|(a, b)| (a - b).abs() < SAME_CORRECTION_UM)
        && (next.timing_correction_deg - state.timing_correction_deg).abs()
            < SAME_CORRECTION_UM * 1e-3;
    let max_correction_um = max_abs_at(&next.correction_um).0;
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

/// After a wheel dressing the control gets a new wheel radius, which replaces everything the
/// loop learned about the wheel's size (the initial radius error and the wear since). So the
/// part of the size correction that was the wheel's, `wheel_size_um` (for one feature, its
/// whole size correction; for a shaft, what all its features have in common: a lobe's own
/// size error, such as the shaft's deflection at its station, is not the wheel's), is
/// replaced by the dressing offset (what the previous dressings needed: a dresser's
/// systematic error), and the shape is kept. The error history restarts so the size step
/// after dressing is not taken for divergence, and the next step learns that step into the
/// offset rather than into the wear rate.
pub fn after_dressing(state: &mut LearningState, wheel_size_um: f64) {
    let shift = state.dressing_offset_um - wheel_size_um;
    state.correction_um.iter_mut().for_each(|u| *u += shift);
    quantise_correction(&mut state.correction_um, f64::INFINITY);
    if let Some(best) = state.best.as_mut() {
        best.correction_um.iter_mut().for_each(|u| *u += shift);
        quantise_correction(&mut best.correction_um, f64::INFINITY);
    }
    state.recent_max_error_um.clear();
    state.dressed = true;
}

/// The size part (order 0, the mean) of a state's correction, µm.
pub fn size_correction_um(state: &LearningState) -> f64 {
    state.correction_um.iter().sum::<f64>() / state.correction_um.len().max(1) as f64
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
}
