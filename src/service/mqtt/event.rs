//! What the plant hears: typed events made from the loop's journal records, their topics
//! and JSON payloads (units in the field names).

use jiff::Timestamp;
use serde::{Deserialize, Serialize};

use crate::names::{FeatureName, MachineName};
use crate::service::journal::{EventKind, Pending};
use crate::store::{EventLevel, Verdict, VersionStatus};

/// Topic level for events that concern the machine rather than one feature.
pub const MACHINE_LEVEL: &str = "machine";

/// [`MACHINE_LEVEL`] where a feature's name goes (a topic level, a payload's `feature`).
fn machine_level() -> FeatureName {
    FeatureName::new(MACHINE_LEVEL).expect("`machine` follows the name rule")
}

/// One event for the broker.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum PlantEvent {
    PartAnalysed {
        machine: MachineName,
        feature: FeatureName,
        part: String,
        #[serde(with = "crate::clock::unix_ms")]
        at_ms: Timestamp,
        verdict: Verdict,
        max_profile_error_um: f64,
        base_radius_error_um: f64,
        phase_error_deg: f64,
        /// Version of the table the part was ground with (0: none known).
        ground_with_version: u64,
    },
    TableDelivered {
        machine: MachineName,
        feature: FeatureName,
        version: u64,
        #[serde(with = "crate::clock::unix_ms")]
        at_ms: Timestamp,
    },
    TableRefused {
        machine: MachineName,
        feature: FeatureName,
        /// The refused version, when one was recorded.
        version: Option<u64>,
        reason: String,
        #[serde(with = "crate::clock::unix_ms")]
        at_ms: Timestamp,
    },
    LearningFrozen {
        machine: MachineName,
        #[serde(with = "crate::clock::unix_ms")]
        at_ms: Timestamp,
        reason: String,
    },
    Dressing {
        machine: MachineName,
        #[serde(with = "crate::clock::unix_ms")]
        at_ms: Timestamp,
        old_radius_mm: f64,
        new_radius_mm: f64,
        /// The dresser's measured infeed, µm, when it reported one.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        infeed_um: Option<f64>,
        source: String,
    },
    Alarm {
        machine: MachineName,
        #[serde(with = "crate::clock::unix_ms")]
        at_ms: Timestamp,
        level: EventLevel,
        kind: String,
        message: String,
    },
}

