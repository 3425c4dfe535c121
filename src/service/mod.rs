//! `camloop run`: the shop-floor service. Builds the adapters and wires the tasks: per
//! machine a gauge source and the machine's loop; a store connector; the HTTP listener; and a
//! graceful shutdown on SIGINT/SIGTERM that lets every machine finish the part in hand.

pub mod http;
pub mod journal;
pub mod machine;
pub mod metrics;
pub mod sim_source;
mod store_guard;

use crate::config::{Config, GaugeSection};
use crate::recipe::Recipe;
use crate::store::Store;
use anyhow::Context;
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
}

/// A started service.
pub struct Running {
    /// Where the HTTP API listens (useful with port 0).
    pub http_addr: std::net::SocketAddr,
    shutdown: watch::Sender<bool>,
    machines_done: Option<tokio::task::JoinHandle<()>>,
    machine_tasks: Vec<tokio::task::JoinHandle<()>>,
    server: tokio::task::JoinHandle<()>,
    connector: tokio::task::JoinHandle<()>,
    retention: tokio::task::JoinHandle<()>,
    store: StoreHandle,
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
        for task in self.machine_tasks {
            let _ = task.await;
        }
        let _ = self.server.await;
        let _ = self.connector.await;
        let _ = self.retention.await;
        if let Some(s) = self.store.read().await.as_ref() {
            s.close().await;
        }
        info!("camloop stopped");
    }
}

/// Runs the service until a signal (or, with `parts`, until every simulated machine is done).
pub async fn run(config: Config, options: RunOptions) -> anyhow::Result<()> {
    let mut running = start(config, options).await?;
    tokio::select! {
        _ = running.machines_done() => info!("every machine finished its parts"),
        _ = shutdown_signal() => info!("signal received: finishing the parts in hand"),
    }
    running.stop().await;
    Ok(())
}

/// Starts every task of the service and returns at once.
pub async fn start(config: Config, options: RunOptions) -> anyhow::Result<Running> {
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let metrics = Arc::new(Metrics::default());
    let store: StoreHandle = Arc::new(tokio::sync::RwLock::new(None));
    connect_store(&config, &store).await;
    store_guard::guard_start(&store, &config, false).await?;
    let connector = tokio::spawn(keep_store_connected(
        config.database_url(),
        store.clone(),
        shutdown_rx.clone(),
    ));

    let retention = tokio::spawn(keep_raw_retention(
        config.database.raw_retention_days,
        store.clone(),
        shutdown_rx.clone(),
    ));

    let var = config.var_dir();
    let mut machine_tasks = Vec::new();
    let mut commands = std::collections::HashMap::new();
    let mut sources_done = Vec::new();
    for m in &config.machines {
        let recipe_path = config.resolve(&m.recipe);
        let recipe = Recipe::load(&recipe_path).with_context(|| format!("machine {}", m.name))?;
        let setup = recipe
            .feature_setup(&recipe_path, &m.lobe)
            .with_context(|| format!("machine {}", m.name))?;
        let state_dir = var.join("machines").join(&m.name);
        let machine = MachineLoop::start(
            m.name.clone(),
            setup,
            config.resolve(&m.share),
            state_dir,
            store.clone(),
            metrics.clone(),
        )
        .await?;
        let (tx, rx) = mpsc::channel::<SourceEvent>(16);
        let (command_tx, command_rx) = mpsc::channel::<http::Command>(4);
        commands.insert(m.name.clone(), command_tx);
        match &m.gauge {
            GaugeSection::Sim {
                part_interval_ms,
                seed,
                grinder,
            } => {
                let source = sim_source::SimSource {
                    machine: m.name.clone(),
                    grinder: grinder.clone(),
                    seed: *seed,
                    feature: machine.feature(),
                    program: machine.program_path(),
                    table_wheel_radius_bits: machine.table_wheel_radius(),
                    part_interval: Duration::from_millis(*part_interval_ms),
                    parts: options.parts,
                };
                tokio::spawn(source.run(tx, shutdown_rx.clone()));
            }
            GaugeSection::Drop { folder, poll_ms } => {
                tokio::spawn(drop_source(
                    m.name.clone(),
                    config.resolve(folder),
                    *poll_ms,
                    tx,
                    shutdown_rx.clone(),
                ));
            }
            GaugeSection::Can { interface, dbc } => {
                let names = crate::gauge::GaugeSignalNames::default();
                let dbc = crate::gauge::GaugeDbc::load(&config.resolve(dbc), &names)
                    .with_context(|| format!("machine {}: gauge DBC", m.name))?;
                let spec = LiveSpec::Can {
                    interface: interface.clone(),
                    dbc: Box::new(dbc),
                };
                tokio::spawn(live_source(m.name.clone(), spec, tx, shutdown_rx.clone()));
            }
            GaugeSection::Serial { port, baud } => {
                let spec = LiveSpec::Serial {
                    port: port.clone(),
                    baud: *baud,
                };
                tokio::spawn(live_source(m.name.clone(), spec, tx, shutdown_rx.clone()));
            }
        }
        let (done_tx, done_rx) = tokio::sync::oneshot::channel();
        sources_done.push(done_rx);
        machine_tasks.push(tokio::spawn(machine_task(
            machine,
            rx,
            command_rx,
            done_tx,
            shutdown_rx.clone(),
        )));
    }

    let app = http::router(http::AppState {
        store: store.clone(),
        metrics: metrics.clone(),
        machines: Arc::new(config.machines.iter().map(|m| m.name.clone()).collect()),
        commands: Arc::new(commands),
        token: config.api_token.clone(),
    });
    let listener = tokio::net::TcpListener::bind(config.http.listen)
        .await
        .with_context(|| format!("cannot listen on {}", config.http.listen))?;
    let http_addr = listener.local_addr()?;
    info!(listen = %http_addr, machines = config.machines.len(), "camloop started");
    let mut http_shutdown = shutdown_rx.clone();
    let server = tokio::spawn(async move {
        let _ = axum::serve(listener, app)
            .with_graceful_shutdown(async move {
                let _ = http_shutdown.changed().await;
            })
            .await;
    });

    let machines_done = tokio::spawn(async move {
        for done in sources_done {
            let _ = done.await;
        }
    });
    Ok(Running {
        http_addr,
        shutdown: shutdown_tx,
        machines_done: Some(machines_done),
        machine_tasks,
        server,
        connector,
        retention,
        store,
    })
}

