//! Start-up reconciliation of a feature's journal, the share's manifest and the loop's
//! memory. A version's record is journalled before the share hears of it
//! ([`FeatureLoop::push`]), so whenever the process died:
//! - a version journalled but never submitted is submitted now, as the number its record
//!   holds (nothing can have reached the share after it);
//! - a version the share holds beyond what the memory knows has its record in the journal,
//!   else in the store: the correction it was made from is adopted, in force if the share
//!   pushed it, waiting otherwise.

use super::super::journal::Pending;
use super::FeatureLoop;
use super::delivery::Draft;
use super::memory::{TableLearning, WaitingTable};
use super::records::event;
use crate::clock::now;
use crate::core::learn::LearningState;
use crate::share::{Submitted, VersionStatus};
use crate::store::EventLevel;
use anyhow::Context;
use camloop_loop::TableVersion;
use tracing::{error, info, warn};

impl FeatureLoop {
    /// See the module doc. Runs before anything is delivered at start.
    pub(super) async fn reconcile_share(&mut self) -> anyhow::Result<()> {
        self.submit_journalled()?;
        self.settle_statuses()?;
        let history = self.share.history();
        let pushed = history.last_pushed().map(|v| v.record.version);
        let waiting = history.waiting().map(|v| v.record.version);
        let in_force = self.machine.memory().in_force_version;
        let known_waiting = self.machine.memory().waiting.as_ref().map(|w| w.version);
        if let Some(w) = waiting
            && Some(w) > in_force
            && known_waiting != Some(w)
        {
            match self.made_from(w).await {
                Some(t) => {
                    info!(machine = %self.name, feature = %self.setup.name, version = w.get(), "a version the share holds but the memory did not: waits with the correction it was made from");
                    let memory = self.machine.memory_mut();
                    memory.waiting = Some(WaitingTable {
                        version: w,
                        learning: adopt(&memory.learning, &t),
                        wheel_radius_mm: t.wheel_radius_mm,
                        // Not known here: a start after its delivery makes it again.
                        va_speed_rpm: None,
                    });
                }
                None => {
                    warn!(machine = %self.name, feature = %self.setup.name, version = w.get(), "the share's waiting version has no record here: delivered with the correction in force");
                    // It waits in the memory as made from the correction in force, so the
                    // machine's retry delivers it like any other.
                    let memory = self.machine.memory_mut();
                    memory.waiting = Some(WaitingTable {
                        version: w,
                        learning: memory.learning.clone(),
                        wheel_radius_mm: memory.wheel_radius_mm,
                        va_speed_rpm: memory.in_force_va_speed_rpm,
                    });
                }
            }
        }
        let Some(p) = pushed.filter(|p| Some(*p) != in_force) else {
            return Ok(());
        };
        // Killed between the push and the record of it: the share is the authority, and the
        // correction in force is the one that table was made from, not the one before it.
        info!(machine = %self.name, feature = %self.setup.name, share_version = p.get(), memory_version = in_force.map_or(0, |v| v.get()), "version in force taken from the share's manifest");
        let now_waiting = self.machine.memory().waiting.as_ref().map(|w| w.version);
        if now_waiting != Some(p) {
            match self.made_from(p).await {
                Some(t) => {
                    let memory = self.machine.memory_mut();
                    memory.learning = adopt(&memory.learning, &t);
                }
                None => {
                    warn!(machine = %self.name, feature = %self.setup.name, version = p.get(), "the version in force has no record here: learning goes on from the memory's correction")
                }
            }
        }
        let memory = self.machine.memory_mut();
        memory.delivered(p);
        // A waiting version older than the one pushed was superseded on the share.
        memory.waiting.take_if(|w| w.version < p);
        Ok(())
    }

