//! End-to-end costs the issues set targets for:
//! - one gauge measurement, 3 × 360 points: CAN frames decoded from the DBC, assembled,
//!   checked, averaged and analysed (target under 200 µs);
//! - one turn of the loop for a 360-point lobe: learning step, table regenerated through the
//!   exact geometry and guarded, program rendered and delivered to the share with its
//!   manifest (target under 2 ms), on tmpfs and on the state disk.

use camloop::core::analysis::{LobeOptions, analyse_lobe};
use camloop::core::compensate::{self, AxisLimits, Feature, LobeLoop, TableRequest};
use camloop::core::fit::TableForm;
use camloop::core::geometry::{CamGeometry, Follower};
use camloop::core::learn::{LearningParams, LearningState, PartError};
use camloop::core::lift::LiftTable;
use camloop::core::measure::{AssemblyLimits, check_and_average};
use camloop::core::program::{ProgramSettings, render_poly_table};
use camloop::gauge::candump::parse_candump_line;
use camloop::gauge::{Assembled, Assembler, CanId, GaugeDbc};
use camloop::share::{ProgramFile, PushRequest, RealFs, Share, ShareConfig};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::path::{Path, PathBuf};

/// The fixture's nominal: h(ψ) = 6.2·((1 − cos ψ)/2)² mm (see tools/encode_candump.py).
fn fixture_nominal(psi_deg: f64) -> (f64, f64) {
    let (s, c) = psi_deg.to_radians().sin_cos();
    let half = (1.0 - c) / 2.0;
    (
        6.2 * half * half,
        6.2 * half * s * std::f64::consts::PI / 180.0,
    )
}

fn frames() -> Vec<(CanId, Vec<u8>)> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/gauge_3x360.log");
    let log = std::fs::read_to_string(path).expect("fixture");
    log.lines()
        .map(|l| {
            let r = parse_candump_line(l).expect("fixture line");
            (r.id, r.data().to_vec())
        })
        .collect()
}

fn measurement(c: &mut Criterion) {
    let dbc = GaugeDbc::builtin();
    let frames = frames();
    let limits = AssemblyLimits::default();
    let options = LobeOptions::default();
    c.bench_function("measurement_3x360_decode_assemble_average_analyse", |b| {
        b.iter(|| {
            let mut assembler = Assembler::new("bench");
            let mut raw = None;
            for (id, data) in &frames {
                if let Ok(frame) = dbc.decode(*id, black_box(data))
                    && let Some(done) = assembler.push(frame)
                {
                    raw = Some(done);
                }
            }
            let Some(Assembled::Measurement(raw)) = raw else {
                panic!("one complete measurement")
            };
            let avg = check_and_average(&raw, &limits).expect("valid");
            analyse_lobe(&avg, &fixture_nominal, &options).expect("analysis")
        })
    });
}

fn loop_turn(c: &mut Criterion) {
    let nominal =
        LiftTable::parse_csv(include_str!("../config/parts/demo-intake-lobe.csv"), "demo")
            .expect("table");
    let limits = AxisLimits::default();
    let params = LearningParams {
        deadband_sigmas: 0.0,
        ..LearningParams::default()
    };
    let lobe = LobeLoop {
        nominal: &nominal,
        feature: Feature::Cam(CamGeometry {
            base_radius_mm: 20.0,
            follower: Follower::Flat,
            wheel_radius_mm: 250.0,
        }),
        request: TableRequest {
            points: 360,
            form: TableForm::Poly,
            poly_tolerance_um: 0.1,
        },
        limits: &limits,
        params: &params,
    };
    // A smooth error of a few µm, as after the first part.
    let error: Vec<f64> = (0..360)
        .map(|j| 3.0 * (2.0 * f64::from(j).to_radians()).cos())
        .collect();
    let repeat = vec![0.1; 360];
    let state = LearningState::new(360);
    let part = PartError {
        error_um: &error,
        repeatability_um: &repeat,
        revolutions: 4,
        timing_error_deg: 0.0,
        timing_sigma_deg: 0.0,
        part_number: None,
        previous: None,
    };
    c.bench_function("loop_learn_and_regenerate_360", |b| {
        b.iter(|| {
            let mut s = state.clone();
            compensate::learn_and_regenerate(&mut s, black_box(&part), &lobe).expect("table")
        })
    });
    turn_and_push(c, &state, &part, &lobe);
}

/// The whole turn through the share, on tmpfs (when there is one) and on disk: learn,
/// regenerate, render and push.
fn turn_and_push(
    c: &mut Criterion,
    state: &LearningState,
    part: &PartError<'_>,
    lobe: &LobeLoop<'_>,
) {
    let shm = Path::new("/dev/shm");
    let targets: Vec<(&str, PathBuf)> = [
        ("tmpfs", shm.is_dir().then(|| shm.to_path_buf())),
        ("disk", Some(PathBuf::from(env!("CARGO_TARGET_TMPDIR")))),
    ]
    .into_iter()
    .filter_map(|(n, p)| p.map(|p| (n, p)))
    .collect();
    for (name, root) in targets {
        let dir = tempfile::tempdir_in(&root).expect("temp dir");
        let config = ShareConfig {
            share_dir: dir.path().join("share"),
            state_dir: dir.path().join("state"),
            table_pair: (1, 2),
            keep_versions: 20,
        };
        std::fs::create_dir_all(&config.share_dir).expect("share dir");
        let (mut share, _) = Share::open(
            config,
            Box::new(RealFs),
            Box::new(|| jiff::Timestamp::UNIX_EPOCH),
        )
        .expect("share");
        c.bench_function(
            &format!("loop_turn_360_learn_regenerate_render_push_{name}"),
            |b| {
                b.iter(|| {
                    let mut s = state.clone();
                    let (_, table) =
                        compensate::learn_and_regenerate(&mut s, black_box(part), lobe)
                            .expect("table");
                    let settings = ProgramSettings {
                        table_number: share.next_table_number(),
                        ..ProgramSettings::default()
                    };
                    let text =
                        render_poly_table(table.segments.as_deref().expect("poly"), &settings)
                            .expect("render");
                    let request = PushRequest {
                        files: vec![ProgramFile {
                            name: "CAMLOOP_TABLE.SPF".into(),
                            text,
                        }],
                        table_number: settings.table_number,
                        reason: "bench".into(),
                        measurement_id: None,
                        learning: serde_json::Value::Null,
                        rollback_of: None,
                        created_at: jiff::Timestamp::UNIX_EPOCH,
                    };
                    share.push_once(request).expect("push")
                })
            },
        );
    }
}

criterion_group!(pipeline, measurement, loop_turn);
criterion_main!(pipeline);
