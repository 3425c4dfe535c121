//! A measurement into the machine: whose it is, whether it was seen before, the loop turn,
//! and its records. The measurement is recorded before anything is learned from it.

use super::super::journal::{EventKind, Pending};
use super::records::{event, keep_reject, outcome_text, raw_revolutions};
use super::{Ingested, MachineLoop, now_ms};
use crate::core::learn::StepOutcome;
use crate::core::measure::{MeasurementHeader, RawMeasurement};
use crate::core::turn::{self, Decision, HoldReason, Measured, TurnError, measurement_sha256};
use crate::store::{EventLevel, Verdict};
use tracing::{error, info, warn};

/// The names a gauge may use for this machine and its feature: the configured names, or
/// the numeric id `1` that the built-in CAN layout carries when one gauge serves one
/// machine.
#[derive(Debug, Clone)]
pub struct GaugeIds {
    machine: String,
    feature: String,
}

const BUS_ID: &str = "1";

impl GaugeIds {
    pub fn for_machine(machine: &str, feature: &str) -> Self {
        Self {
            machine: machine.to_string(),
            feature: feature.to_string(),
        }
    }

    /// Why this header does not belong to this machine and feature, if it does not.
    pub fn mismatch(&self, header: &MeasurementHeader) -> Option<String> {
        let ok = |said: &str, ours: &str| said == ours || said == BUS_ID;
        if !ok(&header.machine, &self.machine) {
            return Some(format!(
                "measurement names machine {:?}, this is machine {:?}",
                header.machine, self.machine
            ));
        }
        if !ok(&header.lobe, &self.feature) {
            return Some(format!(
                "measurement names lobe {:?}, machine {:?} grinds {:?}",
                header.lobe, self.machine, self.feature
            ));
        }
        None
    }
}

impl MachineLoop {
    pub(super) async fn on_measurement(
        &mut self,
        raw: RawMeasurement,
        ground_with: Option<u64>,
    ) -> anyhow::Result<Ingested> {
        let at_ms = now_ms();
        let sha = measurement_sha256(&raw);
        if let Some(reason) = self.ids.mismatch(&raw.header) {
            self.reject(&raw, &sha, &reason, at_ms).await;
            return Ok(Ingested::Rejected { reason });
        }
        if self.memory.has_seen(&sha) {
            info!(machine = %self.name, part = %raw.header.part, origin = %raw.origin, "measurement already learned from: not learned again");
            let message = format!(
                "part {} from {} repeats a measurement already used",
                raw.header.part, raw.origin
            );
            let e = event(
                &self.name,
                at_ms,
                EventLevel::Info,
                EventKind::MeasurementRepeated,
                message,
            );
            self.record(vec![e]).await;
            return Ok(Ingested::Repeated);
        }
        let hold = match ground_with {
            Some(v) if v != self.memory.in_force_version => Some(HoldReason::OtherTable {
                ground_with: v,
                in_force: self.memory.in_force_version,
            }),
            _ => self.disk_full_hold(at_ms).await,
        };
        let done = match turn::turn(&self.setup.turn_setup(), &self.memory.learning, &raw, hold) {
            Ok(t) => t,
            Err(TurnError::Measurement(e)) => {
                let reason = e.to_string();
                self.reject(&raw, &sha, &reason, at_ms).await;
                return Ok(Ingested::Rejected { reason });
            }
            Err(e) => return Err(e.into()),
        };
        let record = self.measurement_record(&raw, &sha, &done.measured, at_ms);
        if !self.record(vec![record]).await {
            // Not counted and not remembered: the same reading sent again once the journal
            // can be written is a new measurement, not a repeat.
            warn!(machine = %self.name, origin = %raw.origin, "part not learned from: its measurement could not be recorded");
            self.metrics.update(&self.name, |m| m.learning_held = 1);
            return Ok(Ingested::NotRecorded);
        }
        self.memory.parts += 1;
        self.memory.remember(sha.clone());
        let part = self.memory.parts;
        let held = matches!(done.decision, Decision::Held(_));
        let ground_with = self.memory.in_force_version;
        let (mut records, text) = self.decide(done.decision, &sha, part, at_ms).await;
        if !held || !self.journal.on_reserve() {
            // On the reserve only measurements are kept: the memory did not change.
            records.push(self.learning_record(at_ms));
        }
        self.record(records).await;
        let max_error_um = done.measured.max_error_um;
        self.metrics.update(&self.name, |m| {
            m.parts_total += 1;
            m.last_max_error_um = max_error_um;
        });
        info!(
            machine = %self.name,
            lobe = %self.setup.name,
            part,
            max_error_um = format!("{max_error_um:.2}"),
            profile_error_um = format!("{:.2}", done.measured.max_profile_error_um),
            ground_with,
            "{} {} part {part}: max error {max_error_um:.2} µm → {text}",
            self.name,
            self.setup.name
        );
        Ok(Ingested::Recorded)
    }

