//! The way from an adapter to a machine's loop: each running machine's mailbox (a
//! [`MachineCommand`] with the channel its answer comes back on), and what the machine's own
//! errors mean as a [`CommandError`]. Neither adapter owns it, so HTTP and OPC UA reach the
//! machines the same way without importing each other, and the runner needs neither.

use crate::names::MachineName;
use camloop_loop::{CommandError, CommandOutcome, MachineCommand, TableVersion};
use std::collections::HashMap;
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot};

/// Where a machine's loop sends its answer to a command.
pub(crate) type Reply = oneshot::Sender<Result<CommandOutcome, CommandError>>;

/// A machine's mailbox: a command and where its answer goes.
pub(crate) type Mailbox = mpsc::Sender<(MachineCommand, Reply)>;

/// The mailbox of each machine running on this instance (in a cluster, those it holds now).
pub(crate) type CommandRoutes = Arc<std::sync::RwLock<HashMap<MachineName, Mailbox>>>;

impl From<crate::service::machine::MachineError> for CommandError {
    /// A write the machine's loop did not make: a rule's refusal is the command's own,
    /// a journal or state folder that failed is the service's, each its own case.
    fn from(e: crate::service::machine::MachineError) -> Self {
        use crate::service::machine::MachineError;
        let reason = e.to_string();
        match e {
            MachineError::Refused { .. } => CommandError::Refused { reason },
            MachineError::Journal { .. } => CommandError::JournalUnavailable { reason },
            MachineError::FencedOut { .. } => CommandError::Elsewhere { reason },
            MachineError::ShareState { .. } => CommandError::ShareStateFailed { reason },
            MachineError::Failed { .. } => CommandError::Failed { reason },
        }
    }
}

impl From<crate::service::machine::RollbackError> for CommandError {
    /// A rollback the machine's loop could not make: an unknown version, a store it could
    /// not read, anything else (a guard, an unusable stored program) refused.
    fn from(e: crate::service::machine::RollbackError) -> Self {
        use crate::service::machine::RollbackError;
        match e {
            RollbackError::NotFound {
                ref lobe, version, ..
            } => match TableVersion::new(version) {
                Some(version) => CommandError::VersionNotFound {
                    lobe: lobe.clone(),
                    version,
                },
                None => CommandError::Refused {
                    reason: e.to_string(),
                },
            },
            RollbackError::StoreUnavailable => CommandError::StoreUnavailable {
                reason: e.to_string(),
            },
            RollbackError::Delivery(e) => CommandError::from(e),
            e => CommandError::Refused {
                reason: format!("{e:#}"),
            },
        }
    }
}
