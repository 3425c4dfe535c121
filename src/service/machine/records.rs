//! The records a machine writes: the loop's records ([`camloop_loop::record`]) in the
//! journal's file format, events, measurements as the journal keeps them, rejects kept on
//! disk with their reason.

use super::super::journal::{EventKind, Pending};
use crate::core::digest::Sha256;
use crate::core::ids::PartId;
use crate::core::measure::RawMeasurement;
use crate::core::turn::Measured;
use crate::names::{FeatureName, MachineName};
use crate::store::{EventLevel, MeasurementStage, NewMeasurement, Verdict, VersionStatus};
use camloop_loop::record::{self, Record, TableStatus};
use std::path::Path;

pub(super) fn event(
    machine: &MachineName,
    at: jiff::Timestamp,
    level: EventLevel,
    kind: EventKind,
    message: String,
) -> Pending {
    Pending::Event {
        machine: machine.clone(),
        at,
        level,
        kind,
        message,
    }
}

/// The store's word for an event kind of the loop.
fn kind(k: record::EventKind) -> EventKind {
    use record::EventKind as K;
    match k {
        K::MeasurementRejected => EventKind::MeasurementRejected,
        K::MeasurementRepeated => EventKind::MeasurementRepeated,
        K::TableRefused => EventKind::TableRefused,
        K::LearningReverted => EventKind::LearningReverted,
        K::LearningHeld => EventKind::LearningHeld,
        K::ShareUnavailable => EventKind::ShareUnavailable,
        K::ShareBack => EventKind::ShareBack,
        K::BlockedByGuard => EventKind::BlockedByGuard,
        K::GuardCleared => EventKind::GuardCleared,
    }
}

/// A version's status as the share and the store keep it.
pub(super) fn status(s: TableStatus, at: jiff::Timestamp) -> VersionStatus {
    match s {
        TableStatus::Waiting { reason } => VersionStatus::Waiting { reason },
        TableStatus::Pushed { note } => VersionStatus::pushed_at(at, &note),
        TableStatus::Refused { reason } => VersionStatus::Refused { reason },
    }
}

/// The loop's records of feature `lobe` of `machine` in the journal's format; `raw` is the
/// measurement of the step, whose samples the measurement record keeps.
pub(super) fn pending(
    machine: &MachineName,
    lobe: &FeatureName,
    records: Vec<Record>,
    raw: Option<&RawMeasurement>,
) -> Vec<Pending> {
    records
        .into_iter()
        .filter_map(|r| match r {
            // The service gives the machine every part it routed with its id; only the
            // simulated cell's machine measures without one, and it keeps no records.
            Record::Measurement {
                sha256,
                part,
                measured,
                ground_with,
                at,
            } => {
                let (raw, part) = (raw?, part?);
                Some(Pending::Measurement {
                    measurement: measurement((machine, lobe, part), raw, &sha256, &measured, at),
                    ground_with_version: ground_with,
                })
            }
            Record::Table(t) => Some(Pending::Table {
                machine: machine.clone(),
                lobe: lobe.clone(),
                version: t.version,
                parent_version: t.parent,
                table_number: t.table_number,
                program_text: t.program_text,
                learning: t.learning,
                reason: t.reason,
                status: status(t.status, t.at),
                created_at: t.at,
                measurement_id: t.measurement,
                rollback_of: t.rollback_of,
            }),
            Record::Status {
                version,
                status: s,
                at,
            } => Some(Pending::VersionStatus {
                machine: machine.clone(),
                lobe: lobe.clone(),
                version,
                status: status(s, at),
                at,
            }),
            Record::Event {
                at,
                level,
                kind: k,
                message,
            } => Some(event(machine, at, level, kind(k), message)),
            Record::Learning { memory, at } => Some(Pending::Learning {
                machine: machine.clone(),
                lobe: lobe.clone(),
                state: memory,
                saved_at: at,
            }),
        })
        .collect()
}

/// A measurement of the finished part as the store keeps it (the in-process one sets its
/// stage after).
pub(super) fn measurement(
    (machine, lobe, part): (&MachineName, &FeatureName, PartId),
    raw: &RawMeasurement,
    sha: &Sha256,
    measured: &Measured,
    received_at: jiff::Timestamp,
) -> NewMeasurement {
    let report = &measured.report;
    NewMeasurement {
        machine: machine.clone(),
        part,
        lobe: lobe.clone(),
        received_at,
        verdict: if report.verdict.pass {
            Verdict::Pass
        } else {
            Verdict::Fail
        },
        max_profile_error_um: measured.max_profile_error_um,
        base_radius_error_um: report.base_radius_error_um,
        phase_error_deg: report.phase_error_deg,
        revolutions_used: measured.averaged.revolutions_used.len() as u32,
        stage: MeasurementStage::Final,
        points_per_rev: measured.averaged.points_per_rev,
        origin: raw.origin.clone(),
        sha256: *sha,
        recipe_snapshot: None,
        raw_lift_mm: raw_revolutions(raw),
        averaged_lift_mm: measured.averaged.mean_lift_mm.clone(),
        analysis_json: serde_json::to_string(report).unwrap_or_default(),
    }
}

/// Raw lifts per revolution, in revolution order (samples are complete after the checks).
pub(super) fn raw_revolutions(raw: &RawMeasurement) -> Vec<Vec<f64>> {
    let n = raw.header.points_per_rev as usize;
    let revs = raw.header.revolutions as usize;
    let mut out = vec![vec![0.0; n]; revs];
    for s in &raw.samples {
        if let Some(slot) = out
            .get_mut(s.revolution as usize)
            .and_then(|r| r.get_mut(s.angle_index as usize))
        {
            *slot = s.lift_mm;
        }
    }
    out
}

/// A rejected measurement is kept as CSV in `<dir>` with its reason beside it, named by its
/// content identity (so a repeat overwrites rather than piles up).
pub(super) fn keep_reject(
    dir: &Path,
    raw: &RawMeasurement,
    sha: &Sha256,
    reason: &str,
) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut csv = format!(
        "# machine={} part={} lobe={}\n# points_per_rev={} revolutions={}\n# origin: {}\nrev,angle_deg,lift_mm\n",
        raw.header.machine,
        raw.header.part,
        raw.header.lobe,
        raw.header.points_per_rev,
        raw.header.revolutions,
        raw.origin.replace('\n', " ")
    );
    for s in &raw.samples {
        let angle = f64::from(s.angle_index) * 360.0 / f64::from(raw.header.points_per_rev.max(1));
        csv.push_str(&format!("{},{angle},{}\n", s.revolution, s.lift_mm));
    }
    let hex = sha.to_string();
    let stem = &hex[..16];
    std::fs::write(dir.join(format!("{stem}.csv")), csv)?;
    std::fs::write(
        dir.join(format!("{stem}.reason.txt")),
        format!("{reason}\n"),
    )
}
