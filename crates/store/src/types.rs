//! The store's vocabulary: id newtypes, what callers write (`New*`), what they read back,
//! and the filters of the history queries. Times are instants ([`Timestamp`]; kept as unix
//! milliseconds in the database and named after those columns), lifts mm, errors µm.

use camloop_core::digest::Sha256;
use camloop_core::ids::PartId;
use camloop_core::names::{FeatureName, MachineName, PartName};
use jiff::Timestamp;
use serde::{Deserialize, Serialize};

use super::error::StoreError;

/// Row id of a measurement. Stable for the life of the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MeasurementId(pub i64);

/// Row id of a recipe snapshot (a part's lobe or pin definition as it was at that time).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct RecipeSnapshotId(pub i64);

/// Row id of a wheel dressing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct DressingId(pub i64);

/// Row id of an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct EventId(pub i64);

/// Stored and API text of the small enums below: the variant's name in lower case, one
/// spelling for the database, serde and `as_str` (strum and serde derive it alike).
macro_rules! text_enum {
    ($(#[$m:meta])* $name:ident, $field:literal { $($variant:ident),+ $(,)? }) => {
        $(#[$m])*
        #[derive(
            Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize,
            strum::IntoStaticStr, strum::EnumString,
        )]
        #[serde(rename_all = "lowercase")]
        #[strum(serialize_all = "lowercase")]
        pub enum $name { $($variant),+ }

        impl $name {
            /// The text stored in the database and used in APIs.
            pub fn as_str(self) -> &'static str {
                self.into()
            }

            /// Parses the stored text.
            pub fn parse(text: &str) -> Result<Self, StoreError> {
                text.parse().map_err(|_| {
                    StoreError::invalid($field, format!("unknown value `{text}`"))
                })
            }
        }
    };
}

/// Whether a part passed and how serious an event is: the core's, so the loop's plant events
/// carry the same words.
pub use camloop_core::levels::{EventLevel, Verdict};
/// Where a table version stands, from its write-ahead record to the share's verdict: the one
/// status of a version, for the share's manifest (this tagged JSON) and the store alike.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum VersionStatus {
    /// Not delivered yet; `reason` is the last failure, if an attempt was made.
    Waiting { reason: Option<String> },
    /// Renames began but were not confirmed (a kill or a failure during them).
    Delivering,
    /// On the share and verified.
    Pushed {
        /// When it was verified on the share; written as unsigned Unix milliseconds
        /// (`at_unix_ms`, the manifest's field since its first version).
        #[serde(rename = "at_unix_ms", with = "crate::unix_ms::unsigned")]
        at: jiff::Timestamp,
        /// How camloop learned it, as the store keeps it ("pushed to the share on retry");
        /// the share's manifest never writes one.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        note: Option<String>,
    },
    /// Never pushed, for this reason.
    Refused { reason: String },
    /// Not delivered before a newer version was accepted.
    Superseded { by: camloop_core::ids::TableVersion },
}

/// What an event is about; stored as its snake_case name (serde, strum and the database
/// spell it alike, as the journal did when it was text in the store).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    Serialize,
    Deserialize,
    strum::IntoStaticStr,
    strum::EnumString,
)]
#[serde(rename_all = "snake_case")]
#[strum(serialize_all = "snake_case")]
pub enum EventKind {
    MeasurementRejected,
    MeasurementRepeated,
    TableRefused,
    LearningReverted,
    LearningHeld,
    LearningResumed,
    ShareUnavailable,
    ShareBack,
    WheelDressed,
    Rollback,
    JournalQuarantined,
    DiskFull,
    DiskSpaceBack,
    /// The same guard refused or limited several parts in a row.
    BlockedByGuard,
    /// A part was learned from again without that guard acting.
    GuardCleared,
    /// A control chart's run rule fired on a characteristic (the loop never acts on it).
    RunRule,
}

