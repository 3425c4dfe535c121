//! `camloop run`: the shop-floor service. Builds the adapters and wires the tasks: per
//! machine a gauge source and the machine's loop; a store connector; the HTTP listener; and a
//! graceful shutdown on SIGINT/SIGTERM that lets every machine finish the part in hand.

mod access_setup;
pub mod backlog;
pub(crate) use access_setup::seal_dir;
pub(crate) mod action;
pub mod app;
mod cluster_task;
pub(crate) mod command;
mod database_health;
mod drop_source;
pub mod health;
pub mod http;
pub mod journal;
mod lease_keeper;
mod listener_setup;
pub mod machine;
pub mod metrics;
pub(crate) mod offload;
pub mod opcua_port;
pub mod plant;
pub(crate) mod runner;
pub(crate) mod sign_in;
pub mod sim_source;
mod sources;
mod startup;
mod store_guard;

use crate::config::{Checked, Config};
use crate::store::Store;
use camloop_loop::{CommandError, CommandOutcome, MachineCommand};
use machine::{MachineLoop, SourceEvent, StoreHandle};
use metrics::Metrics;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tracing::{error, info, warn};

/// How often waiting tables and journal records are retried, the database reconnected, and
/// the journal released of what the database holds durably (a checkpoint on SQLite).
const RETRY_EVERY: Duration = Duration::from_secs(2);

/// How often raw revolutions older than the retention are dropped (also once at start).
const RETENTION_EVERY: Duration = Duration::from_secs(600);

/// Options of one run.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stop after this many parts per simulated machine in this run (demos, tests); `None`:
    /// run until a signal.
    pub parts: Option<u64>,
    /// Continue on a database that is not the one camloop last wrote (after the operator
    /// chose to: see `store_guard`); otherwise such a start is refused.
    pub accept_new_database: bool,
}

impl RunOptions {
    /// Stop after `n` parts per simulated machine.
    pub fn parts(n: u64) -> Self {
        Self {
            parts: Some(n),
            ..Self::default()
        }
    }
}

/// A started service.
pub struct Running {
    /// Where the HTTP API listens (useful with port 0).
    pub http_addr: std::net::SocketAddr,
    shutdown: watch::Sender<bool>,
    machines_done: Option<tokio::task::JoinHandle<()>>,
    machines: Machines,
    server: tokio::task::JoinHandle<()>,
    /// The runtime the listener runs on (its own threads: it answers while the machines'
    /// work saturates the others); shut down last.
    http_runtime: startup::HttpRuntime,
    connector: tokio::task::JoinHandle<()>,
    retention: tokio::task::JoinHandle<()>,
    store: StoreHandle,
    opcua: Option<camloop_opcua::OpcUa>,
    /// The disk reserve every journal of this service shares.
    _reserve: journal::SharedReserve,
}

impl Running {
    /// Waits until every machine's source has finished its parts (only ends with `parts`
    /// set); the machines keep serving requests until [`Running::stop`].
    pub async fn machines_done(&mut self) {
        if let Some(handle) = self.machines_done.take() {
            let _ = handle.await;
        }
    }

    /// Asks every machine to finish the part in hand, then stops everything.
    pub async fn stop(self) {
        let _ = self.shutdown.send(true);
        if let Some(handle) = self.machines_done {
            handle.abort();
        }
        match self.machines {
            Machines::Local(runner) => runner.stop_all().await,
            Machines::Cluster(task) => {
                let _ = task.await;
            }
        }
        let _ = self.server.await;
        if let Some(server) = self.opcua {
            server.stop().await;
        }
        let _ = self.connector.await;
        let _ = self.retention.await;
        if let Some(s) = self.store.read().await.as_ref() {
            s.close().await;
        }
        drop(self.http_runtime);
        info!("camloop stopped");
    }
}

/// Runs the service until a signal (or, with `parts`, until every simulated machine is done).
pub async fn run(checked: Checked, options: RunOptions) -> anyhow::Result<()> {
    let mut running = start_checked(checked, options).await?;
    tokio::select! {
        _ = running.machines_done() => info!("every machine finished its parts"),
        _ = shutdown_signal() => info!("signal received: finishing the parts in hand"),
    }
    running.stop().await;
    Ok(())
}

/// Checks the config and everything it names (see [`crate::config::check`]), then starts
/// every task of the service and returns at once.
pub async fn start(config: Config, options: RunOptions) -> anyhow::Result<Running> {
    start_checked(crate::config::check(config)?, options).await
}

