//! The way from an adapter to a machine's loop, the one every adapter takes: [`write`] checks
//! the caller's [`Action`], hands a [`MachineCommand`] to the machine's mailbox, waits for
//! its answer and audits it; [`acknowledge`] does the same for an alarm. Also what the
//! machine's own errors mean as a [`CommandError`]. Neither adapter owns it, so HTTP and
//! OPC UA reach the machines the same way without importing each other, and the runner
//! needs neither.

use super::action::Action;
use super::machine::StoreHandle;
use super::metrics::Metrics;
use crate::names::{FeatureName, MachineName};
use crate::store::{AckOutcome, AuditEntry, AuditResult, EventId, Role, StoreError};
use camloop_loop::{CommandError, CommandOutcome, MachineCommand};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot};
use tracing::{error, info};

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
            RollbackError::NotFound { lobe, version, .. } => {
                CommandError::VersionNotFound { lobe, version }
            }
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

/// Who asks for a write, as the audit trail names them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    /// User name, `anonymous` or `api-token`.
    pub actor: String,
    /// `None`: no role at all (anonymous without anonymous reading).
    pub role: Option<Role>,
    /// The client's address as the audit trail shows it.
    pub client: String,
}

impl Caller {
    /// An audit entry of `action` by this caller now; the write fills in the rest.
    fn audit(&self, action: &str) -> AuditEntry {
        AuditEntry {
            at: crate::clock::now(),
            actor: self.actor.clone(),
            role: self.role.unwrap_or(Role::Viewer),
            client: self.client.clone(),
            action: action.to_string(),
            machine: None,
            feature: None,
            version: None,
            before: None,
            after: None,
            result: AuditResult::Ok,
            reason: String::new(),
        }
    }
}

/// What the way to the machines needs of the service: the history store (the audit trail,
/// acknowledgements), the metrics (what is in force, for the audit's before and after), the
/// configured machines and the running ones' mailboxes.
#[derive(Clone, Copy)]
pub struct Writes<'a> {
    pub store: &'a StoreHandle,
    pub metrics: &'a Metrics,
    pub machines: &'a BTreeMap<MachineName, Vec<FeatureName>>,
    pub routes: &'a CommandRoutes,
    /// The audit trail's key and head: every row this path appends is sealed with them.
    pub audit_seal: &'a crate::audit_seal::AuditSeal,
}

/// Why a write was not carried out. [`WriteError::code`] is the stable code every adapter
/// reports it by (the API answers with it, the audit trail keeps it).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WriteError {
    /// The caller's role is below the action's (an adapter that checks roles first never
    /// sees it).
    #[error("this needs the role {needed}; {actor} has {}", role.map_or("none", Role::as_str))]
    Forbidden {
        needed: Role,
        actor: String,
        role: Option<Role>,
    },
    #[error("machine {machine} is not configured")]
    NotConfigured { machine: MachineName },
    #[error("machine {machine} does not grind a lobe or pin {feature}")]
    NotGround {
        machine: MachineName,
        feature: FeatureName,
    },
    /// Configured, but another instance of the cluster owns it now.
    #[error(
        "machine {machine} does not run on this instance now: another instance of the cluster holds it; ask that one"
    )]
    Elsewhere { machine: MachineName },
    #[error("machine {machine} is not running")]
    NotRunning { machine: MachineName },
    /// It stopped before it answered.
    #[error("machine {machine} stopped")]
    Stopped { machine: MachineName },
    /// The machine's loop answered that it did not carry the command out.
    #[error("{error}")]
    Command { action: Action, error: CommandError },
}

