//! The port: what the OPC UA server asks of the service that runs it, as one trait with
//! typed requests and answers. The service implements it (its password sign-in, its one
//! write path with the role of each write's `Action`, its audit trail's budget for
//! refusals, its feature status, its store handle, its owner-only files); this crate never
//! names the service, so the compiler holds the adapter rule.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use async_trait::async_trait;
use camloop_core::names::{FeatureName, MachineName};
use camloop_loop::{CommandError, CommandOutcome, MachineCommand};
use camloop_store::{AckOutcome, AuditEntry, Role, Store, StoreError, User};

/// A write an OPC UA method asks for; the service says which role it needs (its `Action`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Write {
    /// `Rollback`: a stored table version of one feature delivered again.
    Rollback,
    /// `AcknowledgeEvent`: an alarm acknowledged.
    Acknowledge,
}

/// Who asks for a write: the user as stored now (the service audits the write under the
/// OPC UA clients' address, [`crate::OPCUA_CLIENT`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    pub user: String,
    pub role: Role,
}

/// How a password sign-in ended.
#[derive(Debug)]
pub enum SignIn {
    Ok(User),
    /// A wrong name or password: counted, logged and audited by the service.
    Wrong,
    /// Not checked (locked out, or as many checks in flight as would lock), and why.
    Refused(String),
}

/// Why a sign-in could not be checked at all (the database down, every hash slot taken):
/// nothing was counted.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct SignInUnavailable(pub String);

/// Why the service did not carry a write out, as OPC UA tells it; `code` is the service's
/// stable code (the API's and the audit trail's), logged beside the status.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct WriteRefused {
    pub kind: Refusal,
    pub code: &'static str,
    pub message: String,
}

/// What kind of refusal a [`WriteRefused`] is.
#[derive(Debug, Clone, PartialEq)]
pub enum Refusal {
    /// The caller's role is below the write's.
    Forbidden,
    /// The machine is not configured, or does not grind the feature named.
    NotFound,
    /// The machine does not run here now (another instance holds it, or it stopped).
    Unavailable,
    /// The machine's loop answered that it did not carry the command out.
    Command(CommandError),
}

/// Why an acknowledgement was not made.
#[derive(Debug, thiserror::Error)]
pub enum AckRefused {
    #[error("this needs the role {needed}")]
    Forbidden { needed: Role },
    #[error("the history database is not reachable")]
    StoreUnavailable,
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// One feature's loop as the service's status shows it now (what `/metrics` reads too).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FeatureView {
    /// The part the newest measurement came from, and its `max |error|`, µm.
    pub last_part: Option<camloop_core::ids::PartId>,
    pub last_max_error_um: Option<f64>,
    /// The table version on the control (none yet before the first), and a newer one
    /// waiting for the share.
    pub in_force_version: Option<camloop_core::ids::TableVersion>,
    pub waiting_version: Option<camloop_core::ids::TableVersion>,
    /// Learning is frozen, and why.
    pub frozen: Option<String>,
    /// The guard that blocked several parts in a row (its alarm stands), and why.
    pub blocked_by_guard: Option<String>,
}

/// Every feature's status and the machines whose journal cannot be written, now.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Status {
    pub features: BTreeMap<(MachineName, FeatureName), FeatureView>,
    pub journal_failing: BTreeSet<MachineName>,
}

/// A file-system error of the service's own file helpers, with what it was about.
pub type FileError = Box<dyn std::error::Error + Send + Sync>;

/// What the OPC UA server needs of the service. Every method answers at once or awaits
/// the service's own work (a sign-in's hash, a machine's answer); none blocks a thread.
#[async_trait]
pub trait Service: Send + Sync + 'static {
    /// The history store now; `None` while the database is down.
    async fn store(&self) -> Option<Store>;

    /// Every configured machine with its features, in grinding order.
    fn machines(&self) -> &BTreeMap<MachineName, Vec<FeatureName>>;

    /// The least role that may ask for `write` (the role of its `Action`).
    fn needed_role(&self, write: Write) -> Role;

    /// The password sign-in every adapter takes (lockout, bounded hashing, counted and
    /// audited failures), for an OPC UA client.
    async fn sign_in(&self, user: &str, password: &str) -> Result<SignIn, SignInUnavailable>;

    /// Carries `command` out on `machine` through the service's write path (role, mailbox,
    /// audit), as HTTP's writes do.
    async fn write(
        &self,
        caller: &Caller,
        machine: &MachineName,
        command: MachineCommand,
    ) -> Result<CommandOutcome, WriteRefused>;

    /// Acknowledges event `id` of `machine` through the service's write path.
    async fn acknowledge(
        &self,
        caller: &Caller,
        machine: &MachineName,
        id: i64,
    ) -> Result<AckOutcome, AckRefused>;

    /// Audits a refused write within the trail's budget for refusals of one client (beyond
    /// it the refusal is only counted).
    async fn audit_refusal(&self, entry: AuditEntry);

    /// Every feature's status and the machines whose journal fails, now.
    fn status(&self) -> Status;

    /// One feature's status now.
    fn feature(&self, machine: &MachineName, feature: &FeatureName) -> Option<FeatureView>;

    /// Creates `dir` and its missing parents, owner-only (the service's private folders).
    fn create_private_dir(&self, dir: &Path) -> std::io::Result<()>;

    /// Narrows the folder or file at `path` to its owner.
    fn restrict_to_owner(&self, path: &Path) -> std::io::Result<()>;

    /// Refuses a key file other accounts can read (the start stops on it).
    fn refuse_readable_by_others(&self, path: &Path) -> Result<(), FileError>;
}
