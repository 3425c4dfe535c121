//! Gauge decoding speed: raw frame decoding (id + payload → GaugeFrame), decode + assemble
//! of a 3 × 360 measurement, candump log replay, and the inverse: encoding a 3 × 360
//! measurement into its 1082 frames. Target: ≥ 5 million frames/s on one core for raw
//! decoding.

use std::hint::black_box;
use std::path::PathBuf;

use camloop::gauge::candump::parse_candump_line;
use camloop::gauge::{Assembler, CanId, GaugeDbc, encode_measurement, read_candump_measurements};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

fn fixture_log() -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/gauge_3x360.log");
    std::fs::read_to_string(&path).expect("fixture written by tools/encode_candump.py")
}

/// The 1082 frames of the fixture (start, 1080 samples, end) as (id, 8-byte buffer, len).
fn frames(log: &str) -> Vec<(CanId, [u8; 8], usize)> {
    log.lines()
        .map(|line| {
            let r = parse_candump_line(line).expect("fixture line");
            let mut data = [0u8; 8];
            data[..r.data().len()].copy_from_slice(r.data());
            (r.id, data, r.data().len())
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let dbc = GaugeDbc::builtin();
    let log = fixture_log();
    let frames = frames(&log);

    let mut group = c.benchmark_group("gauge_decode");
    group.throughput(Throughput::Elements(frames.len() as u64));
    group.bench_function("decode_frames_3x360", |b| {
        b.iter(|| {
            let mut ok = 0usize;
            for (id, data, len) in &frames {
                ok += usize::from(dbc.decode(black_box(*id), black_box(&data[..*len])).is_ok());
            }
            ok
        });
    });
    group.bench_function("decode_and_assemble_3x360", |b| {
        b.iter(|| {
            let mut assembler = Assembler::new("bench");
            let mut out = None;
            for (id, data, len) in &frames {
                let frame = dbc.decode(black_box(*id), black_box(&data[..*len]));
                if let Ok(frame) = frame
                    && let Some(done) = assembler.push(frame)
                {
                    out = Some(done);
                }
            }
            out
        });
    });
    group.bench_function("candump_replay_3x360", |b| {
        b.iter(|| read_candump_measurements(black_box(&log), &dbc, "bench"));
    });
    let measurement = read_candump_measurements(&log, &dbc, "bench")
        .measurements
        .pop()
        .expect("the fixture holds one measurement");
    group.bench_function("encode_measurement_3x360", |b| {
        b.iter(|| encode_measurement(&dbc, black_box(&measurement), 0).map(|f| f.len()));
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
