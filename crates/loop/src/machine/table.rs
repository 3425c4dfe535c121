//! A table's way to the control: rendered as the share will number it, written ahead (its
//! record, with the memory that has it waiting, in one journal write), submitted, delivered;
//! the state in force follows what the share confirmed. A part's table goes this way with
//! the part's records in the same write-ahead; a table the shell orders (a dressing, a part
//! not gauged, the start, a rollback) goes it alone.

use super::part::{PartNote, PartStep};
use super::resume::ResumeReport;
use super::{Alarm, DeliveryError, Effect, FeatureMachine, Finished, Input, Metric, Phase, Ticket};
use crate::memory::{LoopMemory, TableLearning, WaitingTable};
use crate::record::{EventKind, Record, SUBMITTED, TableRecord, TableStatus};
use camloop_core::compensate::GuardedTable;
use camloop_core::digest::Sha256;
use camloop_core::ids::TableVersion;
use camloop_core::learn::LearningState;
use camloop_core::levels::EventLevel;
use camloop_core::speed_plan::tables::VaTables;
use jiff::Timestamp;

/// The program of a table to deliver.
#[derive(Debug, Clone)]
pub enum Program {
    /// A guarded table to render for the share's next number (with the plan's tables over
    /// VA when the turn made them).
    Table {
        table: Box<GuardedTable>,
        planned: Option<Box<VaTables>>,
    },
    /// A program already written (a rollback re-pushes an old version's text).
    Text { text: String, table_number: u32 },
}

/// A table to deliver.
#[derive(Debug, Clone)]
pub struct TableOrder {
    pub program: Program,
    /// The learning state the table was made from: in force once the share confirms it.
    pub next: Box<LearningState>,
    pub reason: String,
    /// The measurement it was learned from.
    pub measurement: Option<Sha256>,
    /// The version it re-pushes (a rollback).
    pub rollback_of: Option<TableVersion>,
    /// What the version's record keeps of the learning; None: made from `next`, the
    /// recipe's parameters and the wheel believed now.
    pub learning: Option<TableLearning>,
    pub at: Timestamp,
}

/// What the shell renders (the share numbers it, the program carries its provenance).
#[derive(Debug, Clone)]
pub struct RenderOrder {
    pub program: Program,
    pub next: LearningState,
    pub learning: TableLearning,
    pub reason: String,
    /// The version in force when this one is made.
    pub parent: Option<TableVersion>,
    pub at: Timestamp,
}

/// A delivered (or waiting, or refused) table order: its version, its status, and the
/// records the caller keeps with its own.
#[derive(Debug)]
pub struct TableDone {
    pub version: TableVersion,
    pub status: TableStatus,
    pub records: Vec<Record>,
}

#[derive(Debug)]
enum Stage {
    Rendering,
    Ahead(Ticket),
    Submitting,
    Delivering,
}

/// A table on its way (see the module doc).
#[derive(Debug)]
pub(super) struct Delivery {
    stage: Stage,
    order: TableOrder,
    learning: TableLearning,
    parent: Option<TableVersion>,
    /// The memory once the table is written ahead (waiting for the share).
    memory: LoopMemory,
    /// What waited before this table: kept again when the share refuses it.
    waiting_before: Option<WaitingTable>,
    record: Option<TableRecord>,
    part: Option<Box<PartStep>>,
    /// A step a stop cut short, finished at resume (with what the start did so far): its
    /// records are the machine's to keep.
    resumed: Option<Box<ResumeReport>>,
}

impl Delivery {
    /// The table of a step cut short, written ahead and on the share already: to deliver.
    pub(super) fn resumed(order: TableOrder, record: TableRecord, memory: LoopMemory) -> Self {
        Self {
            stage: Stage::Delivering,
            learning: record.learning.clone(),
            parent: record.parent,
            order,
            memory,
            waiting_before: None,
            record: Some(record),
            part: None,
            resumed: Some(Box::default()),
        }
    }

    /// With what the start did before it.
    pub(super) fn with_report(mut self, report: Box<ResumeReport>) -> Self {
        self.resumed = Some(report);
        self
    }

