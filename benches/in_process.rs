//! Measure before the finish, camloop's side: from the in-process measurement received (a
//! raw 4 × 360 reading with 20 µm of stock on) to this part's finish table durable on the
//! share. Two paths:
//! - `in_process_finish_table_to_share`: the core's step and one share push (the checks and
//!   analysis, the same-part step and its guards, the POLY table, its program, the table
//!   program and the handshake's count written after it, fsync, rename, read back);
//! - `in_process_through_the_machine`: the service's whole path, `MachineLoop::on_in_process`
//!   on a machine started as the service starts one (whole-cycle recipe, SQLite store,
//!   journal and share on disk under the target folder): routing, the loop's decision, the
//!   journal's write-ahead records (fsync), rendering, the push and the count.
//!
//! The bound: p99 under 100 ms on 2 cores; the bench prints the percentiles of 200
//! timed runs of each besides criterion's figures.

#[path = "support/mod.rs"]
mod support;

use camloop::core::cycle::finish::{InProcess, finish_table};
use camloop::core::learn::LearningState;
use camloop::core::program::{ProgramSettings, READY_PROGRAM, render_ready_program};
use camloop::share::{ProgramFile, PushRequest, RealFs, Share, ShareConfig};
use camloop::sim::{
    CommandedTable, GrinderConfig, PartLabels, SimGrinder, StationErrors, Workpiece,
};
use criterion::{Criterion, criterion_group, criterion_main};
use std::time::Instant;

fn benches(c: &mut Criterion) {
    let setup = support::demo_lobe(360);
    let camloop::core::compensate::Feature::Cam(g) = setup.feature else {
        panic!("a cam")
    };
    let part = setup.feature.part(&setup.nominal).expect("demo part");
    let table =
        CommandedTable::nominal(&part, 360, camloop::core::fit::TableForm::Poly).expect("table");
    let mut sim = SimGrinder::new(GrinderConfig::default(), Workpiece::Cam(g), 1).expect("sim");
    let stock = StationErrors {
        size_um: 20.0,
        ..StationErrors::default()
    };
    let ground = sim
        .grind_station(&table, &Workpiece::Cam(g), &stock)
        .expect("ground");
    let labels = PartLabels {
        machine: "M1".into(),
        part: "17".into(),
        lobe: "IN1".into(),
    };
    let raw = sim.measure(&ground, &labels);
    let in_force = LearningState::new(360);
    let turn_setup = setup.turn_setup();
    let root = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).expect("temporary folder");
    let share_dir = root.path().join("share");
    std::fs::create_dir(&share_dir).expect("share folder");
    let config = ShareConfig {
        share_dir,
        state_dir: root.path().join("state"),
        table_pair: (1, 2),
        keep_versions: 10,
    };
    let (mut share, _) = Share::open(
        config,
        Box::new(RealFs),
        Box::new(|| jiff::Timestamp::UNIX_EPOCH),
    )
    .expect("open the state folder");
    let mut ready = 0u64;
    let mut once = || {
        let input = InProcess {
            setup: &turn_setup,
            in_force: &in_force,
            raw: &raw,
            part: "17",
            remaining_stock_mm: 0.02,
            gain: 0.97,
        };
        let finish = finish_table(&input, "IN1").expect("a finish table");
        let number = share.next_table_number();
        let settings = ProgramSettings {
            table_number: number,
            ..setup.program.clone()
        };
        let text = finish.table.render(&settings).expect("program");
        ready += 1;
        let request = PushRequest {
            files: vec![
                ProgramFile {
                    name: format!("{}.SPF", setup.program.name),
                    text,
                },
                ProgramFile {
                    name: format!("{READY_PROGRAM}.SPF"),
                    text: render_ready_program(ready),
                },
            ],
            table_number: number,
            reason: "same-part finish table".into(),
            measurement_id: None,
            learning: serde_json::Value::Null,
            rollback_of: None,
            created_at: jiff::Timestamp::UNIX_EPOCH,
        };
        share.push_once(request).expect("push")
    };
    let mut ms: Vec<f64> = (0..200)
        .map(|_| {
            let t = Instant::now();
            once();
            t.elapsed().as_secs_f64() * 1000.0
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    eprintln!(
        "measurement to finish table on the share: median {:.1} ms, p99 {:.1} ms, max {:.1} ms (200 runs)",
        ms[100], ms[197], ms[199]
    );
    c.bench_function("in_process_finish_table_to_share", |b| b.iter(&mut once));
}

/// The service's path: each run a new part's in-process measurement, timed from its receipt
/// to `on_in_process` returning with the table and the count on the share.
fn through_the_machine(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config/parts/demo-lobe-in-process.toml");
    let recipe = camloop::recipe::Recipe::load(&path).expect("the in-process recipe");
    let setup = recipe.feature_setup(&path, "IN1").expect("feature IN1");
    let camloop::core::compensate::Feature::Cam(g) = setup.feature else {
        panic!("a cam")
    };
    let part = setup.feature.part(&setup.nominal).expect("demo part");
    let table =
        CommandedTable::nominal(&part, 360, camloop::core::fit::TableForm::Poly).expect("table");
    // A converged machine: the grinder's own errors off, so each reading shows the stock
    // and the gauge's noise, as a part ground with a converged correction does. (A reading
    // of the first part's 16 µm would move the correction again at every run, since the
    // bench grinds no finish, until the timing limit refuses it.)
    let perfect = GrinderConfig {
        servo_lag_ms: 0.0,
        harmonics: Vec::new(),
        wheel_size_error_um: 0.0,
        ..GrinderConfig::default()
    };
    let mut sim = SimGrinder::new(perfect, Workpiece::Cam(g), 1).expect("sim");
    let stock = StationErrors {
        size_um: 20.0,
        ..StationErrors::default()
    };
    let ground = sim
        .grind_station(&table, &Workpiece::Cam(g), &stock)
        .expect("ground");
    // Readings of the same part with the gauge's own noise; each run names a new part.
    let raws: Vec<_> = (0..8)
        .map(|_| {
            sim.measure(
                &ground,
                &PartLabels {
                    machine: "BENCH".into(),
                    part: "0".into(),
                    lobe: "IN1".into(),
                },
            )
        })
        .collect();
    let root = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).expect("temporary folder");
    let runtime = support::machine_runtime();
    let (_store, _handle, mut machine) = support::start_machine(
        &runtime,
        root.path(),
        vec![setup],
        std::sync::Arc::new(camloop::service::metrics::Metrics::default()),
    );
    let mut count = 0usize;
    let mut once = || {
        let raw = support::next_part(&raws, count).remove(0);
        let part = raw.header.part.clone();
        count += 1;
        let received = Instant::now();
        let outcome = runtime
            .block_on(machine.on_in_process(raw, &part, received))
            .expect("in-process measurement");
        assert!(
            matches!(
                outcome,
                camloop::service::machine::InProcessOutcome::Delivered { .. }
            ),
            "{outcome:?}"
        );
        received.elapsed()
    };
    let mut samples: Vec<_> = (0..200).map(|_| once()).collect();
    eprintln!(
        "through the machine, measurement received to finish table and count on the share: {} (200 runs)",
        support::percentiles(&mut samples)
    );
    let mut group = c.benchmark_group("in_process");
    group.sample_size(20);
    group.bench_function("in_process_through_the_machine", |b| {
        b.iter_custom(|iters| (0..iters).map(|_| once()).sum())
    });
    group.finish();
}

criterion_group!(in_process_benches, benches, through_the_machine);
criterion_main!(in_process_benches);
