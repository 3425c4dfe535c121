//! Cost of turning one 3 × 360-point raw lobe measurement into a report: assemble,
//! average and analyse (the gauge decode is measured elsewhere).

#[path = "../tests/common/cycloid_cam.rs"]
mod cycloid_cam;
use camloop::core::analysis::{LobeOptions, analyse_lobe};
use camloop::core::lift::{LiftCurve, LiftTable};
use camloop::core::measure::{
    AssemblyLimits, MeasurementHeader, RawMeasurement, RawSample, check_and_average,
};
use criterion::{Criterion, criterion_group, criterion_main};
use cycloid_cam::cam;
use std::hint::black_box;

fn raw_measurement() -> RawMeasurement {
    let mut state = 0x1234_5678_u64;
    let samples = (0..3u32)
        .flat_map(|r| (0..360u32).map(move |k| (r, k)))
        .map(|(r, k)| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise_mm = ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 1e-3;
            let psi = f64::from(k);
            RawSample {
                revolution: r,
                angle_index: k,
                lift_mm: cam(psi - 0.3).0
                    + 0.002
                    + 0.003 * (4.0 * psi).to_radians().sin()
                    + noise_mm,
            }
        })
        .collect();
    RawMeasurement {
        header: MeasurementHeader {
            machine: "m1".into(),
            part: "p1".into(),
            lobe: "in1".into(),
            revolutions: 3,
            points_per_rev: 360,
        },
        samples,
        origin: "bench".into(),
    }
}

fn bench(c: &mut Criterion) {
    let raw = raw_measurement();
    let limits = AssemblyLimits::default();
    let options = LobeOptions::default();
    c.bench_function("assemble+average 3x360", |b| {
        b.iter(|| check_and_average(black_box(&raw), &limits).expect("valid"))
    });
    let avg = check_and_average(&raw, &limits).expect("valid");
    c.bench_function("analyse_lobe 360", |b| {
        b.iter(|| analyse_lobe(black_box(&avg), &cam, &options).expect("analysable"))
    });
    c.bench_function("assemble+average+analyse 3x360", |b| {
        b.iter(|| {
            let avg = check_and_average(black_box(&raw), &limits).expect("valid");
            analyse_lobe(&avg, &cam, &options).expect("analysable")
        })
    });
}

/// The same, with the nominal from the real intake table through the periodic spline,
/// as the service wires it.
fn bench_spline(c: &mut Criterion) {
    let text = include_str!("../tests/fixtures/ecn-sandia-h2-intake.csv");
    let table = LiftTable::parse_csv(text, "intake").expect("fixture parses");
    let curve = LiftCurve::new(&table);
    let nominal = |psi_deg: f64| {
        let s = curve.eval(psi_deg.to_radians());
        (s.h_mm, s.dh_mm.to_radians())
    };
    let mut raw = raw_measurement();
    for s in &mut raw.samples {
        let psi = f64::from(s.angle_index);
        s.lift_mm += nominal(psi - 0.3).0 - cam(psi - 0.3).0;
    }
    let limits = AssemblyLimits::default();
    let options = LobeOptions::default();
    c.bench_function("assemble+average+analyse 3x360, spline nominal", |b| {
        b.iter(|| {
            let avg = check_and_average(black_box(&raw), &limits).expect("valid");
            analyse_lobe(&avg, &nominal, &options).expect("analysable")
        })
    });
}

criterion_group!(benches, bench, bench_spline);
criterion_main!(benches);
