//! The learning's parameters and their checks.

use serde::{Deserialize, Serialize};

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
