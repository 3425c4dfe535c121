//! The records the journal carries, typed with the store's own enums, and how each goes
//! into the store (once, even when replayed after a crash).

use super::super::machine::memory::{LoopMemory, TableLearning};
use crate::core::digest::Sha256;
use crate::core::ids::TableVersion;
use crate::names::{FeatureName, MachineName, PartName};
use crate::store::Batch;
pub use crate::store::EventKind;
use crate::store::{
    EventLevel, FeatureKind, NewDressing, NewEvent, NewMeasurement, NewRecipeSnapshot,
    NewTableVersion, Store, StoreError, VersionStatus,
};
use jiff::Timestamp;
use serde::{Deserialize, Serialize};

/// One record waiting for the database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "record", rename_all = "snake_case")]
pub enum Pending {
    /// The store's own record, as it goes into the store (field names as they always were
    /// in the journal), with what only the plant's events need.
    Measurement {
        #[serde(flatten)]
        measurement: NewMeasurement,
        /// Version of the table on the control when the part was ground (written 0 when
        /// none is known, as it always was).
        #[serde(default, with = "crate::core::ids::lenient_version::zero_for_none")]
        ground_with_version: Option<TableVersion>,
    },
    Table {
        machine: MachineName,
        lobe: FeatureName,
        /// The share's version number (the one version counter).
        version: TableVersion,
        /// The version in force when this one was made.
        #[serde(default, with = "crate::core::ids::lenient_version")]
        parent_version: Option<TableVersion>,
        table_number: u32,
        program_text: String,
        learning: TableLearning,
        reason: String,
        /// Its first status, with why (lines written before it was typed: see [`read_line`]).
        status: VersionStatus,
        #[serde(rename = "created_at_ms", with = "crate::clock::unix_ms")]
        created_at: Timestamp,
        /// The measurement it was learned from (a replay re-submits the version with it).
        #[serde(default)]
        measurement_id: Option<Sha256>,
        /// The version it re-pushes, for a rollback.
        #[serde(default, with = "crate::core::ids::lenient_version")]
        rollback_of: Option<TableVersion>,
    },
    /// A later status of a recorded version (e.g. waiting → pushed once the share is back).
    #[serde(rename = "table_status")]
    VersionStatus {
        machine: MachineName,
        lobe: FeatureName,
        version: TableVersion,
        status: VersionStatus,
        #[serde(rename = "at_ms", with = "crate::clock::unix_ms")]
        at: Timestamp,
    },
    Event {
        machine: MachineName,
        #[serde(rename = "at_ms", with = "crate::clock::unix_ms")]
        at: Timestamp,
        level: EventLevel,
        kind: EventKind,
        message: String,
    },
    Learning {
        machine: MachineName,
        lobe: FeatureName,
        state: Box<LoopMemory>,
        #[serde(rename = "saved_at_ms", with = "crate::clock::unix_ms")]
        saved_at: Timestamp,
    },
    /// What the machine grinds, kept once per change (the store skips an identical one).
    RecipeSnapshot {
        machine: MachineName,
        part: PartName,
        lobe: FeatureName,
        kind: FeatureKind,
        recipe_json: String,
        #[serde(rename = "created_at_ms", with = "crate::clock::unix_ms")]
        created_at: Timestamp,
    },
    Dressing {
        machine: MachineName,
        #[serde(rename = "at_ms", with = "crate::clock::unix_ms")]
        at: Timestamp,
        old_radius_mm: f64,
        new_radius_mm: f64,
        /// The dresser's measured infeed (radius removed), µm, when it reported one; journal
        /// lines written before it was kept have none.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        infeed_um: Option<f64>,
        /// Who reported it: "sim", "drop file <path>", "api".
        source: String,
    },
}