impl PlantEvent {
    /// The event a journal record announces, if any (learning snapshots and recipes are
    /// the loop's own business, and a master run is the gauge study's: a plant counts its
    /// parts from `part_analysed`, and a master is not one).
    pub(crate) fn from_pending(record: &Pending) -> Option<Self> {
        if let Pending::Measurement { measurement, .. } = record
            && crate::core::measure::is_master_part(&measurement.part)
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
                at_ms: m.received_at_ms,
                verdict: m.verdict,
                max_profile_error_um: m.max_profile_error_um,
                base_radius_error_um: m.base_radius_error_um,
                phase_error_deg: m.phase_error_deg,
                ground_with_version,
            },
            Pending::Table {
                machine,
                lobe,
                version,
                status,
                created_at_ms,
                ..
            } => table_event(machine, lobe, version, status, created_at_ms)?,
            Pending::VersionStatus {
                machine,
                lobe,
                version,
                status,
                at_ms,
            } => table_event(machine, lobe, version, status, at_ms)?,
            Pending::Event {
                machine,
                at_ms,
                level,
                kind,
                message,
            } => event_of(machine, at_ms, level, kind, message)?,
            Pending::Dressing {
                machine,
                at_ms,
                old_radius_mm,
                new_radius_mm,
                infeed_um,
                source,
            } => PlantEvent::Dressing {
                machine,
                at_ms,
                old_radius_mm,
                new_radius_mm,
                infeed_um,
                source,
            },
            Pending::Learning { .. } | Pending::RecipeSnapshot { .. } => return None,
        })
    }

    pub fn machine(&self) -> &MachineName {
        match self {
            PlantEvent::PartAnalysed { machine, .. }
            | PlantEvent::TableDelivered { machine, .. }
            | PlantEvent::TableRefused { machine, .. }
            | PlantEvent::LearningFrozen { machine, .. }
            | PlantEvent::Dressing { machine, .. }
            | PlantEvent::Alarm { machine, .. } => machine,
        }
    }

    /// The feature (lobe or pin) it concerns, or [`MACHINE_LEVEL`].
    pub fn feature(&self) -> &str {
        self.feature_name()
            .map_or(MACHINE_LEVEL, FeatureName::as_str)
    }

    /// The feature's name, for the events that carry one.
    pub(crate) fn feature_name(&self) -> Option<&FeatureName> {
        match self {
            PlantEvent::PartAnalysed { feature, .. }
            | PlantEvent::TableDelivered { feature, .. }
            | PlantEvent::TableRefused { feature, .. } => Some(feature),
            _ => None,
        }
    }

    /// The event's snake_case name, the last topic level.
    pub fn name(&self) -> &'static str {
        match self {
            PlantEvent::PartAnalysed { .. } => "part_analysed",
            PlantEvent::TableDelivered { .. } => "table_delivered",
            PlantEvent::TableRefused { .. } => "table_refused",
            PlantEvent::LearningFrozen { .. } => "learning_frozen",
            PlantEvent::Dressing { .. } => "dressing",
            PlantEvent::Alarm { .. } => "alarm",
        }
    }

    /// `<prefix>/<machine>/<feature>/<event>`.
    pub fn topic(&self, prefix: &str) -> String {
        format!(
            "{prefix}/{}/{}/{}",
            self.machine(),
            self.feature(),
            self.name()
        )
    }

    pub fn payload(&self) -> String {
        // Strings, numbers and enums only: serializing cannot fail.
        serde_json::to_string(self).expect("a plant event serializes to JSON")
    }

    /// The payload with the event's sequence number (`seq`) last.
    pub(crate) fn payload_with_seq(&self, seq: u64) -> String {
        let mut value = serde_json::to_value(self).expect("a plant event serializes to JSON");
        if let Some(fields) = value.as_object_mut() {
            fields.insert("seq".into(), seq.into());
        }
        value.to_string()
    }

    pub fn at_ms(&self) -> Timestamp {
        match self {
            PlantEvent::PartAnalysed { at_ms, .. }
            | PlantEvent::TableDelivered { at_ms, .. }
            | PlantEvent::TableRefused { at_ms, .. }
            | PlantEvent::LearningFrozen { at_ms, .. }
            | PlantEvent::Dressing { at_ms, .. }
            | PlantEvent::Alarm { at_ms, .. } => *at_ms,
        }
    }
}

/// The plant's event for a loop event, if it has one of its own.
fn event_of(
    machine: MachineName,
    at_ms: Timestamp,
    level: EventLevel,
    kind: EventKind,
    message: String,
) -> Option<PlantEvent> {
    Some(match kind {
        EventKind::LearningReverted => PlantEvent::LearningFrozen {
            machine,
            at_ms,
            reason: message,
        },
        // A table refused by the loop's checks before it got a version.
        EventKind::TableRefused => PlantEvent::TableRefused {
            machine,
            feature: machine_level(),
            version: None,
            reason: message,
            at_ms,
        },
        // Told by the dressing record itself.
        EventKind::WheelDressed => return None,
        _ => PlantEvent::Alarm {
            machine,
            at_ms,
            level,
            kind: kind.as_str().to_owned(),
            message,
        },
    })
}