/// One machine: events in order, retries on a timer, stops on shutdown after the part in hand.
/// The machine keeps serving write requests and retries after its source has ended (a
/// simulated run with a part count); `source_done` says when that happened.
async fn machine_task(
    mut machine: MachineLoop,
    mut rx: mpsc::Receiver<SourceEvent>,
    mut commands: mpsc::Receiver<http::Command>,
    source_done: tokio::sync::oneshot::Sender<()>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut retry = tokio::time::interval(RETRY_EVERY);
    let mut source_done = Some(source_done);
    loop {
        tokio::select! {
            biased;
            event = rx.recv(), if source_done.is_some() => match event {
                Some(e) => machine.handle(e).await,
                None => {
                    if let Some(done) = source_done.take() {
                        let _ = done.send(());
                    }
                }
            },
            Some(command) = commands.recv() => match command {
                http::Command::Rollback { version, reply } => {
                    let result = machine.rollback(version).await.map_err(|e| format!("{e:#}"));
                    let _ = reply.send(result);
                }
                http::Command::Dressing { wheel_radius_mm, reply } => {
                    let result = machine.dress(wheel_radius_mm, "api").await.map_err(|e| format!("{e:#}"));
                    let _ = reply.send(result);
                }
            },
            _ = retry.tick() => machine.retry().await,
            _ = shutdown.changed() => break,
        }
    }
    // Whatever is still waiting gets one more try before the process ends.
    machine.retry().await;
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
    url: String,
    store: StoreHandle,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut tick = tokio::time::interval(RETRY_EVERY);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => return,
        }
        if store.read().await.is_some() {
            continue;
        }
        match Store::connect(&url).await {
            Ok(s) => {
                info!(
                    backend = s.backend(),
                    "history store back: writing the journal"
                );
                *store.write().await = Some(s);
            }
            Err(e) => warn!(error = %e, "history store still unavailable"),
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
        let cutoff_ms = crate::clock::now_ms() - i64::from(days) * 86_400_000;
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

/// Measurement files dropped into a folder (taken when complete, moved to processed/ or
/// rejected/ with a reason).
async fn drop_source(
    machine: String,
    folder: std::path::PathBuf,
    poll_ms: u64,
    tx: mpsc::Sender<SourceEvent>,
    mut shutdown: watch::Receiver<bool>,
) {
    let dbc = crate::gauge::GaugeDbc::builtin();
    if let Err(e) = std::fs::create_dir_all(&folder) {
        error!(machine = %machine, folder = %folder.display(), error = %e, "drop folder unusable");
        return;
    }
    let mut drop_folder = match crate::gauge::DropFolder::open(&folder, dbc) {
        Ok(d) => d,
        Err(e) => {
            error!(machine = %machine, folder = %folder.display(), error = %e, "drop folder unusable");
            return;
        }
    };
    let mut tick = tokio::time::interval(Duration::from_millis(poll_ms.max(10)));
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => return,
        }
        // File work off the async threads.
        let (df, events) = match tokio::task::spawn_blocking(move || {
            let events = drop_folder.poll();
            (drop_folder, events)
        })
        .await
        {
            Ok(done) => done,
            Err(_) => return,
        };
        drop_folder = df;
        for event in events {
            match event {
                crate::gauge::DropEvent::Accepted { measurement, .. } => {
                    if tx
                        .send(SourceEvent::Measurement(measurement, None))
                        .await
                        .is_err()
                    {
                        return;
                    }
                }
                crate::gauge::DropEvent::Dressing { report, moved_to } => {
                    let event = SourceEvent::Dressing {
                        wheel_radius_mm: report.wheel_radius_mm,
                        source: format!("drop file {}", moved_to.display()),
                    };
                    if tx.send(event).await.is_err() {
                        return;
                    }
                }
                other => warn!(machine = %machine, event = ?other, "drop folder"),
            }
        }
    }
}

