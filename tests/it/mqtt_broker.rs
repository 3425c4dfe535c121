//! Events to a real broker: Debian's `mosquitto`, started by the test on a free port. The
//! publisher delivers events in order with QoS 1 and keeps the machine's state retained;
//! while the broker is away, events wait on disk up to the bound, the oldest are dropped
//! beyond it, and when the broker is back the drop count is published, then the rest.

use std::path::Path;

use crate::mqtt_support::{DEADLINE, Message, mosquitto, root_user_line, stop, subscribe};
use crate::process_support::{KillOnDrop, free_port};
use camloop::config::{Config, MqttSection};
use camloop::service::{self, RunOptions};
use camloop::store::Verdict;
use camloop_loop::PlantEvent;
use camloop_mqtt::{Progress, Publisher};
use rumqttc::MqttOptions;
use tokio::sync::{mpsc, watch};

/// Starts mosquitto on `port`, persisting sessions in `dir`; returns once it says it runs.
fn broker(port: u16, dir: &Path) -> KillOnDrop {
    let conf = dir.join("mosquitto.conf");
    std::fs::write(
        &conf,
        format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence true\n\
             persistence_location {}/\nlog_dest stderr\nlog_type all\n{}",
            dir.display(),
            root_user_line()
        ),
    )
    .unwrap();
    let exe = ["/usr/sbin/mosquitto", "mosquitto"]
        .into_iter()
        .find(|p| Path::new(p).exists())
        .unwrap_or("mosquitto");
    mosquitto(exe, &conf)
}

/// A subscriber on `filter`; with `clean` false its session persists: what the broker sends
/// it while it reconnects is kept for it. Messages come out as (topic, payload, retained).
async fn subscriber(
    port: u16,
    id: &str,
    filter: &str,
    clean: bool,
) -> mpsc::UnboundedReceiver<Message<serde_json::Value>> {
    let mut options = MqttOptions::new(id, "127.0.0.1", port);
    options.set_clean_session(clean);
    // The status topic says `online`/`offline`, the rest is JSON.
    let decode = |p: &[u8]| {
        serde_json::from_slice::<serde_json::Value>(p)
            .unwrap_or_else(|_| String::from_utf8_lossy(p).into_owned().into())
    };
    subscribe(options, filter, decode)
        .await
        .expect("subscribed")
}

async fn next(
    rx: &mut mpsc::UnboundedReceiver<Message<serde_json::Value>>,
) -> Message<serde_json::Value> {
    tokio::time::timeout(DEADLINE, rx.recv())
        .await
        .expect("a message within the deadline")
        .unwrap()
}

/// The next message published since the subscription: retained copies that the broker
/// hands out on (re)subscribing, and the publisher's `online`/`offline` status, are skipped.
async fn next_live(
    rx: &mut mpsc::UnboundedReceiver<Message<serde_json::Value>>,
) -> Message<serde_json::Value> {
    loop {
        let m = next(rx).await;
        if !m.2 && !m.0.ends_with("/status") {
            return m;
        }
    }
}

/// The next live message that is not a redelivery of the feature's first `seen` events.
/// QoS 1 is at least once: a message the listener had not acknowledged when the broker
/// stopped comes again when both are back (seen with both cores busy). Only those may come
/// again; anything else is returned and judged by the caller.
async fn next_after_redelivery(
    rx: &mut mpsc::UnboundedReceiver<Message<serde_json::Value>>,
    seen: u64,
) -> Message<serde_json::Value> {
    loop {
        let m = next_live(rx).await;
        let again =
            m.0.starts_with("plant/M1/IN1/") && m.1["seq"].as_u64().is_some_and(|s| s <= seen);
        if !again {
            return m;
        }
    }
}

async fn until(
    progress: &mut watch::Receiver<Progress>,
    what: impl Fn(&Progress) -> bool,
) -> Progress {
    *tokio::time::timeout(DEADLINE, progress.wait_for(what))
        .await
        .expect("publisher progress within the deadline")
        .unwrap()
}

fn part(n: u32) -> PlantEvent {
    PlantEvent::PartAnalysed {
        machine: "M1".parse().unwrap(),
        feature: "IN1".parse().unwrap(),
        part: format!("P{n}").parse().unwrap(),
        at: jiff::Timestamp::from_millisecond(1_000 * i64::from(n)).unwrap(),
        verdict: Verdict::Pass,
        max_profile_error_um: 0.5 * f64::from(n),
        base_radius_error_um: -0.25,
        phase_error_deg: 0.01,
        ground_with_version: camloop::core::ids::TableVersion::new(u64::from(n)),
        repeatability_um: None,
    }
}