impl EventKind {
    /// The text stored in the database and used in APIs.
    pub fn as_str(self) -> &'static str {
        self.into()
    }

    /// Parses the stored text.
    pub fn parse(text: &str) -> Result<Self, StoreError> {
        text.parse()
            .map_err(|_| StoreError::invalid("event kind", format!("unknown value `{text}`")))
    }
}

text_enum!(
    /// A camshaft lobe or a crankshaft pin.
    FeatureKind, "feature kind" { Lobe, Pin }
);

/// A recipe snapshot to keep: the definition of one lobe or pin of a part, as JSON text.
#[derive(Debug, Clone, PartialEq)]
pub struct NewRecipeSnapshot {
    pub machine: MachineName,
    pub part: PartName,
    /// Lobe or pin name within the part.
    pub lobe: FeatureName,
    pub kind: FeatureKind,
    /// Must parse as JSON; kept verbatim.
    pub recipe_json: String,
    pub created_at: Timestamp,
}

/// A lobe or pin known on a machine, with its latest recipe snapshot.
#[derive(Debug, Clone, PartialEq)]
pub struct Feature {
    pub part: PartName,
    pub lobe: FeatureName,
    pub kind: FeatureKind,
    pub recipe_snapshot: RecipeSnapshotId,
    pub recipe_json: String,
    pub created_at: Timestamp,
}

/// A lobe or pin known on a machine, by its latest recipe snapshot's kind: what a plant's
/// list of machines shows, read for every machine in one query ([`super::Store::feature_keys`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureKey {
    pub machine: MachineName,
    pub part: PartName,
    pub lobe: FeatureName,
    pub kind: FeatureKind,
}

/// A machine the store has seen (created by its first write).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Machine {
    pub name: MachineName,
    pub first_seen: Timestamp,
}

/// One analysed measurement to append.
///
/// Lifts are stored as i32 little-endian in 0.1 µm units (see [`super::codec`]), so they
/// come back within 0.05 µm and must lie within ±214 m.
///
/// The service's journal carries it as it is (serde), so its field names are also the
/// journal's: renaming one needs a serde alias for the journals already written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NewMeasurement {
    pub machine: MachineName,
    pub part: PartId,
    pub lobe: FeatureName,
    #[serde(rename = "received_at_ms", with = "crate::unix_ms")]
    pub received_at: Timestamp,
    pub verdict: Verdict,
    pub max_profile_error_um: f64,
    pub base_radius_error_um: f64,
    pub phase_error_deg: f64,
    pub revolutions_used: u32,
    /// Final (the finished part) or in-process; journal records written before the
    /// stage existed read as final, and a final one is written as before (no field).
    #[serde(default, skip_serializing_if = "MeasurementStage::is_final")]
    pub stage: MeasurementStage,
    /// Readings per revolution (≥ 1); every revolution and the averaged profile have this many.
    pub points_per_rev: u32,
    /// Where the measurement came from ("can0", a file path, …).
    pub origin: String,
    /// SHA-256 of the measurement as received (64 lower-case hex digits as text). Inserting
    /// the same hash again returns the stored id and writes nothing.
    pub sha256: Sha256,
    /// Journal records never carry one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recipe_snapshot: Option<RecipeSnapshotId>,
    /// Raw lifts per revolution as received, mm. Empty when not kept.
    pub raw_lift_mm: Vec<Vec<f64>>,
    /// Averaged lift per angle index, mm.
    pub averaged_lift_mm: Vec<f64>,
    /// The analysis report; must parse as JSON.
    pub analysis_json: String,
}

/// The stage of the part a measurement was taken at.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum MeasurementStage {
    /// The finished part: what capability, control charts and exports judge. Every row
    /// written before the column existed reads as final.
    #[default]
    Final,
    /// Before the finish pass, stock still on: kept for the history, never learned from
    /// and never counted as a finished part.
    InProcess,
}

impl MeasurementStage {
    /// The finished part's stage.
    pub fn is_final(&self) -> bool {
        *self == Self::Final
    }