    /// The effect that takes a resumed table on.
    pub(super) fn next_effect(&self) -> Effect {
        let record = self.record.clone().expect("a resumed table has its record");
        match self.stage {
            Stage::Delivering => Effect::Deliver {
                version: record.version,
            },
            _ => Effect::Submit(Box::new(record)),
        }
    }
}

impl FeatureMachine {
    /// Starts a table's way; `part` is the part it was learned from, with the memory its
    /// step leaves.
    pub(super) fn start_table(
        &mut self,
        order: TableOrder,
        part: Option<(Box<PartStep>, Box<LoopMemory>)>,
    ) {
        let (part, memory) = match part {
            Some((p, m)) => (Some(p), *m),
            None => (None, self.memory.clone()),
        };
        let learning = order.learning.clone().unwrap_or_else(|| {
            TableLearning::of(&order.next, &self.config.params, memory.wheel_radius_mm)
        });
        let render = RenderOrder {
            program: order.program.clone(),
            next: (*order.next).clone(),
            learning: learning.clone(),
            reason: order.reason.clone(),
            parent: memory.in_force_version,
            at: order.at,
        };
        self.effects.push_back(Effect::Render(Box::new(render)));
        self.phase = Phase::Table(Box::new(Delivery {
            stage: Stage::Rendering,
            parent: memory.in_force_version,
            waiting_before: memory.waiting.clone(),
            order,
            learning,
            memory,
            record: None,
            part,
            resumed: None,
        }));
    }

    /// The share's answers and the render's, for the table on its way.
    pub(super) fn on_table_input(&mut self, input: Input<'_>) {
        let Phase::Table(mut d) = std::mem::take(&mut self.phase) else {
            return;
        };
        match (&d.stage, input) {
            (
                Stage::Rendering,
                Input::Rendered {
                    version,
                    table_number,
                    text,
                    va_speed_rpm,
                },
            ) => self.rendered(d, version, (table_number, text), va_speed_rpm),
            (Stage::Rendering, Input::RenderFailed { reason }) => {
                self.not_delivered(d, DeliveryError::Refused { reason })
            }
            (Stage::Submitting, Input::Submitted { version, outcome }) => {
                let ours = d.record.as_ref().map(|r| r.version);
                match outcome {
                    Ok(()) if Some(version) == ours => {
                        self.effects.push_back(Effect::Deliver { version });
                        d.stage = Stage::Delivering;
                        self.phase = Phase::Table(d);
                    }
                    Ok(()) => {
                        let reason = format!(
                            "the share numbered the version {version}, its record says {}",
                            ours.map_or(0, TableVersion::get)
                        );
                        self.not_delivered(d, DeliveryError::Failed { reason })
                    }
                    Err(reason) => self.settled(d, TableStatus::Refused { reason }, Vec::new()),
                }
            }
            (Stage::Delivering, Input::Delivered { version, .. }) => {
                let ours = d.record.as_ref().map(|r| r.version);
                if Some(version) != ours {
                    let reason = format!(
                        "the share delivered {:?} instead of the version just submitted, {}",
                        Some(version.get()),
                        ours.map_or(0, TableVersion::get)
                    );
                    return self.not_delivered(d, DeliveryError::Failed { reason });
                }
                let radius = self.memory.delivered(version);
                let wheel_radius_mm = radius.unwrap_or(self.memory.wheel_radius_mm);
                self.effects
                    .push_back(Effect::Metric(Metric::TablePushed { wheel_radius_mm }));
                let note = "pushed to the share".to_string();
                self.settled(d, TableStatus::Pushed { note }, Vec::new());
            }
            (
                Stage::Delivering,
                Input::ShareUnavailable {
                    version, reason, ..
                },
            ) => {
                let records = self.hold_for_the_share(&d, version, &reason);
                let reason = Some(format!("waiting: {reason}"));
                self.settled(d, TableStatus::Waiting { reason }, records);
            }
            (Stage::Submitting | Stage::Delivering, Input::ShareRefused { reason, .. }) => {
                self.settled(d, TableStatus::Refused { reason }, Vec::new())
            }
            (Stage::Submitting | Stage::Delivering, Input::ShareFailed { state, reason }) => {
                let e = if state {
                    DeliveryError::ShareState { reason }
                } else {
                    DeliveryError::Failed { reason }
                };
                self.not_delivered(d, e)
            }
            // An answer to nothing asked: the table stays where it is.
            _ => self.phase = Phase::Table(d),
        }
    }

