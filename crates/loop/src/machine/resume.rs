//! A machine rebuilt after a stop from what its journal kept, reconciled with the share's
//! manifest: every decision of a start is here, and the shell only gathers the inputs (the
//! journal's records, the manifest, the store's record of a version the journal no longer
//! holds) and carries out the effects. A version's record is journalled before the share
//! hears of it, so whenever the process died:
//! - a status the share gave and the journal never took (pushed, refused) is written now;
//! - a version journalled and never submitted is submitted now, in order, as the number its
//!   record holds (nothing can have reached the share after it); one the share would number
//!   otherwise is refused with why;
//! - a version the share holds beyond what the memory knows is adopted with the correction
//!   its record (journal, else store) was made from: waiting if the share has it waiting, in
//!   force if the share pushed it; without a record, with the correction in force;
//! - a part's step cut short between its write-ahead and the share's answer is finished:
//!   its table delivered once the share holds it (a table settled as waiting, of a share
//!   outage, is left to the shell's retry).

use super::table::{Delivery, Program, TableOrder};
use super::{Effect, FeatureConfig, FeatureMachine, Finished, Input, Phase};
use crate::memory::{LoopMemory, TableLearning, WaitingTable};
use crate::record::{EventKind, Kept, Record, TableRecord, TableStatus};
use camloop_core::ids::TableVersion;
use camloop_core::learn::LearningState;
use camloop_core::levels::EventLevel;
use jiff::Timestamp;
use std::collections::{BTreeMap, VecDeque};

/// The note of a status taken from the share's manifest at start.
pub const FROM_THE_MANIFEST: &str = "pushed to the share (its manifest, read at start)";

/// What the share's manifest says of one version.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OnShare {
    /// Accepted and not on the control (waiting, delivering, superseded).
    Accepted,
    /// On the control, verified.
    Pushed,
    /// Never pushed, for this reason.
    Refused { reason: String },
}

/// What the share holds for the feature, as its manifest says at start.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShareView {
    /// The number the share gives the next version it accepts.
    pub next_version: TableVersion,
    /// The newest version it pushed (on the control).
    pub pushed: Option<TableVersion>,
    /// The version it would deliver next (accepted, not pushed), if any.
    pub waiting: Option<TableVersion>,
    /// What it says of the versions it remembers (any it forgot are simply absent).
    pub versions: BTreeMap<TableVersion, OnShare>,
}

/// What a start did, for the shell's log.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ResumeReport {
    /// Statuses taken from the share's manifest: the version and the status's name.
    pub settled: Vec<(TableVersion, &'static str)>,
    /// Versions journalled before the stop and submitted now.
    pub submitted: Vec<TableVersion>,
    /// Versions journalled before the stop that the share did not take, with why.
    pub refused: Vec<(TableVersion, String)>,
    /// A version the share holds waiting that the memory did not know; `true` when a record
    /// said what it was made from.
    pub adopted_waiting: Option<(TableVersion, bool)>,
    /// The version in force taken from the share (the memory's before it); `false` when no
    /// record said what it was made from (learning goes on from the memory's correction).
    pub in_force_from_share: Option<(TableVersion, Option<TableVersion>, bool)>,
    /// The share's state folder failed while the start submitted: the start cannot go on.
    pub failed: Option<String>,
    /// The step cut short could not be delivered, for this reason: it waits for the retry.
    pub not_delivered: Option<String>,
}

/// A start in progress: the journalled versions still to submit, what the share will
/// number next, and what it came to so far.
#[derive(Debug)]
pub(super) struct Resuming {
    records: Vec<Kept>,
    share: ShareView,
    /// Records of versions the journal no longer holds, found elsewhere (the store).
    found: BTreeMap<TableVersion, TableLearning>,
    to_submit: VecDeque<TableRecord>,
    /// The record being submitted.
    submitting: Option<TableRecord>,
    out: Vec<Record>,
    report: ResumeReport,
    at: Timestamp,
}

impl FeatureMachine {
    /// The versions whose record [`Self::resume`] (with the same `records`, `fallback` and
    /// `share`) will need and `records` (the feature's journal) do not hold: the shell looks
    /// them up elsewhere (the store) and hands in those it finds. Only a version the share
    /// holds beyond what the memory knows is wanted, so a start in order asks for nothing.
    pub fn records_wanted(
        records: &[Kept],
        fallback: &LoopMemory,
        share: &ShareView,
    ) -> Vec<TableVersion> {
        let resumed = LoopMemory::resume(records);
        let memory = resumed.as_ref().unwrap_or(fallback);
        let in_force = memory.in_force_version;
        let known = memory.waiting.as_ref().map(|w| w.version);
        let waiting = share.waiting.filter(|w| Some(*w) > in_force);
        let pushed = share.pushed.filter(|p| Some(*p) != in_force);
        let mut wanted: Vec<TableVersion> = [waiting, pushed]
            .into_iter()
            .flatten()
            .filter(|v| Some(*v) != known && table_record(records, *v).is_none())
            .collect();
        wanted.sort();
        wanted.dedup();
        wanted
    }

