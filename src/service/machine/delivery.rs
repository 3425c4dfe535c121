//! Tables to the control, the shell's half: a table order handed to the feature's machine
//! (which writes it ahead, submits and delivers it, and keeps which version is in force),
//! the share's request with the main program beside the table program, provenance, retries.

use super::super::journal::{EventKind, Pending};
use super::FeatureLoop;
use super::MachineError;
use super::memory::TableLearning;
use super::records::{self, event};
use crate::clock::now;
use crate::core::compensate::GuardedTable;
use crate::core::digest::Sha256;
use crate::core::learn::LearningState;
use crate::core::program::{Provenance, expected_program_files};
use crate::share::{ProgramFile, PushRequest};
use crate::store::{EventLevel, VersionStatus};
use camloop_loop::machine::{DeliveryError, Finished, Program, TableDone, TableOrder};
use camloop_loop::{Input, TableVersion};
use std::sync::atomic::Ordering;
use tracing::{error, info, warn};

/// A table version before the share numbers it: what its journal record and its push
/// request are both made from.
pub(super) struct Draft {
    /// The table program's text.
    pub(super) text: String,
    pub(super) table_number: u32,
    pub(super) learning: TableLearning,
    pub(super) reason: String,
    pub(super) measurement_id: Option<Sha256>,
    pub(super) rollback_of: Option<TableVersion>,
    pub(super) at: jiff::Timestamp,
}

impl FeatureLoop {
    /// Delivers `table` (made from `next`) through the feature's machine: rendered for the
    /// next table number with its provenance, written ahead, submitted (with the main
    /// program when the share's copy differs) and delivered. `next` is in force once the
    /// share confirms the table, waiting otherwise. Returns the records to keep; an error
    /// means nothing was submitted to the share (the journal or the state folder could not
    /// be written, or the table cannot be rendered).
    pub(super) async fn deliver(
        &mut self,
        table: &GuardedTable,
        next: LearningState,
        reason: &str,
        measurement: Option<Sha256>,
    ) -> Result<Vec<Pending>, MachineError> {
        let order = TableOrder {
            program: Program::Table {
                table: Box::new(table.clone()),
                planned: None,
            },
            next: Box::new(next),
            reason: reason.to_string(),
            measurement,
            rollback_of: None,
            learning: None,
            at: now(),
        };
        let (_, _, records) = self.deliver_order(order).await?;
        Ok(records)
    }

    /// A table order through the feature's machine: its version, status and the records
    /// to keep with the caller's own.
    pub(super) async fn deliver_order(
        &mut self,
        order: TableOrder,
    ) -> Result<(TableVersion, VersionStatus, Vec<Pending>), MachineError> {
        let at = order.at;
        self.machine.handle(Input::Table(Box::new(order)));
        let done = self
            .run_machine(None)
            .await
            .into_iter()
            .find_map(|f| match f {
                Finished::Table(done) => Some(done),
                _ => None,
            })
            .ok_or_else(|| MachineError::Failed {
                reason: "the feature's loop ended a table order without its outcome".into(),
            })??;
        let records = records::pending(&self.name, &self.setup.name, done.records, None);
        Ok((done.version, records::status(done.status, at), records))
    }

    /// The records a table's way left for the caller to keep with its own, or why it failed.
    pub(super) fn table_records(
        &self,
        done: Result<TableDone, DeliveryError>,
    ) -> Result<Vec<Pending>, MachineError> {
        let done = done?;
        Ok(records::pending(
            &self.name,
            &self.setup.name,
            done.records,
            None,
        ))
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

    /// The share's request for a draft: the table program, then the main program when the
    /// share's copy is not this text.
    pub(super) fn request(&self, draft: Draft) -> anyhow::Result<PushRequest> {
        let mut files = self.table_files(draft.text)?;
        files.extend(self.main_program_if_changed()?);
        // A same-part finish table: the handshake's count last, so the control never sees
        // the count move before the table is there.
        files.extend(
            self.main
                .ready
                .as_ref()
                .and_then(|r| r.file_for(&self.setup.name)),
        );
        Ok(PushRequest {
            files,
            table_number: draft.table_number,
            reason: draft.reason,
            measurement_id: draft.measurement_id,
            learning: serde_json::to_value(draft.learning.summary())?,
            rollback_of: draft.rollback_of,
            created_at: draft.at,
        })
    }

    /// A version's table programs: its one text, or with the plan in the whole cycle the
    /// constant-speed program and the plan's, in that order (each must be the file its
    /// feature's program calls: a text that says otherwise is never pushed).
    fn table_files(&self, text: String) -> anyhow::Result<Vec<ProgramFile>> {
        if !self.setup.plan_in_whole_cycle() {
            return Ok(vec![ProgramFile {
                name: self.program_file.clone(),
                text,
            }]);
        }
        let plan_file = format!(
            "{}.SPF",
            crate::recipe::plan_program_name(&self.setup.program.name)
        );
        let files = expected_program_files(&text, &[self.program_file.as_str(), &plan_file])
            .map_err(|e| anyhow::anyhow!("{}: the version's programs: {e}", self.setup.label))?;
        Ok(files
            .into_iter()
            .map(|f| ProgramFile {
                name: f.file,
                text: f.text.to_string(),
            })
            .collect())
    }

    /// A table reached the control: the simulator's wheel, the main program's speed, the
    /// metrics.
    pub(super) fn on_delivered(&self, wheel_radius_mm: f64) {
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
        let number = |v: TableVersion| {
            self.share
                .history()
                .get(v)
                .map_or(String::new(), |s| format!(" (T{})", s.record.table_number))
        };
        let memory = self.machine.memory();
        let in_force = memory.in_force_version;
        let shown = in_force.map_or(0, TableVersion::get);
        let number_in_force = in_force.map_or(String::new(), number);
        match &memory.waiting {
            Some(w) => format!(
                "table v{}{} waiting for the share (v{shown} in force)",
                w.version,
                number(w.version),
            ),
            None => format!("table v{shown}{number_in_force} pushed"),
        }
    }

    /// What the program says about itself, for the operator reading it on the control (the
    /// C offset and direction are on its axes line).
    pub(super) fn provenance(
        &self,
        version: TableVersion,
        parent: Option<TableVersion>,
        learning: &TableLearning,
    ) -> Provenance {
        Provenance {
            camloop_version: env!("CARGO_PKG_VERSION").to_string(),
            table_version: version.get(),
            parent_version: parent.map(|v| v.get()),
            created_utc: crate::clock::utc_text(crate::clock::now()),
            recipe: self.setup.part.to_string(),
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

    /// Delivers the version waiting for the share, if any (the machine's retry, on a tick);
    /// once it is there its learning state is the one in force.
    pub(super) async fn deliver_waiting(&mut self) {
        self.machine.handle(Input::Tick);
        for f in self.run_machine(None).await {
            match f {
                Finished::ShareBack { version } => {
                    info!(machine = %self.name, version = version.get(), "controller share: waiting table delivered, learning resumes from it");
                }
                Finished::StillWaiting { version, reason } => {
                    warn!(machine = %self.name, version = version.get(), error = %reason, "controller share still unavailable");
                }
                _ => {}
            }
        }
    }
}
