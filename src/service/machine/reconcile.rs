//! Start-up reconciliation of a feature's journal, the share's manifest and the loop's
//! memory, as the shell's part of it: the decisions are the loop crate's
//! ([`FeatureMachine::resume`], whose module doc says what a start does after a stop
//! anywhere); this file gathers its inputs (the journal's records of the feature, the
//! manifest, the store's record of a version the journal no longer holds), carries out the
//! effects it queues and logs what it did.

use super::super::journal::Pending;
use super::FeatureLoop;
use super::StoreHandle;
use crate::names::{FeatureName, MachineName};
use crate::share::{Share, VersionStatus};
use crate::store::MeasurementStage;
use camloop_loop::machine::{FeatureConfig, Finished, OnShare, ResumeReport, ShareView};
use camloop_loop::memory::TableLearning;
use camloop_loop::record::{Kept, TableRecord, TableStatus};
use camloop_loop::{FeatureMachine, LoopMemory, PartId, TableVersion};
use std::collections::BTreeMap;
use tracing::{error, info, warn};

/// The machine of feature `setup` of `machine`, resumed from its journal's `records`
/// (`fallback`: the store's memory, or a new one, when they hold none) and reconciled with
/// `view` (the share's manifest, [`share_view`]); its effects are carried out by
/// [`FeatureLoop::reconcile_share`].
pub(super) async fn resumed_machine(
    machine: &MachineName,
    setup: &crate::recipe::FeatureSetup,
    records: Vec<Kept>,
    fallback: LoopMemory,
    view: ShareView,
    store: &StoreHandle,
) -> FeatureMachine {
    let wanted = FeatureMachine::records_wanted(&records, &fallback, &view);
    let found = stored_records(machine, &setup.name, wanted, store).await;
    let config = FeatureConfig {
        feature: setup.name.clone(),
        params: setup.params.clone(),
    };
    FeatureMachine::resume(config, records, fallback, view, found, crate::clock::now())
}

impl FeatureLoop {
    /// Carries out the start's effects (see the module doc). Runs before anything is
    /// delivered at start; an error when the share's state folder failed.
    pub(super) async fn reconcile_share(&mut self) -> anyhow::Result<()> {
        for f in self.run_machine(None).await {
            if let Finished::Resumed(report) = f {
                self.log_resume(&report);
                if let Some(reason) = report.failed {
                    anyhow::bail!("share state folder: {reason}");
                }
            }
        }
        Ok(())
    }

    fn log_resume(&self, report: &ResumeReport) {
        let (machine, feature) = (&self.name, &self.setup.name);
        for (version, status) in &report.settled {
            info!(machine = %machine, feature = %feature, version = version.get(), status, "status taken from the share's manifest");
        }
        for version in &report.submitted {
            info!(machine = %machine, feature = %feature, version = version.get(), "version journalled before a stop submitted to the share");
        }
        for (version, reason) in &report.refused {
            error!(machine = %machine, feature = %feature, version = version.get(), reason = %reason, "journalled version not submitted");
        }
        match report.adopted_waiting {
            Some((version, true)) => {
                info!(machine = %machine, feature = %feature, version = version.get(), "a version the share holds but the memory did not: waits with the correction it was made from")
            }
            Some((version, false)) => {
                warn!(machine = %machine, feature = %feature, version = version.get(), "the share's waiting version has no record here: delivered with the correction in force")
            }
            None => {}
        }
        if let Some((version, before, with_record)) = report.in_force_from_share {
            info!(machine = %machine, feature = %feature, share_version = version.get(), memory_version = before.map_or(0, |v| v.get()), "version in force taken from the share's manifest");
            if !with_record {
                warn!(machine = %machine, feature = %feature, version = version.get(), "the version in force has no record here: learning goes on from the memory's correction");
            }
        }
        if let Some(reason) = &report.not_delivered {
            warn!(machine = %machine, feature = %feature, error = %reason, "table of a step cut short not delivered at start: it waits for the retry");
        }
    }
}

