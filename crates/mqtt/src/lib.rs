//! Events to the plant's MQTT broker (`[mqtt]`, off by default).
//!
//! The service hands each plant event to the publisher's [`Intake`] (never waiting: a full
//! intake counts the event as dropped); an intake task turns it into a [`PlantEvent`] on
//! its topic `<prefix>/<machine>/<feature>/<event>` with its sequence number, plus the
//! retained states it changed (`<prefix>/<machine>/<feature>/state`, see [`state`]), and
//! appends them to the on-disk [`queue::DiskQueue`]; the [`link`] sends the queue to the
//! broker with QoS 1, in order, whenever the broker is there. A broker that is down never
//! blocks a loop: events wait on disk up to `queue_max_events`, the oldest are dropped
//! beyond it (logged when dropping starts), and the number dropped is published on
//! `<prefix>/<client_id>/queue_dropped` when the broker is back (and logged).
//!
//! `<prefix>/<client_id>/status` says `online` (retained) once connected and `offline` when
//! the service stops; the broker publishes `offline` itself (the last will) when the
//! connection is lost without that, e.g. when the process is killed. Credentials and TLS
//! (rustls) come from `[mqtt]`.

//!
//! An adapter of the service: it depends on the loop's types (`PlantEvent`) and its own
//! config section, never on the service or another adapter; the service wires it.

mod config;
mod link;
mod progress;
pub mod queue;
pub mod state;

pub use config::{ENV_MQTT_PASSWORD, MqttSection, Password, SectionProblem};
pub use link::MAX_BACKOFF;
pub use progress::{MqttLinkState, MqttMetrics, Progress};

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use rumqttc::{LastWill, MqttOptions, QoS, TlsConfiguration, Transport};
use tokio::sync::{Notify, mpsc, watch};
use tokio_rustls::rustls;
use tracing::warn;

use camloop_loop::PlantEvent;
use queue::{DiskQueue, Message};

/// Events waiting for the intake task; beyond it an event is dropped (and counted).
const INTAKE: usize = 4096;

/// What the intake, the link and the owner share.
#[derive(Debug)]
struct Shared {
    progress: watch::Sender<Progress>,
    queue: Mutex<DiskQueue>,
    refused: Arc<AtomicU64>,
    connected: AtomicBool,
    link: Mutex<MqttLinkState>,
    sent: AtomicU64,
    client_id: String,
    max: usize,
}

impl Shared {
    fn queue(&self) -> MutexGuard<'_, DiskQueue> {
        // A panic while holding the lock leaves a consistent queue (every change is one
        // push or pop): keep going with it.
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn set_connected(&self, on: bool) {
        self.connected.store(on, Ordering::Relaxed);
        self.set_link(match on {
            true => MqttLinkState::Connected,
            false => MqttLinkState::Unreachable,
        });
    }

    fn link(&self) -> MqttLinkState {
        *self.link.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn set_link(&self, link: MqttLinkState) {
        *self.link.lock().unwrap_or_else(|p| p.into_inner()) = link;
        self.progress();
    }

    /// Publishes the current [`Progress`].
    fn progress(&self) {
        let p = {
            let q = self.queue();
            Progress {
                queued: q.len(),
                sent: self.sent.load(Ordering::Relaxed),
                dropped: q.dropped_total() + self.refused.load(Ordering::Relaxed),
                connected: self.connected.load(Ordering::Relaxed),
                link: self.link(),
            }
        };
        self.progress.send_replace(p);
    }

    fn queued(&self) -> usize {
        self.queue().len()
    }

    /// The next message to send: a drop report when messages were dropped, else the
    /// oldest queued one; with the number of drops the report tells.
    fn next_message(&self, prefix: &str) -> (Option<Message>, u64) {
        let mut q = self.queue();
        q.count_dropped(self.refused.swap(0, Ordering::Relaxed));
        let dropped = q.dropped_unreported();
        if dropped > 0 {
            let report = serde_json::json!({
                "event": "queue_dropped",
                "client_id": self.client_id,
                "dropped_events": dropped,
                "queue_max_events": self.max,
                "at_ms": jiff::Timestamp::now().as_millisecond(),
            });
            let topic = format!("{prefix}/{}/queue_dropped", self.client_id);
            warn!(
                dropped_events = dropped,
                queue_max_events = self.max,
                "MQTT events dropped while the broker was away (queue full): reporting the count on {topic}"
            );
            let m = Message {
                topic,
                payload: report.to_string(),
                state_topic: None,
                states: Vec::new(),
            };
            return (Some(m), dropped);
        }
        (q.front().cloned(), 0)
    }

    /// The message from [`Shared::next_message`] was acknowledged.
    fn sent(&self, dropped_report: u64) {
        let mut q = self.queue();
        let done = if dropped_report > 0 {
            q.dropped_reported(dropped_report);
            Ok(())
        } else {
            q.pop_front()
        };
        drop(q);
        if let Err(e) = done {
            warn!(error = %e, "MQTT queue file cannot be updated: a sent event may be sent again");
        }
        self.sent.fetch_add(1, Ordering::Relaxed);
        self.progress();
    }
}

/// Why the publisher cannot start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("MQTT queue in {}", dir.display())]
    Queue {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("mqtt.tls_ca {}", path.display())]
    CaFile {
        path: PathBuf,
        #[source]
        source: rustls::pki_types::pem::Error,
    },
    #[error("mqtt.tls_ca {}", path.display())]
    CaCertificate {
        path: PathBuf,
        #[source]
        source: rustls::Error,
    },
    #[error("mqtt.tls: no CA certificate to check the broker against")]
    NoCa,
    #[error("mqtt.tls")]
    Tls(#[source] rustls::Error),
}

/// Where the service sends plant events: never waits, and counts what a full intake
/// refuses as dropped. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Intake {
    tx: mpsc::Sender<PlantEvent>,
    refused: Arc<AtomicU64>,
}

