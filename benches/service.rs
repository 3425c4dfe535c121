//! The whole per-part path of the service: measurement complete → checks, analysis,
//! learning, guarded table → program durable on the share → rows committed to SQLite (through
//! the journal), at 360 and 3600 points per revolution. Prints p50/p99 besides criterion's
//! estimate, since the target is on the 99th percentile.
//!
//! Every 2 s, between parts (a machine makes one every ~10 s), the service's machine task
//! retries what waits and releases from the journal what the database holds durably, which on
//! SQLite is a checkpoint of its write-ahead log. The bench runs that same step after every
//! part, outside the timed region, and reports its time separately.

use camloop::core::measure::RawMeasurement;
use camloop::recipe::Recipe;
use camloop::service::machine::{MachineLoop, MachinePaths, SourceEvent, StoreHandle};
use camloop::service::metrics::Metrics;
use camloop::sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
use camloop::store::Store;
use criterion::{Criterion, criterion_group, criterion_main};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Twenty simulated measurements of the demo lobe ground with its nominal table.
fn measurements(points: u32) -> Vec<RawMeasurement> {
    let recipe_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let recipe = Recipe::load(&recipe_path).expect("demo recipe");
    let setup = recipe.feature_setup(&recipe_path, "IN1").expect("lobe");
    let camloop::core::compensate::Feature::Cam(g) = setup.feature else {
        panic!("a cam")
    };
    let mut config = GrinderConfig::default();
    config.gauge.points_per_rev = points;
    let mut sim = SimGrinder::new(config, Workpiece::Cam(g), 9).expect("sim");
    let part = setup.feature.part(&setup.nominal).expect("part");
    let table =
        CommandedTable::nominal(&part, 360, camloop::core::fit::TableForm::Poly).expect("table");
    let ground = sim.grind(&table).expect("ground");
    let labels = PartLabels {
        machine: "1".into(),
        part: "1".into(),
        lobe: "1".into(),
    };
    (0..20).map(|_| sim.measure(&ground, &labels)).collect()
}

/// Where the database, journal and share live: `CAMLOOP_BENCH_DIR` when set (to measure a
/// real disk, whose fsyncs dominate), else memory-backed /dev/shm, which isolates camloop's
/// own cost from the disk's.
fn scratch_root() -> PathBuf {
    if let Some(dir) = std::env::var_os("CAMLOOP_BENCH_DIR") {
        return PathBuf::from(dir);
    }
    let shm = Path::new("/dev/shm");
    if shm.is_dir() {
        shm.to_path_buf()
    } else {
        PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
    }
}

fn per_part(c: &mut Criterion) {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    for points in [360u32, 3600] {
        let dir = tempfile::tempdir_in(scratch_root()).expect("temp dir");
        let recipe_path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
        let recipe = Recipe::load(&recipe_path).expect("demo recipe");
        let mut setup = recipe.feature_setup(&recipe_path, "IN1").expect("lobe");
        setup.request.points = points as usize;
        let url = format!("sqlite://{}/bench.db?mode=rwc", dir.path().display());
        let mut machine = runtime.block_on(async {
            let store: StoreHandle = Arc::new(tokio::sync::RwLock::new(Some(
                Store::connect(&url).await.expect("store"),
            )));
            MachineLoop::start(
                "BENCH".into(),
                setup,
                MachinePaths {
                    share_dir: dir.path().join("share"),
                    state_dir: dir.path().join("state"),
                },
                store,
                Arc::new(Metrics::default()),
            )
            .await
            .expect("machine")
        });
        let raws = measurements(points);
        let mut count = 0usize;
        let mut samples: Vec<Duration> = Vec::new();
        let mut between: Vec<Duration> = Vec::new();
        c.bench_function(&format!("per_part_path_{points}_points_sqlite"), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let mut raw = raws[count % raws.len()].clone();
                    // A new part number makes every measurement new (identity is the content,
                    // so a repeat would be skipped, not processed).
                    raw.header.part = format!("bench-{count}");
                    count += 1;
                    let started = Instant::now();
                    runtime.block_on(machine.handle(SourceEvent::Measurement {
                        raw,
                        ground_with: None,
                        done: None,
                    }));
                    let took = started.elapsed();
                    samples.push(took);
                    total += took;
                    let started = Instant::now();
                    runtime.block_on(machine.retry());
                    between.push(started.elapsed());
                }
                total
            })
        });
        if samples.is_empty() {
            // `--profile-time` runs without collecting samples.
            continue;
        }
        if samples.is_empty() {
            // `--profile-time` runs without collecting samples.
            continue;
        }
        println!(
            "per_part_path_{points}_points_sqlite: {} parts, {}",
            samples.len(),
            percentiles(&mut samples)
        );
        println!(
            "  journal release and checkpoint between parts (not in the path): {}",
            percentiles(&mut between)
        );
    }
}

/// "p50 …, p99 …, max …" in ms of a non-empty list of durations.
fn percentiles(samples: &mut [Duration]) -> String {
    samples.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let pct = |p: f64| ms(samples[((samples.len() as f64 - 1.0) * p).round() as usize]);
    format!(
        "p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        pct(0.5),
        pct(0.99),
        samples.last().map_or(0.0, |&d| ms(d))
    )
}

criterion_group! {
    name = service;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(8));
    targets = per_part
}
criterion_main!(service);
