//! Tables to the control: rendering with provenance, the push, the main program beside the
//! table program, retries, and which version is in force.

use super::super::journal::{EventKind, Pending};
use super::FeatureLoop;
use super::MachineError;
use super::memory::{TableLearning, WaitingTable};
use super::records::event;
use crate::clock::now;
use crate::core::compensate::GuardedTable;
use crate::core::digest::Sha256;
use crate::core::learn::LearningState;
use crate::core::program::{Provenance, comment_text};
use crate::failpoint::crash_point;
use crate::share::{ProgramFile, PushError, PushRequest, Submitted};
use crate::store::{EventLevel, VersionStatus};
use std::sync::atomic::Ordering;
use tracing::{error, info, warn};

/// Why a version's first record says "waiting": it is written before the share hears of it.
pub(super) const SUBMITTED: &str = "submitted to the share";

/// A table version before the share numbers it: what its journal record and its push
/// request are both made from.
pub(super) struct Draft {
    /// The table program's text.
    pub(super) text: String,
    pub(super) table_number: u32,
    pub(super) learning: TableLearning,
    pub(super) reason: String,
    pub(super) measurement_id: Option<Sha256>,
    pub(super) rollback_of: Option<u64>,
    pub(super) at_ms: jiff::Timestamp,
}

impl FeatureLoop {
    /// Renders `table` for the next table number with its provenance and delivers it (with
    /// the main program when the share's copy differs). `next` is the learning state the
    /// table was made from: it is in force once the share confirms the table, waiting
    /// otherwise. Returns the records to keep; an error means nothing was submitted to the
    /// share (the journal or the state folder could not be written).
    pub(super) async fn deliver(
        &mut self,
        table: &GuardedTable,
        next: LearningState,
        reason: &str,
        measurement: Option<Sha256>,
    ) -> Result<Vec<Pending>, MachineError> {
        let at_ms = now();
        let parent = self.memory.in_force_version;
        let version = self.share.history().next_version();
        let learning = TableLearning {
            iteration: next.iteration,
            params: self.setup.params.clone(),
            wheel_radius_mm: self.memory.wheel_radius_mm,
            correction_um: next.correction_um.clone(),
            timing_correction_deg: next.timing_correction_deg,
        };
        let mut settings = self.setup.program.clone();
        settings.table_number = self.share.next_table_number();
        settings.provenance = Some(self.provenance(version, parent, &learning));
        settings.comment_lines = vec![
            comment_text(&format!("reason: {reason}")),
            comment_text(&format!(
                "wheel radius {} mm, learning iteration {}",
                learning.wheel_radius_mm, learning.iteration
            )),
        ];
        let text = self
            .render_table(table, &next, &settings)
            .map_err(MachineError::refused)?;
        crash_point("table_rendered");
        let draft = Draft {
            text,
            table_number: settings.table_number,
            learning,
            reason: reason.to_string(),
            measurement_id: measurement,
            rollback_of: None,
            at_ms,
        };
        let (_, _, records) = self.push(draft, next)?;
        Ok(records)
    }

    /// One push attempt; the state in force follows what the share confirmed.
    ///
    /// Write-ahead: the version's record (status waiting) is in the journal before the
    /// share hears of it, so whenever the process dies the version is known with the
    /// correction it was made from ([`Self::reconcile_share`] finishes what was cut short).
    /// The records returned hold the outcome.
    pub(super) fn push(
        &mut self,
        draft: Draft,
        next: LearningState,
    ) -> Result<(u64, VersionStatus, Vec<Pending>), MachineError> {
        let version = self.share.history().next_version();
        let record = self.table_record(&draft, version);
        if let Err(e) = self.journal.append(std::slice::from_ref(&record)) {
            let reason =
                format!("{e:#}; the table version's record cannot be journalled: not submitted");
            return Err(self.journal_failed(reason));
        }
        let at_ms = draft.at_ms;
        let request = self.request(draft).map_err(MachineError::failed)?;
        let (status, mut records) = self.submit_and_deliver(request, version, next, at_ms)?;
        records.push(Pending::VersionStatus {
            machine: self.name.clone(),
            lobe: self.setup.name.clone(),
            version,
            status: status.clone(),
            at_ms,
        });
        Ok((version, status, records))
    }

    /// A write's records the journal did not keep: another instance owns the machine now
    /// (its fence moved), or the journal failed.
    pub(super) fn journal_failed(&self, reason: String) -> MachineError {
        if self.journal.fenced_out() {
            MachineError::FencedOut { reason }
        } else {
            MachineError::Journal { reason }
        }
    }

