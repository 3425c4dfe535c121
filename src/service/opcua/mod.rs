//! The OPC UA server inside `camloop run` (`[opcua]`, off by default).
//!
//! One endpoint, `opc.tcp://<host>:<port>/`, Basic256Sha256 with SignAndEncrypt (and an
//! unsecured `None` endpoint only when the config asks for it, warned at every start).
//! The server's certificate is made on the first start in the PKI folder (by default
//! `<var>/opcua/pki/own`); client certificates must be in `<pki>/trusted` unless
//! `accept_unknown_clients` (warned). Users are camloop's users (see [`auth`]).
//!
//! The address space (see [`space`]) is fed by [`feed`] from the loops' plant events and
//! the in-process feature status: the loops never wait on it.

mod auth;
mod events;
pub(crate) mod feed;
mod methods;
mod nodes;
mod ordered;
mod pki;
mod seed;
pub(crate) mod space;

use crate::names::{FeatureName, MachineName};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicU64;

use anyhow::Context;
use opcua::server::node_manager::NodeManagerBuilder as _;
use opcua::server::node_manager::memory::{InMemoryNodeManager, InMemoryNodeManagerBuilder};
use opcua::server::{ServerBuilder, ServerEndpoint, ServerHandle};
use opcua::types::BuildInfo;
use tokio::sync::{mpsc, watch};
use tracing::{info, warn};

use crate::config::{Config, OpcUaSection, OpcUaSecurity};
use crate::service::app::AppState;
use crate::service::plant::EventSender;
use camloop_loop::PlantEvent;
pub(crate) use space::MachineLayout;

