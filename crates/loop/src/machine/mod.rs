//! One feature's loop as a sans-IO state machine, in the shape of quinn-proto's
//! `Connection`: the shell hands it what happened ([`FeatureMachine::handle`] with an
//! [`Input`]: a measurement, a table to deliver, a completed journal write, the share's
//! answers) and carries out what it asks ([`FeatureMachine::poll_effect`] until `None`:
//! journal, render, submit, deliver, keep a reject, alarm, metric, finished). It reads no
//! clock (every input that needs a time brings it) and does no I/O.
//!
//! **Write-ahead ordering is the machine's.** A part's step keeps nothing until one journal
//! write holds, together, the measurement, the write-ahead record of the table it made (if
//! any) and the memory the step leaves with that table waiting. Only once that write is
//! reported [`Input::Journalled`] does the machine ask to [`Effect::Submit`] the table, and
//! only once the share accepted it to [`Effect::Deliver`] it. A stop anywhere leaves either
//! nothing of the part (the source still holds it and sends it again) or the whole step,
//! which [`FeatureMachine::resume`] finishes from the journal and the share.
//!
//! - `part`: a measurement's step (repeat, hold, the turn, guards in a row, records);
//! - `table`: a table's way to the control (render, write-ahead, submit, deliver, retry);
//! - `resume`: a machine rebuilt from what the journal kept, reconciled with the share (every
//!   decision of a start);
//! - `between`: a dressing, a part not gauged, a freeze (what happens between parts).

mod between;
mod part;
mod resume;
mod table;

pub use between::{Dressed, DressingDone, NotGaugedDone};
pub use part::{Gauged, PartNote, PartReport};
pub use resume::{FROM_THE_MANIFEST, OnShare, ResumeReport, ShareView, adopt};
pub use table::{Program, RenderOrder, TableDone, TableOrder};

use crate::memory::LoopMemory;
use crate::record::{Record, TableRecord};
use camloop_core::compensate::LobeLoop;
use camloop_core::digest::Sha256;
use camloop_core::ids::{PartId, TableVersion};
use camloop_core::learn::LearningParams;
use camloop_core::names::FeatureName;
use jiff::Timestamp;
use std::collections::VecDeque;

/// What the machine knows of its feature beyond the memory.
#[derive(Debug, Clone)]
pub struct FeatureConfig {
    pub feature: FeatureName,
    /// The recipe's learning parameters (a table's record keeps them; the guards' alarm
    /// threshold is among them).
    pub params: LearningParams,
}

/// Names one journal write, so its completion is matched to the write that asked for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ticket(u64);