impl Pending {
    /// The event to store, for a [`Pending::Event`].
    fn event(&self) -> Result<Option<NewEvent>, StoreError> {
        Ok(match self {
            Pending::Event {
                machine,
                at,
                level,
                kind,
                message,
            } => Some(NewEvent {
                machine: machine.clone(),
                at: *at,
                level: *level,
                kind: *kind,
                message: message.clone(),
            }),
            _ => None,
        })
    }

    /// The record's kind as the journal spells it (its `record` tag).
    pub(super) fn kind_name(&self) -> &'static str {
        match self {
            Pending::Measurement { .. } => "measurement",
            Pending::Table { .. } => "table",
            Pending::VersionStatus { .. } => "table_status",
            Pending::Event { .. } => "event",
            Pending::Learning { .. } => "learning",
            Pending::RecipeSnapshot { .. } => "recipe_snapshot",
            Pending::Dressing { .. } => "dressing",
        }
    }

    /// The crash point once a record of this kind is in the journal (the kinds a part's or
    /// a dressing's durability turns on; the others travel in the same appends).
    pub(super) fn journaled_step(&self) -> Option<&'static str> {
        match self {
            Pending::Measurement { .. } => Some("journaled:measurement"),
            Pending::Table { .. } => Some("journaled:table_version"),
            Pending::Learning { .. } => Some("journaled:learning_state"),
            Pending::Dressing { .. } => Some("journaled:dressing"),
            Pending::VersionStatus { .. }
            | Pending::Event { .. }
            | Pending::RecipeSnapshot { .. } => None,
        }
    }

    /// The crash point once a record of this kind is committed to the store.
    pub(super) fn committed_step(&self) -> &'static str {
        match self {
            Pending::Measurement { .. } => "store_commit:measurement",
            Pending::Table { .. } => "store_commit:table_version",
            Pending::VersionStatus { .. } => "store_commit:table_status",
            Pending::Event { .. } => "store_commit:event",
            Pending::Learning { .. } => "store_commit:learning_state",
            Pending::RecipeSnapshot { .. } => "store_commit:recipe_snapshot",
            Pending::Dressing { .. } => "store_commit:dressing",
        }
    }

    /// The dressing to store, for a [`Pending::Dressing`].
    fn dressing(&self) -> Result<Option<NewDressing>, StoreError> {
        Ok(match self {
            Pending::Dressing {
                machine,
                at,
                old_radius_mm,
                new_radius_mm,
                infeed_um,
                source,
            } => Some(NewDressing {
                machine: machine.clone(),
                at: *at,
                old_radius_mm: *old_radius_mm,
                new_radius_mm: *new_radius_mm,
                infeed_um: *infeed_um,
                source: source.clone(),
            }),
            _ => None,
        })
    }
}

/// Reads one journal line. Table records written before they carried the share's status
/// type spell it as the store's columns: `"status":"pushed"` beside `status_why` (a table)
/// or `why` (a later status), with the record's time; those are read through the store's
/// own [`VersionStatus::from_column`], so a journal left by a stopped service still replays.
pub(super) fn read_line(line: &str) -> serde_json::Result<Pending> {
    serde_json::from_str(line).or_else(|error| {
        let mut value: serde_json::Value = serde_json::from_str(line)?;
        match column_status(&mut value) {
            Ok(true) => serde_json::from_value(value),
            Ok(false) => Err(error),
            Err(e) => Err(serde::de::Error::custom(e)),
        }
    })
}

/// Rewrites a table record's column-spelled status as the typed one; false when `value`
/// is no such record.
fn column_status(value: &mut serde_json::Value) -> Result<bool, StoreError> {
    use serde_json::Value;
    let Some(record) = value.as_object_mut() else {
        return Ok(false);
    };
    let (why_key, at_key) = match record.get("record").and_then(Value::as_str) {
        Some("table") => ("status_why", "created_at_ms"),
        Some("table_status") => ("why", "at_ms"),
        _ => return Ok(false),
    };
    let (Some(Value::String(status)), Some(Value::String(why)), Some(at_ms)) = (
        record.get("status"),
        record.get(why_key),
        record.get(at_key).and_then(Value::as_i64),
    ) else {
        return Ok(false);
    };
    let status = VersionStatus::from_column(status, why.clone(), at_ms)?;
    let status = serde_json::to_value(status)
        .map_err(|e| StoreError::invalid("table status", e.to_string()))?;
    record.remove(why_key);
    record.insert("status".into(), status);
    Ok(true)
}