/// The machines as the address space shows them.
pub(crate) fn layout(machines: &[crate::config::CheckedMachine]) -> Vec<MachineLayout> {
    machines
        .iter()
        .map(|m| MachineLayout {
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

/// Plant events waiting for the feed; beyond it an event is dropped (that part's result and
/// OPC UA event are not shown; the feature's next part replaces it).
const INTAKE: usize = 4096;

/// Sessions served at once (the stack's default is 20: a plant has more clients).
const MAX_SESSIONS: usize = 64;

/// Monitored items per subscription (the stack's default is 1000): a client subscribing to
/// every value of 50 machines × 8 features needs 5600.
const MAX_ITEMS_PER_SUBSCRIPTION: usize = 100_000;

/// The largest queue a monitored item may ask for (the stack's default is 10): an event item
/// on `Server` must hold a plant's events of one publishing interval, 500 machines × 8
/// features' results plus their alarms, with room to spare.
pub(crate) const MAX_ITEM_QUEUE: usize = 10_000;

/// Notifications per publish message: at most a few hundred bytes each, so a message stays
/// well under the stack's 327,675-byte message limit (beyond it a publish was dropped whole);
/// more are sent in further messages of the same publishing interval.
pub(crate) const MAX_NOTIFICATIONS_PER_PUBLISH: u64 = 500;

/// Publish messages a subscription keeps while its client has no publish request waiting
/// (the stack's default is 20): a plant's interval of 9,000 values is 18 messages.
const MAX_QUEUED_MESSAGES: usize = 200;

/// Elements of an array in a request (the stack's default decodes 1,000 while it advertised
/// 10,000 nodes per read): as many as the largest advertised per-call limit.
pub(crate) const MAX_ARRAY_LENGTH: usize = 10_000;

/// The largest message, in bytes, and in chunks of the stack's 65,535 bytes (its default is
/// 5 chunks, 327,675 bytes): a Read of the advertised 10,000 nodes by string ids is about
/// 0.6 MB, so the limits a client is told are limits it can use.
const MAX_MESSAGE_SIZE: usize = 64 * 65_535;
const MAX_CHUNK_COUNT: usize = 64;

/// The server's private key in the PKI folder: refused at start when other accounts can
/// read it, and made owner-only when the server writes it.
const PRIVATE_KEY: &str = "private/private.pem";

/// The server's certificate in the PKI folder.
const CERTIFICATE: &str = "own/cert.der";

/// A running OPC UA server.
pub(crate) struct OpcUa {
    handle: ServerHandle,
    server: tokio::task::JoinHandle<()>,
    feed: tokio::task::JoinHandle<()>,
}

impl OpcUa {
    /// Stops the server (sessions are closed) and the feed.
    pub(crate) async fn stop(self) {
        self.handle.cancel();
        let _ = self.server.await;
        self.feed.abort();
        let _ = self.feed.await;
    }
}

/// The folder of the server's certificate store.
fn pki_dir(config: &Config) -> PathBuf {
    match &config.opcua.pki_dir {
        Some(dir) => config.resolve(dir),
        None => config.var_dir().join("opcua").join("pki"),
    }
}

/// What the loops feed before the server starts: their events and the machines.
pub(crate) struct Intake {
    events: mpsc::Receiver<PlantEvent>,
    /// Events the full intake refused (counted by the loops' sender).
    dropped: Arc<AtomicU64>,
    layout: Vec<MachineLayout>,
    /// Bound before the machines start, so a port in use stops the start before them.
    listener: std::net::TcpListener,
}

/// With `[opcua]` on: the sender the loops feed, and the intake [`start`] takes (made before
/// the loops start; the server starts once the API state it shares exists).
pub(crate) fn prepare(
    config: &Config,
    machines: &[crate::config::CheckedMachine],
) -> anyhow::Result<(Option<EventSender>, Option<Intake>)> {
    if !config.opcua.enabled {
        return Ok((None, None));
    }
    let listener = bind(config.opcua.listen)?;
    let (tx, events) = mpsc::channel(INTAKE);
    let dropped = Arc::new(AtomicU64::new(0));
    let sender = EventSender::new(tx, dropped.clone());
    let layout = layout(machines);
    let intake = Intake {
        events,
        dropped,
        layout,
        listener,
    };
    Ok((Some(sender), Some(intake)))
}

fn bind(listen: std::net::SocketAddr) -> anyhow::Result<std::net::TcpListener> {
    let listener = std::net::TcpListener::bind(listen)
        .with_context(|| format!("opcua: cannot listen on {listen}"))?;
    listener
        .set_nonblocking(true)
        .with_context(|| format!("opcua: cannot listen on {listen}"))?;
    Ok(listener)
}

/// Starts the server on `opcua.listen` and its feed from `intake` (none: `[opcua]` is off).
pub(crate) async fn start(
    config: &Config,
    app: AppState,
    intake: Option<Intake>,
    shutdown: &watch::Receiver<bool>,
) -> anyhow::Result<Option<OpcUa>> {
    start_with(&config.opcua, pki_dir(config), app, intake, shutdown).await
}

/// [`start`] with the section and the PKI folder given.
async fn start_with(
    section: &OpcUaSection,
    pki: PathBuf,
    app: AppState,
    intake: Option<Intake>,
    shutdown: &watch::Receiver<bool>,
) -> anyhow::Result<Option<OpcUa>> {
    let Some(Intake {
        events,
        dropped,
        layout,
        listener,
    }) = intake
    else {
        return Ok(None);
    };
    let shutdown = shutdown.clone();
    crate::private_fs::create_dir_all(&pki)
        .with_context(|| format!("opcua: PKI folder {}", pki.display()))?;
    let key = pki.join(PRIVATE_KEY);
    if key.exists() {
        crate::audit_seal::refuse_readable_by_others(&key).context("opcua: the private key")?;
    }
    let host = section.host();
    make_certificate(section, &pki, &host)?;
    let url = format!("opc.tcp://{host}:{}/", section.listen.port());
    let listeners = Arc::new(events::Listeners::default());
    let builder = server_builder(
        section,
        &pki,
        &url,
        (app.clone(), listeners.clone()),
        layout.clone(),
    );
    let (server, handle) = builder
        .build()
        .map_err(|e| anyhow::anyhow!("opcua: the server cannot be set up: {e}"))?;
    // The stack writes a new key with the umask's mode: narrowed to the owner at once.
    for made in [pki.join("private"), key] {
        crate::private_fs::restrict(&made)
            .with_context(|| format!("opcua: cannot narrow {} to its owner", made.display()))?;
    }
    let listener = tokio::net::TcpListener::from_std(listener)
        .with_context(|| format!("opcua: cannot listen on {}", section.listen))?;
    let server = tokio::spawn(async move {
        if let Err(e) = server.run_with(listener).await {
            tracing::error!(error = %e, "OPC UA server stopped");
        }
    });
    let manager = handle
        .node_managers()
        .get_of_type::<ordered::Ordered>()
        .context("opcua: camloop's node manager is missing")?
        .inner
        .clone();
    let ns = handle
        .get_namespace_index(space::NAMESPACE_URI)
        .context("opcua: camloop's namespace is missing")?;
    let mut feed = feed::Feed::new(
        manager,
        handle.subscriptions().clone(),
        space::Ids { ns },
        app.metrics.clone(),
        layout.clone(),
        listeners,
        handle.clone(),
    );
    feed.dressings = dressing_counts(&app, &layout).await;
    feed.dropped = dropped;
    let (seeds_tx, seeds) = mpsc::channel(16);
    tokio::spawn(seed::send_newest(
        app.store.clone(),
        layout.clone(),
        seeds_tx,
    ));
    let feed = tokio::spawn(feed::run(feed, (events, seeds), shutdown.clone()));
    tokio::spawn(pki::keep_rejected_bounded(pki.clone(), shutdown.clone()));
    let cancel = handle.clone();
    let mut stop = shutdown;
    tokio::spawn(async move {
        let _ = stop.changed().await;
        cancel.cancel();
    });
    let nodes: usize = layout
        .iter()
        .map(|m| space::nodes_per_machine(m.features.len()))
        .sum();
    info!(endpoint = %url, security = ?section.security, machines = layout.len(), nodes, pki = %pki.display(), "OPC UA server started");
    Ok(Some(OpcUa {
        handle,
        server,
        feed,
    }))
}

/// The server's certificate and key, made on the first start (kept once there): RSA 2048,
/// self-signed, for `urn:camloop:<host>`, the configured host name, `localhost` and this
/// computer's names, with the subject the config gives (not the library's sample subject).
fn make_certificate(
    section: &OpcUaSection,
    pki: &std::path::Path,
    host: &str,
) -> anyhow::Result<()> {
    let cert = pki.join(CERTIFICATE);
    let key = pki.join(PRIVATE_KEY);
    if cert.exists() && key.exists() {
        return Ok(());
    }
    for dir in [pki.join("own"), pki.join("private")] {
        crate::private_fs::create_dir_all(&dir)
            .with_context(|| format!("opcua: PKI folder {}", dir.display()))?;
    }
    let description = opcua::types::ApplicationDescription {
        application_uri: format!("urn:camloop:{host}").into(),
        application_name: opcua::types::LocalizedText::new("", "camloop"),
        ..Default::default()
    };
    let mut data = opcua::crypto::X509Data::from((description, Some(vec![host.to_string()])));
    data.organization = section.certificate_organization.clone();
    data.organizational_unit = section.certificate_organizational_unit.clone();
    data.country = section.certificate_country.clone();
    data.state = section.certificate_state.clone();
    data.certificate_duration_days = section.certificate_days;
    opcua::crypto::CertificateStore::create_certificate_and_key(&data, false, &cert, &key)
        .map_err(|e| anyhow::anyhow!("opcua: cannot make the server certificate: {e}"))?;
    info!(certificate = %cert.display(), days = section.certificate_days, "OPC UA: server certificate made");
    Ok(())
}

/// The server as configured: endpoints, certificates, users, camloop's nodes.
fn server_builder(
    section: &OpcUaSection,
    pki: &std::path::Path,
    url: &str,
    (app, listeners): (AppState, Arc<events::Listeners>),
    layout: Vec<MachineLayout>,
) -> ServerBuilder {
    let host = section.host();
    let users = auth::Users::new(app.clone(), section.anonymous_read);
    let mut builder = ServerBuilder::new()
        .application_name("camloop")
        .application_uri(format!("urn:camloop:{host}"))
        .product_uri("urn:camloop")
        .build_info(BuildInfo {
            product_uri: "urn:camloop".into(),
            manufacturer_name: "camloop".into(),
            product_name: "camloop".into(),
            software_version: env!("CARGO_PKG_VERSION").into(),
            build_number: env!("CARGO_PKG_VERSION").into(),
            build_date: build_date(),
        })
        .create_sample_keypair(true)
        .certificate_path(CERTIFICATE)
        .private_key_path(PRIVATE_KEY)
        .pki_dir(pki)
        .trust_client_certs(section.accept_unknown_clients)
        .check_cert_time(true)
        .host(host.clone())
        .port(section.listen.port())
        .discovery_urls(vec![url.to_string()])
        .add_endpoint(
            "basic256sha256_sign_encrypt",
            ServerEndpoint::new_basic256sha256_sign_encrypt("/", &[]),
        )
        .default_endpoint("basic256sha256_sign_encrypt")
        .with_authenticator(Arc::new(users))
        .with_node_manager(move |context| {
            let order = layout.clone();
            let memory = InMemoryNodeManagerBuilder::new(nodes::Builder {
                layout,
                app,
                listeners,
            });
            // The stack builds it as its own trait object: taken back as what it is.
            let built = Box::new(memory).build(context).into_any_arc();
            let inner = built
                .downcast::<InMemoryNodeManager<nodes::CamloopNodes>>()
                .unwrap_or_else(|_| {
                    unreachable!("the in-memory builder builds an in-memory manager")
                });
            ordered::Ordered::new(inner, &order)
        })
        .diagnostics_enabled(false);
    let limits = builder.limits_mut();
    limits.max_sessions = MAX_SESSIONS;
    limits.subscriptions.max_monitored_items_per_sub = MAX_ITEMS_PER_SUBSCRIPTION;
    limits.subscriptions.max_monitored_item_queue_size = MAX_ITEM_QUEUE;
    limits.subscriptions.max_notifications_per_publish = MAX_NOTIFICATIONS_PER_PUBLISH;
    limits.subscriptions.max_queued_notifications = MAX_QUEUED_MESSAGES;
    limits.max_array_length = MAX_ARRAY_LENGTH;
    limits.max_message_size = MAX_MESSAGE_SIZE;
    limits.max_chunk_count = MAX_CHUNK_COUNT;
    if section.security == OpcUaSecurity::Basic256Sha256AndNone {
        warn!(
            "opcua.security allows an unsecured endpoint (None): messages travel in clear; passwords are still encrypted with the server's certificate"
        );
        let mut none = ServerEndpoint::new_none("/", &[]);
        none.password_security_policy = Some("Basic256Sha256".into());
        builder = builder.add_endpoint("none", none);
    }
    if section.accept_unknown_clients {
        warn!("opcua.accept_unknown_clients = true: any client certificate is trusted");
    }
    if section.anonymous_read {
        warn!("opcua.anonymous_read = true: clients without a user may browse, read and subscribe");
    }
    builder
}

/// When this binary was built: the commit's time (`SOURCE_DATE_EPOCH` at build, set by
/// `build.rs`), not the process's start.
fn build_date() -> opcua::types::DateTime {
    let seconds: i64 = env!("CAMLOOP_BUILD_EPOCH_S").parse().unwrap_or(0);
    let at = jiff::Timestamp::from_second(seconds).unwrap_or(jiff::Timestamp::UNIX_EPOCH);
    methods::date_time(at)
}

/// Each machine's dressings as the store has them at start (0 while it is down).
async fn dressing_counts(
    app: &AppState,
    layout: &[MachineLayout],
) -> std::collections::HashMap<MachineName, i64> {
    let mut counts = std::collections::HashMap::new();
    let Some(store) = app.store.read().await.clone() else {
        return counts;
    };
    for m in layout {
        if let Ok(list) = store.dressings(&m.name, 10_000).await {
            counts.insert(
                m.name.clone(),
                i64::try_from(list.len()).unwrap_or(i64::MAX),
            );
        }
    }
    counts
}

/// The server as `benches/opcua.rs` runs it: `machines` (name, features) on `listen`,
/// Basic256Sha256 SignAndEncrypt, its PKI in `pki`, anonymous reading and unknown client
/// certificates accepted (the bench's clients are anonymous and new); fed from the returned
/// sender until `shutdown` turns true. Not part of camloop's interface.
#[doc(hidden)]
pub async fn bench_server(
    listen: std::net::SocketAddr,
    pki: &std::path::Path,
    machines: Vec<(MachineName, Vec<FeatureName>)>,
    metrics: Arc<crate::service::metrics::Metrics>,
    store: crate::service::machine::StoreHandle,
    shutdown: watch::Receiver<bool>,
) -> anyhow::Result<EventSender> {
    let section = OpcUaSection {
        enabled: true,
        listen,
        host_name: Some("localhost".into()),
        accept_unknown_clients: true,
        anonymous_read: true,
        ..OpcUaSection::default()
    };
    let layout = machines
        .into_iter()
        .map(|(name, features)| MachineLayout {
            name,
            recipe: "bench".into(),
            features,
        })
        .collect();
    let app = AppState::without_http(store, metrics);
    let (sender, events) = mpsc::channel(INTAKE);
    let dropped = Arc::new(AtomicU64::new(0));
    let intake = Intake {
        events,
        dropped: dropped.clone(),
        layout,
        listener: bind(listen)?,
    };
    // Runs until shutdown: the server's own watcher cancels it.
    drop(start_with(&section, pki.to_path_buf(), app, Some(intake), &shutdown).await?);
    Ok(EventSender::new(sender, dropped))
}
