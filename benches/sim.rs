//! Simulator speed: grinding one demo lobe from a 360-point table (G1 and POLY) on the
//! default machine, and grinding plus a default 4 × 360 gauge measurement.

use camloop::core::fit::TableForm;
use camloop::core::geometry::{CamGeometry, Follower, Part};
use camloop::core::lift::{LiftCurve, LiftTable};
use camloop::sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn demo() -> (CamGeometry, Part) {
    let text = include_str!("../config/parts/demo-intake-lobe.csv");
    let table = LiftTable::parse_csv(text, "demo-intake-lobe.csv").expect("shipped table is valid");
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    };
    let part = Part::cam(geometry, LiftCurve::new(&table)).expect("shipped part is grindable");
    (geometry, part)
}

fn benches(c: &mut Criterion) {
    let (geometry, part) = demo();
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
