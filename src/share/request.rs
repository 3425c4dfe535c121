//! What a caller hands the share and what it answers: the program files of a version and
//! why it was made, the share's word on a request, a delivered version, what opening the
//! state folder found.

use super::error::{ShareError, StateError};
use crate::core::digest::Sha256;
use crate::core::ids::TableVersion;
use std::path::PathBuf;

/// One program file: a plain file name on the share and its text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProgramFile {
    pub name: String,
    pub text: String,
}

/// A new version to push.
#[derive(Debug, Clone, PartialEq)]
pub struct PushRequest {
    /// Renamed into place in this order: put the main program last, so that it only
    /// calls subprograms that are already there.
    pub files: Vec<ProgramFile>,
    /// The curve-table number the program defines; must be [`Share::next_table_number`].
    pub table_number: u32,
    /// Why this version was made.
    pub reason: String,
    /// The SHA-256 of the measurement the correction was learned from, if any.
    pub measurement_id: Option<Sha256>,
    /// Learning parameters, free-form.
    pub learning: serde_json::Value,
    /// Set for a rollback: the version whose text this re-pushes.
    pub rollback_of: Option<TableVersion>,
    /// From the caller's clock.
    pub created_at: jiff::Timestamp,
}

/// Outcome of recording a request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Submitted {
    /// Recorded and waiting to be delivered.
    Accepted { version: TableVersion },
    /// Recorded as refused; it will never be pushed.
    Refused {
        version: TableVersion,
        reason: String,
    },
}

/// A delivered version.
#[derive(Debug)]
pub struct Pushed {
    pub version: TableVersion,
    pub table_number: u32,
    /// The files on the share, in rename order.
    pub paths: Vec<PathBuf>,
    /// Versions whose kept text was removed after this push.
    pub pruned: Vec<TableVersion>,
    /// Pruning failed (the push itself succeeded; pruning is retried after the next push).
    pub prune_error: Option<StateError>,
}

/// What opening the state folder found and cleaned.
#[derive(Debug, Default)]
pub struct OpenReport {
    /// Bytes of a torn last manifest line (from a kill) that were cut off.
    pub torn_manifest_bytes: u64,
    /// camloop temporaries removed from the share (from a killed run).
    pub removed_share_temporaries: Vec<PathBuf>,
    /// Temporaries and orphan version folders removed from the state folder.
    pub removed_state_entries: Vec<PathBuf>,
    /// The share could not be cleaned now; it is cleaned before the next delivery.
    pub share_unavailable: Option<ShareError>,
}
