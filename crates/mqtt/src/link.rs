//! The connection to the broker: connects (again and again while it is away, backing off
//! up to [`MAX_BACKOFF`]), then sends the queue's oldest message with QoS 1 and removes it
//! once the broker acknowledged it, one at a time, so the queue's order is the plant's.
//! Each connection gets a fresh client whose event loop runs in its own task and reports
//! through a channel; a lost connection drops that client, so nothing is re-sent behind
//! the queue's back.

use std::sync::Arc;
use std::time::Duration;

use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use tokio::sync::{Notify, mpsc, watch};
use tracing::{error, info, warn};

use crate::MqttLinkState;

use super::Shared;

const MIN_BACKOFF: Duration = Duration::from_millis(100);
/// Longest wait between connection attempts while the broker is away.
pub const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// A broker that accepted the connection but does not answer within this is given up on.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(10);
/// The status topic's payloads: the birth message, and the last will (and a clean stop).
pub(crate) const ONLINE: &str = "online";
pub(crate) const OFFLINE: &str = "offline";

/// What a connection attempt or a send ended with.
enum Outcome {
    Shutdown,
    Lost(String),
    /// The broker answered the connection with a refusal (credentials, client id).
    Refused(String),
}

/// Sends the queue to the broker until shutdown.
pub(super) async fn run(
    options: MqttOptions,
    prefix: String,
    shared: Arc<Shared>,
    wake: Arc<Notify>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut backoff = MIN_BACKOFF;
    let mut was_lost = false;
    loop {
        if *shutdown.borrow() {
            return;
        }
        let (client, mut events) = connect(options.clone());
        match wait_connack(&mut events, &mut shutdown).await {
            Ok(()) => {
                backoff = MIN_BACKOFF;
                shared.set_connected(true);
                if was_lost {
                    info!(host = %options.broker_address().0, "MQTT broker back: sending the queued events");
                }
                let status = super::status_topic(&prefix, &shared.client_id);
                let outcome =
                    match send(&client, &mut events, &mut shutdown, &status, true, ONLINE).await {
                        Ok(()) => {
                            send_queue(&client, &mut events, &prefix, &shared, &wake, &mut shutdown)
                                .await
                        }
                        Err(outcome) => outcome,
                    };
                shared.set_connected(false);
                match outcome {
                    Outcome::Shutdown => {
                        // A clean stop sends no last will: say `offline` ourselves.
                        let (_keep, mut never) = watch::channel(false);
                        let bye = send(&client, &mut events, &mut never, &status, true, OFFLINE);
                        let _ = tokio::time::timeout(Duration::from_secs(2), bye).await;
                        let _ = client.disconnect().await;
                        return;
                    }
                    Outcome::Lost(why) | Outcome::Refused(why) => {
                        warn!(reason = %why, queued = shared.queued(), "MQTT broker connection lost: events queue on disk");
                        was_lost = true;
                    }
                }
            }
            Err(Outcome::Shutdown) => return,
            Err(Outcome::Refused(why)) => {
                // Logged when it starts; the state stays in /metrics and /healthz.
                if !matches!(shared.link(), MqttLinkState::Refused) {
                    error!(reason = %why, "MQTT broker refused the connection (check mqtt.username and CAMLOOP_MQTT_PASSWORD): events queue on disk");
                }
                shared.set_link(MqttLinkState::Refused);
                was_lost = true;
            }
            Err(Outcome::Lost(why)) => {
                shared.set_link(MqttLinkState::Unreachable);
                if !was_lost {
                    warn!(reason = %why, "MQTT broker unreachable: events queue on disk");
                    was_lost = true;
                }
            }
        }
        drop(client);
        tokio::select! {
            () = tokio::time::sleep(backoff) => {}
            _ = shutdown.changed() => return,
        }
        backoff = (backoff * 2).min(MAX_BACKOFF);
    }
}

