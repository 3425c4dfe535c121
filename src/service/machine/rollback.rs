//! Rollback: a stored version delivered again as a new version under the table number not
//! in use, its correction restored. History is appended: the rollback is a new version.

use super::super::journal::EventKind;
use super::FeatureLoop;
use super::memory::TableLearning;
use super::records::event;
use crate::clock::now;
use crate::core::program::retarget_table_program;
use crate::names::{FeatureName, MachineName};
use crate::store::EventLevel;
use anyhow::Context;
use camloop_loop::TableVersion;
use camloop_loop::machine::{Program, TableOrder};
use tracing::info;

/// Why a rollback could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RollbackError {
    #[error("machine {machine} grinds {grinds}, not {asked}")]
    UnknownFeature {
        machine: MachineName,
        grinds: String,
        asked: FeatureName,
    },
    #[error("version {version} of {machine} {lobe} not found")]
    NotFound {
        machine: MachineName,
        lobe: FeatureName,
        version: TableVersion,
    },
    #[error("history store unavailable: cannot read the stored version")]
    StoreUnavailable,
    /// The new version's delivery failed (its journal, the share's state folder, …).
    #[error(transparent)]
    Delivery(#[from] super::MachineError),
    #[error(transparent)]
    Other(#[from] anyhow::Error),
}

/// What a rollback delivered.
#[derive(Debug, Clone, PartialEq)]
pub struct RolledBack {
    pub to_version: TableVersion,
    pub new_version: TableVersion,
    pub table_number: u32,
    pub summary: String,
}

impl FeatureLoop {
    /// Delivers the program of version `version` of feature `lobe` again. The text comes
    /// from the share's own kept copy where it still has it (checked against its SHA-256),
    /// else from the history store; either way it is retargeted to the free table number.
    /// With the speed plan the program is made again from the version's correction and
    /// timing for the plan in force (its two tables have two numbers to move).
    pub async fn rollback(
        &mut self,
        lobe: &FeatureName,
        version: TableVersion,
    ) -> Result<RolledBack, RollbackError> {
        if *lobe != self.setup.name {
            return Err(RollbackError::UnknownFeature {
                machine: self.name.clone(),
                grinds: self.setup.name.to_string(),
                asked: lobe.clone(),
            });
        }
        let (text, learning, number) = self.rollback_program(lobe, version).await?;
        let at = now();
        let reason = format!("rollback to v{version}");
        let mut next = self.machine.memory().learning.clone();
        if learning.correction_um.len() == next.correction_um.len() {
            next.correction_um = learning.correction_um.clone();
            next.timing_correction_deg = learning.timing_correction_deg;
            next.recent_max_error_um.clear();
        }
        let order = TableOrder {
            program: Program::Text {
                text,
                table_number: number,
            },
            next: Box::new(next),
            reason: reason.clone(),
            measurement: None,
            rollback_of: Some(version),
            learning: Some(learning),
            at,
        };
        let (new_version, status, mut records) = self.deliver_order(order).await?;
        let why = status.why();
        info!(machine = %self.name, lobe = lobe.as_str(), version = version.get(), new_version = new_version.get(), table_number = number, status = status.name(), "rollback");
        records.extend([
            event(
                &self.name,
                at,
                EventLevel::Info,
                EventKind::Rollback,
                format!("{reason} as v{new_version}, table {number}: {why}"),
            ),
            self.learning_record(at),
        ]);
        self.record(records).await;
        // The status (API, /metrics, OPC UA, the audit row's after) shows the table now in
        // force, not the one before the rollback until the next part.
        self.publish_start_status();
        Ok(RolledBack {
            to_version: version,
            new_version,
            table_number: number,
            summary: format!("{reason} delivered as v{new_version}, table {number} ({why})"),
        })
    }

    /// The program of `version` retargeted to the free table number, with its learning.
    pub(super) async fn rollback_program(
        &mut self,
        lobe: &FeatureName,
        version: TableVersion,
    ) -> Result<(String, TableLearning, u32), RollbackError> {
        let store = self
            .store
            .read()
            .await
            .clone()
            .ok_or(RollbackError::StoreUnavailable)?;
        let old = store
            .table_version(&self.name, lobe, version)
            .await
            .context("reading the stored version")?
            .ok_or_else(|| RollbackError::NotFound {
                machine: self.name.clone(),
                lobe: lobe.clone(),
                version,
            })?;
        // A version rebuilt from the share's manifest (after a new database was accepted)
        // has no correction to restore: refused, naming why.
        let learning: TableLearning =
            serde_json::from_str(&old.learning_params_json).with_context(|| {
                format!(
                    "version {version} has no stored correction (made before this database, or rebuilt from the share): roll back to a version made since"
                )
            })?;
        let number = self.share.next_table_number();
        let text = match self.share.rollback_request(version, now()) {
            Ok(r) => r
                .files
                .into_iter()
                .next()
                .map_or(old.program_text.clone(), |f| f.text),
            Err(_) => old.program_text.clone(),
        };
        let provenance = self.provenance(
            self.share.history().next_version(),
            self.machine.memory().in_force_version,
            &learning,
        );
        let text = if self.setup.speed_plan.enabled {
            // Two tables, two numbers: made again from the version's correction and timing
            // for the plan in force (the wheel believed now), not retargeted.
            self.planned_rollback(&learning, version, number, provenance)?
        } else {
            retarget_table_program(&text, number, Some(&provenance))
                .with_context(|| format!("version {version}: cannot retarget to table {number}"))?
        };
        Ok((text, learning, number))
    }

    /// With the speed plan: the two-table program of `learning`'s correction and timing, for
    /// the plan of the wheel believed now, as version `provenance` names, X under `number`.
    fn planned_rollback(
        &mut self,
        learning: &TableLearning,
        version: TableVersion,
        number: u32,
        provenance: crate::core::program::Provenance,
    ) -> anyhow::Result<String> {
        let mut state = self.machine.memory().learning.clone();
        state.correction_um = learning.correction_um.clone();
        state.timing_correction_deg = learning.timing_correction_deg;
        let table = crate::core::compensate::current_table(&state, &self.lobe_loop())
            .with_context(|| format!("version {version}: its correction cannot be ground now"))?;
        let mut settings = self.setup.program.clone();
        settings.table_number = number;
        settings.provenance = Some(provenance);
        settings.comment_lines = vec![crate::core::program::comment_text(&format!(
            "reason: rollback to v{version}"
        ))];
        self.render_table(&table, &state, &settings)
    }
}
