//! Measure before the finish, the loop's decision: from the in-process measurement (stock
//! still on) either a table order for this part's finish table, or why none (the finish then
//! grinds with the table in force). The table is core's same-part step
//! ([`camloop_core::cycle::finish::finish_table`]); the shell only carries the order out,
//! with the handshake's count in the same push.
//!
//! Nothing is learned here: the memory is read, never changed. The order's `next` is the
//! state the finish table was made from, so once it is in force the finished part's
//! measurement learns from it, once, through the part-to-part loop.

use crate::machine::{Program, TableOrder};
use crate::memory::LoopMemory;
use camloop_core::cycle::finish::{FinishRefused, InProcess, finish_table};
use camloop_core::cycle::{CycleProgram, CycleSettings, StageKind};
use camloop_core::measure::RawMeasurement;
use camloop_core::turn::{TurnSetup, measurement_sha256};
use jiff::Timestamp;

/// What the decision needs besides the measurement.
#[derive(Debug, Clone, Copy)]
pub struct SamePart<'a> {
    pub setup: &'a TurnSetup<'a>,
    pub cycle: Option<&'a CycleSettings>,
    pub memory: &'a LoopMemory,
    /// The lobe or pin name the measurement must carry.
    pub feature: &'a str,
    /// The part the control is grinding, as the gauge names it.
    pub part: &'a str,
    /// How long the measurement has been with camloop, s: past the control's wait
    /// (`handshake_timeout_s`) the finish is already ground with the table in force, and a
    /// table delivered now would be taken for the next part's.
    pub waited_s: f64,
}

/// Why no same-part finish table.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SamePartRefused {
    #[error("the recipe has no [cycle] with program = \"whole\" and a measure stage")]
    NoCycle,
    #[error(
        "too late: the measurement waited {waited_s:.1} s, the control waits {timeout_s} s and grinds the finish with the table in force"
    )]
    TooLate { waited_s: f64, timeout_s: f64 },
    #[error("{0}")]
    Finish(#[from] FinishRefused),
}

/// Radial stock the stages from the measurement on still remove, mm: what the gauge reads
/// as size above the finished part (the measure stage itself removes nothing).
pub fn stock_after_measure_mm(cycle: &CycleSettings) -> Option<f64> {
    let stages = cycle.resolved(1.0);
    let at = stages.iter().position(|s| s.kind == StageKind::Measure)?;
    Some(stages[at..].iter().map(|s| s.infeed_mm).sum())
}

/// This part's finish table as an order for the feature's machine, or why the finish keeps
/// the table in force.
pub fn same_part_order(
    input: &SamePart<'_>,
    raw: &RawMeasurement,
    at: Timestamp,
) -> Result<TableOrder, SamePartRefused> {
    let cycle = input
        .cycle
        .filter(|c| c.program == CycleProgram::Whole)
        .ok_or(SamePartRefused::NoCycle)?;
    let remaining_stock_mm = stock_after_measure_mm(cycle).ok_or(SamePartRefused::NoCycle)?;
    // A wait that is not a number is refused too.
    if input.waited_s.is_nan() || input.waited_s >= cycle.handshake_timeout_s {
        return Err(SamePartRefused::TooLate {
            waited_s: input.waited_s,
            timeout_s: cycle.handshake_timeout_s,
        });
    }
    let finish = finish_table(
        &InProcess {
            setup: input.setup,
            in_force: &input.memory.learning,
            raw,
            part: input.part,
            remaining_stock_mm,
            gain: cycle.same_part_gain,
        },
        input.feature,
    )?;
    Ok(TableOrder {
        program: Program::Table {
            table: Box::new(finish.table),
            planned: None,
        },
        next: Box::new(finish.state),
        reason: format!(
            "same-part finish table of part {} from its in-process measurement ({:.2} µm over the remaining stock)",
            raw.header.part.trim(),
            finish.size_over_stock_um
        ),
        measurement: Some(measurement_sha256(raw)),
        rollback_of: None,
        learning: None,
        at,
    })
}