/// Starts every task of a service whose config passed every check (so nothing below
/// touches the database or a share before the whole config is known good) and returns at
/// once.
pub(crate) async fn start_checked(
    checked: Checked,
    options: RunOptions,
) -> anyhow::Result<Running> {
    begin(checked, options).await?.finish().await
}

/// Checks the config (see [`crate::config::check`]) and starts the store and the HTTP
/// listener; the machines open with [`Starting::finish`]. Meanwhile `/healthz` answers,
/// with the status "starting".
pub async fn start_serving(config: Config, options: RunOptions) -> anyhow::Result<Starting> {
    begin(crate::config::check(config)?, options).await
}

/// The first half of a start: everything up to the listener serving.
async fn begin(checked: Checked, options: RunOptions) -> anyhow::Result<Starting> {
    let Checked {
        config,
        machines: checked_machines,
        listener,
    } = checked;
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let metrics = Arc::new(Metrics::default());
    startup::machines_opening(&metrics, 0, config.machines.len());
    // The TLS pair is checked before anything is made: a bad pair leaves no database,
    // admin or var folder behind.
    let tls = listener_setup::load_tls(&config, &metrics)?;
    access_setup::private_var_dir(&config)?;
    // Before any machine opens: their journals share this one reserve.
    let reserve = journal::share_reserve_under(&config.machines_dir());
    let (store, connector, retention) =
        startup::start_store(&config, options.accept_new_database, &shutdown_rx).await?;
    tokio::spawn(database_health::watch(
        store.clone(),
        metrics.clone(),
        shutdown_rx.clone(),
    ));

    let publisher = startup::start_mqtt(&config, &shutdown_rx)?;
    if let Some(p) = &publisher {
        let metrics = metrics.clone();
        p.report_to(move |m| metrics.set_mqtt(m));
    }

    // OPC UA: the loops feed it from their start; the server starts with the API state.
    let (opcua_events, opcua_intake) = opcua_port::prepare(&config, &checked_machines)?;
    let (features, sheets) = startup::feature_catalogue(&checked_machines);
    let shared = Shared {
        store: store.clone(),
        metrics: metrics.clone(),
        shutdown: shutdown_rx.clone(),
        parts: options.parts,
        plant_events: plant::EventSender::joined(
            publisher
                .as_ref()
                .map(|p| plant::EventSender::from(p.sender())),
            opcua_events,
        ),
    };
    let commands: command::CommandRoutes = Arc::default();
    let runner = runner::Runner::new(config.clone(), checked_machines, shared, commands.clone());
    let cluster_view = startup::cluster_leases(&config).await?;

    // The listener serves from here on, on its own runtime, while the machines open:
    // /healthz says "starting" until they are.
    let limits = http::HttpLimits::from_config(&config.http);
    let app_state = http::AppState {
        store: store.clone(),
        metrics: metrics.clone(),
        machines: Arc::new(features),
        commands,
        auth: Arc::new(access_setup::access_settings(&config)?),
        body_timeout: limits.body_timeout,
        dashboard: Arc::new(sheets),
        cluster: cluster_view.clone(),
    };
    let app = http::router(app_state.clone());
    let http_addr = listener.local_addr()?;
    let policy = listener_setup::policy(&config, http_addr, tls.as_ref(), &metrics, &shutdown_rx)?;
    let http_runtime = startup::HttpRuntime::start()?;
    let tls_on = tls.is_some();
    let server = http_runtime.serve(listener, app, limits, policy, tls, shutdown_rx.clone());
    info!(listen = %http_addr, tls = tls_on, machines = config.machines.len(), "camloop listening; machines opening");

    Ok(Starting {
        http_addr,
        config,
        runner,
        cluster_view,
        metrics,
        app_state,
        opcua_intake,
        _publisher: publisher,
        shutdown: shutdown_tx,
        shutdown_rx,
        server,
        http_runtime,
        connector,
        retention,
        store,
        reserve,
    })
}