/// [`apply`] for a record read back after a crash: skipped when the store already holds it
/// (measurements are idempotent by their SHA-256 anyway).
pub(super) async fn apply_once(store: &Store, record: &Pending) -> Result<(), StoreError> {
    let present = match record {
        // Both are idempotent in the store (by content).
        Pending::Measurement { .. } | Pending::RecipeSnapshot { .. } => false,
        Pending::Table {
            machine,
            lobe,
            version,
            ..
        } => store
            .table_version_status(machine, lobe, *version)
            .await?
            .is_some(),
        Pending::VersionStatus {
            machine,
            lobe,
            version,
            status,
            ..
        } => store
            .table_version_status(machine, lobe, *version)
            .await?
            .is_some_and(|s| s.name() == status.name()),
        Pending::Event { .. } => match record.event()? {
            Some(e) => store.event_exists(&e).await?,
            None => false,
        },
        Pending::Learning {
            machine,
            lobe,
            state,
            saved_at,
        } => {
            store
                .learning_state_covered(machine, lobe, &state_json(state)?, *saved_at)
                .await?
        }
        Pending::Dressing { .. } => match record.dressing()? {
            Some(d) => store.dressing_exists(&d).await?,
            None => false,
        },
    };
    if present {
        Ok(())
    } else {
        apply(store, record).await
    }
}

fn state_json(state: &LoopMemory) -> Result<String, StoreError> {
    serde_json::to_string(state).map_err(|e| StoreError::invalid("learning state", e.to_string()))
}

/// What of a learning state history keeps a snapshot for: the learning's mode (frozen or
/// not, and why), which part gave the best correction, the wheel and the grid. A snapshot
/// that differs only in its counters, recent errors, remembered measurements or correction
/// replaces the newest one: every correction is kept exactly with its table version.
fn meaning_sha256(state: &LoopMemory) -> Result<Sha256, StoreError> {
    #[derive(Serialize)]
    struct Meaning<'a> {
        schema: u32,
        points_per_rev: u32,
        frozen: &'a Option<String>,
        best_iteration: Option<u32>,
        wheel_radius_mm: f64,
    }
    let meaning = Meaning {
        schema: state.schema,
        points_per_rev: state.learning.points_per_rev,
        frozen: &state.learning.frozen,
        best_iteration: state.learning.best.as_ref().map(|b| b.iteration),
        wheel_radius_mm: state.wheel_radius_mm,
    };
    serde_json::to_vec(&meaning)
        .map(|bytes| Sha256::of(&bytes))
        .map_err(|e| StoreError::invalid("learning state", e.to_string()))
}

/// Writes `record` to the store in a transaction of its own.
pub(super) async fn apply(store: &Store, record: &Pending) -> Result<(), StoreError> {
    let mut batch = store.begin_batch().await?;
    apply_in(&mut batch, record).await?;
    batch.commit().await
}

