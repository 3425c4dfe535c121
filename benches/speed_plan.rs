//! Cost of planning the demo intake lobe's finish revolution: sampling the exact geometry
//! every 0.05°, and the phase-plane passes with the 0.1° check of every limit.

use camloop::core::geometry::{CamGeometry, Follower, Part};
use camloop::core::lift::{LiftCurve, LiftTable};
use camloop::core::speed_plan::{self, ProfileSamples, SpeedLimits};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn intake() -> Part {
    let text = include_str!("../config/parts/demo-intake-lobe.csv");
    let table = LiftTable::parse_csv(text, "demo intake lobe").expect("the demo lift parses");
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    };
    Part::cam(geometry, LiftCurve::new(&table)).expect("the demo lobe is grindable")
}

fn bench(c: &mut Criterion) {
    let part = intake();
    let limits = SpeedLimits {
        x_velocity_mm_s: 200.0,
        x_acceleration_mm_s2: 10_000.0,
        x_jerk_mm_s3: 1e7,
        c_max_speed_rpm: 120.0,
        c_max_accel_deg_s2: 3600.0,
        q_w_max_mm3_mm_s: 2.36,
        stock_mm: 0.02,
    };
    let samples = ProfileSamples::new(&part).expect("samples");
    c.bench_function("speed plan: sample the intake lobe", |b| {
        b.iter(|| ProfileSamples::new(black_box(&part)))
    });
    c.bench_function("speed plan: plan and check the intake lobe", |b| {
        b.iter(|| speed_plan::plan_samples(black_box(&samples), black_box(&limits)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
