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
//!
//! An adapter of the service: it depends on the loop's types, its own config section and
//! the history store, never on the service or another adapter. What it needs of the
//! service (sign-in, the write path, the audit trail, the feature status, owner-only
//! files) it asks through the [`Service`] port, which the service implements and hands to
//! [`start`].

mod auth;
mod config;
mod events;
pub(crate) mod feed;
mod methods;
mod nodes;
mod ordered;
mod pki;
mod port;
mod seed;
pub(crate) mod space;

pub use auth::OPCUA_CLIENT;
pub use config::{OpcUaSection, OpcUaSecurity, SectionProblem};
pub use port::{
    AckRefused, Caller, FeatureView, FileError, Refusal, Service, SignIn, SignInUnavailable,
    Status, Write, WriteRefused,
};
pub use space::MachineLayout;

use camloop_core::names::{FeatureName, MachineName};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicU64;

use opcua::server::node_manager::NodeManagerBuilder as _;
use opcua::server::node_manager::memory::{InMemoryNodeManager, InMemoryNodeManagerBuilder};
use opcua::server::{ServerBuilder, ServerEndpoint, ServerHandle};
use opcua::types::BuildInfo;
use tokio::sync::{mpsc, watch};
use tracing::{info, warn};

use camloop_loop::PlantEvent;

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
pub struct OpcUa {
    handle: ServerHandle,
    server: tokio::task::JoinHandle<()>,
    feed: tokio::task::JoinHandle<()>,
}

impl OpcUa {
    /// Stops the server (sessions are closed) and the feed.
    pub async fn stop(self) {
        self.handle.cancel();
        let _ = self.server.await;
        self.feed.abort();
        let _ = self.feed.await;
    }
}

/// Why the server cannot start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("opcua: cannot listen on {listen}")]
    Listen {
        listen: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("opcua: PKI folder {}", dir.display())]
    PkiFolder {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("opcua: the private key")]
    KeyReadable(#[source] FileError),
    #[error("opcua: cannot narrow {} to its owner", path.display())]
    Narrow {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("opcua: cannot make the server certificate: {0}")]
    Certificate(String),
    #[error("opcua: the server cannot be set up: {0}")]
    Setup(String),
    #[error("opcua: camloop's {0} is missing")]
    Missing(&'static str),
}

/// Where the loops send plant events for the server: never waits, and counts what a full
/// intake refuses as dropped (the server tells its clients so).
#[derive(Debug, Clone)]
pub struct Feeder {
    tx: mpsc::Sender<PlantEvent>,
    dropped: Arc<AtomicU64>,
}

impl Feeder {
    /// The channel and its refusal counter, for a sender that feeds several adapters.
    pub fn into_parts(self) -> (mpsc::Sender<PlantEvent>, Arc<AtomicU64>) {
        (self.tx, self.dropped)
    }
}

/// What the loops feed before the server starts: their events and the machines.
pub struct Intake {
    events: mpsc::Receiver<PlantEvent>,
    /// Events the full intake refused (counted by the loops' sender).
    dropped: Arc<AtomicU64>,
    layout: Vec<MachineLayout>,
    /// Bound before the machines start, so a port in use stops the start before them.
    listener: std::net::TcpListener,
}

/// With `[opcua]` on: the feeder the loops send to, and the intake [`start`] takes (made
/// before the loops start, with the listener bound, so a port in use stops the start before
/// them; the server starts once the service it asks exists).
pub fn prepare(
    section: &OpcUaSection,
    layout: Vec<MachineLayout>,
) -> Result<Option<(Feeder, Intake)>, StartError> {
    if !section.enabled {
        return Ok(None);
    }
    let listener = bind(section.listen)?;
    let (tx, events) = mpsc::channel(INTAKE);
    let dropped = Arc::new(AtomicU64::new(0));
    let feeder = Feeder {
        tx,
        dropped: dropped.clone(),
    };
    let intake = Intake {
        events,
        dropped,
        layout,
        listener,
    };
    Ok(Some((feeder, intake)))
}

fn bind(listen: std::net::SocketAddr) -> Result<std::net::TcpListener, StartError> {
    let failed = |source| StartError::Listen { listen, source };
    let listener = std::net::TcpListener::bind(listen).map_err(failed)?;
    listener.set_nonblocking(true).map_err(failed)?;
    Ok(listener)
}

/// Where and as what the server starts: its section, its certificate store's folder and
/// the binary's build time (BuildInfo.BuildDate).
#[derive(Debug, Clone)]
pub struct Setup<'a> {
    pub section: &'a OpcUaSection,
    pub pki: PathBuf,
    pub built: jiff::Timestamp,
}