fn table_event(
    machine: MachineName,
    feature: FeatureName,
    version: u64,
    status: VersionStatus,
    at_ms: Timestamp,
) -> Option<PlantEvent> {
    match status {
        VersionStatus::Pushed { .. } => Some(PlantEvent::TableDelivered {
            machine,
            feature,
            version,
            at_ms,
        }),
        VersionStatus::Refused { reason } => Some(PlantEvent::TableRefused {
            machine,
            feature,
            version: Some(version),
            reason,
            at_ms,
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

    #[test]
    fn records_map_to_events_with_topics_and_unit_named_fields() {
        let status = Pending::VersionStatus {
            machine: "G7".parse().unwrap(),
            lobe: "IN1".parse().unwrap(),
            version: 12,
            status: VersionStatus::Pushed {
                at_unix_ms: 5,
                note: Some("pushed".into()),
            },
            at_ms: jiff::Timestamp::from_millisecond(5).unwrap(),
        };
        let e = PlantEvent::from_pending(&status).unwrap();
        assert_eq!(e.topic("plant"), "plant/G7/IN1/table_delivered");
        assert_eq!(
            e.payload(),
            r#"{"event":"table_delivered","machine":"G7","feature":"IN1","version":12,"at_ms":5}"#
        );
        let dressing = Pending::Dressing {
            machine: "G7".parse().unwrap(),
            at_ms: jiff::Timestamp::from_millisecond(9).unwrap(),
            old_radius_mm: 250.0,
            new_radius_mm: 249.5,
            infeed_um: Some(500.2),
            source: "plc".into(),
        };
        let d = PlantEvent::from_pending(&dressing).unwrap();
        assert_eq!(d.topic("p"), "p/G7/machine/dressing");
        assert!(d.payload().contains(r#""new_radius_mm":249.5"#));
        assert!(d.payload().contains(r#""infeed_um":500.2"#));
        let event = |kind| Pending::Event {
            machine: "G7".parse().unwrap(),
            at_ms: jiff::Timestamp::from_millisecond(1).unwrap(),
            level: EventLevel::Warn,
            kind,
            message: "diverging".into(),
        };
        let name = |kind| PlantEvent::from_pending(&event(kind)).map(|e| e.name());
        assert_eq!(name(EventKind::LearningReverted), Some("learning_frozen"));
        assert_eq!(name(EventKind::TableRefused), Some("table_refused"));
        assert_eq!(name(EventKind::LearningHeld), Some("alarm"));
        assert_eq!(name(EventKind::RunRule), Some("alarm"));
        assert_eq!(name(EventKind::WheelDressed), None);
        let waiting = Pending::VersionStatus {
            machine: "G7".parse().unwrap(),
            lobe: "IN1".parse().unwrap(),
            version: 13,
            status: VersionStatus::Waiting {
                reason: Some("share down".into()),
            },
            at_ms: jiff::Timestamp::from_millisecond(6).unwrap(),
        };
        assert_eq!(PlantEvent::from_pending(&waiting), None);
    }

    #[test]
    fn a_master_run_is_no_part_analysed_and_a_production_part_is() {
        let measurement = |part: &str| Pending::Measurement {
            measurement: crate::store::NewMeasurement {
                machine: "G7".parse().unwrap(),
                part: part.into(),
                lobe: "IN1".parse().unwrap(),
                received_at_ms: jiff::Timestamp::from_millisecond(7).unwrap(),
                verdict: Verdict::Pass,
                max_profile_error_um: 0.4,
                base_radius_error_um: 0.1,
                phase_error_deg: 0.0,
                revolutions_used: 3,
                points_per_rev: 360,
                origin: "gauge".into(),
                sha256: "0".repeat(64).parse().unwrap(),
                recipe_snapshot: None,
                raw_lift_mm: Vec::new(),
                averaged_lift_mm: Vec::new(),
                analysis_json: "{}".into(),
            },
            ground_with_version: 0,
        };
        for master in ["MASTER", "master-7", "Master_B"] {
            assert_eq!(
                PlantEvent::from_pending(&measurement(master)),
                None,
                "{master}"
            );
        }
        let part = PlantEvent::from_pending(&measurement("S-1042")).unwrap();
        assert_eq!(part.name(), "part_analysed");
    }
}
