//! The plant's events on their way out of the machine loops: the [`PlantEvent`] each
//! journal record announces, its JSON payload, and the [`EventSender`] the loops hand them
//! to (it feeds MQTT's intake and OPC UA's feed alike, so neither adapter owns it). The
//! MQTT wire's payload with its sequence number is the MQTT crate's.

use jiff::Timestamp;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use tokio::sync::mpsc;

use crate::names::{FeatureName, MachineName};
use crate::service::journal::{EventKind, Pending};
use crate::store::{EventLevel, VersionStatus};
use camloop_loop::{MACHINE_LEVEL, PlantEvent, TableVersion};

/// [`MACHINE_LEVEL`] where a feature's name goes (a topic level, a payload's `feature`).
fn machine_level() -> FeatureName {
    FeatureName::new(MACHINE_LEVEL).expect("`machine` follows the name rule")
}

/// Where the machine loops send events. Cheap to clone; never blocks.
#[derive(Debug, Clone)]
pub struct EventSender {
    tx: mpsc::Sender<PlantEvent>,
    refused: Arc<AtomicU64>,
    /// Another consumer of the same events (the OPC UA server), sent to first.
    also: Option<Arc<EventSender>>,
}

impl EventSender {
    /// A sender into `tx`, counting what a full channel refuses in `refused` (public for
    /// the tests that watch a machine's events).
    pub fn new(tx: mpsc::Sender<PlantEvent>, refused: Arc<AtomicU64>) -> Self {
        Self {
            tx,
            refused,
            also: None,
        }
    }

    /// One sender feeding both, or whichever there is.
    pub(crate) fn joined(a: Option<Self>, b: Option<Self>) -> Option<Self> {
        match (a, b) {
            (Some(mut a), Some(b)) => {
                a.also = Some(Arc::new(b));
                Some(a)
            }
            (a, b) => a.or(b),
        }
    }

    /// Events this sender's own channel refused (full) so far.
    pub fn refused(&self) -> u64 {
        self.refused.load(Ordering::Relaxed)
    }

    pub fn send(&self, event: PlantEvent) {
        if let Some(other) = &self.also {
            other.send(event.clone());
        }
        if self.tx.try_send(event).is_err() {
            self.refused.fetch_add(1, Ordering::Relaxed);
        }
    }
}

impl From<camloop_mqtt::Intake> for EventSender {
    /// The MQTT publisher's intake, counting what it refuses where MQTT reports its drops.
    fn from(intake: camloop_mqtt::Intake) -> Self {
        let (tx, refused) = intake.into_parts();
        Self::new(tx, refused)
    }
}

/// The event a journal record announces, if any (learning snapshots and recipes are
/// the loop's own business, and a master run is the gauge study's: a plant counts its
/// parts from `part_analysed`, and neither a master nor an in-process measurement is one).
pub(crate) fn of_record(record: &Pending) -> Option<PlantEvent> {
    if let Pending::Measurement { measurement, .. } = record
        && (crate::core::measure::is_master_part(&measurement.part)
            || measurement.stage != crate::store::MeasurementStage::Final)
    {
        return None;
    }
    Some(match record.clone() {
        // The plant's payload: the summary of the store's record (the wire names stay).
        Pending::Measurement {
            measurement: m,
            ground_with_version,
        } => PlantEvent::PartAnalysed {
            machine: m.machine,
            feature: m.lobe,
            part: m.part,
            at: m.received_at,
            verdict: m.verdict,
            max_profile_error_um: m.max_profile_error_um,
            base_radius_error_um: m.base_radius_error_um,
            phase_error_deg: m.phase_error_deg,
            ground_with_version,
            repeatability_um: repeatability_um(&m.analysis_json),
        },
        Pending::Table {
            machine,
            lobe,
            version,
            status,
            created_at,
            ..
        } => table_event(machine, lobe, version, status, created_at)?,
        Pending::VersionStatus {
            machine,
            lobe,
            version,
            status,
            at,
        } => table_event(machine, lobe, version, status, at)?,
        Pending::Event {
            machine,
            at,
            level,
            kind,
            message,
        } => event_of(machine, at, level, kind, message)?,
        Pending::Dressing {
            machine,
            at,
            old_radius_mm,
            new_radius_mm,
            infeed_um,
            source,
        } => PlantEvent::Dressing {
            machine,
            at,
            old_radius_mm,
            new_radius_mm,
            infeed_um,
            source,
        },
        Pending::Learning { .. } | Pending::RecipeSnapshot { .. } => return None,
    })
}