/// Writes `record` in `batch`, which commits it with the batch's other records.
pub(super) async fn apply_in(batch: &mut Batch<'_>, record: &Pending) -> Result<(), StoreError> {
    match record.clone() {
        Pending::Measurement { measurement, .. } => {
            batch.insert_measurement(&measurement).await.map(|_| ())
        }
        record @ Pending::Table { .. } => insert_table(batch, record).await,
        Pending::VersionStatus {
            machine,
            lobe,
            version,
            status,
            at,
        } => {
            batch
                .set_table_status(&machine, &lobe, version, &status, at)
                .await
        }
        Pending::Event { .. } => match record.event()? {
            Some(e) => batch.insert_event(&e).await.map(|_| ()),
            None => Ok(()),
        },
        Pending::Learning {
            machine,
            lobe,
            state,
            saved_at,
        } => {
            let meaning = meaning_sha256(&state)?;
            batch
                .save_learning_snapshot(
                    &machine,
                    &lobe,
                    &state_json(&state)?,
                    Some(&meaning),
                    saved_at,
                )
                .await
        }
        Pending::RecipeSnapshot {
            machine,
            part,
            lobe,
            kind,
            recipe_json,
            created_at,
        } => {
            let r = NewRecipeSnapshot {
                machine,
                part,
                lobe,
                kind,
                recipe_json,
                created_at,
            };
            batch.insert_recipe_snapshot(&r).await.map(|_| ())
        }
        Pending::Dressing { .. } => match record.dressing()? {
            Some(d) => batch.insert_dressing(&d).await.map(|_| ()),
            None => Ok(()),
        },
    }
}

