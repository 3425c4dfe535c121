//! Simulator speed: grinding one demo lobe from a 360-point table (G1 and POLY) on the
//! default machine, and grinding plus a default 4 × 360 gauge measurement.

#[path = "support/mod.rs"]
mod support;
use support::demo_cam;

use camloop::core::fit::TableForm;
use camloop::sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn benches(c: &mut Criterion) {
    let (geometry, part) = demo_cam();
    let labels = PartLabels::default();
    let mut sim = SimGrinder::new(GrinderConfig::default(), Workpiece::Cam(geometry), 1)
        .expect("default settings are valid");
    for (name, form) in [("g1", TableForm::G1), ("poly", TableForm::Poly)] {
        let table = CommandedTable::nominal(&part, 360, form).expect("nominal table");
        c.bench_function(&format!("grind_{name}_360"), |b| {
            b.iter(|| sim.grind(black_box(&table)).expect("grind"))
        });
        c.bench_function(&format!("grind_and_measure_{name}_360"), |b| {
            b.iter(|| {
                let ground = sim.grind(black_box(&table)).expect("grind");
                sim.measure(&ground, &labels)
            })
        });
    }
}

criterion_group!(sim, benches);
criterion_main!(sim);
