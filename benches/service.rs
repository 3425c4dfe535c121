//! The whole per-part path of the service: measurement complete → checks, analysis,
//! learning, guarded table → program durable on the share → rows committed to SQLite (through
//! the journal), at 360 and 3600 points per revolution. Prints p50/p99 besides criterion's
//! estimate, since the target is on the 99th percentile.
//!
//! Every 2 s, between parts (a machine makes one every ~10 s), the service's machine task
//! retries what waits and releases from the journal what the database holds durably, which on
//! SQLite is a checkpoint of its write-ahead log. The bench runs that same step after every
//! part, outside the timed region, and reports its time separately.
//!
//! The 360-point case runs a second time with 200 history readers on the same store, to show
//! that reads do not hold up the part path (the store's separate writer pool and bounded
//! reads). The core count is printed with it: the readers compete with the loop for cores.

#[path = "support/mod.rs"]
mod support;
use support::{
    demo_lobe, machine_runtime, measurements, next_part, percentiles, scratch_root, start_machine,
    time_parts,
};

use camloop::service::metrics::Metrics;
use camloop::store::{EventFilter, HistoryFilter, Store};
use criterion::{Criterion, criterion_group, criterion_main};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// History readers hammering the store while parts are made, as 200 HTTP clients on the
/// database-backed routes do: each loops over a page of the machine's measurements and of its
/// events. They run on their own two-thread runtime, as the service's HTTP tasks run beside
/// the machine tasks. Dropping it stops them.
struct Readers {
    runtime: tokio::runtime::Runtime,
    served: Arc<std::sync::atomic::AtomicU64>,
    refused: Arc<std::sync::atomic::AtomicU64>,
}

impl Readers {
    fn start(store: &Store, clients: usize) -> Self {
        use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .expect("reader runtime");
        let served = Arc::new(AtomicU64::new(0));
        let refused = Arc::new(AtomicU64::new(0));
        for i in 0..clients {
            let (store, served, refused) = (store.clone(), served.clone(), refused.clone());
            runtime.spawn(async move {
                let history = HistoryFilter::new("BENCH".parse().unwrap(), 100);
                let events = EventFilter {
                    machine: Some("BENCH".parse().unwrap()),
                    limit: 100,
                    ..EventFilter::default()
                };
                loop {
                    let ok = if i % 2 == 0 {
                        store.measurement_history(&history).await.is_ok()
                    } else {
                        store.events(&events).await.is_ok()
                    };
                    let counter = if ok { &served } else { &refused };
                    counter.fetch_add(1, Relaxed);
                    tokio::task::yield_now().await;
                }
            });
        }
        Readers {
            runtime,
            served,
            refused,
        }
    }
}

fn per_part(c: &mut Criterion) {
    for (points, readers) in [(360u32, 0usize), (360, 200), (3600, 0)] {
        per_part_case(c, points, readers);
    }
}

fn per_part_case(c: &mut Criterion, points: u32, clients: usize) {
    let runtime = machine_runtime();
    let dir = tempfile::tempdir_in(scratch_root()).expect("temp dir");
    let metrics = Arc::new(Metrics::default());
    let (store, _, mut machine) =
        start_machine(&runtime, dir.path(), vec![demo_lobe(points)], metrics);
    let readers = (clients > 0).then(|| Readers::start(&store, clients));
    let raws = measurements(points);
    let name = match clients {
        0 => format!("per_part_path_{points}_points_sqlite"),
        n => format!("per_part_path_{points}_points_sqlite_{n}_readers"),
    };
    let reads_before = readers
        .as_ref()
        .map(|r| r.served.load(std::sync::atomic::Ordering::Relaxed));
    let started_all = Instant::now();
    let mut times = time_parts(c, &name, &runtime, &mut machine, |count| {
        next_part(&raws, count)
    });
    if !times.print_parts(&name) {
        return;
    }
    println!(
        "  journal release and checkpoint between parts (not in the path): {}",
        percentiles(&mut times.between)
    );
    if let (Some(r), Some(before)) = (&readers, reads_before) {
        use std::sync::atomic::Ordering::Relaxed;
        let secs = started_all.elapsed().as_secs_f64();
        println!(
            "  readers: {clients} clients, {:.0} reads/s served, {} refused busy, {} cores",
            (r.served.load(Relaxed) - before) as f64 / secs,
            r.refused.load(Relaxed),
            std::thread::available_parallelism().map_or(0, |n| n.get())
        );
    }
    if let Some(r) = readers {
        r.runtime.shutdown_background();
    }
}

criterion_group! {
    name = service;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(8));
    targets = per_part
}
criterion_main!(service);
