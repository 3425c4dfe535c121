//! A measurement's step: a repeat is noted, a failed check rejected, and otherwise the turn
//! taken from the table in force (held when the part was ground with another table or the
//! disk is full), its guards' streak moved, and everything it decided written in one
//! journal write before anything of it takes effect.

use super::table::{Program, TableOrder};
use super::{Alarm, DeliveryError, Effect, FeatureMachine, Finished, Metric, Phase};
use crate::guards::{self, GuardKind};
use crate::memory::LoopMemory;
use crate::record::{EventKind, Record};
use camloop_core::compensate::CycleError;
use camloop_core::digest::Sha256;
use camloop_core::ids::{PartId, TableVersion};
use camloop_core::learn::StepOutcome;
use camloop_core::levels::EventLevel;
use camloop_core::measure::RawMeasurement;
use camloop_core::turn::{self, Decision, HoldReason, Measured, Turn, TurnError, TurnSetup};
use jiff::Timestamp;

/// A measurement routed to this feature.
#[derive(Debug)]
pub struct Gauged<'a> {
    /// The turn's setup (the recipe's, with the plan's time law when it grinds with one).
    pub setup: TurnSetup<'a>,
    pub raw: &'a RawMeasurement,
    /// Its content identity ([`turn::measurement_sha256`]).
    pub sha256: Sha256,
    /// The part's id, when the gauge's text is one.
    pub part: Option<PartId>,
    /// The table the control reports having ground the part with, where it can say.
    pub ground_with: Option<TableVersion>,
    /// The journal runs on its reserve (the disk is full): measurements are kept, nothing
    /// is learned.
    pub on_reserve: bool,
    pub at: Timestamp,
}

/// What a recorded part came to, for the shell's status, metrics and log line.
#[derive(Debug)]
pub struct PartReport {
    pub measured: Box<Measured>,
    /// The part's count on this feature.
    pub part_no: u64,
    /// The table in force when it was ground.
    pub ground_with: Option<TableVersion>,
    /// A new table reached the control in this step.
    pub pushed: bool,
    pub note: PartNote,
}

/// What the loop did with the part, for its log line.
#[derive(Debug, Clone, PartialEq)]
pub enum PartNote {
    /// A table was made: delivered, waiting, or refused by the share (the memory says).
    Table,
    /// The table was not recorded (nothing reached the share).
    NotRecorded(DeliveryError),
    /// A guard refused the table (for `reason`), this many parts in a row.
    Refused { in_a_row: u32, reason: CycleError },
    /// Not learned from.
    Held(HoldReason),
}

/// A part between its turn and its report.
#[derive(Debug)]
pub(super) struct PartStep {
    pub(super) measured: Box<Measured>,
    pub(super) part_no: u64,
    pub(super) ground_with: Option<TableVersion>,
    held: bool,
    on_reserve: bool,
    pub(super) at: Timestamp,
    /// What the step writes: the measurement first.
    pub(super) records: Vec<Record>,
    /// Alarms and metrics said once the step is durable.
    pub(super) effects: Vec<Effect>,
    pub(super) note: PartNote,
}

impl FeatureMachine {
    pub(super) fn on_gauged(&mut self, g: Gauged<'_>) {
        let raw = g.raw;
        if self.memory.has_seen(&g.sha256) {
            let message = format!(
                "part {} from {} repeats a measurement already used",
                raw.header.part, raw.origin
            );
            let e = Record::event(
                g.at,
                EventLevel::Info,
                EventKind::MeasurementRepeated,
                message,
            );
            return self.close(vec![e], Finished::Repeated);
        }
        let in_force = self.memory.in_force_version;
        let hold = match g.ground_with {
            Some(v) if Some(v) != in_force => Some(HoldReason::OtherTable {
                ground_with: v.get(),
                in_force: in_force.map_or(0, TableVersion::get),
            }),
            _ if g.on_reserve => {
                self.effects.push_back(Effect::Alarm(Alarm::DiskFull));
                Some(HoldReason::DiskFull)
            }
            _ => None,
        };
        let previous = self.memory.previous;
        let done = match turn::turn(&g.setup, &self.memory.learning, raw, hold, previous) {
            Ok(t) => t,
            Err(TurnError::Measurement(reason)) => {
                // The reject's file beside it keeps the text: that effect is I/O's.
                self.effects.push_back(Effect::KeepReject {
                    sha256: g.sha256,
                    reason: reason.to_string(),
                });
                self.effects
                    .push_back(Effect::Metric(Metric::MeasurementRejected));
                let message = format!("{} (from {})", reason, raw.origin);
                let e = Record::event(
                    g.at,
                    EventLevel::Warn,
                    EventKind::MeasurementRejected,
                    message,
                );
                return self.close(vec![e], Finished::Rejected { reason });
            }
            Err(e) => {
                return self.finish(Finished::Failed {
                    reason: e.to_string(),
                });
            }
        };
        self.turned(&g, done);
    }