    /// Writes the share's outcome (pushed or refused) for each version whose newest status
    /// in the journal is still the one before it: the process died between the share's
    /// answer and its record.
    fn settle_statuses(&mut self) -> anyhow::Result<()> {
        let mine = &self.setup.name;
        let mut journalled = std::collections::BTreeMap::new();
        for r in self.journal.records() {
            match r {
                Pending::Table {
                    lobe,
                    version,
                    status,
                    ..
                }
                | Pending::VersionStatus {
                    lobe,
                    version,
                    status,
                    ..
                } if lobe == mine => {
                    journalled.insert(*version, status.name());
                }
                _ => {}
            }
        }
        let at_ms = now();
        let mut records = Vec::new();
        for (version, said) in journalled {
            let Some(v) = self.share.history().get(version) else {
                continue;
            };
            let status = match &v.status {
                VersionStatus::Pushed { .. } => VersionStatus::pushed_at(
                    at_ms,
                    "pushed to the share (its manifest, read at start)",
                ),
                refused @ VersionStatus::Refused { .. } => refused.clone(),
                _ => continue,
            };
            if status.name() != said {
                info!(machine = %self.name, feature = %mine, version = version.get(), status = status.name(), "status taken from the share's manifest");
                records.push(Pending::VersionStatus {
                    machine: self.name.clone(),
                    lobe: mine.clone(),
                    version,
                    status,
                    at_ms,
                });
            }
        }
        if !records.is_empty() {
            self.journal.append(&records)?;
        }
        Ok(())
    }

    /// Submits the versions journalled after the share's newest, in order.
    fn submit_journalled(&mut self) -> anyhow::Result<()> {
        let first = self.share.history().next_version();
        let mine = &self.setup.name;
        let mut drafts: Vec<(TableVersion, Draft)> = self
            .journal
            .records()
            .iter()
            .filter_map(|r| match r {
                Pending::Table {
                    lobe,
                    version,
                    table_number,
                    program_text,
                    learning,
                    reason,
                    created_at_ms,
                    measurement_id,
                    rollback_of,
                    ..
                } if lobe == mine && *version >= first => Some((
                    *version,
                    Draft {
                        text: program_text.clone(),
                        table_number: *table_number,
                        learning: learning.clone(),
                        reason: reason.clone(),
                        measurement_id: *measurement_id,
                        rollback_of: *rollback_of,
                        at_ms: *created_at_ms,
                    },
                )),
                _ => None,
            })
            .collect();
        drafts.sort_by_key(|(v, _)| *v);
        let mut records = Vec::new();
        for (version, draft) in drafts {
            let at_ms = now();
            let outcome = match self.share.history().next_version() {
                next if next == version => {
                    let request = self.request(draft)?;
                    match self.share.submit(request).context("share state folder")? {
                        Submitted::Accepted { .. } => {
                            info!(machine = %self.name, feature = %mine, version = version.get(), "version journalled before a stop submitted to the share");
                            continue;
                        }
                        Submitted::Refused { reason, .. } => reason,
                    }
                }
                next => format!("journalled as v{version} but the share is at v{next}"),
            };
            error!(machine = %self.name, feature = %mine, version = version.get(), reason = %outcome, "journalled version not submitted");
            records.push(Pending::VersionStatus {
                machine: self.name.clone(),
                lobe: mine.clone(),
                version,
                status: VersionStatus::Refused {
                    reason: outcome.clone(),
                },
                at_ms,
            });
            records.push(event(
                &self.name,
                at_ms,
                EventLevel::Error,
                super::super::journal::EventKind::TableRefused,
                format!("{mine} v{version}: {outcome}"),
            ));
        }
        if !records.is_empty() {
            self.journal.append(&records)?;
        }
        Ok(())
    }

    /// The correction version `version` was made from: its journal record, else the store's.
    async fn made_from(&mut self, version: TableVersion) -> Option<TableLearning> {
        let journalled = self.journal.records().iter().rev().find_map(|r| match r {
            Pending::Table {
                lobe,
                version: v,
                learning,
                ..
            } if *lobe == self.setup.name && *v == version => Some(learning.clone()),
            _ => None,
        });
        if journalled.is_some() {
            return journalled;
        }
        let store = self.store.read().await.clone()?;
        let stored = store
            .table_version(&self.name, &self.setup.name, version.to_i64())
            .await;
        match stored {
            Ok(Some(t)) => serde_json::from_str(&t.learning_params_json).ok(),
            Ok(None) => None,
            Err(e) => {
                warn!(machine = %self.name, version = version.get(), error = %e, "stored version unreadable");
                None
            }
        }
    }
}

/// `state` with the correction (lift and timing) of a table's learning.
fn adopt(state: &LearningState, table: &TableLearning) -> LearningState {
    let mut next = state.clone();
    if table.correction_um.len() == next.correction_um.len() {
        next.correction_um = table.correction_um.clone();
        next.timing_correction_deg = table.timing_correction_deg;
        next.iteration = table.iteration;
    }
    next
}