    /// The machine `records` (the feature's journal, oldest first) leave, `fallback` when
    /// they hold no memory, reconciled with the share (see the module doc) through the
    /// effects it queues; `found` holds the records of [`Self::records_wanted`] the shell
    /// found. Its work ends with [`Finished::Resumed`].
    pub fn resume(
        config: FeatureConfig,
        records: Vec<Kept>,
        fallback: LoopMemory,
        share: ShareView,
        found: BTreeMap<TableVersion, TableLearning>,
        at: Timestamp,
    ) -> Self {
        let memory = LoopMemory::resume(&records).unwrap_or(fallback);
        let mut machine = Self::new(config, memory);
        let mut to_submit: Vec<TableRecord> = records
            .iter()
            .filter_map(|r| match r {
                Kept::Table(t) if t.version >= share.next_version => Some((**t).clone()),
                _ => None,
            })
            .collect();
        to_submit.sort_by_key(|t| t.version);
        let mut resuming = Box::new(Resuming {
            out: settle_statuses(&records, &share, at),
            records,
            share,
            found,
            to_submit: to_submit.into(),
            submitting: None,
            report: ResumeReport::default(),
            at,
        });
        resuming.report.settled = resuming
            .out
            .iter()
            .filter_map(|r| match r {
                Record::Status {
                    version, status, ..
                } => Some((*version, status.name())),
                _ => None,
            })
            .collect();
        machine.submit_next(resuming);
        machine
    }

    /// Submits the next journalled version the share never heard of; reconciles the
    /// memory once none is left.
    fn submit_next(&mut self, mut r: Box<Resuming>) {
        while let Some(record) = r.to_submit.pop_front() {
            let next = r.share.next_version;
            if record.version == next {
                self.effects
                    .push_back(Effect::Submit(Box::new(record.clone())));
                r.submitting = Some(record);
                self.phase = Phase::Resuming(r);
                return;
            }
            let reason = format!(
                "journalled as v{} but the share is at v{next}",
                record.version
            );
            self.refused_at_resume(&mut r, record.version, reason);
        }
        self.reconcile(r);
    }

    /// The share's answers to a start's submissions.
    pub(super) fn on_resume_input(&mut self, input: Input<'_>) {
        let Phase::Resuming(mut r) = std::mem::take(&mut self.phase) else {
            return;
        };
        let Some(record) = r.submitting.take() else {
            self.phase = Phase::Resuming(r);
            return;
        };
        match input {
            Input::Submitted {
                version,
                outcome: Ok(()),
            } if version == record.version => {
                r.report.submitted.push(version);
                r.share.next_version = version.next();
                r.share.waiting = Some(version);
                r.share.versions.insert(version, OnShare::Accepted);
            }
            Input::Submitted {
                version,
                outcome: Ok(()),
            } => {
                let reason = format!(
                    "the share numbered the version {version}, its record says {}",
                    record.version
                );
                r.share.next_version = version.next();
                self.refused_at_resume(&mut r, record.version, reason);
            }
            Input::Submitted {
                outcome: Err(reason),
                ..
            }
            | Input::ShareRefused { reason, .. } => {
                self.refused_at_resume(&mut r, record.version, reason)
            }
            Input::ShareFailed { reason, .. } => {
                // Nothing more can be submitted: the start stops here, nothing reconciled.
                r.report.failed = Some(reason);
                let report = r.report;
                self.close(r.out, Finished::Resumed(Box::new(report)));
                return;
            }
            _ => {
                // Not an answer to the submission: it is still awaited.
                r.submitting = Some(record);
                self.phase = Phase::Resuming(r);
                return;
            }
        }
        self.submit_next(r);
    }

    /// A journalled version the share did not take at start: refused, and no longer waiting.
    fn refused_at_resume(&mut self, r: &mut Resuming, version: TableVersion, reason: String) {
        r.out.push(Record::Status {
            version,
            status: TableStatus::Refused {
                reason: reason.clone(),
            },
            at: r.at,
        });
        r.out.push(Record::event(
            r.at,
            EventLevel::Error,
            EventKind::TableRefused,
            format!("{} v{version}: {reason}", self.config.feature),
        ));
        r.share.versions.insert(
            version,
            OnShare::Refused {
                reason: reason.clone(),
            },
        );
        r.report.refused.push((version, reason));
    }

    /// The memory made to agree with the share, then the step a stop cut short finished.
    fn reconcile(&mut self, mut r: Box<Resuming>) {
        let before = self.memory.clone();
        // The memory's waiting version, refused by the share: it never reaches the control.
        let refused = |v: &WaitingTable| {
            matches!(
                r.share.versions.get(&v.version),
                Some(OnShare::Refused { .. })
            )
        };
        self.memory.waiting.take_if(|w| refused(w));
        self.adopt_waiting(&mut r);
        self.adopt_pushed(&mut r);
        if self.memory != before {
            r.out.push(self.learning_record(r.at));
        }
        let report = Box::new(std::mem::take(&mut r.report));
        let Some(delivery) = self.cut_short(&r) else {
            return self.close(r.out, Finished::Resumed(report));
        };
        if !r.out.is_empty() {
            self.journal(std::mem::take(&mut r.out));
        }
        self.effects.push_back(delivery.next_effect());
        self.phase = Phase::Table(Box::new(delivery.with_report(report)));
    }

