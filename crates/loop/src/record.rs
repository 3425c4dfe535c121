//! The records the loop asks to keep, in its own words: what a step decided, before the
//! shell writes it in the journal's file format (and from there the store). A replay reads
//! back what it needs of them as [`Kept`] ([`crate::memory::LoopMemory::resume`],
//! [`crate::machine::FeatureMachine::resume`]).

use crate::memory::{LoopMemory, TableLearning};
use camloop_core::digest::Sha256;
use camloop_core::ids::{PartId, TableVersion};
use camloop_core::levels::EventLevel;
use camloop_core::turn::Measured;
use jiff::Timestamp;

/// Why a version's first record says "waiting": it is written before the share hears of it.
pub const SUBMITTED: &str = "submitted to the share";

/// What an event of the loop is about (the store's event kinds the loop raises).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    MeasurementRejected,
    MeasurementRepeated,
    TableRefused,
    LearningReverted,
    LearningHeld,
    ShareUnavailable,
    ShareBack,
    BlockedByGuard,
    GuardCleared,
}

/// Where a table version stands, as the loop knows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TableStatus {
    /// Not on the control; why, when an attempt was made.
    Waiting { reason: Option<String> },
    /// On the share and verified; how the loop learned it.
    Pushed { note: String },
    /// Never pushed, for this reason.
    Refused { reason: String },
}

/// A table version as its write-ahead record keeps it: everything a replay needs to submit
/// it again.
#[derive(Debug, Clone, PartialEq)]
pub struct TableRecord {
    pub version: TableVersion,
    /// The version in force when this one was made.
    pub parent: Option<TableVersion>,
    pub table_number: u32,
    pub program_text: String,
    pub learning: TableLearning,
    pub reason: String,
    /// Always [`TableStatus::Waiting`] with [`SUBMITTED`]: written before the share hears.
    pub status: TableStatus,
    pub at: Timestamp,
    /// The measurement it was learned from.
    pub measurement: Option<Sha256>,
    /// The version it re-pushes, for a rollback.
    pub rollback_of: Option<TableVersion>,
}

/// One record to keep.
#[derive(Debug, Clone)]
pub enum Record {
    /// A part's measurement, analysed (the shell adds the raw samples it holds).
    Measurement {
        sha256: Sha256,
        part: Option<PartId>,
        measured: Box<Measured>,
        /// The table on the control when the part was ground.
        ground_with: Option<TableVersion>,
        at: Timestamp,
    },
    Table(Box<TableRecord>),
    /// A later status of a recorded version.
    Status {
        version: TableVersion,
        status: TableStatus,
        at: Timestamp,
    },
    Event {
        at: Timestamp,
        level: EventLevel,
        kind: EventKind,
        message: String,
    },
    /// The loop's memory: what a restart resumes from.
    Learning {
        memory: Box<LoopMemory>,
        at: Timestamp,
    },
}

impl Record {
    pub(crate) fn event(
        at: Timestamp,
        level: EventLevel,
        kind: EventKind,
        message: String,
    ) -> Self {
        Record::Event {
            at,
            level,
            kind,
            message,
        }
    }
}

/// A journalled record as a restart reads it back: what the resume needs of it (a
/// measurement's identity, a table's write-ahead record, a status, the memory). The shell
/// reads its journal's lines into these; [`Record::kept`] is the same for the loop's own.
#[derive(Debug, Clone, PartialEq)]
pub enum Kept {
    /// A part's measurement of the finished part (one more part, known by its identity).
    Measurement {
        sha256: Sha256,
        part: Option<PartId>,
    },
    Table(Box<TableRecord>),
    Status {
        version: TableVersion,
        status: TableStatus,
    },
    Learning(Box<LoopMemory>),
}

impl Record {
    /// What a resume reads back of this record (nothing, for an event).
    pub fn kept(&self) -> Option<Kept> {
        Some(match self {
            Record::Measurement { sha256, part, .. } => Kept::Measurement {
                sha256: *sha256,
                part: part.clone(),
            },
            Record::Table(t) => Kept::Table(t.clone()),
            Record::Status {
                version, status, ..
            } => Kept::Status {
                version: *version,
                status: status.clone(),
            },
            Record::Learning { memory, .. } => Kept::Learning(memory.clone()),
            Record::Event { .. } => return None,
        })
    }
}

impl TableStatus {
    /// The status's name, as the journal and the store spell it.
    pub fn name(&self) -> &'static str {
        match self {
            TableStatus::Waiting { .. } => "waiting",
            TableStatus::Pushed { .. } => "pushed",
            TableStatus::Refused { .. } => "refused",
        }
    }
}