impl WriteError {
    /// The stable code (`machine_stopped`, `rollback_refused`, …); a refusal is the
    /// action's own.
    pub fn code(&self) -> &'static str {
        match self {
            WriteError::Forbidden { .. } => "forbidden",
            WriteError::NotConfigured { .. } => "machine_not_found",
            WriteError::NotGround { .. } => "lobe_not_found",
            WriteError::Elsewhere { .. } => "machine_elsewhere",
            WriteError::NotRunning { .. } | WriteError::Stopped { .. } => "machine_stopped",
            WriteError::Command { action, error } => match error {
                CommandError::VersionNotFound { .. } => "table_version_not_found",
                CommandError::StoreUnavailable { .. } => "store_unavailable",
                CommandError::Refused { .. } => refused_code(*action),
                CommandError::Failed { .. } => "command_failed",
                CommandError::JournalUnavailable { .. } => "journal_unavailable",
                CommandError::ShareStateFailed { .. } => "share_state_failed",
                CommandError::Elsewhere { .. } => "machine_elsewhere",
            },
        }
    }

    /// The service is at fault or not serving the machine now (try again later), not the
    /// request: the audit trail says `failed`, not `refused`.
    pub fn is_service_fault(&self) -> bool {
        match self {
            WriteError::Forbidden { .. }
            | WriteError::NotConfigured { .. }
            | WriteError::NotGround { .. } => false,
            WriteError::Elsewhere { .. }
            | WriteError::NotRunning { .. }
            | WriteError::Stopped { .. } => true,
            WriteError::Command { error, .. } => !matches!(
                error,
                CommandError::VersionNotFound { .. } | CommandError::Refused { .. }
            ),
        }
    }
}

/// The code of a command the loop refused: the action's own.
fn refused_code(action: Action) -> &'static str {
    match action {
        Action::FreezeLearning => "freeze_refused",
        Action::ReportDressing => "dressing_refused",
        _ => "rollback_refused",
    }
}

/// The action a command is, for its role and its refusal's code.
pub fn action_of(command: &MachineCommand) -> Action {
    match command {
        MachineCommand::Rollback { .. } => Action::Rollback,
        MachineCommand::RollbackPart { .. } => Action::RollbackPart,
        MachineCommand::Freeze { .. } => Action::FreezeLearning,
        MachineCommand::Dressing { .. } => Action::ReportDressing,
    }
}

/// Carries out `command` on `machine` for `caller`, whatever adapter it came through:
/// checks the caller's role and that the machine grinds the features named, hands the
/// command to the machine's loop (which owns the loop state, so a write never races a
/// part), waits for its answer and audits the write with its outcome. The adapter has
/// checked the values' ranges.
pub(crate) async fn write(
    w: Writes<'_>,
    caller: &Caller,
    machine: &MachineName,
    command: MachineCommand,
) -> Result<CommandOutcome, WriteError> {
    let action = action_of(&command);
    if !action.allowed(caller.role) {
        return Err(WriteError::Forbidden {
            needed: action.role(),
            actor: caller.actor.clone(),
            role: caller.role,
        });
    }
    let Some(grinds) = w.machines.get(machine) else {
        return Err(WriteError::NotConfigured {
            machine: machine.clone(),
        });
    };
    let named: Vec<FeatureName> = match &command {
        MachineCommand::Rollback { lobe, .. } | MachineCommand::Freeze { lobe, .. } => {
            vec![lobe.clone()]
        }
        MachineCommand::RollbackPart { versions } => {
            versions.iter().map(|(f, _)| f.clone()).collect()
        }
        MachineCommand::Dressing { .. } => Vec::new(),
    };
    if let Some(feature) = named.iter().find(|f| !grinds.contains(f)) {
        return Err(WriteError::NotGround {
            machine: machine.clone(),
            feature: feature.clone(),
        });
    }
    let record = Record::of(w, caller, machine, &command, grinds);
    let done = send(w, machine, command)
        .await
        .map_err(|error| match error {
            Sent::Command(error) => WriteError::Command { action, error },
            Sent::Not(e) => e,
        });
    record.outcome(w, &done).await;
    done
}

/// What the audit row of a write keeps: the entry as it stood before, and how to read the
/// state after.
struct Record {
    machine: MachineName,
    entry: AuditEntry,
    after: After,
}