    /// The text stored in the database and used in APIs.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Final => "final",
            Self::InProcess => "in_process",
        }
    }

    /// Parses the stored text.
    pub fn parse(text: &str) -> Result<Self, camloop_core::levels::UnknownValue> {
        match text {
            "final" => Ok(Self::Final),
            "in_process" => Ok(Self::InProcess),
            _ => Err(camloop_core::levels::UnknownValue {
                field: "stage",
                text: text.to_string(),
            }),
        }
    }
}

impl std::fmt::Display for MeasurementStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for MeasurementStage {
    type Err = camloop_core::levels::UnknownValue;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::parse(s)
    }
}

/// The summary columns of a measurement, as listed by the history query.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementSummary {
    pub id: MeasurementId,
    pub machine: MachineName,
    pub part: PartId,
    pub lobe: FeatureName,
    pub received_at: Timestamp,
    pub verdict: Verdict,
    pub max_profile_error_um: f64,
    pub base_radius_error_um: f64,
    pub phase_error_deg: f64,
    pub revolutions_used: u32,
    pub points_per_rev: u32,
    pub origin: String,
    pub sha256: Sha256,
    pub recipe_snapshot: Option<RecipeSnapshotId>,
    pub stage: MeasurementStage,
}

/// A measurement with its profiles and report.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementDetail {
    pub summary: MeasurementSummary,
    /// Raw lifts per revolution, mm; `None` once pruned by retention (or never kept).
    pub raw_lift_mm: Option<Vec<Vec<f64>>>,
    pub averaged_lift_mm: Vec<f64>,
    pub analysis_json: String,
}

/// Which measurements the history query lists, newest first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HistoryFilter {
    pub machine: MachineName,
    pub lobe: Option<FeatureName>,
    /// Inclusive lower bound on `received_at_ms`.
    pub since: Option<Timestamp>,
    /// Exclusive upper bound on `received_at_ms`.
    pub until: Option<Timestamp>,
    pub verdict: Option<Verdict>,
    /// One stage only; `None` lists both.
    pub stage: Option<MeasurementStage>,
    /// Page size, 1 to [`MAX_PAGE`].
    pub limit: u32,
    /// `next_cursor` of the previous page; `None` for the first page.
    pub cursor: Option<String>,
    /// Production parts, master runs (part ids `MASTER…`), or both.
    pub masters: MasterRuns,
}

impl HistoryFilter {
    /// The first `limit` measurements of `machine`, every lobe, time and verdict, masters
    /// included: the base the callers narrow with struct update syntax.
    pub fn new(machine: MachineName, limit: u32) -> Self {
        Self {
            machine,
            lobe: None,
            since: None,
            until: None,
            verdict: None,
            stage: None,
            limit,
            cursor: None,
            masters: MasterRuns::Included,
        }
    }
}

/// Which kind of part a history lists: master runs are a gauge study's, never production
/// parts, so what a user reads as history leaves them out unless asked for them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MasterRuns {
    /// Every measurement (the store's own callers, which sort the kinds themselves).
    #[default]
    Included,
    /// Production parts only.
    Excluded,
    /// Master runs only.
    Only,
}

/// Largest page the list queries return.
pub const MAX_PAGE: u32 = 10_000;

/// One page of a keyset-paginated list.
#[derive(Debug, Clone, PartialEq)]
pub struct Page<T> {
    pub items: Vec<T>,
    /// Opaque cursor for the next page; `None` when this page is the last.
    pub next_cursor: Option<String>,
}