/// A service that serves HTTP (`/healthz` says "starting") and has not opened its machines
/// yet: [`Starting::finish`] opens them.
pub struct Starting {
    /// Where the HTTP API listens (useful with port 0).
    pub http_addr: std::net::SocketAddr,
    config: Config,
    runner: runner::Runner,
    cluster_view: Option<crate::cluster::Leases>,
    metrics: Arc<Metrics>,
    app_state: http::AppState,
    opcua_intake: Option<camloop_opcua::Intake>,
    _publisher: Option<camloop_mqtt::Publisher>,
    shutdown: watch::Sender<bool>,
    shutdown_rx: watch::Receiver<bool>,
    server: tokio::task::JoinHandle<()>,
    http_runtime: startup::HttpRuntime,
    connector: tokio::task::JoinHandle<()>,
    retention: tokio::task::JoinHandle<()>,
    store: StoreHandle,
    reserve: journal::SharedReserve,
}

impl Starting {
    /// Opens every machine (or joins the cluster's leases), starts OPC UA, and returns the
    /// running service. An error stops what had started.
    pub async fn finish(self) -> anyhow::Result<Running> {
        let Starting {
            http_addr,
            config,
            runner,
            cluster_view,
            metrics,
            app_state,
            opcua_intake,
            _publisher,
            shutdown,
            shutdown_rx,
            server,
            http_runtime,
            connector,
            retention,
            store,
            reserve,
        } = self;
        let (machines, sources_done) =
            startup::start_machines(&config, runner, cluster_view, &metrics, &shutdown_rx).await?;
        let opcua = opcua_port::start(&config, app_state, opcua_intake, &shutdown_rx).await?;
        info!(listen = %http_addr, machines = config.machines.len(), "camloop started");
        let machines_done = tokio::spawn(startup::sources_ended(sources_done));
        Ok(Running {
            http_addr,
            shutdown,
            machines_done: Some(machines_done),
            machines,
            server,
            http_runtime,
            connector,
            retention,
            store,
            opcua,
            _reserve: reserve,
        })
    }
}

/// What every machine's tasks share.
struct Shared {
    store: StoreHandle,
    metrics: Arc<Metrics>,
    shutdown: watch::Receiver<bool>,
    parts: Option<u64>,
    /// Where the loops send plant events (MQTT), when enabled.
    plant_events: Option<plant::EventSender>,
}

/// This instance's machines: all of them, or those a cluster gives it.
enum Machines {
    Local(Arc<runner::Runner>),
    Cluster(tokio::task::JoinHandle<()>),
}

/// One machine: events in order, retries on a timer, stops on shutdown after the part in hand.
/// The machine keeps serving write requests and retries after its source has ended (a
/// simulated run with a part count); `source_done` says when that happened.
async fn machine_task(
    mut machine: MachineLoop,
    mut rx: mpsc::Receiver<SourceEvent>,
    mut commands: mpsc::Receiver<(MachineCommand, command::Reply)>,
    source_done: tokio::sync::oneshot::Sender<()>,
    mut shutdown: watch::Receiver<bool>,
    metrics: &Metrics,
) {
    let mut retry = tokio::time::interval(RETRY_EVERY);
    // After a pause (a stopped process, a suspended VM) one retry, not one per tick missed.
    retry.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut source_done = Some(source_done);
    loop {
        tokio::select! {
            biased;
            event = rx.recv(), if source_done.is_some() => match event {
                Some(_) if machine.fenced_out() => return fenced_out(&machine),
                Some(e) => {
                    let measurement = matches!(e, SourceEvent::Measurement { .. });
                    offload::drive(machine.handle(e)).await;
                    if measurement {
                        metrics.backlog.recorded(&machine.name);
                    }
                }
                None => {
                    if let Some(done) = source_done.take() {
                        let _ = done.send(());
                    }
                }
            },
            Some((command, reply)) = commands.recv() => {
                let _ = reply.send(offload::drive(carry_out(&mut machine, command)).await);
            }
            _ = retry.tick() => {
                if machine.fenced_out() {
                    return fenced_out(&machine);
                }
                offload::drive(machine.retry()).await;
            }
            _ = shutdown.changed() => break,
        }
    }
    // Whatever is still waiting gets one more try before the process ends.
    if !machine.fenced_out() {
        offload::drive(machine.retry()).await;
    }
}

/// Another instance took the machine while this one could not renew its lease (paused, cut
/// off from the database): the event in hand stays with its source (a drop file in its
/// inbox, for the new owner) and this loop ends without another write.
fn fenced_out(machine: &MachineLoop) {
    error!(machine = %machine.name, "cluster: another instance owns this machine now; stopped here without writing");
}

