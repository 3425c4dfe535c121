//! What the service benches share: the simulated measurements they feed and where their
//! database, journal and share live.

use camloop::core::measure::RawMeasurement;
use camloop::recipe::Recipe;
use camloop::sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Twenty simulated measurements of the demo lobe ground with its nominal table.
pub fn measurements(points: u32) -> Vec<RawMeasurement> {
    let recipe_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
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