/// What a write's audit row reads after it.
enum After {
    InForce(Vec<FeatureName>),
    Frozen(FeatureName),
    Dressed(Vec<FeatureName>, f64),
}

impl Record {
    fn of(
        w: Writes<'_>,
        caller: &Caller,
        machine: &MachineName,
        command: &MachineCommand,
        grinds: &[FeatureName],
    ) -> Self {
        let (name, after) = match command {
            MachineCommand::Rollback { lobe, .. } => {
                ("rollback", After::InForce(vec![lobe.clone()]))
            }
            MachineCommand::RollbackPart { versions } => (
                "rollback_part",
                After::InForce(versions.iter().map(|(f, _)| f.clone()).collect()),
            ),
            MachineCommand::Freeze { lobe, frozen } => (
                match frozen {
                    Some(_) => "learning.freeze",
                    None => "learning.resume",
                },
                After::Frozen(lobe.clone()),
            ),
            MachineCommand::Dressing {
                wheel_radius_mm, ..
            } => (
                "dressing",
                After::Dressed(grinds.to_vec(), *wheel_radius_mm),
            ),
        };
        let mut entry = caller.audit(name);
        entry.machine = Some(machine.to_string());
        match command {
            MachineCommand::Rollback { lobe, version } => {
                entry.feature = Some(lobe.to_string());
                entry.version = Some(version.to_i64());
            }
            MachineCommand::Freeze { lobe, .. } => entry.feature = Some(lobe.to_string()),
            MachineCommand::RollbackPart { .. } | MachineCommand::Dressing { .. } => {}
        }
        let mut record = Self {
            machine: machine.clone(),
            entry,
            after,
        };
        record.entry.before = Some(record.state(w, false));
        record
    }

    /// The state the audit row keeps before or after the write, as JSON.
    fn state(&self, w: Writes<'_>, after: bool) -> String {
        let machine = &self.machine;
        match &self.after {
            After::InForce(features) => in_force(w, machine, features).to_string(),
            After::Frozen(lobe) => {
                let f = w.metrics.features();
                let now = f
                    .get(&(machine.clone(), lobe.clone()))
                    .and_then(|f| f.frozen.clone());
                serde_json::json!({ "frozen": now }).to_string()
            }
            After::Dressed(features, radius_mm) => {
                let mut state = in_force(w, machine, features);
                if after {
                    state["wheel_radius_mm"] = serde_json::json!(radius_mm);
                }
                state.to_string()
            }
        }
    }

    /// Appends the audit row with the write's outcome.
    async fn outcome(mut self, w: Writes<'_>, done: &Result<CommandOutcome, WriteError>) {
        match done {
            Ok(d) => {
                self.entry.reason = d.message.clone();
                self.entry.after = Some(self.state(w, true));
            }
            Err(e) => {
                self.entry.result = match e.is_service_fault() {
                    true => AuditResult::Failed,
                    false => AuditResult::Refused,
                };
                self.entry.reason = format!("{}: {e}", e.code());
            }
        }
        record_audit(w, self.entry).await;
    }
}

/// The table versions on the control of `features` of `machine`, as `{"in_force": {…}}`.
fn in_force(w: Writes<'_>, machine: &MachineName, features: &[FeatureName]) -> serde_json::Value {
    let statuses = w.metrics.features();
    let versions: BTreeMap<&str, i64> = features
        .iter()
        .filter_map(|f| {
            let s = statuses.get(&(machine.clone(), f.clone()))?;
            let version = s.in_force_version.map_or(0, |v| v.get());
            Some((f.as_str(), i64::try_from(version).ok()?))
        })
        .collect();
    serde_json::json!({ "in_force": versions })
}

/// Why a command did not come back with the loop's answer.
enum Sent {
    Not(WriteError),
    Command(CommandError),
}

