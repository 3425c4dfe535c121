//! The per-part path of the service with the OPC UA server publishing, against the same path
//! without it: measurement complete → checks, analysis, learning, guarded table → program
//! durable on the share → rows committed to SQLite, at 360 points per revolution (as
//! `benches/service.rs`), printing p50/p99.
//!
//! With OPC UA, the server carries 50 machines × 8 features plus the timed machine, whose
//! events it gets as in the service (the loop's `try_send`). A driver makes every one of the
//! 50 machines measure a shaft (8 features) every second, updating the feature status and
//! sending the events, as 50 real machines would every 10 s or so: ten times the load. 20
//! anonymous clients with Basic256Sha256 SignAndEncrypt sessions each subscribe to every
//! value of every feature (publishing every 100 ms). Server, driver and clients run on their
//! own two-thread runtime, as the service's tasks run beside the machine task; the loop is
//! timed on the bench thread. The core count is printed: they all compete for the cores.

#[path = "../tests/opcua_support/mod.rs"]
mod opcua_support;
#[path = "support/mod.rs"]
mod support;
use opcua_support::{connect_with, free_port, namespace, plant, value_nodes};
use support::{
    demo_lobe, machine_runtime, measurements, next_part, scratch_root, start_machine, time_parts,
};

use camloop::names::{FeatureName, MachineName};
use camloop::service::machine::StoreHandle;
use camloop::service::metrics::Metrics;
use camloop::store::Verdict;
use camloop_loop::PlantEvent;
use criterion::{Criterion, criterion_group, criterion_main};
use opcua::client::{ClientBuilder, DataChangeCallback};
use opcua::types::{MonitoredItemCreateRequest, TimestampsToReturn};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

const MACHINES: usize = 50;
const FEATURES: usize = 8;
const CLIENTS: usize = 20;

/// The plant of 50 × 8 and the timed machine.
fn names() -> Vec<(MachineName, Vec<FeatureName>)> {
    let mut machines = plant(MACHINES, FEATURES);
    let bench = "BENCH".parse().expect("a bench name");
    machines.push((bench, vec!["IN1".parse().expect("a bench name")]));
    machines
}

/// The OPC UA side: server, driver and clients on their own runtime. Dropping it stops them.
struct Publishing {
    runtime: tokio::runtime::Runtime,
    shutdown: tokio::sync::watch::Sender<bool>,
    notifications: Arc<AtomicU64>,
    events_sent: Arc<AtomicU64>,
}

