//! What the benches share: the demo cam; for the service benches the simulated measurements
//! they feed, where their database, journal and share live, the machine they feed, and the
//! timed loop over parts.

// Each bench includes this file and uses the part it needs.
#![allow(dead_code)]

use camloop::core::geometry::{CamGeometry, Follower, Part};
use camloop::core::lift::{LiftCurve, LiftTable};
use camloop::core::measure::RawMeasurement;
use camloop::recipe::{FeatureSetup, Recipe};
use camloop::service::machine::{MachineLoop, MachinePaths, SourceEvent, StoreHandle};
use camloop::service::metrics::Metrics;
use camloop::sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
use camloop::store::Store;
use criterion::Criterion;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The demo intake lobe (`config/parts/demo-intake-lobe.csv`) on its flat follower, 20 mm base
/// circle, 250 mm wheel: the geometry and the part.
pub fn demo_cam() -> (CamGeometry, Part) {
    let text = include_str!("../../config/parts/demo-intake-lobe.csv");
    let table = LiftTable::parse_csv(text, "demo-intake-lobe.csv").expect("shipped table is valid");
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    };
    let part = Part::cam(geometry, LiftCurve::new(&table)).expect("shipped part is grindable");
    (geometry, part)
}

/// The demo lobe's setup (IN1 of `config/parts/demo-lobe.toml`) at `points` per revolution.
pub fn demo_lobe(points: u32) -> FeatureSetup {
    let recipe_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let recipe = Recipe::load(&recipe_path).expect("demo recipe");
    let mut setup = recipe.feature_setup(&recipe_path, "IN1").expect("lobe");
    setup.request.points = points as usize;
    setup
}

/// Twenty simulated measurements of the demo lobe ground with its nominal table.
pub fn measurements(points: u32) -> Vec<RawMeasurement> {
    nominal_measurements(&demo_lobe(points), points, "1", 20)
}

/// `count` simulated measurements of the cam `setup` ground once with its nominal table, at
/// `points` per revolution, labelled lobe `lobe`, in the lobe's own frame.
pub fn nominal_measurements(
    setup: &FeatureSetup,
    points: u32,
    lobe: &str,
    count: usize,
) -> Vec<RawMeasurement> {
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
        lobe: lobe.into(),
    };
    (0..count).map(|_| sim.measure(&ground, &labels)).collect()
}

/// Where the database, journal and share live: `CAMLOOP_BENCH_DIR` when set (to measure a
/// real disk, whose fsyncs dominate), else memory-backed /dev/shm, which isolates camloop's
/// own cost from the disk's.
pub fn scratch_root() -> PathBuf {
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

/// "p50 …, p99 …, max …" in ms of a non-empty list of durations.
pub fn percentiles(samples: &mut [Duration]) -> String {
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

/// The single-thread runtime the machine task runs on, as in the service.
pub fn machine_runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime")
}

/// For [`time_parts`]: the `count`-th of `raws` in turn, numbered as a new part.
pub fn next_part(raws: &[RawMeasurement], count: usize) -> Vec<RawMeasurement> {
    let mut raw = raws[count % raws.len()].clone();
    raw.header.part = format!("bench-{count}");
    vec![raw]
}

/// Machine BENCH grinding `setups` on a fresh SQLite store in `dir` (share and state beside
/// it), as the service starts one; also the store and the handle the loop writes through.
pub fn start_machine(
    runtime: &tokio::runtime::Runtime,
    dir: &Path,
    setups: Vec<FeatureSetup>,
    metrics: Arc<Metrics>,
) -> (Store, StoreHandle, MachineLoop) {
    let url = format!("sqlite://{}/bench.db?mode=rwc", dir.display());
    let store = runtime.block_on(Store::connect(&url)).expect("store");
    let handle: StoreHandle = Arc::new(tokio::sync::RwLock::new(Some(store.clone())));
    let paths = MachinePaths {
        share_dir: dir.join("share"),
        state_dir: dir.join("state"),
    };
    let machine = runtime
        .block_on(MachineLoop::start(
            "BENCH".parse().expect("a machine name"),
            setups,
            paths,
            handle.clone(),
            metrics,
        ))
        .expect("machine");
    (store, handle, machine)
}

/// The times [`time_parts`] took: each iteration's measurements, and the step between parts.
#[derive(Debug, Default)]
pub struct PartTimes {
    /// Handling the iteration's measurements: checks to rows committed.
    pub parts: Vec<Duration>,
    /// The machine's between-parts step (`retry`: journal release and checkpoint), which the
    /// service runs every 2 s between parts, outside the path.
    pub between: Vec<Duration>,
}

impl PartTimes {
    /// Prints "NAME: N parts, p50 …, p99 …, max …"; false when criterion collected nothing
    /// (`--profile-time` runs without samples).
    pub fn print_parts(&mut self, name: &str) -> bool {
        if self.parts.is_empty() {
            return false;
        }
        let n = self.parts.len();
        println!("{name}: {n} parts, {}", percentiles(&mut self.parts));
        true
    }
}

/// Criterion's bench `name` of the machine's per-part path: each iteration hands `machine`
/// the measurements `next(i)` makes (`i` counts from 0, so a part number from it is new:
/// identity is the content, and a repeat would be skipped, not processed), timing their
/// handling; the between-parts step follows, timed apart.
pub fn time_parts(
    c: &mut Criterion,
    name: &str,
    runtime: &tokio::runtime::Runtime,
    machine: &mut MachineLoop,
    mut next: impl FnMut(usize) -> Vec<RawMeasurement>,
) -> PartTimes {
    let mut times = PartTimes::default();
    let mut count = 0usize;
    c.bench_function(name, |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let raws = next(count);
                count += 1;
                let started = Instant::now();
                for raw in raws {
                    runtime.block_on(machine.handle(SourceEvent::Measurement {
                        raw,
                        ground_with: None,
                        done: None,
                    }));
                }
                let took = started.elapsed();
                times.parts.push(took);
                total += took;
                let started = Instant::now();
                runtime.block_on(machine.retry());
                times.between.push(started.elapsed());
            }
            total
        })
    });
    times
}
