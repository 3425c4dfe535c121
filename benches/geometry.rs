//! Table generation speed: a 3600-point flat-follower table from a 1° lift table, and the
//! POLY fit of a 360-point table (with and without the deviation check against the exact path).

#[path = "support/mod.rs"]
mod support;
use support::demo_cam;

use camloop::core::fit;
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn benches(c: &mut Criterion) {
    let (_, part) = demo_cam();
    c.bench_function("flat_table_3600_points", |b| {
        b.iter(|| part.wheel_table(black_box(3600)).expect("table"))
    });
    let points = part.wheel_table(360).expect("table");
    c.bench_function("poly_fit_360_points", |b| {
        b.iter(|| fit::fit_poly(black_box(&points)))
    });
    c.bench_function("poly_fit_360_points_checked_to_0.1um", |b| {
        b.iter(|| fit::fit_poly_within(&part, black_box(&points), 0.1).expect("fit"))
    });
}

criterion_group!(geometry, benches);
criterion_main!(geometry);