    /// The journal record of a version not yet submitted.
    fn table_record(&self, draft: &Draft, version: u64) -> Pending {
        let parent = self.memory.in_force_version;
        Pending::Table {
            machine: self.name.clone(),
            lobe: self.setup.name.clone(),
            version,
            parent_version: (parent > 0).then_some(parent),
            table_number: draft.table_number,
            program_text: draft.text.clone(),
            learning: draft.learning.clone(),
            reason: draft.reason.clone(),
            status: VersionStatus::Waiting {
                reason: Some(SUBMITTED.into()),
            },
            created_at_ms: draft.at_ms,
            measurement_id: draft.measurement_id,
            rollback_of: draft.rollback_of,
        }
    }

    /// The share's request for a draft: the table program, then the main program when the
    /// share's copy is not this text.
    pub(super) fn request(&self, draft: Draft) -> anyhow::Result<PushRequest> {
        let mut files = vec![ProgramFile {
            name: self.program_file.clone(),
            text: draft.text,
        }];
        files.extend(self.main_program_if_changed()?);
        Ok(PushRequest {
            files,
            table_number: draft.table_number,
            reason: draft.reason,
            measurement_id: draft.measurement_id,
            learning: serde_json::to_value(draft.learning.summary())?,
            rollback_of: draft.rollback_of,
            created_at_unix_ms: draft.at_ms,
        })
    }

    /// Submits `request` as `version` and delivers it: its status (with why), and the
    /// records of what happened on the way.
    fn submit_and_deliver(
        &mut self,
        request: PushRequest,
        version: u64,
        next: LearningState,
        at_ms: jiff::Timestamp,
    ) -> Result<(VersionStatus, Vec<Pending>), MachineError> {
        let mut records = Vec::new();
        let submitted = self
            .share
            .submit(request)
            .map_err(|e| MachineError::ShareState {
                reason: format!("{e:#}"),
            })?;
        match submitted {
            Submitted::Refused { reason, .. } => {
                error!(machine = %self.name, version, reason = %reason, "table version refused by the share");
                return Ok((VersionStatus::Refused { reason }, records));
            }
            Submitted::Accepted { version: v } if v != version => {
                return Err(MachineError::Failed {
                    reason: format!(
                        "the share numbered the version {v}, its record says {version}"
                    ),
                });
            }
            Submitted::Accepted { .. } => {}
        }
        match self.share.deliver() {
            Ok(Some(p)) if p.version == version => {
                self.memory.waiting = None;
                self.memory.learning = next;
                self.memory.in_force_version = version;
                self.on_delivered(self.memory.wheel_radius_mm);
                let pushed = VersionStatus::pushed_at(at_ms, "pushed to the share");
                Ok((pushed, records))
            }
            Err(PushError::Share { version, error: e }) => {
                self.hold_for_the_share(version, next, &e, at_ms, &mut records);
                let reason = Some(format!("waiting: {e}"));
                Ok((VersionStatus::Waiting { reason }, records))
            }
            Ok(other) => Err(MachineError::Failed {
                reason: format!(
                    "the share delivered {:?} instead of the version just submitted, {version}",
                    other.map(|p| p.version)
                ),
            }),
            Err(PushError::Refused { reason, .. }) => {
                Ok((VersionStatus::Refused { reason }, records))
            }
            Err(PushError::State(e)) => Err(MachineError::ShareState {
                reason: format!("{e:#}"),
            }),
        }
    }

    /// The share cannot take `version`: it waits (with the learning state it was made from)
    /// while parts go on being ground and learned from the table in force.
    fn hold_for_the_share(
        &mut self,
        version: u64,
        next: LearningState,
        e: &dyn std::fmt::Display,
        at_ms: jiff::Timestamp,
        records: &mut Vec<Pending>,
    ) {
        // Parts ground while the learning's tables cannot reach the control say
        // nothing about the learning: the divergence guard's history restarts, or
        // the wear of the outage (and a dressing in it) would be taken for the
        // learning diverging as soon as the share is back.
        self.memory.learning.recent_max_error_um.clear();
        if self.memory.waiting.is_none() {
            // Said once per outage, not per part.
            error!(machine = %self.name, error = %e, in_force = self.memory.in_force_version, "controller share: table not delivered; learning holds on the table in force");
            let message = format!(
                "{e}: parts are ground with v{} and learned from it alone until the share takes v{version} or a newer table",
                self.memory.in_force_version
            );
            records.push(event(
                &self.name,
                at_ms,
                EventLevel::Error,
                EventKind::ShareUnavailable,
                message,
            ));
            self.metrics.update(&self.name, |m| m.alarms_total += 1);
        }
        self.memory.waiting = Some(WaitingTable {
            version,
            learning: next,
            wheel_radius_mm: self.memory.wheel_radius_mm,
        });
        self.metrics.update(&self.name, |m| {
            m.share_waiting = 1;
            m.learning_held = 1;
        });
    }