/// Receives part `n`'s event (sequence number `seq`) and then the feature's state.
async fn expect_part(
    rx: &mut mpsc::UnboundedReceiver<Message<serde_json::Value>>,
    n: u32,
    seq: u64,
) {
    let (topic, payload, _) = next_live(rx).await;
    assert_eq!(topic, "plant/M1/IN1/part_analysed");
    assert_eq!(payload["part"], format!("P{n}"), "{payload}");
    assert_eq!(payload["max_profile_error_um"], 0.5 * f64::from(n));
    assert_eq!(payload["event"], "part_analysed");
    assert_eq!(payload["seq"], seq, "{payload}");
    let (topic, state, _) = next_live(rx).await;
    assert_eq!(topic, "plant/M1/IN1/state");
    assert_eq!(state["last_part"], format!("P{n}"), "{state}");
    assert_eq!(state["last_verdict"], "pass");
    assert_eq!(
        (state["alarm"].clone(), state["seq"].clone()),
        (false.into(), seq.into())
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn events_reach_a_real_broker_survive_its_outage_and_report_what_the_bound_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let broker_dir = dir.path().join("broker");
    std::fs::create_dir(&broker_dir).unwrap();
    let b = broker(port, &broker_dir);
    let mut rx = subscriber(port, "plant-listener", "plant/#", false).await;
    let settings = MqttSection {
        enabled: true,
        host: "127.0.0.1".into(),
        port,
        client_id: "camloop-test".into(),
        topic_prefix: "plant".into(),
        queue_max_events: 5,
        keep_alive_s: 5,
        ..MqttSection::default()
    };
    let (shutdown_tx, shutdown) = watch::channel(false);
    let publisher = Publisher::start(&settings, &dir.path().join("queue"), shutdown).unwrap();
    let mut progress = publisher.progress();
    let events = publisher.sender();

    // Broker up: three parts arrive in order, each with the machine's state.
    for n in 1..=3 {
        events.send(part(n));
    }
    for n in 1..=3 {
        expect_part(&mut rx, n, u64::from(n)).await;
    }
    until(&mut progress, |p| p.sent == 3 && p.queued == 0).await;

    // Broker away: 12 more parts; the queue keeps the newest 5 and drops 7.
    stop(b);
    until(&mut progress, |p| !p.connected).await;
    for n in 4..=15 {
        events.send(part(n));
    }
    // Every event went through the intake: 5 kept and 7 dropped, none sent.
    let p = until(&mut progress, |p| p.queued + p.dropped as usize == 12).await;
    assert_eq!((p.queued, p.dropped, p.sent), (5, 7, 3));
    // They wait on disk: exactly the bound in lines, the newest last.
    let on_disk = std::fs::read_to_string(dir.path().join("queue/queue.jsonl")).unwrap();
    assert!(on_disk.contains(r#"\"part\":\"P15\""#), "{on_disk}");
    assert_eq!(on_disk.lines().count(), 5, "{on_disk}");

    // Broker back (same port, same sessions): the drop report, then parts 11 to 15.
    let b = broker(port, &broker_dir);
    let (topic, report, _) = next_after_redelivery(&mut rx, 3).await;
    assert_eq!(topic, "plant/camloop-test/queue_dropped");
    assert_eq!(report["dropped_events"], 7);
    assert_eq!(report["queue_max_events"], 5);
    // Their sequence numbers show the 7 dropped (4 to 10) as a gap.
    for n in 11..=15 {
        expect_part(&mut rx, n, u64::from(n)).await;
    }
    let p = until(&mut progress, |p| p.queued == 0 && p.sent == 3 + 1 + 5).await;
    assert!(p.connected);
    assert_eq!(
        std::fs::metadata(dir.path().join("queue/queue.jsonl"))
            .unwrap()
            .len(),
        0,
        "a sent queue leaves an empty file"
    );

    // A newcomer gets the machine's newest state, retained by the broker.
    let mut late = subscriber(port, "plant-late", "plant/M1/IN1/state", true).await;
    let (topic, state, retained) = next(&mut late).await;
    assert_eq!(topic, "plant/M1/IN1/state");
    assert!(retained);
    assert_eq!(state["last_part"], "P15");
    let mut status = subscriber(port, "plant-status", "plant/camloop-test/status", true).await;
    assert_eq!(next(&mut status).await.1, "online");

    shutdown_tx.send(true).unwrap();
    drop(events);
    tokio::time::timeout(DEADLINE, publisher.join())
        .await
        .unwrap();
    // A clean stop says `offline` itself.
    assert_eq!(next(&mut status).await.1, "offline");
    stop(b);
}

/// The service with `[mqtt]` on: the simulated machine's parts and deliveries reach the
/// broker through the loop's hook, one event per part, in order.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_running_service_publishes_its_parts_and_tables() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let broker_dir = dir.path().join("broker");
    std::fs::create_dir(&broker_dir).unwrap();
    let b = broker(port, &broker_dir);
    let mut rx = subscriber(port, "plant-service", "camloop/#", true).await;
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://{}/var/camloop.db?mode=rwc\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n[mqtt]\nenabled = true\nport = {port}\n\
         [[machines]]\nname = \"SIM1\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share/SIM1\"\n\
         [machines.gauge]\nkind = \"sim\"\npart_interval_ms = 20\nseed = 3\n",
        dir.path().display(),
        recipe.display()
    );
    let config = Config::parse(&text, &dir.path().join("camloop.toml"), |_| None).unwrap();
    let mut running = service::start(config, RunOptions::parts(3)).await.unwrap();
    running.machines_done().await;
    let mut parts = Vec::new();
    let mut delivered = 0;
    while parts.len() < 3 {
        let (topic, payload, _) = next_live(&mut rx).await;
        match topic.as_str() {
            "camloop/SIM1/IN1/part_analysed" => {
                assert!(payload["max_profile_error_um"].as_f64().unwrap() > 0.0);
                parts.push(payload["part"].as_str().unwrap().to_owned());
            }
            "camloop/SIM1/IN1/table_delivered" => delivered += 1,
            _ => {}
        }
    }
    assert_eq!(parts.len(), 3, "{parts:?}");
    assert!(parts.windows(2).all(|w| w[0] != w[1]), "{parts:?}");
    assert!(
        delivered >= 1,
        "the first part's table was delivered before part 2"
    );
    running.stop().await;
    stop(b);
}