impl Publishing {
    fn start(
        dir: &Path,
        store: StoreHandle,
        metrics: Arc<Metrics>,
    ) -> (Self, camloop::service::plant::EventSender) {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .expect("OPC UA runtime");
        let (shutdown, watch) = tokio::sync::watch::channel(false);
        let port = free_port();
        let listen = std::net::SocketAddr::from(([127, 0, 0, 1], port));
        let pki = dir.join("pki");
        let sender = runtime
            .block_on(camloop::service::opcua_port::bench_server(
                listen,
                &pki,
                names(),
                metrics.clone(),
                store,
                watch,
            ))
            .expect("OPC UA server");
        let notifications = Arc::new(AtomicU64::new(0));
        let events_sent = Arc::new(AtomicU64::new(0));
        runtime.spawn(drive(sender.clone(), metrics, events_sent.clone()));
        let url = format!("opc.tcp://localhost:{port}/");
        let ready = Arc::new(AtomicU64::new(0));
        for i in 0..CLIENTS {
            let client_dir = dir.join(format!("client-{i}"));
            runtime.spawn(subscriber(
                url.clone(),
                client_dir,
                notifications.clone(),
                ready.clone(),
            ));
        }
        let started = Instant::now();
        while ready.load(Relaxed) < CLIENTS as u64 {
            assert!(
                started.elapsed() < Duration::from_secs(300),
                "clients not subscribed in 300 s"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        let publishing = Publishing {
            runtime,
            shutdown,
            notifications,
            events_sent,
        };
        (publishing, sender)
    }
}

/// 50 machines measuring a shaft each per second, round the clock: status and events.
async fn drive(
    sender: camloop::service::plant::EventSender,
    metrics: Arc<Metrics>,
    sent: Arc<AtomicU64>,
) {
    let mut tick = tokio::time::interval(Duration::from_millis(1000 / MACHINES as u64));
    let mut part = 0u64;
    loop {
        tick.tick().await;
        part += 1;
        let machine: MachineName = format!("M{:02}", part % MACHINES as u64)
            .parse()
            .expect("a bench name");
        for f in 1..=FEATURES {
            let feature: FeatureName = format!("F{f}").parse().expect("a bench name");
            let error_um = (part % 7) as f64 * 0.1;
            metrics_update(&metrics, &machine, &feature, part, error_um);
            sender.send(PlantEvent::PartAnalysed {
                machine: machine.clone(),
                feature: feature.clone(),
                part: format!("S-{part}").parse().expect("a part id"),
                at: camloop::clock::now(),
                verdict: Verdict::Pass,
                max_profile_error_um: error_um,
                base_radius_error_um: 0.1,
                phase_error_deg: 0.001,
                ground_with_version: camloop::core::ids::TableVersion::new(part),
                repeatability_um: Some(0.3),
            });
            sent.fetch_add(1, Relaxed);
        }
    }
}

fn metrics_update(
    metrics: &Metrics,
    machine: &MachineName,
    feature: &FeatureName,
    part: u64,
    error_um: f64,
) {
    metrics.update_feature(machine, feature, |f| {
        f.parts += 1;
        f.last_part = Some(format!("S-{part}").parse().expect("a part id"));
        f.last_max_error_um = Some(error_um);
        f.last_profile_error_um = Some(error_um);
        f.in_force_version = camloop::core::ids::TableVersion::new(part);
    });
}

/// One client: a SignAndEncrypt session, one subscription to every value of every feature.
async fn subscriber(
    url: String,
    dir: PathBuf,
    notifications: Arc<AtomicU64>,
    ready: Arc<AtomicU64>,
) {
    let session = connect_with(&url, dir, ClientBuilder::new()).await;
    let ns = namespace(&session).await;
    let counter = notifications.clone();
    let subscription = session
        .create_subscription(
            Duration::from_millis(100),
            100,
            10,
            // At most 500 values a reply: the default client decodes messages up to 64 KiB
            // in a few chunks, and a reply with every changed value outgrows it.
            500,
            0,
            true,
            DataChangeCallback::new(move |_, _| {
                counter.fetch_add(1, Relaxed);
            }),
        )
        .await
        .expect("subscription");
    let items: Vec<MonitoredItemCreateRequest> = value_nodes(ns, &names())
        .into_iter()
        .map(Into::into)
        .collect();
    // Small calls: a reply for 1000 items outgrows the default message size.
    for chunk in items.chunks(100) {
        session
            .create_monitored_items(subscription, TimestampsToReturn::Both, chunk.to_vec())
            .await
            .expect("monitored items");
    }
    ready.fetch_add(1, Relaxed);
    std::future::pending::<()>().await;
}

fn per_part(c: &mut Criterion) {
    for publishing in [false, true] {
        per_part_case(c, publishing);
    }
}

fn per_part_case(c: &mut Criterion, publishing: bool) {
    let runtime = machine_runtime();
    let dir = tempfile::tempdir_in(scratch_root()).expect("temp dir");
    let metrics = Arc::new(Metrics::default());
    let (_, handle, mut machine) =
        start_machine(&runtime, dir.path(), vec![demo_lobe(360)], metrics.clone());
    let side = publishing.then(|| {
        let (side, sender) = Publishing::start(dir.path(), handle.clone(), metrics.clone());
        machine.set_plant_events(Some(sender));
        side
    });
    let raws = measurements(360);
    let name = match publishing {
        false => "per_part_path_360_points_sqlite_no_opcua".to_string(),
        true => {
            format!("per_part_path_360_points_sqlite_opcua_{MACHINES}x{FEATURES}_{CLIENTS}_clients")
        }
    };
    let before = side
        .as_ref()
        .map(|s| (s.notifications.load(Relaxed), s.events_sent.load(Relaxed)));
    let started_all = Instant::now();
    let mut times = time_parts(c, &name, &runtime, &mut machine, |count| {
        next_part(&raws, count)
    });
    if !times.print_parts(&name) {
        return;
    }
    if let Some(s) = side {
        s.report(before, started_all.elapsed());
    }
}

impl Publishing {
    /// What the OPC UA side did while parts were timed, then stops it.
    fn report(self, before: Option<(u64, u64)>, took: Duration) {
        let (n0, e0) = before.unwrap_or_default();
        let secs = took.as_secs_f64();
        println!(
            "  OPC UA: {CLIENTS} clients got {:.0} value notifications/s in all; {:.0} part events/s fed; {} cores",
            (self.notifications.load(Relaxed) - n0) as f64 / secs,
            (self.events_sent.load(Relaxed) - e0) as f64 / secs,
            std::thread::available_parallelism().map_or(0, |n| n.get())
        );
        let _ = self.shutdown.send(true);
        self.runtime.shutdown_timeout(Duration::from_secs(5));
    }
}

criterion_group! {
    name = opcua_bench;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(8));
    targets = per_part
}
criterion_main!(opcua_bench);