/// A live gauge connection: a SocketCAN bus through the DBC, or a serial port speaking the
/// line protocol.
enum LiveGauge {
    Can(Box<crate::gauge::CanGauge<crate::gauge::CanBus>>),
    Serial(Box<crate::gauge::SerialGauge<tokio_serial::SerialStream>>),
}

/// How to open a live gauge again after it failed.
#[derive(Clone)]
enum LiveSpec {
    Can {
        interface: String,
        dbc: Box<crate::gauge::GaugeDbc>,
    },
    Serial {
        port: String,
        baud: u32,
    },
}

impl LiveSpec {
    fn name(&self) -> &str {
        match self {
            LiveSpec::Can { interface, .. } => interface,
            LiveSpec::Serial { port, .. } => port,
        }
    }

    fn open(&self) -> Result<LiveGauge, String> {
        match self {
            LiveSpec::Can { interface, dbc } => {
                crate::gauge::CanGauge::open(interface, (**dbc).clone())
                    .map(|g| LiveGauge::Can(Box::new(g)))
                    .map_err(|e| e.to_string())
            }
            LiveSpec::Serial { port, baud } => crate::gauge::SerialGauge::open(port, *baud)
                .map(|g| LiveGauge::Serial(Box::new(g)))
                .map_err(|e| e.to_string()),
        }
    }
}

impl LiveGauge {
    /// The next measurement, a problem to log, or `None` when the connection ended.
    async fn next(
        &mut self,
    ) -> std::io::Result<Option<Result<crate::core::measure::RawMeasurement, String>>> {
        Ok(match self {
            LiveGauge::Can(g) => g.next_event().await?.map(|e| match e {
                crate::gauge::CanEvent::Measurement(m) => Ok(m),
                other => Err(format!("{other:?}")),
            }),
            LiveGauge::Serial(g) => g.next_event().await?.map(|e| match e {
                crate::gauge::SerialEvent::Measurement(m) => Ok(m),
                crate::gauge::SerialEvent::Problem(p) => Err(format!("{p:?}")),
            }),
        })
    }
}

/// A live gauge. One that cannot be opened (missing device, a kernel without SocketCAN) or
/// that fails is an ERROR naming it, retried every 10 s; never a panic, never fatal.
async fn live_source(
    machine: String,
    spec: LiveSpec,
    tx: mpsc::Sender<SourceEvent>,
    mut shutdown: watch::Receiver<bool>,
) {
    loop {
        match spec.open() {
            Ok(mut gauge) => {
                info!(machine = %machine, gauge = %spec.name(), "gauge listening");
                loop {
                    let event = tokio::select! {
                        e = gauge.next() => e,
                        _ = shutdown.changed() => return,
                    };
                    match event {
                        Ok(Some(Ok(m))) => {
                            if tx.send(SourceEvent::Measurement(m, None)).await.is_err() {
                                return;
                            }
                        }
                        Ok(Some(Err(problem))) => {
                            warn!(machine = %machine, problem = %problem, "gauge data discarded")
                        }
                        Ok(None) => break,
                        Err(e) => {
                            error!(machine = %machine, gauge = %spec.name(), error = %e, "gauge read failed");
                            break;
                        }
                    }
                }
            }
            Err(e) => error!(machine = %machine, error = %e, "gauge unavailable; retrying in 10 s"),
        }
        tokio::select! {
            _ = tokio::time::sleep(Duration::from_secs(10)) => {}
            _ = shutdown.changed() => return,
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
