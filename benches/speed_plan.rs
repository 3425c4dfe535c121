//! Cost of planning the demo intake lobe's finish revolution: sampling the exact geometry
//! every 0.05°, and the phase-plane passes with the 0.1° check of every limit.

#[path = "support/mod.rs"]
mod support;
use support::demo_cam;

use camloop::core::speed_plan::{self, ProfileSamples, SpeedLimits};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let (_, part) = demo_cam();
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