    /// The table is rendered: its record and the memory with it waiting go to the journal
    /// in one write (with the part's records, when a part made it).
    fn rendered(
        &mut self,
        mut d: Box<Delivery>,
        version: TableVersion,
        (number, text): (u32, String),
        va_speed_rpm: Option<f64>,
    ) {
        let record = TableRecord {
            version,
            parent: d.parent,
            table_number: number,
            program_text: text,
            learning: d.learning.clone(),
            reason: d.order.reason.clone(),
            status: TableStatus::Waiting {
                reason: Some(SUBMITTED.into()),
            },
            at: d.order.at,
            measurement: d.order.measurement,
            rollback_of: d.order.rollback_of,
        };
        d.memory.waiting = Some(WaitingTable {
            version,
            learning: (*d.order.next).clone(),
            wheel_radius_mm: d.memory.wheel_radius_mm,
            va_speed_rpm,
        });
        let mut records = d
            .part
            .as_mut()
            .map(|p| std::mem::take(&mut p.records))
            .unwrap_or_default();
        records.push(Record::Table(Box::new(record.clone())));
        records.push(Record::Learning {
            memory: Box::new(d.memory.clone()),
            at: d.order.at,
        });
        d.record = Some(record);
        d.stage = Stage::Ahead(self.journal(records));
        self.phase = Phase::Table(d);
    }

    /// The write-ahead is durable: the memory is the step's, and the share may hear.
    pub(super) fn table_journalled(&mut self, mut d: Box<Delivery>, ticket: Ticket) {
        if !matches!(d.stage, Stage::Ahead(t) if t == ticket) {
            self.phase = Phase::Table(d);
            return;
        }
        self.memory = d.memory.clone();
        if let Some(p) = d.part.as_mut() {
            self.effects.extend(std::mem::take(&mut p.effects));
        }
        let record = d
            .record
            .clone()
            .expect("a table written ahead has its record");
        self.effects.push_back(Effect::Submit(Box::new(record)));
        d.stage = Stage::Submitting;
        self.phase = Phase::Table(d);
    }

    /// The write-ahead failed: nothing was submitted; a part is not recorded at all.
    pub(super) fn table_journal_failed(
        &mut self,
        d: Box<Delivery>,
        ticket: Ticket,
        fenced_out: bool,
        reason: String,
    ) {
        if !matches!(d.stage, Stage::Ahead(t) if t == ticket) {
            self.phase = Phase::Table(d);
            return;
        }
        if d.part.is_some() {
            return self.part_not_recorded();
        }
        let reason =
            format!("{reason}; the table version's record cannot be journalled: not submitted");
        let e = if fenced_out {
            DeliveryError::FencedOut { reason }
        } else {
            DeliveryError::Journal { reason }
        };
        self.phase = Phase::Idle;
        self.finish(Finished::Table(Err(e)));
    }

    /// The share cannot take `version`: it waits (with the learning state it was made from)
    /// while parts go on being ground and learned from the table in force.
    fn hold_for_the_share(&mut self, d: &Delivery, version: TableVersion, e: &str) -> Vec<Record> {
        // Parts ground while the learning's tables cannot reach the control say nothing
        // about the learning: the divergence guard's history restarts, or the wear of the
        // outage (and a dressing in it) would be taken for the learning diverging as soon
        // as the share is back.
        self.memory.learning.recent_max_error_um.clear();
        self.effects.push_back(Effect::Metric(Metric::ShareWaiting));
        if d.waiting_before.is_some() {
            return Vec::new();
        }
        // Said once per outage, not per part.
        let in_force = self.memory.in_force_version.map_or(0, TableVersion::get);
        self.effects
            .push_back(Effect::Alarm(Alarm::ShareUnavailable {
                reason: e.to_string(),
            }));
        let message = format!(
            "{e}: parts are ground with v{in_force} and learned from it alone until the share takes v{version} or a newer table"
        );
        vec![Record::event(
            d.order.at,
            EventLevel::Error,
            EventKind::ShareUnavailable,
            message,
        )]
    }