/// What happened, for the machine.
#[derive(Debug)]
pub enum Input<'a> {
    /// A measurement of this feature (routed to it by the shell).
    Gauged(Box<Gauged<'a>>),
    /// Deliver a table the shell decided (the start, a rollback): rendered, written ahead,
    /// submitted and delivered like a part's table.
    Table(Box<TableOrder>),
    /// The wheel was dressed.
    Dressed(Box<Dressed<'a>>),
    /// A part of this feature was ground and not gauged (`lobe`: the feature as ground).
    NotGauged {
        part: Option<PartId>,
        lobe: &'a LobeLoop<'a>,
        at: Timestamp,
    },
    /// An engineer froze learning for this reason, or (`None`) let it learn again.
    Freeze {
        frozen: Option<String>,
        at: Timestamp,
    },
    /// Time for the shell's retry: a table waiting for the share is delivered again.
    Tick,
    /// The journal write `ticket` is durable.
    Journalled(Ticket),
    /// The journal write `ticket` failed; `fenced_out` when another instance owns the
    /// machine now (not a fault here).
    JournalFailed {
        ticket: Ticket,
        fenced_out: bool,
        reason: String,
    },
    /// The table of [`Effect::Render`] as the share will number it; with a speed plan, the
    /// virtual axis' speed its program was rendered for (rev/min).
    Rendered {
        version: TableVersion,
        table_number: u32,
        text: String,
        va_speed_rpm: Option<f64>,
    },
    /// The table could not be rendered (a rule refused it): nothing was written.
    RenderFailed { reason: String },
    /// The share's answer to [`Effect::Submit`]: `Err` with its refusal.
    Submitted {
        version: TableVersion,
        outcome: Result<(), String>,
    },
    /// The share delivered `version` (to an [`Effect::Deliver`], or on a retry the shell
    /// made while the machine was idle).
    Delivered {
        version: TableVersion,
        at: Timestamp,
    },
    /// The share cannot take `version` now (unwritable, unmounted): it waits.
    ShareUnavailable {
        version: TableVersion,
        reason: String,
        at: Timestamp,
    },
    /// The share refused the version for good.
    ShareRefused {
        version: TableVersion,
        reason: String,
    },
    /// The share's state folder (or the numbering) failed: nothing more is done.
    ShareFailed { state: bool, reason: String },
}

/// What the machine asks the shell to do, in order.
#[derive(Debug)]
pub enum Effect {
    /// Append `records` to the journal (durably, in one write) and answer
    /// [`Input::Journalled`] or [`Input::JournalFailed`].
    Journal {
        ticket: Ticket,
        records: Vec<Record>,
    },
    /// Render a table as the share will number it; answer [`Input::Rendered`] or
    /// [`Input::RenderFailed`].
    Render(Box<RenderOrder>),
    /// Submit a version whose record is durable; answer [`Input::Submitted`].
    Submit(Box<TableRecord>),
    /// Deliver the version submitted; answer [`Input::Delivered`],
    /// [`Input::ShareUnavailable`], [`Input::ShareRefused`] or [`Input::ShareFailed`].
    Deliver { version: TableVersion },
    /// Keep a rejected measurement with its reason (the reject folder).
    KeepReject { sha256: Sha256, reason: String },
    /// An operator must act: counted and logged by the shell.
    Alarm(Alarm),
    /// A counter or gauge of the feature's metrics.
    Metric(Metric),
    /// The input's work is done, with what it came to.
    Finished(Finished),
}

/// Why an operator must act.
#[derive(Debug, Clone, PartialEq)]
pub enum Alarm {
    /// Learning was reverted and frozen.
    LearningReverted { reason: String },
    /// A guard acted part after part (the streak's alarm text).
    BlockedByGuard { reason: String, message: String },
    /// The share cannot take the table; said once per outage.
    ShareUnavailable { reason: String },
    /// The part was held because the journal runs on its reserve (the shell raises the
    /// disk alarm once per outage).
    DiskFull,
}

/// A metric the machine moves.
#[derive(Debug, Clone, PartialEq)]
pub enum Metric {
    MeasurementRejected,
    TableRefused,
    /// A part's measurement could not be recorded: learning holds.
    LearningHeld,
    /// A table (made for a wheel of this radius) reached the control.
    TablePushed {
        wheel_radius_mm: f64,
    },
    /// A table waits for the share.
    ShareWaiting,
    /// The feature's "blocked by a guard" status: set with the alarm, cleared with it.
    Blocked(Option<String>),
}

/// What an input came to.
#[derive(Debug)]
pub enum Finished {
    /// A part's measurement, recorded: its report.
    Recorded(Box<PartReport>),
    /// A reading already used: not learned again.
    Repeated,
    /// Failed the checks: never learned from.
    Rejected {
        reason: camloop_core::measure::MeasurementError,
    },
    /// Could not be recorded: the source keeps it.
    NotRecorded,
    /// Could not be analysed.
    Failed { reason: String },
    /// A table order's outcome: the records it leaves for the caller to keep with its own.
    Table(Result<TableDone, DeliveryError>),
    /// A waiting version reached the control on a retry.
    ShareBack { version: TableVersion },
    /// A start's reconciliation is done (a step cut short finished with it): what it did.
    Resumed(Box<ResumeReport>),
    /// A dressing moved the correction (its table's way follows, when it made one).
    Dressed(DressingDone),
    /// A part ground but not gauged.
    NotGauged(NotGaugedDone),
    /// Learning frozen or unfrozen; the reason before.
    Frozen { before: Option<String> },
    /// A tick's retry did not reach the control: the version still waits, for this reason.
    StillWaiting {
        version: TableVersion,
        reason: String,
    },
}

/// Why a table was not delivered, typed so the API answers each case with its own code.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DeliveryError {
    /// A rule refused the table (it cannot be rendered): nothing was changed.
    #[error("{reason}")]
    Refused { reason: String },
    /// The journal could not keep the table's record: nothing was submitted.
    #[error("the journal cannot be written: {reason}")]
    Journal { reason: String },
    /// Another instance of the cluster owns the machine now.
    #[error("another instance owns this machine now: {reason}")]
    FencedOut { reason: String },
    /// The share's state folder could not be written or read.
    #[error("share state folder: {reason}")]
    ShareState { reason: String },
    /// The share numbered or delivered another version than this one.
    #[error("{reason}")]
    Failed { reason: String },
}

/// Where the machine is in the work of one input.
#[derive(Debug, Default)]
enum Phase {
    #[default]
    Idle,
    /// A part decided without a table: its write, then its report.
    Recording {
        ticket: Ticket,
        part: Box<part::PartStep>,
        memory: Box<LoopMemory>,
    },
    /// A table's way to the control.
    Table(Box<table::Delivery>),
    /// A waiting version delivered again on a tick.
    Retrying(TableVersion),
    /// A start reconciling the journal with the share.
    Resuming(Box<resume::Resuming>),
}