async fn insert_table(batch: &mut Batch<'_>, record: Pending) -> Result<(), StoreError> {
    let Pending::Table {
        machine,
        lobe,
        version,
        parent_version,
        table_number,
        program_text,
        learning,
        reason,
        status,
        created_at,
        ..
    } = record
    else {
        return Ok(());
    };
    // A parent the store never saw (history from before one version counter) is
    // left out rather than blocking every later record. Asked in the batch: a parent
    // written earlier in it counts.
    let parent_version = match parent_version {
        Some(p) if batch.has_table_version(&machine, &lobe, p).await? => Some(p),
        _ => None,
    };
    let learning_params_json = serde_json::to_string(&learning)
        .map_err(|e| StoreError::invalid("table learning", e.to_string()))?;
    let t = NewTableVersion {
        machine,
        lobe,
        version: Some(version),
        parent_version,
        table_number,
        program_text,
        learning_params_json,
        reason,
        status,
        created_at,
    };
    batch.insert_table_version(&t).await.map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::Verdict;

    /// Table lines as builds before the typed status wrote them (the status as the store's
    /// column pair) read as the typed status with the same text, and are written back in the
    /// typed form, which reads again as the same record.
    #[test]
    fn table_lines_with_the_status_as_columns_read_as_the_typed_status() {
        let table = r#"{"record":"table","machine":"G7","lobe":"IN1","version":3,
            "parent_version":null,"table_number":1,"program_text":"CTABEND","learning":
            {"iteration":0,"params":{},"wheel_radius_mm":250.0,"correction_um":[0.0],
            "timing_correction_deg":0.0},"reason":"learned","status":"waiting",
            "status_why":"submitted to the share","created_at_ms":7}"#;
        let later = r#"{"record":"table_status","machine":"G7","lobe":"IN1","version":3,
            "status":"pushed","why":"pushed to the share on retry","at_ms":9}"#;
        let refused = later.replace(r#""pushed""#, r#""refused""#);
        let read = |line: &str| read_line(line).unwrap_or_else(|e| panic!("{e}: {line}"));
        let Pending::Table { status, .. } = read(table) else {
            panic!("a table record")
        };
        let submitted = Some("submitted to the share".to_string());
        assert_eq!(status, VersionStatus::Waiting { reason: submitted });
        let record = read(later);
        let Pending::VersionStatus { status, at, .. } = &record else {
            panic!("a status record")
        };
        let note = Some("pushed to the share on retry".to_string());
        let pushed = VersionStatus::Pushed {
            at: jiff::Timestamp::from_millisecond(9).expect("a time"),
            note,
        };
        assert_eq!(
            (status, *at),
            (&pushed, jiff::Timestamp::from_millisecond(9).unwrap())
        );
        let Pending::VersionStatus { status, .. } = read(&refused) else {
            panic!("a status record")
        };
        assert_eq!(status.why(), "pushed to the share on retry");
        assert_eq!(status.name(), "refused");
        // Written back typed; the typed line reads as the same record.
        let typed = serde_json::to_string(&record).unwrap();
        assert!(typed.contains(r#""status":{"status":"pushed""#), "{typed}");
        assert_eq!(read(&typed), record);
        // A status no build ever wrote is an error naming it, not a record.
        let unknown = later.replace(r#""pushed""#, r#""delivered""#);
        let e = read_line(&unknown).unwrap_err().to_string();
        assert!(e.contains("unknown value `delivered`"), "{e}");
    }

    /// A table line's measurement is the digest's text, as builds that kept it as a string
    /// wrote it: read as the typed digest and written back byte for byte.
    #[test]
    fn a_table_lines_measurement_reads_as_its_digest_and_writes_back_the_same() {
        let sha = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";
        let line = format!(
            r#"{{"record":"table","machine":"G7","lobe":"IN1","version":3,"parent_version":null,"table_number":1,"program_text":"CTABEND","learning":{{"iteration":0,"params":{{}},"wheel_radius_mm":250.0,"correction_um":[0.0],"timing_correction_deg":0.0}},"reason":"learned","status":{{"status":"waiting","reason":null}},"created_at_ms":7,"measurement_id":"{sha}","rollback_of":null}}"#
        );
        let record = read_line(&line).unwrap_or_else(|e| panic!("{e}: {line}"));
        let Pending::Table { measurement_id, .. } = &record else {
            panic!("a table record")
        };
        assert_eq!(measurement_id.map(|m| m.to_string()).as_deref(), Some(sha));
        let written = serde_json::to_string(&record).unwrap();
        let field = format!(r#""measurement_id":"{sha}""#);
        assert!(
            line.contains(&field) && written.contains(&field),
            "{written}"
        );
    }

    /// A measurement line as builds before the shared record wrote it (its fields flat
    /// beside the tag, no recipe snapshot) reads as the store's record, and is written back
    /// as the same JSON: journals left by a stopped service still replay. (Its digest is a
    /// real one: the store never took anything but 64 lower-case hex digits.)
    #[test]
    fn a_measurement_line_of_the_flat_format_reads_and_writes_back_the_same() {
        let line = r#"{"record":"measurement","machine":"G7","part":"S-1","lobe":"IN1",
            "received_at_ms":7,"verdict":"fail","max_profile_error_um":2.5,
            "base_radius_error_um":-0.25,"phase_error_deg":0.125,"revolutions_used":3,
            "points_per_rev":4,"origin":"can0","ground_with_version":5,
            "sha256":"ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad",
            "raw_lift_mm":[[0.0,1.5]],"averaged_lift_mm":[0.5,1.0],"analysis_json":"{}"}"#;
        let record: Pending = serde_json::from_str(line).unwrap();
        let Pending::Measurement {
            measurement: m,
            ground_with_version,
        } = &record
        else {
            panic!("{record:?}");
        };
        assert_eq!(ground_with_version.map(|v| v.get()), Some(5));
        assert_eq!((m.machine.as_str(), m.part.as_str()), ("G7", "S-1"));
        assert_eq!(
            (m.verdict, m.points_per_rev, m.recipe_snapshot),
            (Verdict::Fail, 4, None)
        );
        assert_eq!(
            (m.base_radius_error_um, m.raw_lift_mm.clone()),
            (-0.25, vec![vec![0.0, 1.5]])
        );
        let written = serde_json::to_value(&record).unwrap();
        let read: serde_json::Value = serde_json::from_str(line).unwrap();
        assert_eq!(written, read);
        // Lines from before the version was kept have none: 0, "none known".
        let older = line.replace(r#""ground_with_version":5,"#, "");
        let record: Pending = serde_json::from_str(&older).unwrap();
        assert!(matches!(
            record,
            Pending::Measurement {
                ground_with_version: None,
                ..
            }
        ));
    }
}
