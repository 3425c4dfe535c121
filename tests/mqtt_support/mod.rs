//! What the MQTT tests share: Debian's `mosquitto` started under a guard from a config the
//! test writes, and a subscriber that hands on every message it receives.

use crate::process_support::KillOnDrop;
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;
use tokio::sync::mpsc;

/// Longest wait for anything the broker, a client or camloop should do; a failure, not a pace.
pub const DEADLINE: Duration = Duration::from_secs(30);

/// A received message: topic, payload as the test decodes it, retained flag.
pub type Message<T> = (String, T, bool);

/// The config line mosquitto needs to start as root (it refuses otherwise): `user root`, or
/// nothing for anyone else.
pub fn root_user_line() -> &'static str {
    let root = std::fs::read_to_string("/proc/self/status")
        .unwrap_or_default()
        .lines()
        .any(|l| l.starts_with("Uid:") && l.split_whitespace().nth(1) == Some("0"));
    if root { "user root\n" } else { "" }
}

/// Starts mosquitto (`exe`) with the config file `conf`; returns once its log says it runs.
pub fn mosquitto(exe: &str, conf: &Path) -> KillOnDrop {
    let mut child = KillOnDrop::spawn(
        Command::new(exe)
            .arg("-c")
            .arg(conf)
            .stdout(Stdio::null())
            .stderr(Stdio::piped()),
    )
    .unwrap_or_else(|e| panic!("mosquitto cannot start ({e}): install Debian's mosquitto"));
    // Its log goes to stderr, which is not buffered: the line arrives when it is written.
    let mut lines = BufReader::new(child.stderr.take().expect("piped")).lines();
    let mut seen = Vec::new();
    loop {
        match lines.next() {
            Some(Ok(line)) => {
                let running = line.contains(" running");
                seen.push(line);
                if running {
                    break;
                }
            }
            _ => panic!("mosquitto stopped before running: {seen:?}"),
        }
    }
    // Keep reading its log so it never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    child
}

/// Stops the broker as an operator would (SIGTERM: it saves its sessions) and waits.
pub fn stop(mut broker: KillOnDrop) {
    broker.signal("-TERM");
    broker.wait().expect("mosquitto exits");
}

/// A client with `options` subscribed to `filter` (QoS 1, again after every reconnection),
/// handing on each message with its payload through `decode`. `None` when it has not
/// subscribed within [`DEADLINE`] (refused, or the broker is not there).
pub async fn subscribe<T: Send + 'static>(
    options: MqttOptions,
    filter: &str,
    decode: fn(&[u8]) -> T,
) -> Option<mpsc::UnboundedReceiver<Message<T>>> {
    let (client, mut eventloop) = AsyncClient::new(options, 16);
    let (tx, rx) = mpsc::unbounded_channel();
    let (subscribed_tx, mut subscribed) = mpsc::channel(1);
    let filter = filter.to_owned();
    tokio::spawn(async move {
        loop {
            match eventloop.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    client.subscribe(&filter, QoS::AtLeastOnce).await.unwrap();
                }
                Ok(Event::Incoming(Packet::SubAck(_))) => {
                    let _ = subscribed_tx.try_send(());
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    if tx.send((p.topic, decode(&p.payload), p.retain)).is_err() {
                        return;
                    }
                }
                Ok(_) => {}
                // The broker is away: rumqttc reconnects on the next poll; pace the retries.
                Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
            }
        }
    });
    let ready = tokio::time::timeout(DEADLINE, subscribed.recv()).await;
    ready.ok().flatten().map(|()| rx)
}