    fn on_delivered(&self, wheel_radius_mm: f64) {
        self.table_wheel_radius_bits
            .store(wheel_radius_mm.to_bits(), Ordering::SeqCst);
        // The main program pairs each feature's table with the VA speed it was made for.
        if let Some(rpm) = self.va_speed_delivered(wheel_radius_mm)
            && let Err(e) = self.main.delivered(&self.setup.name, rpm)
        {
            error!(machine = %self.name, error = format!("{e:#}"), "main program: the plan's speed not kept");
        }
        self.metrics.update(&self.name, |m| {
            m.tables_pushed_total += 1;
            m.share_waiting = 0;
            m.learning_held = 0;
        });
    }

    /// The log's word on the newest delivery.
    pub(super) fn delivery_line(&self) -> String {
        let number = |v: u64| {
            self.share
                .history()
                .get(v)
                .map_or(String::new(), |s| format!(" (T{})", s.record.table_number))
        };
        match &self.memory.waiting {
            Some(w) => format!(
                "table v{}{} waiting for the share (v{} in force)",
                w.version,
                number(w.version),
                self.memory.in_force_version
            ),
            None => format!(
                "table v{}{} pushed",
                self.memory.in_force_version,
                number(self.memory.in_force_version)
            ),
        }
    }

    /// What the program says about itself, for the operator reading it on the control (the
    /// C offset and direction are on its axes line).
    pub(super) fn provenance(
        &self,
        version: u64,
        parent: u64,
        learning: &TableLearning,
    ) -> Provenance {
        Provenance {
            camloop_version: env!("CARGO_PKG_VERSION").to_string(),
            table_version: version,
            parent_version: (parent > 0).then_some(parent),
            created_utc: crate::clock::utc_text(crate::clock::now()),
            recipe: self.setup.part.clone(),
            feature: self.setup.name.clone(),
            correction_sha256: crate::core::turn::correction_sha256(&learning.correction_um),
        }
    }

    /// The main program, when the share's copy is not this text (written again only when it
    /// changes, so the control runs what camloop tested). It calls every feature's table
    /// program, so it goes with the last of them to reach the share.
    pub(super) fn main_program_if_changed(&self) -> anyhow::Result<Option<ProgramFile>> {
        let dir = &self.share.config().share_dir;
        let Some(text) = self
            .main
            .text_with(&self.setup.name, self.plan.pending_va_rpm)?
        else {
            // With the plan: a feature's table (and its speed) is not on the share yet.
            return Ok(None);
        };
        let on_share = std::fs::read_to_string(dir.join(&self.main.file)).ok();
        if on_share.as_deref() == Some(text.as_str()) {
            return Ok(None);
        }
        let others_there = self
            .main
            .table_files
            .iter()
            .filter(|f| **f != self.program_file)
            .all(|f| dir.join(f).exists());
        Ok(others_there.then(|| ProgramFile {
            name: self.main.file.clone(),
            text,
        }))
    }

    /// Retries what waits: a version for the share, records for the database; and drops
    /// from the journal what the database now holds durably.
    pub async fn retry(&mut self) {
        if self.disk_alarm && self.journal.restore_reserve() {
            self.disk_alarm = false;
            info!(machine = %self.name, "disk space back: journal reserve restored, learning resumes");
            let e = event(
                &self.name,
                now(),
                EventLevel::Info,
                EventKind::DiskSpaceBack,
                "disk space back: journal reserve restored, learning resumes".into(),
            );
            self.record(vec![e]).await;
        }
        self.deliver_waiting().await;
        self.flush_journal().await;
        let store = self.store.read().await.clone();
        if let Some(store) = store
            && let Err(e) = self.journal.release_durable(&store).await
        {
            warn!(machine = %self.name, error = format!("{e:#}"), "database not confirmed durable: records stay in the journal");
        }
    }

    /// Delivers the version waiting for the share, if any; once it is there its learning
    /// state is the one in force.
    pub(super) async fn deliver_waiting(&mut self) {
        match self.share.deliver() {
            Ok(Some(p)) => {
                info!(machine = %self.name, version = p.version, "controller share: waiting table delivered, learning resumes from it");
                let at_ms = now();
                let radius = self.memory.delivered(p.version);
                self.on_delivered(radius.unwrap_or(self.memory.wheel_radius_mm));
                let records = vec![
                    Pending::VersionStatus {
                        machine: self.name.clone(),
                        lobe: self.setup.name.clone(),
                        version: p.version,
                        status: VersionStatus::pushed_at(at_ms, "pushed to the share on retry"),
                        at_ms,
                    },
                    event(
                        &self.name,
                        at_ms,
                        EventLevel::Info,
                        EventKind::ShareBack,
                        format!(
                            "share back: v{} delivered, learning resumes from it",
                            p.version
                        ),
                    ),
                    self.learning_record(at_ms),
                ];
                self.record(records).await;
            }
            Ok(None) => {}
            Err(e) => warn!(machine = %self.name, error = %e, "controller share still unavailable"),
        }
    }
}