/// A regenerated curve-table program to append.
#[derive(Debug, Clone, PartialEq)]
pub struct NewTableVersion {
    pub machine: MachineName,
    pub lobe: FeatureName,
    /// Its number: the share's version (camloop keeps one version counter, the share's), or
    /// `None` for one more than the highest stored.
    pub version: Option<camloop_core::ids::TableVersion>,
    /// The version it was derived from, if any; must exist for this machine and lobe.
    pub parent_version: Option<camloop_core::ids::TableVersion>,
    /// SINUMERIK curve-table number used by this version.
    pub table_number: u32,
    pub program_text: String,
    /// Learning parameters in force; must parse as JSON.
    pub learning_params_json: String,
    /// Why the version was made ("learned from part 1234", "wheel dressed", …).
    pub reason: String,
    /// Its first status, and why ("waiting for operator", "pushed to share", "step too
    /// large"); the store keeps `created_at_ms` as the status's time.
    pub status: VersionStatus,
    pub created_at: Timestamp,
}

/// A stored table version with its latest status (the row; its number is the core's
/// [`camloop_core::ids::TableVersion`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StoredTableVersion {
    pub machine: MachineName,
    pub lobe: FeatureName,
    /// 1, 2, 3, … per (machine, lobe).
    pub version: camloop_core::ids::TableVersion,
    pub parent_version: Option<camloop_core::ids::TableVersion>,
    pub table_number: u32,
    pub program_text: String,
    /// SHA-256 of `program_text` (UTF-8), computed by the store.
    pub sha256: Sha256,
    pub learning_params_json: String,
    pub reason: String,
    pub created_at: Timestamp,
    pub status: VersionStatus,
    pub status_at: Timestamp,
}

/// A wheel dressing: the wheel radius camloop believed before and after.
#[derive(Debug, Clone, PartialEq)]
pub struct NewDressing {
    pub machine: MachineName,
    pub at: Timestamp,
    pub old_radius_mm: f64,
    pub new_radius_mm: f64,
    /// The dresser's measured infeed (radius removed), µm, when it reported one.
    pub infeed_um: Option<f64>,
    /// Who reported it ("plc", "operator", "sim").
    pub source: String,
}

/// A stored dressing.
#[derive(Debug, Clone, PartialEq)]
pub struct Dressing {
    pub id: DressingId,
    pub machine: MachineName,
    pub at: Timestamp,
    pub old_radius_mm: f64,
    pub new_radius_mm: f64,
    /// `None` for dressings reported without it, and for rows older than the column.
    pub infeed_um: Option<f64>,
    pub source: String,
}

/// An alarm or event to append.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NewEvent {
    pub machine: MachineName,
    pub at: Timestamp,
    pub level: EventLevel,
    pub kind: EventKind,
    pub message: String,
}

/// A stored event.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Event {
    pub id: EventId,
    pub machine: MachineName,
    pub at: Timestamp,
    pub level: EventLevel,
    pub kind: EventKind,
    pub message: String,
}

/// Which events to list, newest first.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct EventFilter {
    pub machine: Option<MachineName>,
    /// Inclusive.
    pub since: Option<Timestamp>,
    /// Exclusive.
    pub until: Option<Timestamp>,
    pub level: Option<EventLevel>,
    /// 1 to [`MAX_PAGE`].
    pub limit: u32,
}

/// The newest learning-state snapshot of a (machine, lobe).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LearningState {
    pub state_json: String,
    pub saved_at: Timestamp,
}

text_enum!(
    /// What a user may do; each role may do everything the ones before it may:
    /// `viewer` reads, `operator` also acknowledges alarms and reports dressings,
    /// `engineer` also rolls back and changes what the loop may do, `admin` also manages
    /// users.
    Role, "role" { Viewer, Operator, Engineer, Admin }
);

impl Role {
    /// Every role, least first.
    pub const ALL: [Role; 4] = [Role::Viewer, Role::Operator, Role::Engineer, Role::Admin];

    fn rank(self) -> u8 {
        match self {
            Role::Viewer => 0,
            Role::Operator => 1,
            Role::Engineer => 2,
            Role::Admin => 3,
        }
    }
}

impl PartialOrd for Role {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Role {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.rank().cmp(&other.rank())
    }
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

text_enum!(
    /// How an audited action ended.
    AuditResult, "audit result" { Ok, Refused, Failed }
);
