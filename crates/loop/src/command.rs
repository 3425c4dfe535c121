//! The writes an adapter (HTTP, OPC UA) asks of a machine's loop, what the loop answers when
//! it carried one out, and why it did not. Pure types: the channel that carries a command and
//! its answer is the service's, and so is each adapter's mapping of an error to its own
//! status (an HTTP code, an OPC UA status).

use crate::{FeatureName, TableVersion};

/// A write request for a machine's loop. The adapter has already checked the caller's role,
/// the machine, the feature (one the machine grinds) and the values' ranges.
#[derive(Debug, Clone, PartialEq)]
pub enum MachineCommand {
    /// Deliver stored table `version` of `lobe` again, as a new version under the table
    /// number not in use, and restore the correction it was made from.
    Rollback {
        lobe: FeatureName,
        version: TableVersion,
    },
    /// The wheel was dressed to this radius (mm, already within 5–1000), the dresser
    /// measured this infeed (µm, already within 0–1000) if it said: regenerate the table.
    /// `source` is who reported it (`api:<user>`), as the store keeps it.
    Dressing {
        wheel_radius_mm: f64,
        infeed_um: Option<f64>,
        source: String,
    },
    /// Freeze the learning of `lobe` with this reason, or (`None`) let it learn again.
    Freeze {
        lobe: FeatureName,
        frozen: Option<String>,
    },
    /// Roll several features back together (a whole part: one version of each); every
    /// version is checked before any is pushed.
    RollbackPart {
        versions: Vec<(FeatureName, TableVersion)>,
    },
}

/// A write the machine's loop carried out.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandOutcome {
    /// The table version the write made, when it made one.
    pub version: Option<TableVersion>,
    /// One line for the operator ("rollback to v1 delivered as v7 (T2)").
    pub message: String,
}

/// Why a machine's loop did not carry out a write. Each adapter maps every case to one
/// status of its own (HTTP: a status and a stable code).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// The version asked for does not exist for the lobe.
    #[error("version {version} of {lobe} not found")]
    VersionNotFound {
        lobe: FeatureName,
        version: TableVersion,
    },
    /// The history database is needed and not reachable.
    #[error("the history database is not reachable: {reason}")]
    StoreUnavailable { reason: String },
    /// The loop refused (a guard failed, the stored program is unusable, …): the command's
    /// own refusal.
    #[error("{reason}")]
    Refused { reason: String },
    /// Anything else that went wrong on the machine's side.
    #[error("{reason}")]
    Failed { reason: String },
    /// The machine's journal could not keep the write.
    #[error("{reason}")]
    JournalUnavailable { reason: String },
    /// The share's state folder could not be written.
    #[error("{reason}")]
    ShareStateFailed { reason: String },
    /// Another instance of the cluster took the machine meanwhile.
    #[error("{reason}")]
    Elsewhere { reason: String },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The messages the API and the audit trail have always shown.
    #[test]
    fn errors_read_as_before() {
        let e = CommandError::VersionNotFound {
            lobe: FeatureName::new("IN1").unwrap(),
            version: TableVersion::new(7).unwrap(),
        };
        assert_eq!(e.to_string(), "version 7 of IN1 not found");
        let e = CommandError::StoreUnavailable {
            reason: "down".into(),
        };
        assert_eq!(e.to_string(), "the history database is not reachable: down");
        let e = CommandError::Refused {
            reason: "guard".into(),
        };
        assert_eq!(e.to_string(), "guard");
    }
}