/// One feature's loop (see the module doc).
#[derive(Debug)]
pub struct FeatureMachine {
    config: FeatureConfig,
    memory: LoopMemory,
    effects: VecDeque<Effect>,
    phase: Phase,
    next_ticket: u64,
}

impl FeatureMachine {
    /// A machine resuming from `memory` with nothing in flight (see [`Self::resume`] for one
    /// rebuilt from its journal).
    pub fn new(config: FeatureConfig, memory: LoopMemory) -> Self {
        Self {
            config,
            memory,
            effects: VecDeque::new(),
            phase: Phase::Idle,
            next_ticket: 0,
        }
    }

    /// What the loop remembers.
    pub fn memory(&self) -> &LoopMemory {
        &self.memory
    }

    /// The memory for the shell's own writes that are not yet the machine's (a rollback's
    /// adoption, the share's reconciliation at start); never while an input is in flight.
    pub fn memory_mut(&mut self) -> &mut LoopMemory {
        &mut self.memory
    }

    pub fn config(&self) -> &FeatureConfig {
        &self.config
    }

    /// Whether an input is still being worked on (its effects not all answered).
    pub fn busy(&self) -> bool {
        !matches!(self.phase, Phase::Idle)
    }

    /// The next effect to carry out, in order.
    pub fn poll_effect(&mut self) -> Option<Effect> {
        self.effects.pop_front()
    }

    /// Takes one input. A new measurement or table while another is in flight is refused
    /// as failed: the shell drives one input to its end before the next.
    pub fn handle(&mut self, input: Input<'_>) {
        match input {
            Input::Gauged(g) if !self.busy() => self.on_gauged(*g),
            Input::Table(order) if !self.busy() => self.start_table(*order, None),
            Input::Dressed(d) if !self.busy() => self.on_dressed(*d),
            Input::NotGauged { part, lobe, at } if !self.busy() => {
                self.on_not_gauged(part, lobe, at)
            }
            Input::Freeze { frozen, at } if !self.busy() => self.on_freeze(frozen, at),
            Input::Tick if !self.busy() => self.on_tick(),
            // The retry waits for the next tick: the input in flight is not disturbed.
            Input::Tick => {}
            Input::Gauged(_)
            | Input::Table(_)
            | Input::Dressed(_)
            | Input::NotGauged { .. }
            | Input::Freeze { .. } => self.finish(Finished::Failed {
                reason: "the feature's loop is still working on the previous input".into(),
            }),
            Input::Journalled(ticket) => self.on_journalled(ticket),
            Input::JournalFailed {
                ticket,
                fenced_out,
                reason,
            } => self.on_journal_failed(ticket, fenced_out, reason),
            other if matches!(self.phase, Phase::Retrying(_)) => self.on_retry_answer(other),
            other if matches!(self.phase, Phase::Resuming(_)) => self.on_resume_input(other),
            other => self.on_table_input(other),
        }
    }

    fn ticket(&mut self) -> Ticket {
        self.next_ticket += 1;
        Ticket(self.next_ticket)
    }

    /// Asks for a journal write; returns its ticket.
    fn journal(&mut self, records: Vec<Record>) -> Ticket {
        let ticket = self.ticket();
        self.effects.push_back(Effect::Journal { ticket, records });
        ticket
    }

    fn finish(&mut self, finished: Finished) {
        self.effects.push_back(Effect::Finished(finished));
    }

    /// Writes `records` (if any) and then finishes with `then`; the machine is free again
    /// once the shell has the effects (a closing write's failure changes nothing decided).
    fn close(&mut self, records: Vec<Record>, then: Finished) {
        if !records.is_empty() {
            self.journal(records);
        }
        self.phase = Phase::Idle;
        self.finish(then);
    }

    fn on_journalled(&mut self, ticket: Ticket) {
        match std::mem::take(&mut self.phase) {
            Phase::Recording {
                ticket: t,
                part,
                memory,
            } if t == ticket => {
                self.memory = *memory;
                self.part_recorded(*part);
            }
            Phase::Table(d) => self.table_journalled(d, ticket),
            other => self.phase = other,
        }
    }

    fn on_journal_failed(&mut self, ticket: Ticket, fenced_out: bool, reason: String) {
        match std::mem::take(&mut self.phase) {
            Phase::Recording { ticket: t, .. } if t == ticket => {
                self.part_not_recorded();
            }
            Phase::Table(d) => self.table_journal_failed(d, ticket, fenced_out, reason),
            other => self.phase = other,
        }
    }
}
