//! A measurement into the machine: whose it is (the gauge's names routed to a feature), then
//! the feature's machine (repeat, hold, the turn, records in write-ahead order) driven, and
//! the part's status, charts and log line said; a master part's run is recorded for the
//! gauge study only. The measurement is recorded before anything is learned from it.

use super::super::journal::{EventKind, Pending};
use super::records::{self, event, keep_reject};
use super::{FeatureLoop, Ingested, MachineError};
use crate::clock::now;
use crate::core::digest::Sha256;
use crate::core::ids::PartId;
use crate::core::measure::{MeasurementHeader, RawMeasurement};
use crate::core::turn::{self, Measured, TurnError, measurement_sha256};
use crate::names::{FeatureName, MachineName};
use crate::store::EventLevel;
use camloop_loop::machine::{Finished, Gauged, PartNote, PartReport};
use camloop_loop::{Input, TableVersion};
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

    /// The index of the feature this measurement belongs to and its part's id, or why it
    /// belongs to none of this machine's. A control report of the table that ground the part
    /// must name the same feature: a gauge that mixes two lobes up is caught here, never
    /// learned from. The part's label becomes a [`PartId`] here, the service's one edge for
    /// it: every gauge codec checks the same rule, so a refusal means a source that did not.
    pub fn route(
        &self,
        header: &MeasurementHeader,
        ground_with: Option<&super::GroundWith>,
    ) -> Result<(usize, PartId), String> {
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
        let part = PartId::new(&header.part).map_err(|e| format!("measurement names {e}"))?;
        Ok((index, part))
    }
}

/// What the newest part of a feature came to, for the machine's line per shaft.
#[derive(Debug, Clone)]
pub(crate) struct PartLine {
    pub feature: FeatureName,
    /// The part (shaft) number the gauge gave.
    pub part: PartId,
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
    /// A measurement of this feature, through the feature's machine
    /// ([`camloop_loop::FeatureMachine`]: repeat, hold, the turn, guards in a row, the
    /// write-ahead of its records and table); here the effects are carried out and the
    /// part's status, metrics and log line said.
    pub(crate) async fn on_measurement(
        &mut self,
        raw: RawMeasurement,
        part: PartId,
        ground_with: Option<u64>,
    ) -> anyhow::Result<Ingested> {
        let at = now();
        self.refresh_plan();
        let gauged = Gauged {
            setup: super::planned::turn_setup(&self.setup, &self.plan),
            raw: &raw,
            sha256: measurement_sha256(&raw),
            part: Some(part.clone()),
            ground_with: ground_with.and_then(TableVersion::new),
            on_reserve: self.journal.on_reserve(),
            at,
        };
        self.machine.handle(Input::Gauged(Box::new(gauged)));
        let finished = self.run_machine(Some(&raw)).await;
        match finished.into_iter().last() {
            Some(Finished::Recorded(report)) => {
                self.after_part(&raw, part, *report, at).await;
                Ok(Ingested::Recorded)
            }
            Some(Finished::Repeated) => {
                info!(machine = %self.name, part = %raw.header.part, origin = %raw.origin, "measurement already learned from: not learned again");
                Ok(Ingested::Repeated)
            }
            Some(Finished::Rejected { reason }) => Ok(Ingested::Rejected {
                reason: reason.to_string(),
            }),
            Some(Finished::NotRecorded) => {
                // Not counted and not remembered: the same reading sent again once the journal
                // can be written is a new measurement, not a repeat.
                warn!(machine = %self.name, origin = %raw.origin, "part not learned from: its measurement could not be recorded");
                Ok(Ingested::NotRecorded)
            }
            Some(Finished::Failed { reason }) => Err(anyhow::anyhow!(reason)),
            other => Err(anyhow::anyhow!(
                "the feature's loop ended a measurement with {other:?}"
            )),
        }
    }

