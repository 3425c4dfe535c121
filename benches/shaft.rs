//! A whole shaft through the service's machine: the eight measurements of the demo camshaft
//! (each lobe read in the shaft's frame, at its phase) in, eight guarded tables rendered,
//! durable on the share and recorded in SQLite (through each lobe's journal) out, at 360 and
//! 3600 points per revolution. Prints p50/p99 per shaft besides criterion's estimate.

use camloop::core::measure::RawMeasurement;
use camloop::recipe::{FeatureSetup, Recipe};
use camloop::service::machine::{MachineLoop, MachinePaths, SourceEvent, StoreHandle};
use camloop::service::metrics::Metrics;
use camloop::sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
use camloop::store::Store;
use criterion::{Criterion, criterion_group, criterion_main};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn recipe() -> (PathBuf, Recipe) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let recipe = Recipe::load(&path).expect("demo camshaft");
    (path, recipe)
}

/// One measurement of `setup` ground with its nominal table, in the shaft's frame.
fn measurement(setup: &FeatureSetup, points: u32, index: usize) -> RawMeasurement {
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
        lobe: (index + 1).to_string(),
    };
    let mut raw = sim.measure(&ground, &labels);
    let shift = (setup.phase_deg / 360.0 * f64::from(points)).round() as u32;
    for s in &mut raw.samples {
        s.angle_index = (s.angle_index + shift) % points;
    }
    raw
}

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

fn shaft(c: &mut Criterion) {
    for points in [360u32, 3600] {
        shaft_case(c, points);
    }
}

fn shaft_case(c: &mut Criterion, points: u32) {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let dir = tempfile::tempdir_in(scratch_root()).expect("temp dir");
    let (path, recipe) = recipe();
    let mut setups = recipe.feature_setups(&path).expect("lobes");
    for s in &mut setups {
        s.request.points = points as usize;
    }
    let raws: Vec<RawMeasurement> = setups
        .iter()
        .enumerate()
        .map(|(k, s)| measurement(s, points, k))
        .collect();
    let url = format!("sqlite://{}/bench.db?mode=rwc", dir.path().display());
    let store = runtime.block_on(Store::connect(&url)).expect("store");
    let mut machine = runtime.block_on(async {
        let handle: StoreHandle = Arc::new(tokio::sync::RwLock::new(Some(store)));
        MachineLoop::start(
            "BENCH".parse().unwrap(),
            setups,
            MachinePaths {
                share_dir: dir.path().join("share"),
                state_dir: dir.path().join("state"),
            },
            handle,
            Arc::new(Metrics::default()),
        )
        .await
        .expect("machine")
    });
    let mut count = 0usize;
    let mut samples: Vec<Duration> = Vec::new();
    let name = format!("shaft_8_lobes_{points}_points_sqlite");
    c.bench_function(&name, |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                count += 1;
                let started = Instant::now();
                for raw in &raws {
                    let mut raw = raw.clone();
                    // A new part number makes every measurement new.
                    raw.header.part = count.to_string();
                    runtime.block_on(machine.handle(SourceEvent::Measurement {
                        raw,
                        ground_with: None,
                        done: None,
                    }));
                }
                let took = started.elapsed();
                samples.push(took);
                total += took;
                runtime.block_on(machine.retry());
            }
            total
        })
    });
    if samples.is_empty() {
        return;
    }
    samples.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let pct = |p: f64| ms(samples[((samples.len() as f64 - 1.0) * p).round() as usize]);
    println!(
        "{name}: {} shafts, p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms per shaft (8 tables), {} cores",
        samples.len(),
        pct(0.5),
        pct(0.99),
        samples.last().map_or(0.0, |&d| ms(d)),
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(10));
    targets = shaft
}
criterion_main!(benches);
