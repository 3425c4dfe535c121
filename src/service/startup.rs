//! The start-up steps of the service, in the order `start_checked` runs them: the store
//! and its keepers, the catalogue of features, the machines (here or by lease).

use super::health::State;
use super::machine::StoreHandle;
use super::metrics::Metrics;
use super::{
    Machines, access_setup, cluster_task, connect_store, http, keep_raw_retention,
    keep_store_connected, runner, store_guard,
};
use crate::config::Config;
use crate::names::{FeatureName, MachineName};
use anyhow::Context;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tracing::info;

/// Connects the store (or leaves it to the connector when the database is down), checks
/// it is this service's, makes sure an admin exists, and starts the tasks that keep it
/// connected and trim raw data past retention.
pub(super) async fn start_store(
    config: &Config,
    accept_new_database: bool,
    shutdown_rx: &watch::Receiver<bool>,
) -> anyhow::Result<(StoreHandle, JoinHandle<()>, JoinHandle<()>)> {
    let store: StoreHandle = Arc::new(tokio::sync::RwLock::new(None));
    connect_store(config, &store).await;
    store_guard::guard_start(&store, config, accept_new_database).await?;
    if let Some(s) = store.read().await.as_ref() {
        access_setup::ensure_admin(s, config).await?;
    }
    let connector = tokio::spawn(keep_store_connected(
        config.clone(),
        store.clone(),
        shutdown_rx.clone(),
    ));

    let retention = tokio::spawn(keep_raw_retention(
        config.database.raw_retention_days,
        store.clone(),
        shutdown_rx.clone(),
    ));
    Ok((store, connector, retention))
}

/// Each machine's feature names.
type FeatureNames = BTreeMap<MachineName, Vec<FeatureName>>;
/// Each (machine, feature)'s sheet.
type SheetMap = BTreeMap<(MachineName, FeatureName), http::FeatureSheet>;

/// Each machine's feature names (for the API) and feature sheets (for the dashboard).
pub(super) fn feature_catalogue(
    machines: &[crate::config::CheckedMachine],
) -> (FeatureNames, SheetMap) {
    let mut features = BTreeMap::new();
    let mut sheets = BTreeMap::new();
    let mut drawings = crate::quality::Drawings::default();
    for m in machines {
        features.insert(
            m.name.clone(),
            m.setups.iter().map(|s| s.name.clone()).collect(),
        );
        for setup in &m.setups {
            let sheet = http::FeatureSheet::from_setup_drawn(setup, &mut drawings);
            sheets.insert((m.name.clone(), setup.name.clone()), sheet);
        }
    }
    (features, sheets)
}

/// When each local machine's gauge source ended (none in a cluster).
pub(super) type SourcesDone = Option<Vec<tokio::sync::oneshot::Receiver<()>>>;

/// Machines opened at once at start: their journals, shares and first tables are mostly
/// waits on the disk, which overlap, and the more journals wait together the fewer syncs
/// the group commit issues for them (each opening holds a thread while it waits).
const OPEN_AT_ONCE: usize = 64;

/// In a cluster: the leases, joined (for the API and the machines' task).
pub(super) async fn cluster_leases(
    config: &Config,
) -> anyhow::Result<Option<crate::cluster::Leases>> {
    if !config.cluster.enabled {
        return Ok(None);
    }
    let lease = Duration::from_millis(config.cluster.lease_ms);
    let instance = config.cluster.instance_name();
    let leases = crate::cluster::Leases::connect(&config.database_url(), &instance, lease)
        .await
        .context("cluster")?;
    info!(instance = %instance, lease_ms = config.cluster.lease_ms, "cluster: joined; machines are taken as leases allow");
    Ok(Some(leases))
}

/// `/healthz`'s "machines" component while they open.
pub(super) fn machines_opening(metrics: &Metrics, open: usize, total: usize) {
    let reason = format!("{open} of {total} machines open");
    metrics
        .health
        .set("machines", State::Starting, Some(reason));
}