impl Intake {
    /// Queues the event, or counts it dropped when the intake is full.
    pub fn send(&self, event: PlantEvent) {
        if self.tx.try_send(event).is_err() {
            self.refused.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The channel and its refusal counter, for a sender that feeds several adapters.
    pub fn into_parts(self) -> (mpsc::Sender<PlantEvent>, Arc<AtomicU64>) {
        (self.tx, self.refused)
    }
}

/// A running publisher: where to send events, and what it has done.
#[derive(Debug)]
pub struct Publisher {
    sender: Intake,
    shared: Arc<Shared>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

impl Publisher {
    /// Starts the intake and the link, the queue in `queue_dir`; they stop on `shutdown`.
    pub fn start(
        settings: &MqttSection,
        queue_dir: &Path,
        shutdown: watch::Receiver<bool>,
    ) -> Result<Self, StartError> {
        let queue = DiskQueue::open(queue_dir, settings.queue_max_events).map_err(|source| {
            StartError::Queue {
                dir: queue_dir.to_owned(),
                source,
            }
        })?;
        let (tx, rx) = mpsc::channel(INTAKE);
        let refused = Arc::new(AtomicU64::new(0));
        let shared = Arc::new(Shared {
            progress: watch::Sender::new(Progress::default()),
            queue: Mutex::new(queue),
            refused: refused.clone(),
            connected: AtomicBool::new(false),
            link: Mutex::new(MqttLinkState::Connecting),
            sent: AtomicU64::new(0),
            client_id: settings.client_id.clone(),
            max: settings.queue_max_events,
        });
        shared.progress();
        let wake = Arc::new(Notify::new());
        let options = options(settings)?;
        let tracker = state::Tracker::open(queue_dir);
        let intake = tokio::spawn(intake(
            rx,
            settings.topic_prefix.clone(),
            shared.clone(),
            wake.clone(),
            tracker,
        ));
        let link = tokio::spawn(link::run(
            options,
            settings.topic_prefix.clone(),
            shared.clone(),
            wake,
            shutdown,
        ));
        Ok(Self {
            sender: Intake { tx, refused },
            shared,
            tasks: vec![intake, link],
        })
    }

    pub fn sender(&self) -> Intake {
        self.sender.clone()
    }

    /// Its progress, updated after every change.
    pub fn progress(&self) -> watch::Receiver<Progress> {
        self.shared.progress.subscribe()
    }

    /// Calls `report` with the link's series (state, queue depth, sent, dropped) after
    /// every change until the publisher ends: the service's `/metrics` shows them, and
    /// `/healthz` says `degraded` while the broker refuses or cannot be reached.
    pub fn report_to(&self, report: impl Fn(MqttMetrics) + Send + 'static) {
        let mut progress = self.progress();
        tokio::spawn(async move {
            loop {
                let now = progress.borrow_and_update().metrics();
                report(now);
                if progress.changed().await.is_err() {
                    return;
                }
            }
        });
    }

    /// Waits for both tasks to end (after shutdown, once every sender is dropped).
    pub async fn join(self) {
        drop(self.sender);
        for t in self.tasks {
            let _ = t.await;
        }
    }
}

/// `<prefix>/<client_id>/status`: `online` while connected, else `offline`.
pub(crate) fn status_topic(prefix: &str, client_id: &str) -> String {
    format!("{prefix}/{client_id}/status")
}

/// The client's options: keep-alive, the last will, credentials and TLS.
fn options(settings: &MqttSection) -> Result<MqttOptions, StartError> {
    let mut options = MqttOptions::new(&settings.client_id, &settings.host, settings.port);
    options.set_keep_alive(Duration::from_secs(settings.keep_alive_s));
    options.set_clean_session(true);
    let status = status_topic(&settings.topic_prefix, &settings.client_id);
    options.set_last_will(LastWill::new(status, link::OFFLINE, QoS::AtLeastOnce, true));
    if let Some(warning) = credentials_warning(settings) {
        warn!(
            user = settings.username.as_deref().unwrap_or("-"),
            "{warning}"
        );
    }
    if let Some(user) = &settings.username {
        let password = settings.password.as_ref().map(|p| p.expose().to_owned());
        options.set_credentials(user, password.unwrap_or_default());
    }
    if settings.tls {
        let config = tls_client(settings.tls_ca.as_deref())?;
        options.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(
            Arc::new(config),
        )));
    }
    Ok(options)
}

/// What to warn of at start about the credentials: a user name without a password (a
/// missing `CAMLOOP_MQTT_PASSWORD`, most likely), which the broker will refuse.
fn credentials_warning(settings: &MqttSection) -> Option<&'static str> {
    (settings.username.is_some() && settings.password.is_none()).then_some(
        "mqtt.username is set without a password (CAMLOOP_MQTT_PASSWORD is not set): the broker will likely refuse the connection",
    )
}

