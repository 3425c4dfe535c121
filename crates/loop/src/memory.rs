//! What a feature's loop remembers between parts, as one typed, versioned record: the
//! learning state of the table on the control, the table waiting for the share if any, the
//! wheel, and the identities of the newest measurements. It travels through the journal into
//! the store, and a restart resumes from the newest copy ([`LoopMemory::resume`]).

use crate::guards::GuardStreak;
use crate::record::Kept;
use camloop_core::digest::Sha256;
use camloop_core::ids::{PartId, TableVersion};
use camloop_core::learn::{LearningParams, LearningState, PreviousPart};
use serde::{Deserialize, Deserializer, Serialize};

/// Layout of [`LoopMemory`] written by this build. Records without the field are layout 1
/// (one learning state, no version attribution) and are read as such.
pub const MEMORY_SCHEMA: u32 = 2;

/// How many measurement identities are remembered to recognise a repeat.
pub const RECENT_MEASUREMENTS: usize = 256;

/// A table computed and recorded but not yet on the control (the share refused it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WaitingTable {
    /// Its version on the share.
    pub version: TableVersion,
    /// The state to adopt once it is delivered.
    pub learning: LearningState,
    /// Wheel radius it was made for, mm.
    pub wheel_radius_mm: f64,
    /// With a speed plan: the virtual axis' speed its program was rendered for, rev/min.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub va_speed_rpm: Option<f64>,
}

/// The loop's memory (see the module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoopMemory {
    #[serde(default = "layout_one")]
    pub schema: u32,
    /// The learning state of the table on the control: its correction ground the parts now
    /// being measured, so every learning step starts from it.
    pub learning: LearningState,
    /// Version of the table on the control, None before the first delivery (written as 0,
    /// the form the journal and the store have always held).
    #[serde(default, with = "camloop_core::ids::lenient_version::zero_for_none")]
    pub in_force_version: Option<TableVersion>,
    /// A newer table that has not reached the control.
    #[serde(default)]
    pub waiting: Option<WaitingTable>,
    /// Wheel radius the control believes (after the last dressing), mm.
    pub wheel_radius_mm: f64,
    /// Parts measured so far.
    pub parts: u64,
    /// Content identities (SHA-256) of the newest measurements, oldest first.
    #[serde(default)]
    pub recent_measurements: Vec<Sha256>,
    /// What the previous part measured: the next step's evidence that an error repeats.
    #[serde(default)]
    pub previous: Option<PreviousPart>,
    /// The guard that refused or limited the latest parts in a row, if one did.
    #[serde(default)]
    pub guard: Option<GuardStreak>,
    /// The newest part (shaft) this feature was ground for, gauged or not: where a resumed
    /// shaft program starts is derived from it. A text that is not a part id reads as none
    /// (it cannot name a shaft to resume).
    #[serde(default, deserialize_with = "lenient_part")]
    pub last_part: Option<PartId>,
    /// With a speed plan: the virtual axis' speed the table in force was rendered for,
    /// rev/min (a start compares it with the plan of the wheel believed, rather than read
    /// the share's program back).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub in_force_va_speed_rpm: Option<f64>,
}

fn layout_one() -> u32 {
    1
}

fn lenient_part<'de, D: Deserializer<'de>>(d: D) -> Result<Option<PartId>, D::Error> {
    let text = Option::<String>::deserialize(d)?;
    Ok(text.and_then(|t| PartId::new(&t).ok()))
}

impl LoopMemory {
    /// A new loop: the nominal table, nothing measured.
    pub fn new(wheel_radius_mm: f64) -> Self {
        Self {
            schema: MEMORY_SCHEMA,
            learning: LearningState::new(360),
            in_force_version: None,
            waiting: None,
            wheel_radius_mm,
            parts: 0,
            recent_measurements: Vec::new(),
            previous: None,
            guard: None,
            last_part: None,
            in_force_va_speed_rpm: None,
        }
    }

    /// The memory a feature's journal leaves: its newest learning record, with the
    /// measurements recorded after it (the process died before their learning record) still
    /// counted and known, so a replay does not learn them again. None when the journal holds
    /// no learning record (the store's copy, or a new memory, is then the one to start from).
    pub fn resume<'a>(records: impl IntoIterator<Item = &'a Kept>) -> Option<Self> {
        let mut memory: Option<LoopMemory> = None;
        for r in records {
            match r {
                Kept::Learning(m) => memory = Some((**m).clone()),
                Kept::Measurement { sha256, part } => {
                    if let Some(m) = memory.as_mut() {
                        m.measured(*sha256, part.clone());
                    }
                }
                _ => {}
            }
        }
        memory
    }

    /// A measurement was recorded: one more part, known by its identity.
    pub fn measured(&mut self, sha256: Sha256, part: Option<PartId>) {
        self.parts += 1;
        self.remember(sha256);
        self.last_part = part;
    }

    /// The learning state of the newest table made, delivered or not (what a dressing or a
    /// restart regenerates from).
    pub fn newest_learning(&self) -> &LearningState {
        self.waiting
            .as_ref()
            .map_or(&self.learning, |w| &w.learning)
    }

    /// The newest part's number, when the gauge gave a number.
    pub fn last_part_number(&self) -> Option<u64> {
        self.last_part
            .as_deref()
            .and_then(|p| p.trim().parse().ok())
    }

    /// Whether this measurement identity was seen among the newest ones.
    pub fn has_seen(&self, sha256: &Sha256) -> bool {
        self.recent_measurements.contains(sha256)
    }

    pub fn remember(&mut self, sha256: Sha256) {
        self.recent_measurements.push(sha256);
        let excess = self
            .recent_measurements
            .len()
            .saturating_sub(RECENT_MEASUREMENTS);
        self.recent_measurements.drain(..excess);
    }

    /// Version `version` reached the control: if it is the waiting one, its state is now
    /// the one in force, and the wheel radius it was made for is returned.
    pub fn delivered(&mut self, version: TableVersion) -> Option<f64> {
        self.in_force_version = Some(version);
        let w = self.waiting.take_if(|w| w.version == version)?;
        self.learning = w.learning;
        self.in_force_va_speed_rpm = w.va_speed_rpm;
        Some(w.wheel_radius_mm)
    }
}