    /// The turn of a part that passed the checks: the step's memory and records, and its
    /// table on its way when it made one.
    fn turned(&mut self, g: &Gauged<'_>, done: Turn) {
        let in_force = self.memory.in_force_version;
        let mut memory = self.memory.clone();
        let record = Record::Measurement {
            sha256: g.sha256,
            part: g.part.clone(),
            measured: Box::new(done.measured.clone()),
            ground_with: in_force,
            at: g.at,
        };
        memory.measured(g.sha256, g.part.clone());
        memory.previous = Some(done.measured.as_previous());
        let mut step = PartStep {
            part_no: memory.parts,
            measured: Box::new(done.measured),
            ground_with: in_force,
            held: matches!(done.decision, Decision::Held(_)),
            on_reserve: g.on_reserve,
            at: g.at,
            records: vec![record],
            effects: Vec::new(),
            note: PartNote::Table,
        };
        match done.decision {
            Decision::Table {
                outcome,
                next,
                table,
                planned,
            } => {
                self.note_outcome(&mut memory, &outcome, &mut step);
                let order = TableOrder {
                    program: Program::Table { table, planned },
                    next,
                    reason: format!("part {}: {outcome}", step.part_no),
                    measurement: Some(g.sha256),
                    rollback_of: None,
                    learning: None,
                    at: g.at,
                };
                self.start_table(order, Some((Box::new(step), Box::new(memory))));
            }
            Decision::Refused(e) => {
                self.note_refusal(&mut memory, &e, &mut step);
                self.record_part(step, memory);
            }
            Decision::Held(reason) => {
                step.records.push(Record::event(
                    g.at,
                    EventLevel::Info,
                    EventKind::LearningHeld,
                    format!("part {} not learned from: {reason}", step.part_no),
                ));
                step.note = PartNote::Held(reason);
                self.record_part(step, memory);
            }
        }
    }

    /// What a learning step's outcome means for the alarms and the guards' streaks.
    fn note_outcome(&self, memory: &mut LoopMemory, outcome: &StepOutcome, step: &mut PartStep) {
        match outcome {
            StepOutcome::Reverted { reason, .. } => {
                step.effects.push(Effect::Alarm(Alarm::LearningReverted {
                    reason: reason.clone(),
                }));
                step.records.push(Record::event(
                    step.at,
                    EventLevel::Error,
                    EventKind::LearningReverted,
                    reason.clone(),
                ));
            }
            StepOutcome::Limited { bound, .. } => {
                let kind = GuardKind::of_bound(bound.quantity);
                self.guard_acted(memory, kind, &bound.to_string(), step);
            }
            StepOutcome::Updated { .. } | StepOutcome::InTolerance { .. } => {
                let Some(streak) = memory.guard.take() else {
                    return;
                };
                if let Some(message) =
                    guards::cleared(Some(streak), step.part_no, &self.config.feature)
                {
                    step.records.push(Record::event(
                        step.at,
                        EventLevel::Info,
                        EventKind::GuardCleared,
                        message,
                    ));
                }
                step.effects.push(Effect::Metric(Metric::Blocked(None)));
            }
            StepOutcome::Frozen { .. } => {}
        }
    }

    /// A guard refused or limited the part; returns how many parts in a row it has. At the
    /// recipe's `blocked_alarm_after_parts` in a row, one alarm ([`guards::acted`]).
    fn guard_acted(
        &self,
        memory: &mut LoopMemory,
        kind: GuardKind,
        reason: &str,
        step: &mut PartStep,
    ) -> u32 {
        let acted = guards::acted(
            memory.guard.take(),
            kind,
            reason,
            step.part_no,
            &self.config.feature,
            self.config.params.blocked_alarm_after_parts,
        );
        let in_a_row = acted.streak.parts;
        memory.guard = Some(acted.streak);
        if let Some(message) = acted.alarm {
            step.effects.push(Effect::Alarm(Alarm::BlockedByGuard {
                reason: reason.to_string(),
                message: message.clone(),
            }));
            step.records.push(Record::event(
                step.at,
                EventLevel::Error,
                EventKind::BlockedByGuard,
                message.clone(),
            ));
            step.effects
                .push(Effect::Metric(Metric::Blocked(Some(message))));
        }
        in_a_row
    }

    /// A refused table: counted, its guard's streak extended, warned about once per streak.
    fn note_refusal(&self, memory: &mut LoopMemory, e: &CycleError, step: &mut PartStep) {
        step.effects.push(Effect::Metric(Metric::TableRefused));
        let in_a_row = self.guard_acted(memory, GuardKind::of_refusal(e), &e.to_string(), step);
        let level = if in_a_row == 1 {
            EventLevel::Warn
        } else {
            EventLevel::Info
        };
        step.records.push(Record::event(
            step.at,
            level,
            EventKind::TableRefused,
            format!("{} ({in_a_row} in a row): {e}", self.config.feature),
        ));
        step.note = PartNote::Refused {
            in_a_row,
            reason: e.clone(),
        };
    }

    /// A part without a table to deliver: its records and the memory it leaves, in one write
    /// (on the journal's reserve only the measurement and its events: nothing changed).
    pub(super) fn record_part(&mut self, mut step: PartStep, memory: LoopMemory) {
        if !step.held || !step.on_reserve {
            step.records.push(Record::Learning {
                memory: Box::new(memory.clone()),
                at: step.at,
            });
        }
        let ticket = self.journal(std::mem::take(&mut step.records));
        self.phase = Phase::Recording {
            ticket,
            part: Box::new(step),
            memory: Box::new(memory),
        };
    }

    /// The part's write is durable (the memory already committed): its alarms, metrics and
    /// report.
    pub(super) fn part_recorded(&mut self, mut step: PartStep) {
        self.effects.extend(std::mem::take(&mut step.effects));
        let report = PartReport {
            pushed: self.memory.in_force_version != step.ground_with,
            measured: step.measured,
            part_no: step.part_no,
            ground_with: step.ground_with,
            note: step.note,
        };
        self.phase = Phase::Idle;
        self.finish(Finished::Recorded(Box::new(report)));
    }

    /// The part's write failed: nothing of it is kept or learned, the source keeps it.
    pub(super) fn part_not_recorded(&mut self) {
        self.phase = Phase::Idle;
        self.effects.push_back(Effect::Metric(Metric::LearningHeld));
        self.finish(Finished::NotRecorded);
    }
}