/// A client and the channel its event loop task reports on (ending with the first error).
fn connect(
    options: MqttOptions,
) -> (
    AsyncClient,
    mpsc::Receiver<Result<Event, rumqttc::ConnectionError>>,
) {
    let (client, mut eventloop) = AsyncClient::new(options, 16);
    let (tx, rx) = mpsc::channel(64);
    tokio::spawn(async move {
        loop {
            let event = eventloop.poll().await;
            let failed = event.is_err();
            if tx.send(event).await.is_err() || failed {
                return;
            }
        }
    });
    (client, rx)
}

async fn next_event(
    events: &mut mpsc::Receiver<Result<Event, rumqttc::ConnectionError>>,
    shutdown: &mut watch::Receiver<bool>,
) -> Result<Event, Outcome> {
    tokio::select! {
        e = tokio::time::timeout(ANSWER_TIMEOUT, events.recv()) => match e {
            Err(_elapsed) => Err(Outcome::Lost(format!("no answer within {} s", ANSWER_TIMEOUT.as_secs()))),
            Ok(None) => Err(Outcome::Lost("connection closed".into())),
            Ok(Some(Err(e @ rumqttc::ConnectionError::ConnectionRefused(_)))) => Err(Outcome::Refused(e.to_string())),
            Ok(Some(Err(e))) => Err(Outcome::Lost(e.to_string())),
            Ok(Some(Ok(event))) => Ok(event),
        },
        _ = shutdown.changed() => Err(Outcome::Shutdown),
    }
}

async fn wait_connack(
    events: &mut mpsc::Receiver<Result<Event, rumqttc::ConnectionError>>,
    shutdown: &mut watch::Receiver<bool>,
) -> Result<(), Outcome> {
    loop {
        if let Event::Incoming(Packet::ConnAck(_)) = next_event(events, shutdown).await? {
            return Ok(());
        }
    }
}

/// Sends the oldest message (a drop report first, when messages were dropped) and waits
/// for its acknowledgement, until the connection is lost or the service stops.
async fn send_queue(
    client: &AsyncClient,
    events: &mut mpsc::Receiver<Result<Event, rumqttc::ConnectionError>>,
    prefix: &str,
    shared: &Shared,
    wake: &Notify,
    shutdown: &mut watch::Receiver<bool>,
) -> Outcome {
    loop {
        let (message, dropped) = shared.next_message(prefix);
        let Some(message) = message else {
            // Nothing to send: wait for an event, keeping the connection's pings going.
            tokio::select! {
                () = wake.notified() => continue,
                e = events.recv() => match e {
                    Some(Ok(_)) => continue,
                    Some(Err(e)) => return Outcome::Lost(e.to_string()),
                    None => return Outcome::Lost("connection closed".into()),
                },
                _ = shutdown.changed() => return Outcome::Shutdown,
            }
        };
        let event = std::iter::once((&message.topic, false, &message.payload));
        let legacy = message
            .state_topic
            .iter()
            .map(|t| (t, true, &message.payload));
        let states = message.states.iter().map(|(t, p)| (t, true, p));
        for (topic, retain, payload) in event.chain(legacy).chain(states) {
            if let Err(outcome) = send(client, events, shutdown, topic, retain, payload).await {
                return outcome;
            }
        }
        shared.sent(dropped);
    }
}

/// Publishes with QoS 1 and waits for the broker's acknowledgement.
async fn send(
    client: &AsyncClient,
    events: &mut mpsc::Receiver<Result<Event, rumqttc::ConnectionError>>,
    shutdown: &mut watch::Receiver<bool>,
    topic: &str,
    retain: bool,
    payload: &str,
) -> Result<(), Outcome> {
    client
        .publish(topic, QoS::AtLeastOnce, retain, payload.as_bytes().to_vec())
        .await
        .map_err(|e| Outcome::Lost(e.to_string()))?;
    loop {
        if let Event::Incoming(Packet::PubAck(_)) = next_event(events, shutdown).await? {
            return Ok(());
        }
    }
}