/// What a table version keeps of the learning that made it: enough to restore the
/// correction on a rollback and to tell, later, what the loop knew. The share's manifest
/// keeps [`TableLearningSummary`] (without the 360+ numbers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableLearning {
    pub iteration: u32,
    pub params: LearningParams,
    pub wheel_radius_mm: f64,
    pub correction_um: Vec<f64>,
    /// The timing correction in the table's C offset, degrees.
    #[serde(default)]
    pub timing_correction_deg: f64,
}

/// [`TableLearning`] without the correction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableLearningSummary {
    pub iteration: u32,
    pub params: LearningParams,
    pub wheel_radius_mm: f64,
    pub correction_sha256: Sha256,
    #[serde(default)]
    pub timing_correction_deg: f64,
}

impl TableLearning {
    /// What a table made from `next` for a wheel of `wheel_radius_mm` keeps.
    pub fn of(next: &LearningState, params: &LearningParams, wheel_radius_mm: f64) -> Self {
        Self {
            iteration: next.iteration,
            params: params.clone(),
            wheel_radius_mm,
            correction_um: next.correction_um.clone(),
            timing_correction_deg: next.timing_correction_deg,
        }
    }

    pub fn summary(&self) -> TableLearningSummary {
        TableLearningSummary {
            iteration: self.iteration,
            params: self.params.clone(),
            wheel_radius_mm: self.wheel_radius_mm,
            correction_sha256: camloop_core::turn::correction_sha256(&self.correction_um),
            timing_correction_deg: self.timing_correction_deg,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(n: u64) -> TableVersion {
        TableVersion::new(n).expect("not 0")
    }

    /// A memory written before version attribution existed still loads, as layout 1 with
    /// nothing waiting.
    #[test]
    fn layout_one_records_load() {
        let old = r#"{"learning":{"points_per_rev":2,"correction_um":[0.5,-0.5],"iteration":3,
            "recent_max_error_um":[],"best":null,"frozen":null},"wheel_radius_mm":250.0,"parts":3}"#;
        let m: LoopMemory = serde_json::from_str(old).expect("layout 1 parses");
        assert_eq!(m.schema, 1);
        assert_eq!(m.learning.correction_um, vec![0.5, -0.5]);
        assert_eq!(m.in_force_version, None);
        assert!(m.waiting.is_none());
    }

    /// The typed fields keep the records' form: no version is 0, a version its number, a
    /// part its text; a last part that is no part id reads as none rather than failing the
    /// whole memory.
    #[test]
    fn typed_fields_keep_the_records_form() {
        let mut m = LoopMemory::new(250.0);
        let json = serde_json::to_value(&m).expect("serializes");
        assert_eq!(json["in_force_version"], 0);
        m.in_force_version = Some(v(7));
        m.last_part = Some(PartId::new("S-12").expect("valid"));
        let json = serde_json::to_value(&m).expect("serializes");
        assert_eq!(json["in_force_version"], 7);
        assert_eq!(json["last_part"], "S-12");
        let back: LoopMemory = serde_json::from_value(json.clone()).expect("reads back");
        assert_eq!(back, m);
        let mut odd = json;
        odd["last_part"] = "not a part id!".into();
        let back: LoopMemory = serde_json::from_value(odd).expect("still reads");
        assert_eq!(back.last_part, None);
    }

    #[test]
    fn delivering_the_waiting_table_puts_its_state_in_force() {
        let mut m = LoopMemory::new(250.0);
        let mut next = m.learning.clone();
        next.correction_um[0] = -2.0;
        m.waiting = Some(WaitingTable {
            version: v(7),
            learning: next.clone(),
            wheel_radius_mm: 249.98,
            va_speed_rpm: Some(49.75),
        });
        assert_eq!(m.delivered(v(6)), None);
        assert_eq!(m.in_force_version, Some(v(6)));
        assert!(
            m.waiting.is_some(),
            "an older version does not settle the waiting one"
        );
        assert_eq!(m.delivered(v(7)), Some(249.98));
        assert_eq!(m.learning, next);
        assert_eq!(m.in_force_va_speed_rpm, Some(49.75));
        assert!(m.waiting.is_none());
    }

    #[test]
    fn remembers_a_bounded_number_of_identities() {
        let id = |i: u32| Sha256::of(&i.to_le_bytes());
        let mut m = LoopMemory::new(250.0);
        for i in 0..300 {
            m.remember(id(i));
        }
        assert_eq!(m.recent_measurements.len(), RECENT_MEASUREMENTS);
        assert!(m.has_seen(&id(299)) && m.has_seen(&id(44)) && !m.has_seen(&id(43)));
    }
}
