//! A measurement into the machine: whose it is, whether it was seen before, the loop turn,
//! and its records. The measurement is recorded before anything is learned from it.

use super::super::journal::{EventKind, Pending};
use super::memory::GuardKind;
use super::records::{event, keep_reject, raw_revolutions};
use super::{FeatureLoop, Ingested};
use crate::clock::now;
use crate::core::compensate::{CycleError, GuardedTable};
use crate::core::digest::Sha256;
use crate::core::learn::{LearningState, StepOutcome};
use crate::core::measure::{MeasurementHeader, RawMeasurement};
use crate::core::turn::{self, Decision, HoldReason, Measured, TurnError, measurement_sha256};
use crate::names::{FeatureName, MachineName};
use crate::store::{EventLevel, NewMeasurement, Verdict};
use tracing::{debug, error, info, warn};

/// The names a gauge may use for a machine and its features: the configured names, or the
/// numeric ids of the built-in CAN layout, where the machine is `1` (one gauge serves one
/// machine) and a feature is its position in the recipe, from 1.
#[derive(Debug, Clone)]
pub struct GaugeIds {
    machine: MachineName,
    features: Vec<FeatureName>,
}

const BUS_ID: &str = "1";

impl GaugeIds {
    pub fn new(machine: &MachineName, setups: &[crate::recipe::FeatureSetup]) -> Self {
        Self {
            machine: machine.clone(),
            features: setups.iter().map(|s| s.name.clone()).collect(),
        }
    }

    /// The index of the feature this measurement belongs to, or why it belongs to none of
    /// this machine's. A control report of the table that ground the part must name the
    /// same feature: a gauge that mixes two lobes up is caught here, never learned from.
    pub fn route(
        &self,
        header: &MeasurementHeader,
        ground_with: Option<&super::GroundWith>,
    ) -> Result<usize, String> {
        if header.machine != self.machine && header.machine != BUS_ID {
            return Err(format!(
                "measurement names machine {:?}, this is machine {:?}",
                header.machine, self.machine
            ));
        }
        let by_name = self.features.iter().position(|f| *f == header.lobe);
        let by_id = header
            .lobe
            .parse::<usize>()
            .ok()
            .filter(|k| (1..=self.features.len()).contains(k))
            .map(|k| k - 1);
        let Some(index) = by_name.or(by_id) else {
            return Err(format!(
                "measurement names lobe {:?}, machine {:?} grinds {} (or their positions 1 to {})",
                header.lobe,
                self.machine,
                self.features.join(", "),
                self.features.len()
            ));
        };
        if let Some(g) = ground_with
            && let Some(table_feature) = &g.feature
            && *table_feature != self.features[index]
        {
            return Err(format!(
                "measurement names lobe {} but the control ground that part with the table of {} (v{}): lobes mixed up, not learned from",
                self.features[index], table_feature, g.version
            ));
        }
        Ok(index)
    }
}

/// What the newest part of a feature came to, for the machine's line per shaft.
#[derive(Debug, Clone)]
pub(crate) struct PartLine {
    pub feature: FeatureName,
    /// The part (shaft) number the gauge gave.
    pub part: String,
    pub max_error_um: f64,
    pub profile_error_um: f64,
    /// Size (base-circle radius) error, µm, positive oversize.
    pub size_error_um: f64,
    pub timing_error_deg: f64,
    /// Its next table reached the share.
    pub pushed: bool,
    /// What the loop did.
    pub text: String,
}