/// The event's JSON payload (the MQTT wire's).
pub fn payload(event: &PlantEvent) -> String {
    // Strings, numbers and enums only: serializing cannot fail.
    serde_json::to_string(event).expect("a plant event serializes to JSON")
}

/// The gauge's repeatability a measurement's analysis reported (`repeatability_max_um` of
/// the core's report, which the measurement stores as JSON); `None` when it has none.
fn repeatability_um(analysis_json: &str) -> Option<f64> {
    #[derive(serde::Deserialize)]
    struct Reported {
        repeatability_max_um: f64,
    }
    serde_json::from_str::<Reported>(analysis_json)
        .ok()
        .map(|r| r.repeatability_max_um)
}

/// The plant's event for a loop event, if it has one of its own.
fn event_of(
    machine: MachineName,
    at: Timestamp,
    level: EventLevel,
    kind: EventKind,
    message: String,
) -> Option<PlantEvent> {
    Some(match kind {
        EventKind::LearningReverted => PlantEvent::LearningFrozen {
            machine,
            at,
            reason: message,
        },
        // A table refused by the loop's checks before it got a version.
        EventKind::TableRefused => PlantEvent::TableRefused {
            machine,
            feature: machine_level(),
            version: None,
            reason: message,
            at,
        },
        // Told by the dressing record itself.
        EventKind::WheelDressed => return None,
        _ => PlantEvent::Alarm {
            machine,
            at,
            level,
            kind: kind.as_str().to_owned(),
            message,
        },
    })
}

