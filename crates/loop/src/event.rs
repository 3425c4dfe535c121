//! What the plant hears: typed events made from the loop's records, with their topic
//! (`<prefix>/<machine>/<feature>/<event>`) and JSON shape (units in the field names). MQTT
//! publishes them, OPC UA shows them; neither adapter owns them.

use jiff::Timestamp;
use serde::{Deserialize, Serialize};

use crate::{FeatureName, MachineName, PartId, TableVersion};
use camloop_core::levels::{EventLevel, Verdict};

/// Topic level (and a payload's `feature`) for events that concern the machine rather than
/// one feature.
pub const MACHINE_LEVEL: &str = "machine";

/// One event for the plant (MQTT's topics, OPC UA's values and events).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum PlantEvent {
    PartAnalysed {
        machine: MachineName,
        feature: FeatureName,
        part: PartId,
        #[serde(rename = "at_ms", with = "crate::unix_ms")]
        at: Timestamp,
        verdict: Verdict,
        max_profile_error_um: f64,
        base_radius_error_um: f64,
        phase_error_deg: f64,
        /// Version of the table the part was ground with, when known (null on the wire;
        /// an older payload's 0 reads as none).
        #[serde(default, with = "camloop_core::ids::lenient_version")]
        ground_with_version: Option<TableVersion>,
        /// The gauge's repeatability: the largest per-angle spread (1σ) over the
        /// revolutions, µm, when the analysis reported it. Not on the MQTT wire (its
        /// payload stays as it was); OPC UA shows it.
        #[serde(skip)]
        repeatability_um: Option<f64>,
    },
    TableDelivered {
        machine: MachineName,
        feature: FeatureName,
        version: TableVersion,
        #[serde(rename = "at_ms", with = "crate::unix_ms")]
        at: Timestamp,
    },
    TableRefused {
        machine: MachineName,
        feature: FeatureName,
        /// The refused version, when one was recorded.
        version: Option<TableVersion>,
        reason: String,
        #[serde(rename = "at_ms", with = "crate::unix_ms")]
        at: Timestamp,
    },
    LearningFrozen {
        machine: MachineName,
        #[serde(rename = "at_ms", with = "crate::unix_ms")]
        at: Timestamp,
        reason: String,
    },
    Dressing {
        machine: MachineName,
        #[serde(rename = "at_ms", with = "crate::unix_ms")]
        at: Timestamp,
        old_radius_mm: f64,
        new_radius_mm: f64,
        /// The dresser's measured infeed, µm, when it reported one.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        infeed_um: Option<f64>,
        source: String,
    },
    Alarm {
        machine: MachineName,
        #[serde(rename = "at_ms", with = "crate::unix_ms")]
        at: Timestamp,
        level: EventLevel,
        kind: String,
        message: String,
    },
}

impl PlantEvent {
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
    pub fn feature_name(&self) -> Option<&FeatureName> {
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

    /// When it happened (`at_ms` on the wire, integer Unix milliseconds).
    pub fn at(&self) -> Timestamp {
        match self {
            PlantEvent::PartAnalysed { at, .. }
            | PlantEvent::TableDelivered { at, .. }
            | PlantEvent::TableRefused { at, .. }
            | PlantEvent::LearningFrozen { at, .. }
            | PlantEvent::Dressing { at, .. }
            | PlantEvent::Alarm { at, .. } => *at,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(ground_with_version: Option<TableVersion>) -> PlantEvent {
        PlantEvent::PartAnalysed {
            machine: "M1".parse().expect("a machine name"),
            feature: "IN1".parse().expect("a feature name"),
            part: "P1".parse().unwrap(),
            at: Timestamp::from_millisecond(1_000).expect("a time"),
            verdict: Verdict::Pass,
            max_profile_error_um: 1.5,
            base_radius_error_um: 0.0,
            phase_error_deg: 0.0,
            ground_with_version,
            repeatability_um: None,
        }
    }

    /// The version a part was ground with is its number on the wire, null when none is
    /// known; a payload of a build that wrote 0 for none reads as none, not as a version.
    #[test]
    fn ground_with_version_is_null_when_none_is_known() {
        let none = serde_json::to_value(part(None)).expect("serializes");
        assert_eq!(none["ground_with_version"], serde_json::Value::Null);
        let three = serde_json::to_value(part(TableVersion::new(3))).expect("serializes");
        assert_eq!(three["ground_with_version"], 3);
        assert_eq!(
            three["at_ms"], 1_000,
            "the time keeps its wire name and form"
        );
        let mut old = three.clone();
        old["ground_with_version"] = 0.into();
        let back: PlantEvent = serde_json::from_value(old).expect("an old payload reads");
        assert_eq!(back, part(None));
        let back: PlantEvent = serde_json::from_value(three).expect("reads back");
        assert_eq!(back, part(TableVersion::new(3)));
    }
}