impl FeatureLoop {
    pub(crate) async fn on_measurement(
        &mut self,
        raw: RawMeasurement,
        ground_with: Option<u64>,
    ) -> anyhow::Result<Ingested> {
        let at_ms = now();
        let sha = measurement_sha256(&raw);
        if self.memory.has_seen(&sha) {
            self.note_repeat(&raw, at_ms).await;
            return Ok(Ingested::Repeated);
        }
        let hold = match ground_with {
            Some(v) if v != self.memory.in_force_version => Some(HoldReason::OtherTable {
                ground_with: v,
                in_force: self.memory.in_force_version,
            }),
            _ => self.disk_full_hold(at_ms).await,
        };
        let previous = self.memory.previous;
        self.refresh_plan();
        let done = match turn::turn(
            &self.turn_setup(),
            &self.memory.learning,
            &raw,
            hold,
            previous,
        ) {
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
        self.memory.remember(sha);
        self.memory.previous = Some(done.measured.as_previous());
        self.memory.last_part = Some(raw.header.part.clone());
        let part = self.memory.parts;
        let held = matches!(done.decision, Decision::Held(_));
        let ground_with = self.memory.in_force_version;
        let decision = self.keep_planned(done.decision);
        let (mut records, text) = self.decide(decision, &sha, part, at_ms).await;
        records.extend(self.chart_events(&raw.header.part, &done.measured, at_ms));
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
        self.publish_status(&raw.header.part, &done.measured);
        let line = PartLine {
            feature: self.setup.name.clone(),
            part: raw.header.part.clone(),
            max_error_um,
            profile_error_um: done.measured.max_profile_error_um,
            size_error_um: done.measured.report.base_radius_error_um,
            timing_error_deg: done.measured.timing_error_deg,
            pushed: self.memory.in_force_version != ground_with,
            text,
        };
        self.log_part_line(&line, part, ground_with);
        self.last_line = Some(line);
        Ok(Ingested::Recorded)
    }

    /// A measurement seen before is recorded as an event, never learned from twice.
    async fn note_repeat(&mut self, raw: &RawMeasurement, at_ms: jiff::Timestamp) {
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
    }

    /// The part's line in the log: INFO for a one-feature machine, else DEBUG.
    fn log_part_line(&self, line: &PartLine, part: u64, ground_with: u64) {
        let max_error_um = line.max_error_um;
        if self.main.table_files.len() == 1 {
            info!(
                machine = %self.name,
                lobe = %self.setup.name,
                part,
                max_error_um = format!("{max_error_um:.2}"),
                profile_error_um = format!("{:.2}", line.profile_error_um),
                timing_error_deg = format!("{:.4}", line.timing_error_deg),
                ground_with,
                "{} {} part {part}: max error {max_error_um:.2} µm → {}",
                self.name,
                self.setup.name,
                line.text
            );
        } else {
            // A whole part: the machine says one line per shaft; each lobe's is detail.
            debug!(
                machine = %self.name,
                lobe = %self.setup.name,
                part = %line.part,
                max_error_um = format!("{max_error_um:.2}"),
                profile_error_um = format!("{:.2}", line.profile_error_um),
                timing_error_deg = format!("{:.4}", line.timing_error_deg),
                ground_with,
                "{} {} part {}: max error {max_error_um:.2} µm → {}",
                self.name,
                self.setup.name,
                line.part,
                line.text
            );
        }
    }

    /// A master part's run (see [`crate::core::measure::is_master_part`]): checked, analysed
    /// and recorded for the gauge study, never a step of learning (the turn is not taken),
    /// never counted as a part, never the previous part of the next one.
    pub(crate) async fn on_master(&mut self, raw: RawMeasurement) -> anyhow::Result<Ingested> {
        let at_ms = now();
        let sha = measurement_sha256(&raw);
        if self.memory.has_seen(&sha) {
            return Ok(Ingested::Repeated);
        }
        let measured = match turn::measure(&self.setup.turn_setup(), &raw) {
            Ok(m) => m,
            Err(TurnError::Measurement(e)) => {
                let reason = e.to_string();
                self.reject(&raw, &sha, &reason, at_ms).await;
                return Ok(Ingested::Rejected { reason });
            }
            Err(e) => return Err(e.into()),
        };
        let record = self.measurement_record(&raw, &sha, &measured, at_ms);
        if !self.record(vec![record]).await {
            return Ok(Ingested::NotRecorded);
        }
        self.memory.remember(sha);
        info!(machine = %self.name, lobe = %self.setup.name, part = %raw.header.part, size_error_um = format!("{:.3}", measured.report.base_radius_error_um), "master run recorded for the gauge study (not learned from)");
        Ok(Ingested::Master)
    }

    /// Acts on the turn's decision; returns the records and a line for the log.
    async fn decide(
        &mut self,
        decision: Decision,
        sha: &Sha256,
        part: u64,
        at_ms: jiff::Timestamp,
    ) -> (Vec<Pending>, String) {
        let mut records = Vec::new();
        let text = match decision {
            Decision::Table {
                outcome,
                next,
                table,
                ..
            } => {
                self.note_outcome(&outcome, part, at_ms, &mut records);
                let reason = format!("part {part}: {outcome}");
                self.deliver_table(&table, *next, &reason, sha, &mut records)
                    .await
            }
            Decision::Refused(e) => self.note_refusal(&e, part, at_ms, &mut records),
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

    /// What a learning step's outcome means for the alarms and the guards' streaks.
    fn note_outcome(
        &mut self,
        outcome: &StepOutcome,
        part: u64,
        at_ms: jiff::Timestamp,
        records: &mut Vec<Pending>,
    ) {
        match outcome {
            StepOutcome::Reverted { reason, .. } => {
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
            StepOutcome::Limited { bound, .. } => {
                let kind = GuardKind::of_bound(bound.quantity);
                self.guard_acted(kind, &bound.to_string(), part, at_ms, records);
            }
            StepOutcome::Updated { .. } | StepOutcome::InTolerance { .. } => {
                self.guard_cleared(part, at_ms, records);
            }
            StepOutcome::Frozen { .. } => {}
        }
    }

    /// Delivers a new table; returns the log line. A table not recorded leaves the one in
    /// force (quietly when another instance of the cluster owns the machine now).
    async fn deliver_table(
        &mut self,
        table: &GuardedTable,
        next: LearningState,
        reason: &str,
        sha: &Sha256,
        records: &mut Vec<Pending>,
    ) -> String {
        match self.deliver(table, next, reason, Some(*sha)).await {
            Ok(mut more) => {
                records.append(&mut more);
                self.delivery_line()
            }
            Err(e) if self.journal.fenced_out() => {
                warn!(machine = %self.name, error = format!("{e:#}"), "cluster: another instance owns this machine now; table not recorded here");
                format!("table not recorded: {e:#}")
            }
            Err(e) => {
                error!(machine = %self.name, error = format!("{e:#}"), "table not recorded: previous table stays in force");
                format!("table not recorded: {e:#}")
            }
        }
    }

    /// A refused table: counted, its guard's streak extended, warned about once per streak.
    fn note_refusal(
        &mut self,
        e: &CycleError,
        part: u64,
        at_ms: jiff::Timestamp,
        records: &mut Vec<Pending>,
    ) -> String {
        self.metrics
            .update(&self.name, |m| m.tables_refused_total += 1);
        let in_a_row = self.guard_acted(
            GuardKind::of_refusal(e),
            &e.to_string(),
            part,
            at_ms,
            records,
        );
        if in_a_row == 1 {
            warn!(machine = %self.name, lobe = %self.setup.name, reason = %e, "table refused, previous table stays in force");
        }
        let level = if in_a_row == 1 {
            EventLevel::Warn
        } else {
            EventLevel::Info
        };
        records.push(event(
            &self.name,
            at_ms,
            level,
            EventKind::TableRefused,
            format!("{} ({in_a_row} in a row): {e}", self.setup.name),
        ));
        format!("table refused, previous kept ({in_a_row} in a row)")
    }

    fn measurement_record(
        &self,
        raw: &RawMeasurement,
        sha: &Sha256,
        measured: &Measured,
        at_ms: jiff::Timestamp,
    ) -> Pending {
        let report = &measured.report;
        let measurement = NewMeasurement {
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
            sha256: *sha,
            recipe_snapshot: None,
            raw_lift_mm: raw_revolutions(raw),
            averaged_lift_mm: measured.averaged.mean_lift_mm.clone(),
            analysis_json: serde_json::to_string(report).unwrap_or_default(),
        };
        Pending::Measurement {
            measurement,
            ground_with_version: self.memory.in_force_version,
        }
    }

    /// A measurement that is not this machine's, or fails the checks: kept among the
    /// rejects with the reason, recorded as an event, never learned from.
    pub(super) async fn reject(
        &mut self,
        raw: &RawMeasurement,
        sha: &Sha256,
        reason: &str,
        at_ms: jiff::Timestamp,
    ) {
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
