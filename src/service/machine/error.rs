//! Why a write of a machine's loop (a table delivery, a dressing) did not happen, typed so
//! the API answers each case with its own code (see `CommandError`'s `From` in
//! `service::command`): a rule that refused is the caller's to hear about (409), a journal
//! or state folder that cannot be written is the service's fault (503, 500), never reported
//! as a refusal.

/// What went wrong on a machine's write path.
#[derive(Debug, thiserror::Error)]
pub enum MachineError {
    /// A rule refused the write (a wheel radius or infeed out of range, a table the checks
    /// refuse to render): nothing was changed.
    #[error("{reason}")]
    Refused { reason: String },
    /// The journal could not keep the write's records (disk full, folder unwritable): the
    /// write-ahead rule holds, so nothing was submitted to the share.
    #[error("the journal cannot be written: {reason}")]
    Journal { reason: String },
    /// Another instance of the cluster owns the machine now: nothing was written here.
    #[error("another instance owns this machine now: {reason}")]
    FencedOut { reason: String },
    /// The share's state folder (manifest, kept texts) could not be written or read.
    #[error("share state folder: {reason}")]
    ShareState { reason: String },
    /// Anything else that went wrong on the machine's side (the share numbered a version
    /// other than its record says, the main program could not be made).
    #[error("{reason}")]
    Failed { reason: String },
}

impl MachineError {
    /// A rule's refusal, its text with every cause.
    pub(super) fn refused(e: impl Into<anyhow::Error>) -> Self {
        MachineError::Refused {
            reason: format!("{:#}", e.into()),
        }
    }
}

/// The feature machine's word for a table not delivered, as the API's.
impl From<camloop_loop::machine::DeliveryError> for MachineError {
    fn from(e: camloop_loop::machine::DeliveryError) -> Self {
        use camloop_loop::machine::DeliveryError as D;
        match e {
            D::Refused { reason } => MachineError::Refused { reason },
            D::Journal { reason } => MachineError::Journal { reason },
            D::FencedOut { reason } => MachineError::FencedOut { reason },
            D::ShareState { reason } => MachineError::ShareState { reason },
            D::Failed { reason } => MachineError::Failed { reason },
        }
    }
}