/// A rustls client trusting `ca` (PEM), or the system's roots.
fn tls_client(ca: Option<&Path>) -> Result<rustls::ClientConfig, StartError> {
    use rustls::pki_types::CertificateDer;
    use rustls::pki_types::pem::PemObject;
    let mut roots = rustls::RootCertStore::empty();
    match ca {
        Some(path) => {
            let file = |source| StartError::CaFile {
                path: path.to_owned(),
                source,
            };
            for cert in CertificateDer::pem_file_iter(path).map_err(file)? {
                roots
                    .add(cert.map_err(file)?)
                    .map_err(|source| StartError::CaCertificate {
                        path: path.to_owned(),
                        source,
                    })?;
            }
        }
        None => {
            let found = rustls_native_certs::load_native_certs();
            roots.add_parsable_certificates(found.certs);
        }
    }
    if roots.is_empty() {
        return Err(StartError::NoCa);
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    Ok(rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(StartError::Tls)?
        .with_root_certificates(roots)
        .with_no_client_auth())
}

/// The event's JSON payload with its sequence number (`seq`) last: the MQTT wire's.
pub fn payload_with_seq(event: &PlantEvent, seq: u64) -> String {
    let mut value = serde_json::to_value(event).expect("a plant event serializes to JSON");
    if let Some(fields) = value.as_object_mut() {
        fields.insert("seq".into(), seq.into());
    }
    value.to_string()
}

/// Moves events from the loops to the disk queue, numbering them and tracking the states
/// they change.
async fn intake(
    mut rx: mpsc::Receiver<PlantEvent>,
    prefix: String,
    shared: Arc<Shared>,
    wake: Arc<Notify>,
    mut tracker: state::Tracker,
) {
    while let Some(event) = rx.recv().await {
        let (seq, states) = tracker.apply(&event, &prefix);
        if let Err(e) = tracker.save() {
            warn!(error = %e, "MQTT state file cannot be written: sequence numbers may repeat after a restart");
        }
        let message = Message {
            topic: event.topic(&prefix),
            payload: payload_with_seq(&event, seq),
            state_topic: None,
            states,
        };
        // The guard goes before the match: the arms take the lock again.
        let pushed = shared.queue().push(message);
        match pushed {
            // The first drop since the last report: say so now, the count follows.
            Ok(true) if shared.queue().dropped_unreported() == 1 => warn!(
                queue_max_events = shared.max,
                "MQTT queue full: the oldest events are dropped until the broker is back"
            ),
            Ok(_) => {}
            Err(e) => {
                warn!(error = %e, "MQTT queue file cannot be written: event kept in memory only")
            }
        }
        shared.progress();
        wake.notify_one();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_user_name_without_a_password_is_warned_of() {
        let mut settings = MqttSection {
            username: Some("camloop".into()),
            password: None,
            ..MqttSection::default()
        };
        assert!(credentials_warning(&settings).is_some_and(|w| w.contains("without a password")));
        settings.password = Some(Password::new("s3cret"));
        assert_eq!(credentials_warning(&settings), None);
        settings.username = None;
        settings.password = None;
        assert_eq!(credentials_warning(&settings), None);
    }
}
