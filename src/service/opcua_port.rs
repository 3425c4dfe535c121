//! The service's side of the OPC UA crate's port (`camloop_opcua::Service`): its sign-in,
//! write path, audit trail, feature status, store handle and owner-only files, each a thin
//! call into what HTTP uses too; and the wiring (the machines' layout, the events' sender,
//! the certificate store's folder, the build time). The decisions stay where they are:
//! roles in `action`, the writes in `command`, the sign-in in `sign_in`.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use async_trait::async_trait;
use camloop_loop::{CommandOutcome, MachineCommand};
use camloop_opcua::{
    AckRefused, Caller, FeatureView, FileError, Intake, OPCUA_CLIENT, OpcUa, Refusal, Service,
    SignIn, SignInUnavailable, Status, Write, WriteRefused,
};
use tokio::sync::watch;

use super::action::Action;
use super::app::AppState;
use super::command::{self, AckError, WriteError};
use super::machine::StoreHandle;
use super::metrics::{FeatureStatus, Metrics};
use super::plant::EventSender;
use super::sign_in;
use crate::auth::Client;
use crate::config::{CheckedMachine, Config};
use crate::names::{FeatureName, MachineName};
use crate::store::{AckOutcome, AuditEntry, Role, Store};

/// The service as the OPC UA server sees it: the state every adapter shares.
struct Port {
    app: AppState,
}

#[async_trait]
impl Service for Port {
    async fn store(&self) -> Option<Store> {
        self.app.store.read().await.clone()
    }

    fn machines(&self) -> &BTreeMap<MachineName, Vec<FeatureName>> {
        &self.app.machines
    }

    fn needed_role(&self, write: Write) -> Role {
        match write {
            Write::Rollback => Action::Rollback.role(),
            Write::Acknowledge => Action::Acknowledge.role(),
        }
    }

    async fn sign_in(&self, user: &str, password: &str) -> Result<SignIn, SignInUnavailable> {
        let done =
            sign_in::password_sign_in(&self.app, user, password, Client::OpcUa, OPCUA_CLIENT)
                .await
                .map_err(|e| SignInUnavailable(e.to_string()))?;
        Ok(match done {
            sign_in::SignIn::Ok(user) => SignIn::Ok(user),
            sign_in::SignIn::Wrong => SignIn::Wrong,
            sign_in::SignIn::Refused(why) => SignIn::Refused(why.to_string()),
        })
    }

    async fn write(
        &self,
        caller: &Caller,
        machine: &MachineName,
        command: MachineCommand,
    ) -> Result<CommandOutcome, WriteRefused> {
        command::write(self.app.writes(), &caller_of(caller), machine, command)
            .await
            .map_err(refused)
    }

    async fn acknowledge(
        &self,
        caller: &Caller,
        machine: &MachineName,
        id: i64,
    ) -> Result<AckOutcome, AckRefused> {
        command::acknowledge(self.app.writes(), &caller_of(caller), machine, id)
            .await
            .map_err(|e| match e {
                AckError::Forbidden { needed } => AckRefused::Forbidden { needed },
                AckError::StoreUnavailable => AckRefused::StoreUnavailable,
                AckError::Store(e) => AckRefused::Store(e),
            })
    }

    async fn audit_refusal(&self, entry: AuditEntry) {
        let w = self.app.writes();
        match w.audit_seal.within_refusal_budget(entry) {
            Some(entry) => command::record_audit(w, entry).await,
            None => w
                .metrics
                .update_access(|a| a.refusals_unrecorded_total += 1),
        }
    }

    fn status(&self) -> Status {
        let features = self.app.metrics.features();
        Status {
            features: features.iter().map(|(k, s)| (k.clone(), view(s))).collect(),
            journal_failing: self
                .app
                .metrics
                .snapshot()
                .into_iter()
                .filter(|(_, m)| m.journal_failing > 0)
                .map(|(name, _)| name)
                .collect(),
        }
    }

    fn feature(&self, machine: &MachineName, feature: &FeatureName) -> Option<FeatureView> {
        let features = self.app.metrics.features();
        features.get(&(machine.clone(), feature.clone())).map(view)
    }

    fn create_private_dir(&self, dir: &Path) -> std::io::Result<()> {
        crate::private_fs::create_dir_all(dir)
    }

    fn restrict_to_owner(&self, path: &Path) -> std::io::Result<()> {
        crate::private_fs::restrict(path)
    }

    fn refuse_readable_by_others(&self, path: &Path) -> Result<(), FileError> {
        crate::audit_seal::refuse_readable_by_others(path).map_err(|e| Box::new(e) as FileError)
    }
}