/// What the feature's journal holds that a resume reads back: its measurements of finished
/// parts, tables, statuses and memories (the in-process measurement is history only).
pub(super) fn kept(machine: &MachineName, feature: &FeatureName, records: &[Pending]) -> Vec<Kept> {
    records
        .iter()
        .filter_map(|r| match r {
            Pending::Measurement { measurement: m, .. }
                if m.lobe == *feature && m.stage == MeasurementStage::Final =>
            {
                Some(Kept::Measurement {
                    sha256: m.sha256,
                    part: PartId::new(&m.part).ok(),
                })
            }
            Pending::Table {
                lobe,
                version,
                parent_version,
                table_number,
                program_text,
                learning,
                reason,
                status,
                created_at,
                measurement_id,
                rollback_of,
                ..
            } if lobe == feature => Some(Kept::Table(Box::new(TableRecord {
                version: *version,
                parent: *parent_version,
                table_number: *table_number,
                program_text: program_text.clone(),
                learning: learning.clone(),
                reason: reason.clone(),
                status: table_status(status),
                at: *created_at,
                measurement: *measurement_id,
                rollback_of: *rollback_of,
            }))),
            Pending::VersionStatus {
                lobe,
                version,
                status,
                ..
            } if lobe == feature => Some(Kept::Status {
                version: *version,
                status: table_status(status),
            }),
            Pending::Learning {
                machine: m,
                lobe,
                state,
                ..
            } if m == machine && lobe == feature => Some(Kept::Learning(state.clone())),
            _ => None,
        })
        .collect()
}

/// A journalled status in the loop's words (the journal holds only the three the loop
/// writes; the share's others read as not on the control).
fn table_status(status: &VersionStatus) -> TableStatus {
    match status {
        VersionStatus::Waiting { reason } => TableStatus::Waiting {
            reason: reason.clone(),
        },
        VersionStatus::Pushed { note, .. } => TableStatus::Pushed {
            note: note.clone().unwrap_or_default(),
        },
        VersionStatus::Refused { reason } => TableStatus::Refused {
            reason: reason.clone(),
        },
        other @ (VersionStatus::Delivering | VersionStatus::Superseded { .. }) => {
            TableStatus::Waiting {
                reason: Some(other.name().to_string()),
            }
        }
    }
}

/// The share's manifest as the resume reads it.
pub(super) fn share_view(share: &Share) -> ShareView {
    let history = share.history();
    let versions = history
        .versions()
        .iter()
        .map(|v| {
            let on = match &v.status {
                VersionStatus::Pushed { .. } => OnShare::Pushed,
                VersionStatus::Refused { reason } => OnShare::Refused {
                    reason: reason.clone(),
                },
                _ => OnShare::Accepted,
            };
            (v.record.version, on)
        })
        .collect();
    ShareView {
        next_version: history.next_version(),
        pushed: history.last_pushed().map(|v| v.record.version),
        waiting: history.waiting().map(|v| v.record.version),
        versions,
    }
}

/// What the store's records of `wanted` say each was made from (a version it lacks, or
/// whose record cannot be read, is left out: the resume says what it does without one).
async fn stored_records(
    machine: &MachineName,
    feature: &FeatureName,
    wanted: Vec<TableVersion>,
    store: &StoreHandle,
) -> BTreeMap<TableVersion, TableLearning> {
    let mut found = BTreeMap::new();
    let Some(store) = store.read().await.clone().filter(|_| !wanted.is_empty()) else {
        return found;
    };
    for version in wanted {
        match store.table_version(machine, feature, version).await {
            Ok(Some(t)) => match serde_json::from_str(&t.learning_params_json) {
                Ok(learning) => {
                    found.insert(version, learning);
                }
                Err(e) => {
                    warn!(machine = %machine, version = version.get(), error = %e, "stored version's learning unreadable")
                }
            },
            Ok(None) => {}
            Err(e) => {
                warn!(machine = %machine, version = version.get(), error = %e, "stored version unreadable")
            }
        }
    }
    found
}