/// Hands `command` to the machine's loop and waits for its answer.
async fn send(
    w: Writes<'_>,
    machine: &MachineName,
    command: MachineCommand,
) -> Result<CommandOutcome, Sent> {
    let mailbox = w
        .routes
        .read()
        .ok()
        .and_then(|routes| routes.get(machine).cloned());
    let Some(mailbox) = mailbox else {
        return Err(Sent::Not(match w.machines.contains_key(machine) {
            true => WriteError::Elsewhere {
                machine: machine.clone(),
            },
            false => WriteError::NotConfigured {
                machine: machine.clone(),
            },
        }));
    };
    let (reply, answer) = oneshot::channel();
    if mailbox.send((command, reply)).await.is_err() {
        return Err(Sent::Not(WriteError::NotRunning {
            machine: machine.clone(),
        }));
    }
    match answer.await {
        Ok(result) => result.map_err(Sent::Command),
        Err(_) => Err(Sent::Not(WriteError::Stopped {
            machine: machine.clone(),
        })),
    }
}

/// Why an acknowledgement was not made.
#[derive(Debug, thiserror::Error)]
pub enum AckError {
    #[error("this needs the role {needed}")]
    Forbidden { needed: Role },
    /// The history database is not reachable (nothing is audited: the trail is there).
    #[error("the history database is not reachable")]
    StoreUnavailable,
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// Acknowledges event `id` of `machine` for `caller`, and audits it with its outcome.
pub(crate) async fn acknowledge(
    w: Writes<'_>,
    caller: &Caller,
    machine: &MachineName,
    id: i64,
) -> Result<AckOutcome, AckError> {
    if !Action::Acknowledge.allowed(caller.role) {
        return Err(AckError::Forbidden {
            needed: Action::Acknowledge.role(),
        });
    }
    let store = w
        .store
        .read()
        .await
        .clone()
        .ok_or(AckError::StoreUnavailable)?;
    let at = crate::clock::now();
    let outcome = store
        .acknowledge_event(machine, EventId(id), at, &caller.actor)
        .await;
    let mut entry = caller.audit("acknowledge");
    entry.machine = Some(machine.to_string());
    entry.after = Some(format!("{{\"event\":{id}}}"));
    entry.reason = match &outcome {
        Ok(AckOutcome::Acknowledged) => "acknowledged".into(),
        Ok(AckOutcome::AlreadyAcknowledged) => "acknowledged before".into(),
        Ok(AckOutcome::NotFound) => "no such event".into(),
        Err(e) => e.to_string(),
    };
    if !matches!(
        outcome,
        Ok(AckOutcome::Acknowledged | AckOutcome::AlreadyAcknowledged)
    ) {
        entry.result = AuditResult::Refused;
    }
    record_audit(w, entry).await;
    Ok(outcome?)
}

/// Appends `entry` to the audit trail and logs it. When the database cannot take it, the
/// whole entry goes to the log at error level and `camloop_audit_failures_total` counts it:
/// the action has happened and stays done, and what happened is not lost.
pub(crate) async fn record_audit(w: Writes<'_>, entry: AuditEntry) {
    info!(
        actor = %entry.actor,
        role = %entry.role,
        client = %entry.client,
        action = %entry.action,
        machine = entry.machine.as_deref().unwrap_or("-"),
        feature = entry.feature.as_deref().unwrap_or("-"),
        version = entry.version.unwrap_or(0),
        result = entry.result.as_str(),
        reason = %entry.reason,
        "audit"
    );
    let store = w.store.read().await.clone();
    let stored = match store {
        Some(store) => w
            .audit_seal
            .append(&store, &entry)
            .await
            .map(|_| ())
            .map_err(|e| e.to_string()),
        None => Err(STORE_DOWN.to_string()),
    };
    if let Err(why) = stored {
        w.metrics.update_access(|a| a.audit_failures_total += 1);
        let text = serde_json::to_string(&entry).unwrap_or_default();
        error!(entry = %text, why = %why, "audit row not stored");
    }
}

/// Why an audit row could not be stored while the database is down (the API's words).
const STORE_DOWN: &str =
    "the history database is not reachable; measurements are kept in the journal";