    /// The share answered for good (pushed, waiting, refused): the version's status and
    /// `more` records close the work.
    fn settled(&mut self, mut d: Box<Delivery>, status: TableStatus, more: Vec<Record>) {
        let record = d.record.take().expect("a settled table was written ahead");
        if matches!(status, TableStatus::Refused { .. }) {
            // Never on the control: what waited before still waits.
            self.memory.waiting = d.waiting_before.take();
        }
        let mut records = more;
        records.push(Record::Status {
            version: record.version,
            status: status.clone(),
            at: d.order.at,
        });
        match d.part.take() {
            Some(part) => self.close_part(*part, records),
            None if d.resumed.is_some() => {
                records.push(self.learning_record(d.order.at));
                let report = d.resumed.take().unwrap_or_default();
                self.close(records, Finished::Resumed(report));
            }
            None => {
                self.phase = Phase::Idle;
                self.finish(Finished::Table(Ok(super::TableDone {
                    version: record.version,
                    status,
                    records,
                })));
            }
        }
    }

    /// The table did not get through (a rule, the share's state, the numbering): the memory
    /// is what it was before the table, and a part is recorded with the reason.
    fn not_delivered(&mut self, mut d: Box<Delivery>, e: DeliveryError) {
        let written = d.record.is_some();
        match d.part.take() {
            Some(mut part) if !written => {
                // Nothing was written yet: the part goes on without its table.
                part.note = PartNote::NotRecorded(e);
                let mut memory = d.memory;
                memory.waiting = d.waiting_before;
                self.record_part(*part, memory);
            }
            Some(mut part) => {
                part.note = PartNote::NotRecorded(e);
                self.memory.waiting = d.waiting_before.take();
                self.close_part(*part, Vec::new());
            }
            None if d.resumed.is_some() => {
                // A start's delivery that failed: the version still waits, for the retry.
                let mut report = d.resumed.take().unwrap_or_default();
                report.not_delivered = Some(e.to_string());
                self.close(Vec::new(), Finished::Resumed(report));
            }
            None => {
                let mut records = Vec::new();
                if written {
                    self.memory.waiting = d.waiting_before.take();
                    records.push(self.learning_record(d.order.at));
                }
                self.phase = Phase::Idle;
                if !records.is_empty() {
                    self.journal(records);
                }
                self.finish(Finished::Table(Err(e)));
            }
        }
    }

    /// A part whose table's way ended: the records of that, the memory it leaves, its report.
    fn close_part(&mut self, part: PartStep, mut records: Vec<Record>) {
        records.push(self.learning_record(part.at));
        self.journal(records);
        self.part_recorded(part);
    }

    pub(super) fn learning_record(&self, at: Timestamp) -> Record {
        Record::Learning {
            memory: Box::new(self.memory.clone()),
            at,
        }
    }

    /// A waiting version reached the control on the shell's retry: its state is in force.
    pub(super) fn delivered_on_retry(&mut self, version: TableVersion, at: Timestamp) {
        let radius = self.memory.delivered(version);
        let wheel_radius_mm = radius.unwrap_or(self.memory.wheel_radius_mm);
        self.effects
            .push_back(Effect::Metric(Metric::TablePushed { wheel_radius_mm }));
        let records = vec![
            Record::Status {
                version,
                status: TableStatus::Pushed {
                    note: "pushed to the share on retry".into(),
                },
                at,
            },
            Record::event(
                at,
                EventLevel::Info,
                EventKind::ShareBack,
                format!("share back: v{version} delivered, learning resumes from it"),
            ),
            self.learning_record(at),
        ];
        self.close(records, Finished::ShareBack { version });
    }
}
