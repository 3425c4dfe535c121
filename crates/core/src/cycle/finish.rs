//! Measure before the finish: this part's finish table from the learned correction plus what
//! the in-process measurement (stock still on) says, the remaining stock taken out as a
//! known wheel-centre offset (read angle by angle through
//! [`crate::geometry::Part::lift_per_x_offset`]). The same guards as the part-to-part loop; a refusal means the finish
//! grinds with the table in force and nothing is learned.
//!
//! The learning state is never changed here: the part-to-part loop learns from the finished
//! part's measurement, once, from the state of the table in force (so no part is learned
//! from twice).

use crate::compensate::{self, CycleError, GuardedTable};
use crate::learn::{LearningState, PartError, StepOutcome};
use crate::measure::RawMeasurement;
use crate::turn::{self, Measured, TurnError, TurnSetup};

/// What the finish table is made from.
#[derive(Debug, Clone, Copy)]
pub struct InProcess<'a> {
    pub setup: &'a TurnSetup<'a>,
    /// The learning state of the table in force (the one the part is being ground with).
    pub in_force: &'a LearningState,
    pub raw: &'a RawMeasurement,
    /// The part the control is grinding (its id as the gauge names parts): a measurement
    /// that names another is refused.
    pub part: &'a str,
    /// Radial stock still on when the gauge read, mm: a known size offset.
    pub remaining_stock_mm: f64,
    /// Gain of the same-part step, 0 < g < 1 (the recipe's `cycle.same_part_gain`).
    pub gain: f64,
}