    /// Acts on the turn's decision; returns the records and a line for the log.
    async fn decide(
        &mut self,
        decision: Decision,
        sha: &str,
        part: u64,
        at_ms: i64,
    ) -> (Vec<Pending>, String) {
        let mut records = Vec::new();
        let text = match decision {
            Decision::Table {
                outcome,
                next,
                table,
            } => {
                if let StepOutcome::Reverted { reason, .. } = &outcome {
                    error!(machine = %self.name, lobe = %self.setup.name, reason = %reason, "learning reverted and frozen: operator action needed");
                    self.metrics.update(&self.name, |m| m.alarms_total += 1);
                    records.push(event(
                        &self.name,
                        at_ms,
                        EventLevel::Error,
                        EventKind::LearningReverted,
                        reason.clone(),
                    ));
                }
                let reason = format!("part {part}: {}", outcome_text(&outcome));
                match self
                    .deliver(&table, *next, &reason, Some(sha.to_string()))
                    .await
                {
                    Ok(mut more) => {
                        records.append(&mut more);
                        self.delivery_line()
                    }
                    Err(e) => {
                        error!(machine = %self.name, error = format!("{e:#}"), "table not recorded: previous table stays in force");
                        format!("table not recorded: {e:#}")
                    }
                }
            }
            Decision::Refused(e) => {
                warn!(machine = %self.name, lobe = %self.setup.name, reason = %e, "table refused, previous table stays in force");
                self.metrics
                    .update(&self.name, |m| m.tables_refused_total += 1);
                records.push(event(
                    &self.name,
                    at_ms,
                    EventLevel::Warn,
                    EventKind::TableRefused,
                    e.to_string(),
                ));
                "table refused, previous kept".to_string()
            }
            Decision::Held(reason) => {
                info!(machine = %self.name, reason = %reason, "part analysed, not learned from");
                records.push(event(
                    &self.name,
                    at_ms,
                    EventLevel::Info,
                    EventKind::LearningHeld,
                    format!("part {part} not learned from: {reason}"),
                ));
                format!("not learned from: {reason}")
            }
        };
        (records, text)
    }

    fn measurement_record(
        &self,
        raw: &RawMeasurement,
        sha: &str,
        measured: &Measured,
        at_ms: i64,
    ) -> Pending {
        let report = &measured.report;
        Pending::Measurement {
            machine: self.name.clone(),
            part: raw.header.part.clone(),
            lobe: self.setup.name.clone(),
            received_at_ms: at_ms,
            verdict: if report.verdict.pass {
                Verdict::Pass
            } else {
                Verdict::Fail
            },
            max_profile_error_um: measured.max_profile_error_um,
            base_radius_error_um: report.base_radius_error_um,
            phase_error_deg: report.phase_error_deg,
            revolutions_used: measured.averaged.revolutions_used.len() as u32,
            points_per_rev: measured.averaged.points_per_rev,
            origin: raw.origin.clone(),
            sha256: sha.to_string(),
            ground_with_version: self.memory.in_force_version,
            raw_lift_mm: raw_revolutions(raw),
            averaged_lift_mm: measured.averaged.mean_lift_mm.clone(),
            analysis_json: serde_json::to_string(report).unwrap_or_default(),
        }
    }

    /// A measurement that is not this machine's, or fails the checks: kept among the
    /// rejects with the reason, recorded as an event, never learned from.
    async fn reject(&mut self, raw: &RawMeasurement, sha: &str, reason: &str, at_ms: i64) {
        warn!(machine = %self.name, lobe = %self.setup.name, origin = %raw.origin, reason = %reason, "measurement rejected");
        let dir = self.share.config().state_dir.with_file_name("rejected");
        if let Err(e) = keep_reject(&dir, raw, sha, reason) {
            error!(machine = %self.name, folder = %dir.display(), error = %e, "rejected measurement could not be kept");
        }
        self.metrics
            .update(&self.name, |m| m.measurements_rejected_total += 1);
        let message = format!("{} (from {})", reason, raw.origin);
        let e = event(
            &self.name,
            at_ms,
            EventLevel::Warn,
            EventKind::MeasurementRejected,
            message,
        );
        self.record(vec![e]).await;
    }
}