/// Starts every machine here (several opening at once, `/healthz` counting them), or, in a
/// cluster, the task that takes machines as leases allow.
pub(super) async fn start_machines(
    config: &Config,
    runner: runner::Runner,
    leases: Option<crate::cluster::Leases>,
    metrics: &Arc<Metrics>,
    shutdown_rx: &watch::Receiver<bool>,
) -> anyhow::Result<(Machines, SourcesDone)> {
    if let Some(leases) = leases {
        let task = cluster_task::ClusterTask {
            leases,
            url: config.database_url(),
            lease: Duration::from_millis(config.cluster.lease_ms),
            machines_dir: config.machines_dir(),
            runner,
            metrics: metrics.clone(),
        };
        let task = tokio::spawn(task.run(shutdown_rx.clone()));
        // Machines come and go with the leases: none is awaited here.
        metrics.health.set("machines", State::Ok, None);
        return Ok((Machines::Cluster(task), None));
    }
    let runner = Arc::new(runner);
    let names = runner.names();
    let total = names.len();
    let gate = Arc::new(tokio::sync::Semaphore::new(OPEN_AT_ONCE));
    let plan = Arc::new(runner.plant_opening().await);
    let mut opening = tokio::task::JoinSet::new();
    for name in names {
        let (runner, gate, plan) = (runner.clone(), gate.clone(), plan.clone());
        opening.spawn(async move {
            let _slot = gate.acquire_owned().await;
            super::offload::drive(runner.open(&name, None, &plan)).await
        });
    }
    let mut done = Vec::with_capacity(total);
    // A machine that cannot open ends the start (the others are aborted with the set).
    while let Some(opened) = opening.join_next().await {
        let opened = opened.context("a machine's opening panicked")??;
        done.push(runner.launch(opened)?);
        machines_opening(metrics, done.len(), total);
    }
    metrics.health.set("machines", State::Ok, None);
    Ok((Machines::Local(runner), Some(done)))
}

/// Ends when every local source has ended; in a cluster the machines come and go, so the
/// service runs until a signal.
pub(super) async fn sources_ended(sources_done: SourcesDone) {
    match sources_done {
        Some(sources) => {
            for done in sources {
                let _ = done.await;
            }
        }
        None => std::future::pending().await,
    }
}

/// MQTT: events to the plant's broker, when `[mqtt]` enables them.
pub(super) fn start_mqtt(
    config: &Config,
    shutdown: &watch::Receiver<bool>,
) -> anyhow::Result<Option<camloop_mqtt::Publisher>> {
    if !config.mqtt.enabled {
        return Ok(None);
    }
    Ok(Some(camloop_mqtt::Publisher::start(
        &config.mqtt_settings(),
        &config.var_dir().join("mqtt"),
        shutdown.clone(),
    )?))
}

/// The HTTP listener's own runtime: two threads that serve `/healthz`, the API and the
/// dashboard whatever the machines' work does to the service's runtime. Shut down when
/// dropped (in the order the service stops, or when a start fails half-way).
pub(super) struct HttpRuntime(Option<tokio::runtime::Runtime>);

impl HttpRuntime {
    pub(super) fn start() -> anyhow::Result<Self> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("camloop-http")
            .enable_all()
            .build()
            .context("cannot start the HTTP runtime")?;
        Ok(Self(Some(runtime)))
    }

    /// Serves `app` on the listener the config check bound until `shutdown`.
    pub(super) fn serve(
        &self,
        listener: std::net::TcpListener,
        app: axum::Router,
        limits: http::HttpLimits,
        policy: http::Policy,
        tls: Option<Arc<http::Tls>>,
        shutdown: watch::Receiver<bool>,
    ) -> JoinHandle<()> {
        let runtime = self.0.as_ref().expect("the runtime lives until dropped");
        runtime.spawn(async move {
            // Registered with this runtime's reactor, so its accepts never wait on the
            // service's workers.
            match tokio_listener(listener) {
                Ok(listener) => {
                    http::serve_with(listener, app, limits, policy, tls, shutdown).await;
                }
                Err(e) => tracing::error!(error = %format!("{e:#}"), "HTTP listener unusable: not serving"),
            }
        })
    }
}

impl Drop for HttpRuntime {
    fn drop(&mut self) {
        // Dropped inside the service's runtime, where a blocking shutdown is not allowed.
        if let Some(runtime) = self.0.take() {
            runtime.shutdown_background();
        }
    }
}

/// The HTTP listener the config check bound, handed to tokio.
fn tokio_listener(listener: std::net::TcpListener) -> anyhow::Result<tokio::net::TcpListener> {
    listener
        .set_nonblocking(true)
        .context("cannot set up the HTTP listener")?;
    tokio::net::TcpListener::from_std(listener).context("cannot set up the HTTP listener")
}