    /// A recorded part: its control charts, metrics, status and log line.
    async fn after_part(
        &mut self,
        raw: &RawMeasurement,
        part: PartId,
        report: PartReport,
        at: jiff::Timestamp,
    ) {
        let measured = &report.measured;
        let text = match &report.note {
            PartNote::Table => self.delivery_line(),
            PartNote::NotRecorded(e) => {
                let e = MachineError::from(e.clone());
                if self.journal.fenced_out() {
                    warn!(machine = %self.name, error = format!("{e:#}"), "cluster: another instance owns this machine now; table not recorded here");
                } else {
                    error!(machine = %self.name, error = format!("{e:#}"), "table not recorded: previous table stays in force");
                }
                format!("table not recorded: {e:#}")
            }
            PartNote::Refused { in_a_row, reason } => {
                if *in_a_row == 1 {
                    warn!(machine = %self.name, lobe = %self.setup.name, reason = %reason, "table refused, previous table stays in force");
                }
                format!("table refused, previous kept ({in_a_row} in a row)")
            }
            PartNote::Held(reason) => {
                info!(machine = %self.name, reason = %reason, "part analysed, not learned from");
                format!("not learned from: {reason}")
            }
        };
        let charts = self.chart_events(&raw.header.part, measured, at);
        if !charts.is_empty() {
            self.record(charts).await;
        }
        let max_error_um = measured.max_error_um;
        self.metrics.update(&self.name, |m| {
            m.parts_total += 1;
            m.last_max_error_um = max_error_um;
        });
        self.publish_status(&part, measured);
        let line = PartLine {
            feature: self.setup.name.clone(),
            part,
            max_error_um,
            profile_error_um: measured.max_profile_error_um,
            size_error_um: measured.report.base_radius_error_um,
            timing_error_deg: measured.timing_error_deg,
            pushed: report.pushed,
            text,
        };
        let ground_with = report.ground_with.map_or(0, |v| v.get());
        self.log_part_line(&line, report.part_no, ground_with);
        self.last_line = Some(line);
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
    pub(crate) async fn on_master(
        &mut self,
        raw: RawMeasurement,
        part: PartId,
    ) -> anyhow::Result<Ingested> {
        let at = now();
        let sha = measurement_sha256(&raw);
        if self.machine.memory().has_seen(&sha) {
            return Ok(Ingested::Repeated);
        }
        let measured = match turn::measure(&self.setup.turn_setup(), &raw) {
            Ok(m) => m,
            Err(TurnError::Measurement(e)) => {
                let reason = e.to_string();
                self.reject(&raw, &sha, &reason, at).await;
                return Ok(Ingested::Rejected { reason });
            }
            Err(e) => return Err(e.into()),
        };
        let record = self.measurement_record(&raw, part, &sha, &measured, at);
        if !self.record(vec![record]).await {
            return Ok(Ingested::NotRecorded);
        }
        self.machine.memory_mut().remember(sha);
        info!(machine = %self.name, lobe = %self.setup.name, part = %raw.header.part, size_error_um = format!("{:.3}", measured.report.base_radius_error_um), "master run recorded for the gauge study (not learned from)");
        Ok(Ingested::Master)
    }

    fn measurement_record(
        &self,
        raw: &RawMeasurement,
        part: PartId,
        sha: &Sha256,
        measured: &Measured,
        at: jiff::Timestamp,
    ) -> Pending {
        let in_force = self.machine.memory().in_force_version;
        Pending::Measurement {
            measurement: records::measurement(
                (&self.name, &self.setup.name, part),
                raw,
                sha,
                measured,
                at,
            ),
            ground_with_version: in_force,
        }
    }

    /// A measurement that is not this machine's, or fails the checks: kept among the
    /// rejects with the reason, recorded as an event, never learned from.
    pub(super) async fn reject(
        &mut self,
        raw: &RawMeasurement,
        sha: &Sha256,
        reason: &str,
        at: jiff::Timestamp,
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
            at,
            EventLevel::Warn,
            EventKind::MeasurementRejected,
            message,
        );
        self.record(vec![e]).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(machine: &str, part: &str, lobe: &str) -> MeasurementHeader {
        MeasurementHeader {
            machine: machine.into(),
            part: part.into(),
            lobe: lobe.into(),
            revolutions: 3,
            points_per_rev: 360,
        }
    }

    /// The routing is where a gauge's part label becomes a `PartId`: a label off the gauges'
    /// rule is refused there with its text, by name or by the bus's numeric ids alike.
    #[test]
    fn a_routed_measurement_carries_its_part_id_and_a_bad_label_is_refused() {
        let ids = GaugeIds {
            machine: "G7".parse().unwrap(),
            features: vec!["IN1".parse().unwrap(), "EX1".parse().unwrap()],
        };
        let (index, part) = ids.route(&header("G7", "S-17.a", "EX1"), None).unwrap();
        assert_eq!((index, part.as_str()), (1, "S-17.a"));
        let (index, part) = ids.route(&header("1", "1234", "1"), None).unwrap();
        assert_eq!((index, part.as_str()), (0, "1234"));
        for bad in ["", "S 17", "../x", &"9".repeat(33)] {
            let err = ids.route(&header("G7", bad, "IN1"), None).unwrap_err();
            assert!(
                err.starts_with("measurement names part id"),
                "{bad:?}: {err}"
            );
            assert!(err.contains(&crate::names::quote(bad)), "{bad:?}: {err}");
        }
        // The machine and the feature are still judged first, as before.
        let err = ids.route(&header("G8", "S 17", "IN1"), None).unwrap_err();
        assert!(err.contains("this is machine"), "{err}");
    }
}
