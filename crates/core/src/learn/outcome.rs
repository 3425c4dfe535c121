//! What a learning step reports: its outcome, the limit that bounded it, or why it refused.

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

/// One line for logs, records and the CLI: the one wording of a step's outcome.
impl std::fmt::Display for StepOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StepOutcome::Updated {
                max_error_um,
                max_correction_um,
            } => write!(
                f,
                "learned from max error {max_error_um:.2} µm, correction up to {max_correction_um:.2} µm"
            ),
            StepOutcome::Limited {
                max_error_um,
                bound,
                ..
            } => write!(f, "learned from max error {max_error_um:.2} µm, {bound}"),
            StepOutcome::InTolerance { max_error_um } => {
                write!(
                    f,
                    "max error {max_error_um:.2} µm within tolerance, table kept"
                )
            }
            StepOutcome::Frozen {
                max_error_um,
                reason,
            } => write!(
                f,
                "max error {max_error_um:.2} µm; learning frozen: {reason}"
            ),
            StepOutcome::Reverted { reason, .. } => write!(f, "ALARM: {reason}"),
        }
    }
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
