//! A whole shaft through the service's machine: the eight measurements of the demo camshaft
//! (each lobe read in the shaft's frame, at its phase) in, eight guarded tables rendered,
//! durable on the share and recorded in SQLite (through each lobe's journal) out, at 360 and
//! 3600 points per revolution. Prints p50/p99 per shaft besides criterion's estimate.

#[path = "support/mod.rs"]
mod support;
use support::{
    machine_runtime, nominal_measurements, percentiles, scratch_root, start_machine, time_parts,
};

use camloop::core::measure::RawMeasurement;
use camloop::recipe::{FeatureSetup, Recipe};
use camloop::service::metrics::Metrics;
use criterion::{Criterion, criterion_group, criterion_main};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

fn recipe() -> (PathBuf, Recipe) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let recipe = Recipe::load(&path).expect("demo camshaft");
    (path, recipe)
}

/// One measurement of `setup` ground with its nominal table, in the shaft's frame.
fn measurement(setup: &FeatureSetup, points: u32, index: usize) -> RawMeasurement {
    let lobe = (index + 1).to_string();
    let mut raw = nominal_measurements(setup, points, &lobe, 1).remove(0);
    let shift = (setup.phase_deg / 360.0 * f64::from(points)).round() as u32;
    for s in &mut raw.samples {
        s.angle_index = (s.angle_index + shift) % points;
    }
    raw
}

fn shaft(c: &mut Criterion) {
    for points in [360u32, 3600] {
        shaft_case(c, points);
    }
}

fn shaft_case(c: &mut Criterion, points: u32) {
    let runtime = machine_runtime();
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
    let metrics = Arc::new(Metrics::default());
    let (_, _, mut machine) = start_machine(&runtime, dir.path(), setups, metrics);
    let name = format!("shaft_8_lobes_{points}_points_sqlite");
    let mut times = time_parts(c, &name, &runtime, &mut machine, |count| {
        // A new part number makes every measurement new.
        let part = format!("bench-{count}");
        raws.iter()
            .map(|raw| {
                let mut raw = raw.clone();
                raw.header.part.clone_from(&part);
                raw
            })
            .collect()
    });
    if times.parts.is_empty() {
        return;
    }
    println!(
        "{name}: {} shafts, {} per shaft (8 tables), {} cores",
        times.parts.len(),
        percentiles(&mut times.parts),
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(10));
    targets = shaft
}
criterion_main!(benches);
