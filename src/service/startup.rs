//! The start-up steps of the service, in the order `start_checked` runs them: the store
//! and its keepers, the catalogue of features, the machines (here or by lease).

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
    for m in machines {
        features.insert(
            m.name.clone(),
            m.setups.iter().map(|s| s.name.clone()).collect(),
        );
        for setup in &m.setups {
            let sheet = http::FeatureSheet::from_setup(setup);
            sheets.insert((m.name.clone(), setup.name.clone()), sheet);
        }
    }
    (features, sheets)
}

/// When each local machine's gauge source ended (none in a cluster).
pub(super) type SourcesDone = Option<Vec<tokio::sync::oneshot::Receiver<()>>>;

/// Starts every machine here, or, in a cluster, the task that takes machines as leases
/// allow (and returns the leases for the API).
pub(super) async fn start_machines(
    config: &Config,
    runner: runner::Runner,
    metrics: &Arc<Metrics>,
    shutdown_rx: &watch::Receiver<bool>,
) -> anyhow::Result<(Machines, SourcesDone, Option<crate::cluster::Leases>)> {
    if config.cluster.enabled {
        let lease = Duration::from_millis(config.cluster.lease_ms);
        let instance = config.cluster.instance_name();
        let leases = crate::cluster::Leases::connect(&config.database_url(), &instance, lease)
            .await
            .context("cluster")?;
        info!(instance = %instance, lease_ms = config.cluster.lease_ms, "cluster: joined; machines are taken as leases allow");
        let cluster_view = Some(leases.clone());
        let task = cluster_task::ClusterTask {
            leases,
            url: config.database_url(),
            lease,
            machines_dir: config.machines_dir(),
            runner,
            metrics: metrics.clone(),
        };
        let task = tokio::spawn(task.run(shutdown_rx.clone()));
        Ok((Machines::Cluster(task), None, cluster_view))
    } else {
        let mut done = Vec::new();
        for name in runner.names() {
            done.push(runner.start(&name, None).await?);
        }
        Ok((Machines::Local(Box::new(runner)), Some(done), None))
    }
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
) -> anyhow::Result<Option<super::mqtt::Publisher>> {
    if !config.mqtt.enabled {
        return Ok(None);
    }
    Ok(Some(super::mqtt::Publisher::start(
        &config.mqtt_settings(),
        &config.var_dir().join("mqtt"),
        shutdown.clone(),
    )?))
}

/// The HTTP listener the config check bound, handed to tokio.
pub(super) fn tokio_listener(
    listener: std::net::TcpListener,
) -> anyhow::Result<tokio::net::TcpListener> {
    listener
        .set_nonblocking(true)
        .context("cannot set up the HTTP listener")?;
    tokio::net::TcpListener::from_std(listener).context("cannot set up the HTTP listener")
}