/// Starts the server on `opcua.listen` and its feed from `intake` (none: `[opcua]` is off),
/// asking `service` for what it needs; it stops when `shutdown` changes.
pub async fn start(
    setup: Setup<'_>,
    service: Arc<dyn Service>,
    intake: Option<Intake>,
    shutdown: &watch::Receiver<bool>,
) -> Result<Option<OpcUa>, StartError> {
    let Setup {
        section,
        pki,
        built,
    } = setup;
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
    service
        .create_private_dir(&pki)
        .map_err(|source| StartError::PkiFolder {
            dir: pki.clone(),
            source,
        })?;
    let key = pki.join(PRIVATE_KEY);
    if key.exists() {
        service
            .refuse_readable_by_others(&key)
            .map_err(StartError::KeyReadable)?;
    }
    let host = section.host();
    make_certificate(section, &pki, &host, service.as_ref())?;
    let url = format!("opc.tcp://{host}:{}/", section.listen.port());
    let listeners = Arc::new(events::Listeners::default());
    let builder = server_builder(
        section,
        (&pki, &url, built),
        (service.clone(), listeners.clone()),
        layout.clone(),
    );
    let (server, handle) = builder
        .build()
        .map_err(|e| StartError::Setup(e.to_string()))?;
    // The stack writes a new key with the umask's mode: narrowed to the owner at once.
    for made in [pki.join("private"), key] {
        service
            .restrict_to_owner(&made)
            .map_err(|source| StartError::Narrow { path: made, source })?;
    }
    let listener =
        tokio::net::TcpListener::from_std(listener).map_err(|source| StartError::Listen {
            listen: section.listen,
            source,
        })?;
    let server = tokio::spawn(async move {
        if let Err(e) = server.run_with(listener).await {
            tracing::error!(error = %e, "OPC UA server stopped");
        }
    });
    let manager = handle
        .node_managers()
        .get_of_type::<ordered::Ordered>()
        .ok_or(StartError::Missing("node manager"))?
        .inner
        .clone();
    let ns = handle
        .get_namespace_index(space::NAMESPACE_URI)
        .ok_or(StartError::Missing("namespace"))?;
    let mut feed = feed::Feed::new(
        manager,
        handle.subscriptions().clone(),
        space::Ids { ns },
        service.clone(),
        layout.clone(),
        listeners,
        handle.clone(),
    );
    feed.dressings = dressing_counts(service.as_ref(), &layout).await;
    feed.dropped = dropped;
    let (seeds_tx, seeds) = mpsc::channel(16);
    tokio::spawn(seed::send_newest(service.clone(), layout.clone(), seeds_tx));
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
    pki: &Path,
    host: &str,
    service: &dyn Service,
) -> Result<(), StartError> {
    let cert = pki.join(CERTIFICATE);
    let key = pki.join(PRIVATE_KEY);
    if cert.exists() && key.exists() {
        return Ok(());
    }
    for dir in [pki.join("own"), pki.join("private")] {
        service
            .create_private_dir(&dir)
            .map_err(|source| StartError::PkiFolder { dir, source })?;
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
        .map_err(|e| StartError::Certificate(e.to_string()))?;
    info!(certificate = %cert.display(), days = section.certificate_days, "OPC UA: server certificate made");
    Ok(())
}

/// The server as configured: endpoints, certificates, users, camloop's nodes.
fn server_builder(
    section: &OpcUaSection,
    (pki, url, built): (&Path, &str, jiff::Timestamp),
    (service, listeners): (Arc<dyn Service>, Arc<events::Listeners>),
    layout: Vec<MachineLayout>,
) -> ServerBuilder {
    let host = section.host();
    let users = auth::Users::new(service.clone(), section.anonymous_read);
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
            build_date: methods::date_time(built),
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
                service,
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

/// Each machine's dressings as the store has them at start (0 while it is down).
async fn dressing_counts(
    service: &dyn Service,
    layout: &[MachineLayout],
) -> std::collections::HashMap<MachineName, i64> {
    let mut counts = std::collections::HashMap::new();
    let Some(store) = service.store().await else {
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

/// The server as `benches/opcua.rs` and the address-space tests run it: `machines` (name,
/// features) on `listen`, Basic256Sha256 SignAndEncrypt, its PKI in `pki`, anonymous
/// reading and unknown client certificates accepted (the bench's clients are anonymous and
/// new); fed from the returned feeder until `shutdown` turns true. Not part of camloop's
/// interface.
#[doc(hidden)]
pub async fn bench_server(
    (listen, pki, built): (std::net::SocketAddr, &Path, jiff::Timestamp),
    machines: Vec<(MachineName, Vec<FeatureName>)>,
    service: Arc<dyn Service>,
    shutdown: watch::Receiver<bool>,
) -> Result<Feeder, StartError> {
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
    let (tx, events) = mpsc::channel(INTAKE);
    let dropped = Arc::new(AtomicU64::new(0));
    let intake = Intake {
        events,
        dropped: dropped.clone(),
        layout,
        listener: bind(listen)?,
    };
    let setup = Setup {
        section: &section,
        pki: pki.to_path_buf(),
        built,
    };
    // Runs until shutdown: the server's own watcher cancels it.
    drop(start(setup, service, Some(intake), &shutdown).await?);
    Ok(Feeder { tx, dropped })
}