fn table_event(
    machine: MachineName,
    feature: FeatureName,
    version: TableVersion,
    status: VersionStatus,
    at: Timestamp,
) -> Option<PlantEvent> {
    match status {
        VersionStatus::Pushed { .. } => Some(PlantEvent::TableDelivered {
            machine,
            feature,
            version,
            at,
        }),
        VersionStatus::Refused { reason } => Some(PlantEvent::TableRefused {
            machine,
            feature,
            version: Some(version),
            reason,
            at,
        }),
        // Not the plant's news yet: the share's own states never reach the journal.
        VersionStatus::Waiting { .. }
        | VersionStatus::Delivering
        | VersionStatus::Superseded { .. } => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(n: u64) -> crate::core::ids::TableVersion {
        crate::core::ids::TableVersion::new(n).unwrap()
    }
    use crate::store::Verdict;

    #[test]
    fn records_map_to_events_with_topics_and_unit_named_fields() {
        let status = Pending::VersionStatus {
            machine: "G7".parse().unwrap(),
            lobe: "IN1".parse().unwrap(),
            version: v(12),
            status: VersionStatus::Pushed {
                at: jiff::Timestamp::from_millisecond(5).expect("a time"),
                note: Some("pushed".into()),
            },
            at: jiff::Timestamp::from_millisecond(5).unwrap(),
        };
        let e = of_record(&status).unwrap();
        assert_eq!(e.topic("plant"), "plant/G7/IN1/table_delivered");
        assert_eq!(
            payload(&e),
            r#"{"event":"table_delivered","machine":"G7","feature":"IN1","version":12,"at_ms":5}"#
        );
        let dressing = Pending::Dressing {
            machine: "G7".parse().unwrap(),
            at: jiff::Timestamp::from_millisecond(9).unwrap(),
            old_radius_mm: 250.0,
            new_radius_mm: 249.5,
            infeed_um: Some(500.2),
            source: "plc".into(),
        };
        let d = of_record(&dressing).unwrap();
        assert_eq!(d.topic("p"), "p/G7/machine/dressing");
        assert!(payload(&d).contains(r#""new_radius_mm":249.5"#));
        assert!(payload(&d).contains(r#""infeed_um":500.2"#));
        let event = |kind| Pending::Event {
            machine: "G7".parse().unwrap(),
            at: jiff::Timestamp::from_millisecond(1).unwrap(),
            level: EventLevel::Warn,
            kind,
            message: "diverging".into(),
        };
        let name = |kind| of_record(&event(kind)).map(|e| e.name());
        assert_eq!(name(EventKind::LearningReverted), Some("learning_frozen"));
        assert_eq!(name(EventKind::TableRefused), Some("table_refused"));
        assert_eq!(name(EventKind::LearningHeld), Some("alarm"));
        assert_eq!(name(EventKind::RunRule), Some("alarm"));
        assert_eq!(name(EventKind::WheelDressed), None);
        let waiting = Pending::VersionStatus {
            machine: "G7".parse().unwrap(),
            lobe: "IN1".parse().unwrap(),
            version: v(13),
            status: VersionStatus::Waiting {
                reason: Some("share down".into()),
            },
            at: jiff::Timestamp::from_millisecond(6).unwrap(),
        };
        assert_eq!(of_record(&waiting), None);
    }

    #[test]
    fn a_master_run_is_no_part_analysed_and_a_production_part_is() {
        let measurement = |part: &str| Pending::Measurement {
            measurement: crate::store::NewMeasurement {
                machine: "G7".parse().unwrap(),
                part: part.parse().unwrap(),
                lobe: "IN1".parse().unwrap(),
                received_at: jiff::Timestamp::from_millisecond(7).unwrap(),
                verdict: Verdict::Pass,
                max_profile_error_um: 0.4,
                base_radius_error_um: 0.1,
                phase_error_deg: 0.0,
                revolutions_used: 3,
                stage: crate::store::MeasurementStage::Final,
                points_per_rev: 360,
                origin: "gauge".into(),
                sha256: "0".repeat(64).parse().unwrap(),
                recipe_snapshot: None,
                raw_lift_mm: Vec::new(),
                averaged_lift_mm: Vec::new(),
                analysis_json: "{}".into(),
            },
            ground_with_version: None,
        };
        for master in ["MASTER", "master-7", "Master_B"] {
            assert_eq!(of_record(&measurement(master)), None, "{master}");
        }
        let part = of_record(&measurement("S-1042")).unwrap();
        assert_eq!(part.name(), "part_analysed");
        // No repeatability in an analysis that has none ("{}"), and none on the wire.
        assert!(matches!(
            part,
            PlantEvent::PartAnalysed {
                repeatability_um: None,
                ..
            }
        ));
        assert!(!payload(&part).contains("repeatability"));
    }

    /// The repeatability is the report's typed field, read from what the measurement keeps.
    #[test]
    fn repeatability_is_the_reports_largest_spread() {
        assert_eq!(
            repeatability_um(r#"{"repeatability_max_um":0.8,"other":1}"#),
            Some(0.8)
        );
        assert_eq!(
            repeatability_um(r#"{"nested":{"repeatability_max_um":0.8}}"#),
            None
        );
        assert_eq!(repeatability_um("not json"), None);
    }

    /// Read from the core's own report as a measurement stores it: a field renamed in the
    /// core fails here, not as events without repeatability in the field.
    #[test]
    fn repeatability_is_read_from_the_cores_report() {
        use crate::core::analysis::{LobeOptions, analyse_lobe};
        use crate::core::measure::AveragedMeasurement;
        let n = 360;
        let nominal = |psi: f64| {
            let r = psi.to_radians();
            (2.0 + r.cos(), -r.sin() * std::f64::consts::PI / 180.0)
        };
        // The gauge's spread differs per angle; its largest (0.7 µm) is the one reported.
        let spread: Vec<f64> = (0..n).map(|k| if k == 90 { 0.7 } else { 0.2 }).collect();
        let avg = AveragedMeasurement {
            origin: "test".into(),
            points_per_rev: n as u32,
            mean_lift_mm: (0..n)
                .map(|k| nominal(k as f64 * 360.0 / n as f64).0)
                .collect(),
            repeatability_std_um: spread,
            repeatability_range_um: vec![0.5; n],
            revolutions_used: vec![0, 1, 2],
            dropped_revolutions: Vec::new(),
        };
        let report = analyse_lobe(&avg, &nominal, &LobeOptions::default()).unwrap();
        let stored = serde_json::to_string(&report).unwrap();
        assert_eq!(repeatability_um(&stored), Some(0.7));
    }
}
