//! The MQTT link to a broker that wants a password and speaks TLS only: Debian's
//! `mosquitto` with a password file (made by `mosquitto_passwd`) and a TLS listener whose
//! certificate camloop's own `self_signed` made. A wrong password is refused; the right one
//! over TLS delivers; and when the `camloop` process is killed with SIGKILL, the broker
//! publishes its last will `offline` on the status topic.

use crate::process_support;

use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::time::Duration;

use crate::mqtt_support::{DEADLINE, Message, mosquitto, root_user_line, subscribe};
use camloop::config::MqttSection;
use camloop::service::metrics::{Metrics, MqttLinkState};
use camloop::store::Verdict;
use camloop_loop::PlantEvent;
use camloop_mqtt::{Password, Publisher};
use process_support::{KillOnDrop, camloop_run, free_port};
use rumqttc::{AsyncClient, ConnectionError, MqttOptions};
use rumqttc::{TlsConfiguration, Transport};
use tokio::sync::{mpsc, watch};

const USER: &str = "camloop";
const PASSWORD: &str = "correct horse battery";

fn found(exe: &str) -> Option<String> {
    ["/usr/sbin/", "/usr/bin/"]
        .iter()
        .map(|d| format!("{d}{exe}"))
        .find(|p| Path::new(p).exists())
}

/// mosquitto and mosquitto_passwd, or `None` (with a line saying so) when CI does not
/// require them.
fn tools() -> Option<(String, String)> {
    match (found("mosquitto"), found("mosquitto_passwd")) {
        (Some(b), Some(p)) => Some((b, p)),
        _ if std::env::var_os("CAMLOOP_REQUIRE_MQTT").is_some() => {
            panic!("mosquitto is required (CAMLOOP_REQUIRE_MQTT) but not installed")
        }
        _ => {
            eprintln!("SKIPPED: mosquitto or mosquitto_passwd not installed (Debian's mosquitto)");
            None
        }
    }
}

/// A TLS-only, password-only mosquitto on `port`; `dir` gets its files. Returns the broker
/// and the certificate a client must trust.
fn secure_broker(port: u16, dir: &Path, (exe, passwd): &(String, String)) -> (KillOnDrop, String) {
    let (cert, key) =
        camloop::service::http::self_signed(&["localhost".into(), "127.0.0.1".into()]).unwrap();
    std::fs::write(dir.join("cert.pem"), &cert).unwrap();
    std::fs::write(dir.join("key.pem"), &key).unwrap();
    let made = Command::new(passwd)
        .args(["-b", "-c"])
        .arg(dir.join("passwd"))
        .args([USER, PASSWORD])
        .status()
        .unwrap();
    assert!(made.success(), "mosquitto_passwd failed");
    let d = dir.display();
    let conf = format!(
        "listener {port} 127.0.0.1\ncertfile {d}/cert.pem\nkeyfile {d}/key.pem\n\
         allow_anonymous false\npassword_file {d}/passwd\nlog_dest stderr\nlog_type all\n{}",
        root_user_line()
    );
    std::fs::write(dir.join("mosquitto.conf"), conf).unwrap();
    let child = mosquitto(exe, &dir.join("mosquitto.conf"));
    (child, cert)
}

/// A client over TLS trusting `cert`, as `password`.
fn client_options(id: &str, port: u16, cert: &str, password: &str) -> MqttOptions {
    let config = crate::http_tls::trusting(cert);
    let mut o = MqttOptions::new(id, "localhost", port);
    o.set_credentials(USER, password);
    o.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(
        Arc::new(config),
    )));
    o
}

/// A subscriber on `filter`: messages as (topic, payload text, retained).
async fn subscriber(
    id: &str,
    port: u16,
    cert: &str,
    filter: &str,
) -> mpsc::UnboundedReceiver<Message<String>> {
    let options = client_options(id, port, cert, PASSWORD);
    let text = |p: &[u8]| String::from_utf8_lossy(p).into_owned();
    subscribe(options, filter, text)
        .await
        .expect("the subscriber connects over TLS with the right password")
}