/// The write path's caller: the user as stored now, audited under the OPC UA clients'
/// address.
fn caller_of(caller: &Caller) -> command::Caller {
    command::Caller {
        actor: caller.user.clone(),
        role: Some(caller.role),
        client: OPCUA_CLIENT.to_string(),
    }
}

/// A write the service did not carry out, as the OPC UA crate tells it (the code and
/// message are the API's).
fn refused(e: WriteError) -> WriteRefused {
    let code = e.code();
    let message = e.to_string();
    let kind = match e {
        WriteError::Forbidden { .. } => Refusal::Forbidden,
        WriteError::NotConfigured { .. } | WriteError::NotGround { .. } => Refusal::NotFound,
        WriteError::Elsewhere { .. }
        | WriteError::NotRunning { .. }
        | WriteError::Stopped { .. } => Refusal::Unavailable,
        WriteError::Command { error, .. } => Refusal::Command(error),
    };
    WriteRefused {
        kind,
        code,
        message,
    }
}

/// What the OPC UA crate shows of a feature's status.
fn view(s: &FeatureStatus) -> FeatureView {
    FeatureView {
        last_part: s.last_part.clone(),
        last_max_error_um: s.last_max_error_um,
        in_force_version: s.in_force_version,
        waiting_version: s.waiting_version,
        frozen: s.frozen.clone(),
        blocked_by_guard: s.blocked_by_guard.clone(),
    }
}

impl From<camloop_opcua::Feeder> for EventSender {
    /// The OPC UA server's intake, counting what it refuses where the server reports drops.
    fn from(feeder: camloop_opcua::Feeder) -> Self {
        let (tx, dropped) = feeder.into_parts();
        Self::new(tx, dropped)
    }
}

/// The machines as the address space shows them.
fn layout(machines: &[CheckedMachine]) -> Vec<camloop_opcua::MachineLayout> {
    machines
        .iter()
        .map(|m| camloop_opcua::MachineLayout {
            name: m.name.clone(),
            recipe: m
                .recipe_path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            features: m.setups.iter().map(|s| s.name.clone()).collect(),
        })
        .collect()
}

/// With `[opcua]` on: the sender the loops feed, and the intake [`start`] takes (made before
/// the loops start, the listener bound; the server starts once the API state it shares
/// exists).
pub(crate) fn prepare(
    config: &Config,
    machines: &[CheckedMachine],
) -> anyhow::Result<(Option<EventSender>, Option<Intake>)> {
    match camloop_opcua::prepare(&config.opcua, layout(machines))? {
        Some((feeder, intake)) => Ok((Some(feeder.into()), Some(intake))),
        None => Ok((None, None)),
    }
}

/// The folder of the server's certificate store.
fn pki_dir(config: &Config) -> std::path::PathBuf {
    match &config.opcua.pki_dir {
        Some(dir) => config.resolve(dir),
        None => config.var_dir().join("opcua").join("pki"),
    }
}

/// When this binary was built: the commit's time (`SOURCE_DATE_EPOCH` at build, set by
/// `build.rs`), not the process's start.
fn built() -> jiff::Timestamp {
    let seconds: i64 = env!("CAMLOOP_BUILD_EPOCH_S").parse().unwrap_or(0);
    jiff::Timestamp::from_second(seconds).unwrap_or(jiff::Timestamp::UNIX_EPOCH)
}

/// Starts the server on `opcua.listen` and its feed from `intake` (none: `[opcua]` is off).
pub(crate) async fn start(
    config: &Config,
    app: AppState,
    intake: Option<Intake>,
    shutdown: &watch::Receiver<bool>,
) -> anyhow::Result<Option<OpcUa>> {
    let setup = camloop_opcua::Setup {
        section: &config.opcua,
        pki: pki_dir(config),
        built: built(),
    };
    let service: Arc<dyn Service> = Arc::new(Port { app });
    Ok(camloop_opcua::start(setup, service, intake, shutdown).await?)
}

/// The server as `benches/opcua.rs` runs it: `machines` (name, features) on `listen`,
/// Basic256Sha256 SignAndEncrypt, its PKI in `pki`, anonymous reading and unknown client
/// certificates accepted (the bench's clients are anonymous and new); fed from the returned
/// sender until `shutdown` turns true. Not part of camloop's interface.
#[doc(hidden)]
pub async fn bench_server(
    listen: std::net::SocketAddr,
    pki: &Path,
    machines: Vec<(MachineName, Vec<FeatureName>)>,
    metrics: Arc<Metrics>,
    store: StoreHandle,
    shutdown: watch::Receiver<bool>,
) -> anyhow::Result<EventSender> {
    let app = AppState::without_http(store, metrics);
    let service: Arc<dyn Service> = Arc::new(Port { app });
    let feeder =
        camloop_opcua::bench_server((listen, pki, built()), machines, service, shutdown).await?;
    Ok(feeder.into())
}