/// Carries out a command an adapter sent to the machine's loop.
async fn carry_out(
    machine: &mut MachineLoop,
    command: MachineCommand,
) -> Result<CommandOutcome, CommandError> {
    match command {
        MachineCommand::Rollback { lobe, version } => {
            let done = machine.rollback(&lobe, version).await?;
            Ok(CommandOutcome {
                version: Some(done.new_version),
                message: done.summary,
            })
        }
        MachineCommand::Freeze { lobe, frozen } => {
            match machine.set_frozen(&lobe, frozen.clone()).await {
                Some(_) => Ok(CommandOutcome {
                    version: None,
                    message: match frozen {
                        Some(why) => format!("learning of {lobe} frozen: {why}"),
                        None => format!("learning of {lobe} resumed"),
                    },
                }),
                None => Err(CommandError::Refused {
                    reason: format!("{lobe} is not ground here"),
                }),
            }
        }
        MachineCommand::RollbackPart { versions } => {
            let done = machine.rollback_part(&versions).await?;
            Ok(CommandOutcome {
                version: None,
                message: done
                    .iter()
                    .map(|d| d.summary.clone())
                    .collect::<Vec<_>>()
                    .join("; "),
            })
        }
        MachineCommand::Dressing {
            wheel_radius_mm,
            infeed_um,
            source,
        } => {
            let d = machine.dress(wheel_radius_mm, infeed_um, &source).await?;
            Ok(CommandOutcome {
                version: None,
                message: d.summary,
            })
        }
    }
}

async fn connect_store(config: &Config, store: &StoreHandle) {
    match Store::connect(&config.database_url()).await {
        Ok(s) => {
            info!(backend = s.backend(), "history store connected");
            *store.write().await = Some(s);
        }
        Err(e) => {
            error!(error = %e, "history store unavailable: measurements are kept in the journal until it is back")
        }
    }
}

async fn keep_store_connected(
    config: Config,
    store: StoreHandle,
    mut shutdown: watch::Receiver<bool>,
) {
    let url = config.database_url();
    let mut tick = tokio::time::interval(RETRY_EVERY);
    // A problem is said once (ERROR) until it changes, not every 2 s.
    let mut said = String::new();
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => return,
        }
        if store.read().await.is_some() {
            said.clear();
            continue;
        }
        let problem = match Store::connect(&url).await {
            // A database that comes back late is checked as at start: a replaced or emptied
            // one is never written to.
            Ok(s) => match store_guard::check_late(&s, &config).await {
                Ok(()) => {
                    info!(
                        backend = s.backend(),
                        "history store back: writing the journal"
                    );
                    *store.write().await = Some(s);
                    continue;
                }
                Err(e) => {
                    s.close().await;
                    format!("{e:#}")
                }
            },
            Err(e) if e.is_permanent() => format!("{e}"),
            Err(e) => {
                warn!(error = %e, "history store still unavailable");
                continue;
            }
        };
        if problem != said {
            error!(error = %problem, "history store refused: records stay in the journal until an operator acts");
            said = problem;
        }
    }
}

/// Raw-revolution retention: at start and every [`RETENTION_EVERY`], drops the raw
/// revolutions of measurements older than `days` (summaries, averaged profiles and analyses
/// stay). 0 days: raw data is kept forever. A database that is down is tried next time.
async fn keep_raw_retention(days: u32, store: StoreHandle, mut shutdown: watch::Receiver<bool>) {
    if days == 0 {
        return;
    }
    let mut tick = tokio::time::interval(RETENTION_EVERY);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => return,
        }
        let Some(s) = store.read().await.clone() else {
            continue;
        };
        let age = jiff::SignedDuration::from_hours(i64::from(days) * 24);
        let cutoff_ms = crate::clock::now()
            .saturating_sub(age)
            .unwrap_or(jiff::Timestamp::MIN);
        match s.prune_raw_older_than(cutoff_ms).await {
            Ok(0) => {}
            Ok(n) => info!(
                measurements = n,
                days, "raw revolutions older than the retention dropped"
            ),
            Err(e) => warn!(error = %e, "raw-data retention failed, tried again later"),
        }
    }
}

async fn shutdown_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term =
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(s) => s,
                Err(_) => {
                    let _ = ctrl_c.await;
                    return;
                }
            };
        tokio::select! {
            _ = ctrl_c => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    {
        let _ = ctrl_c.await;
    }
}