/// The next message on `topic` (others skipped), within the deadline.
async fn next_on(rx: &mut mpsc::UnboundedReceiver<Message<String>>, topic: &str) -> (String, bool) {
    loop {
        let (t, payload, retained) = tokio::time::timeout(DEADLINE, rx.recv())
            .await
            .unwrap_or_else(|_| panic!("nothing on {topic} within {DEADLINE:?}"))
            .unwrap();
        if t == topic {
            return (payload, retained);
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrong_password_is_refused_and_the_right_one_delivers_over_tls() {
    let Some(tools) = tools() else { return };
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let (_broker, cert) = secure_broker(port, dir.path(), &tools);

    // A wrong password: the broker answers the CONNECT with a refusal.
    let (_c, mut wrong) = AsyncClient::new(client_options("intruder", port, &cert, "guess"), 4);
    let refused = tokio::time::timeout(DEADLINE, async {
        loop {
            if let Err(e) = wrong.poll().await {
                return e;
            }
        }
    })
    .await
    .unwrap();
    assert!(
        matches!(refused, ConnectionError::ConnectionRefused(_)),
        "{refused:?}"
    );
    // Plain MQTT on the TLS port does not get through either.
    let (_p, mut plain) = AsyncClient::new(MqttOptions::new("plain", "127.0.0.1", port), 4);
    let plain_result = tokio::time::timeout(DEADLINE, plain.poll()).await.unwrap();
    assert!(plain_result.is_err(), "{plain_result:?}");

    // camloop's publisher with the right password and the broker's certificate as its CA.
    let mut rx = subscriber("listener", port, &cert, "plant/#").await;
    std::fs::write(dir.path().join("ca.pem"), &cert).unwrap();
    let settings = MqttSection {
        enabled: true,
        host: "localhost".into(),
        port,
        client_id: "camloop-tls".into(),
        topic_prefix: "plant".into(),
        username: Some(USER.into()),
        password: Some(Password::new(PASSWORD)),
        tls: true,
        tls_ca: Some(dir.path().join("ca.pem")),
        ..MqttSection::default()
    };
    let (stop, shutdown) = watch::channel(false);
    let publisher = Publisher::start(&settings, &dir.path().join("queue"), shutdown).unwrap();
    publisher.sender().send(PlantEvent::PartAnalysed {
        machine: "M1".parse().unwrap(),
        feature: "IN1".parse().unwrap(),
        part: "P1".parse().unwrap(),
        at: jiff::Timestamp::from_millisecond(1).unwrap(),
        verdict: Verdict::Pass,
        max_profile_error_um: 1.5,
        base_radius_error_um: 0.0,
        phase_error_deg: 0.0,
        ground_with_version: camloop::core::ids::TableVersion::new(2),
        repeatability_um: None,
    });
    assert_eq!(
        next_on(&mut rx, "plant/camloop-tls/status").await.0,
        "online"
    );
    let (event, _) = next_on(&mut rx, "plant/M1/IN1/part_analysed").await;
    let event: serde_json::Value = serde_json::from_str(&event).unwrap();
    assert_eq!(
        (event["part"].clone(), event["seq"].clone()),
        ("P1".into(), 1.into())
    );
    let (state, retained) = next_on(&mut rx, "plant/M1/IN1/state").await;
    assert!(!retained, "live delivery to a subscriber already there");
    assert!(state.contains(r#""version_in_force":2"#), "{state}");

    // The same publisher with a wrong password never connects, and says why in its log.
    let wrong_settings = MqttSection {
        client_id: "camloop-wrong".into(),
        password: Some(Password::new("guess")),
        ..settings.clone()
    };
    let (_stop2, shutdown2) = watch::channel(false);
    let other = Publisher::start(&wrong_settings, &dir.path().join("queue2"), shutdown2).unwrap();
    let mut progress = other.progress();
    // Bound: 3 s covers several connection attempts (100 ms backoff, doubling).
    let connected =
        tokio::time::timeout(Duration::from_secs(3), progress.wait_for(|p| p.connected)).await;
    assert!(connected.is_err(), "connected with a wrong password");
    // The refusal is visible: the link's state, in /metrics and as degraded for /healthz.
    let metrics = Arc::new(Metrics::default());
    let shown_in = metrics.clone();
    other.report_to(move |m| shown_in.set_mqtt(m));
    let mut link = other.progress();
    let refused = link.wait_for(|p| p.link == MqttLinkState::Refused);
    tokio::time::timeout(DEADLINE, refused)
        .await
        .expect("the link says refused")
        .unwrap();
    let shown = async {
        while !metrics.mqtt_degraded() {
            tokio::task::yield_now().await;
        }
    };
    tokio::time::timeout(DEADLINE, shown).await.unwrap();
    let text = metrics.render();
    assert!(
        text.contains("camloop_mqtt_link_state{state=\"refused\"} 1"),
        "{text}"
    );
    assert!(text.contains("camloop_mqtt_queue_events 0"), "{text}");

    stop.send(true).unwrap();
    tokio::time::timeout(DEADLINE, publisher.join())
        .await
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_broker_publishes_the_last_will_when_camloop_is_killed() {
    let Some(tools) = tools() else { return };
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let (_broker, cert) = secure_broker(port, dir.path(), &tools);
    std::fs::write(dir.path().join("ca.pem"), &cert).unwrap();
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let config = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n\
         [mqtt]\nenabled = true\nhost = \"localhost\"\nport = {port}\nusername = \"{USER}\"\n\
         tls = true\ntls_ca = \"ca.pem\"\nkeep_alive_s = 5\n\
         [[machines]]\nname = \"SIM1\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share/SIM1\"\n\
         [machines.gauge]\nkind = \"sim\"\npart_interval_ms = 200\n",
        recipe.display()
    );
    std::fs::write(dir.path().join("camloop.toml"), config).unwrap();
    let mut rx = subscriber("listener", port, &cert, "camloop/#").await;
    let mut run = camloop_run(dir.path());
    let mut camloop = KillOnDrop::spawn(run.env("CAMLOOP_MQTT_PASSWORD", PASSWORD)).unwrap();
    let status = "camloop/camloop/status";
    assert_eq!(next_on(&mut rx, status).await.0, "online");
    // A part's state arrives: the link is in use when the process dies.
    next_on(&mut rx, "camloop/SIM1/IN1/state").await;
    camloop.kill().unwrap(); // SIGKILL: no chance to say goodbye.
    camloop.wait().unwrap();
    let (will, retained) = next_on(&mut rx, status).await;
    assert_eq!(will, "offline");
    assert!(!retained, "live delivery to a subscriber already there");
    // A newcomer finds `offline` retained.
    let mut late = subscriber("late", port, &cert, status).await;
    assert_eq!(next_on(&mut late, status).await, ("offline".into(), true));
}