    /// A version the share holds waiting, newer than the one in force and not the memory's
    /// waiting one, waits in the memory with the correction it was made from.
    fn adopt_waiting(&mut self, r: &mut Resuming) {
        let Some(w) = r.share.waiting else { return };
        let known = self.memory.waiting.as_ref().map(|w| w.version);
        if Some(w) <= self.memory.in_force_version || known == Some(w) {
            return;
        }
        let made_from = made_from(r, w);
        let memory = &mut self.memory;
        memory.waiting = Some(match &made_from {
            Some(t) => WaitingTable {
                version: w,
                learning: adopt(&memory.learning, t),
                wheel_radius_mm: t.wheel_radius_mm,
                // Not known here: a start after its delivery makes it again.
                va_speed_rpm: None,
            },
            // As made from the correction in force, so the retry delivers it like any other.
            None => WaitingTable {
                version: w,
                learning: memory.learning.clone(),
                wheel_radius_mm: memory.wheel_radius_mm,
                va_speed_rpm: memory.in_force_va_speed_rpm,
            },
        });
        r.report.adopted_waiting = Some((w, made_from.is_some()));
    }

    /// The share pushed another version than the memory's in force: the share is the
    /// authority, and the correction in force is the one that table was made from.
    fn adopt_pushed(&mut self, r: &mut Resuming) {
        let in_force = self.memory.in_force_version;
        let Some(p) = r.share.pushed.filter(|p| Some(*p) != in_force) else {
            return;
        };
        let known = self.memory.waiting.as_ref().map(|w| w.version) == Some(p);
        let with_record = known || {
            let made_from = made_from(r, p);
            if let Some(t) = &made_from {
                self.memory.learning = adopt(&self.memory.learning, t);
            }
            made_from.is_some()
        };
        self.memory.delivered(p);
        // A waiting version older than the one pushed was superseded on the share.
        self.memory.waiting.take_if(|w| w.version < p);
        r.report.in_force_from_share = Some((p, in_force, with_record));
    }

    /// The step a stop cut short between its write-ahead and the share's answer: the
    /// memory's waiting version, held by the share and not pushed, with its record and no
    /// status after it.
    fn cut_short(&self, r: &Resuming) -> Option<Delivery> {
        let waiting = self.memory.waiting.as_ref()?;
        let v = waiting.version;
        let settled = r
            .records
            .iter()
            .any(|k| matches!(k, Kept::Status { version, .. } if *version == v));
        if settled || r.share.waiting != Some(v) {
            return None;
        }
        let record = table_record(&r.records, v)?.clone();
        let order = TableOrder {
            program: Program::Text {
                text: record.program_text.clone(),
                table_number: record.table_number,
            },
            next: Box::new(waiting.learning.clone()),
            reason: record.reason.clone(),
            measurement: record.measurement,
            rollback_of: record.rollback_of,
            learning: Some(record.learning.clone()),
            at: record.at,
        };
        Some(Delivery::resumed(order, record, self.memory.clone()))
    }
}

/// A status the share's manifest gives (pushed, refused) for each version whose newest
/// status in the journal is another: the process died between the answer and its record.
fn settle_statuses(records: &[Kept], share: &ShareView, at: Timestamp) -> Vec<Record> {
    let mut journalled = BTreeMap::new();
    for r in records {
        match r {
            Kept::Table(t) => journalled.insert(t.version, t.status.name()),
            Kept::Status { version, status } => journalled.insert(*version, status.name()),
            _ => None,
        };
    }
    journalled
        .into_iter()
        .filter_map(|(version, said)| {
            let status = match share.versions.get(&version)? {
                OnShare::Pushed => TableStatus::Pushed {
                    note: FROM_THE_MANIFEST.into(),
                },
                OnShare::Refused { reason } => TableStatus::Refused {
                    reason: reason.clone(),
                },
                OnShare::Accepted => return None,
            };
            (status.name() != said).then_some(Record::Status {
                version,
                status,
                at,
            })
        })
        .collect()
}

/// The newest write-ahead record of `version` in the journal.
fn table_record(records: &[Kept], version: TableVersion) -> Option<&TableRecord> {
    records.iter().rev().find_map(|r| match r {
        Kept::Table(t) if t.version == version => Some(t.as_ref()),
        _ => None,
    })
}

/// What `version` was made from: its journal record, else the one found elsewhere.
fn made_from(r: &Resuming, version: TableVersion) -> Option<TableLearning> {
    table_record(&r.records, version)
        .map(|t| t.learning.clone())
        .or_else(|| r.found.get(&version).cloned())
}

/// `state` with the correction (lift and timing) of a table's learning, when it is for the
/// same number of points.
pub fn adopt(state: &LearningState, table: &TableLearning) -> LearningState {
    let mut next = state.clone();
    if table.correction_um.len() == next.correction_um.len() {
        next.correction_um = table.correction_um.clone();
        next.timing_correction_deg = table.timing_correction_deg;
        next.iteration = table.iteration;
    }
    next
}