/// Why no same-part table: the finish grinds with the table in force.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FinishRefused {
    #[error("the in-process measurement names part {got}, the control grinds {expected}")]
    WrongPart { expected: String, got: String },
    #[error("the in-process measurement names lobe {got}, the finish is of {expected}")]
    WrongFeature { expected: String, got: String },
    #[error("the in-process measurement has {got} usable revolutions, at least 3 are needed")]
    Incomplete { got: usize },
    #[error("the in-process measurement: {0}")]
    Measurement(#[from] TurnError),
    #[error("remaining stock {0} mm: must be a finite number ≥ 0")]
    Stock(f64),
    #[error("same-part gain {0}: must be 0 < g < 1")]
    Gain(f64),
    #[error("the same-part table: {0}")]
    Guard(#[from] CycleError),
}

/// This part's finish table, with what it was made from.
#[derive(Debug, Clone)]
pub struct FinishTable {
    pub table: GuardedTable,
    /// The learning state the table was made from (the learned correction plus this step):
    /// what the finished part is ground with, so the part-to-part step learns from it.
    pub state: LearningState,
    pub outcome: StepOutcome,
    pub measured: Measured,
    /// The error the finish would leave, per gauge angle of the feature's frame, µm: the
    /// in-process lift error with the remaining stock taken out (what the step learns from).
    pub error_um: Vec<f64>,
    /// The mean error the gauge read above the finished part, µm (the remaining stock taken
    /// out angle by angle).
    pub size_over_stock_um: f64,
}

/// The finish table of the part in the machine, or why the finish keeps the table in force.
/// `feature` is the lobe or pin name the measurement must carry.
pub fn finish_table(input: &InProcess<'_>, feature: &str) -> Result<FinishTable, FinishRefused> {
    let raw = input.raw;
    if raw.header.part.trim() != input.part.trim() {
        return Err(FinishRefused::WrongPart {
            expected: input.part.to_owned(),
            got: raw.header.part.clone(),
        });
    }
    if raw.header.lobe.trim() != feature {
        return Err(FinishRefused::WrongFeature {
            expected: feature.to_owned(),
            got: raw.header.lobe.clone(),
        });
    }
    if !(input.remaining_stock_mm.is_finite() && input.remaining_stock_mm >= 0.0) {
        return Err(FinishRefused::Stock(input.remaining_stock_mm));
    }
    if !(input.gain > 0.0 && input.gain < 1.0) {
        return Err(FinishRefused::Gain(input.gain));
    }
    let measured = turn::measure(input.setup, raw)?;
    let used = measured.averaged.revolutions_used.len();
    if used < 3 {
        return Err(FinishRefused::Incomplete { got: used });
    }
    let report = &measured.report;
    let stock_um = input.remaining_stock_mm * 1000.0;
    let lift_error: Vec<f64> = report
        .profile_error_um
        .iter()
        .map(|e| e + report.base_radius_error_um)
        .collect();
    // The stock is left on as a wheel-centre offset (X stops that far out), which the gauge
    // reads as the offset times the angle's gain: 1 on a base circle, down to cos γ where
    // the contact normal leans from the line of centres (0.5 % on the demo crankpins, so a
    // uniform 20 µm would leave 0.1 µm of size and 0.2 µm of shape in every finish).
    let part_geometry = input
        .setup
        .lobe
        .feature
        .part(input.setup.lobe.nominal)
        .map_err(|e| CycleError::Guard(e.into()))?;
    let n = lift_error.len();
    let error_um: Vec<f64> = turn::to_feature_frame(&lift_error, input.setup.phase_deg)
        .iter()
        .enumerate()
        .map(|(j, e)| {
            let psi_rad = std::f64::consts::TAU * j as f64 / n as f64;
            e - stock_um * part_geometry.lift_per_x_offset(psi_rad)
        })
        .collect();
    let size_um = error_um.iter().sum::<f64>() / n.max(1) as f64;
    let repeatability_um = turn::to_feature_frame(&report.repeatability_um, input.setup.phase_deg);
    let part = PartError {
        error_um: &error_um,
        repeatability_um: &repeatability_um,
        revolutions: used as u32,
        timing_error_deg: measured.timing_error_deg,
        timing_sigma_deg: measured.timing_sigma_deg,
        part_number: measured.part_number,
        previous: None,
    };
    let mut params = input.setup.lobe.params.clone();
    params.gain = input.gain;
    let lobe = compensate::LobeLoop {
        params: &params,
        ..input.setup.lobe
    };
    let (outcome, state) = same_part_step(input.in_force, &part, &params)?;
    let table = compensate::current_table(&state, &lobe).map_err(CycleError::from)?;
    Ok(FinishTable {
        table,
        state,
        outcome,
        measured,
        error_um,
        size_over_stock_um: size_um,
    })
}

/// The same-part step: the correction (lift and timing) moved by what this part's
/// measurement says, and nothing else of the state of the table in force.
///
/// The rest of the state is the part-to-part loop's, and the same-part step must leave it as
/// it was:
/// - no drift anticipated: the wheel wears from part to part, but the finish is of the part
///   just measured, within the same feature's grinding (a full part's drift taken off here
///   grinds every finish undersize by it: 0.5–0.6 µm on the demo camshaft, whose lobe sees
///   eight lobes' wear between two shafts);
/// - no drift learned: the in-process size and the finished size are of one part, so their
///   change is not a part's wear, and the finished part's drift must be measured against the
///   previous finished part;
/// - no dressing offset moved, no part counted, no divergence judged: the in-process error
///   (stock on) is not a finished part's.
fn same_part_step(
    in_force: &LearningState,
    part: &PartError<'_>,
    params: &crate::learn::LearningParams,
) -> Result<(StepOutcome, LearningState), CycleError> {
    let mut scratch = LearningState {
        size_drift_um_per_part: 0.0,
        last_size_disturbance_um: None,
        last_size_disturbance_part: None,
        dressed: false,
        dressing_measured: false,
        recent_max_error_um: Vec::new(),
        best: None,
        ..in_force.clone()
    };
    let outcome = crate::learn::step(&mut scratch, part, params)?;
    let state = LearningState {
        correction_um: scratch.correction_um,
        timing_correction_deg: scratch.timing_correction_deg,
        ..in_force.clone()
    };
    Ok((outcome, state))
}
