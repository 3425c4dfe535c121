//! The same-part finish table: the remaining stock is taken out as a known size offset, and
//! a measurement of another part, another lobe, too few revolutions or a faulty gauge is
//! refused (the finish then grinds with the table in force, nothing learned). The same-part
//! step moves the correction only: drift, dressing offset and part history stay the
//! part-to-part loop's.

use camloop_core::analysis::ToleranceBand;
use camloop_core::compensate::{AxisLimits, Feature, LobeLoop, TableRequest};
use camloop_core::cycle::finish::{FinishRefused, InProcess, finish_table};
use camloop_core::fit::TableForm;
use camloop_core::geometry::{CamGeometry, Follower, Part};
use camloop_core::learn::{LearningParams, LearningState};
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::measure::{AssemblyLimits, RawMeasurement};
use camloop_core::turn::{self, TurnSetup};
use camloop_sim::{
    CommandedTable, GrinderConfig, PartLabels, SimGrinder, StationErrors, Workpiece,
};

const INTAKE: &str = include_str!("../../../config/parts/demo-intake-lobe.csv");

fn geometry() -> CamGeometry {
    CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    }
}

/// The demo lobe ground with its nominal table, `stock_um` still on, as the gauge reads it.
fn measured(stock_um: f64, part: &str, seed: u64) -> RawMeasurement {
    let nominal = LiftTable::parse_csv(INTAKE, "demo").unwrap();
    let p = Part::cam(geometry(), LiftCurve::new(&nominal)).unwrap();
    let table = CommandedTable::nominal(&p, 360, TableForm::Poly).unwrap();
    let mut sim =
        SimGrinder::new(GrinderConfig::default(), Workpiece::Cam(geometry()), seed).unwrap();
    let errors = StationErrors {
        size_um: stock_um,
        ..StationErrors::default()
    };
    let ground = sim
        .grind_station(&table, &Workpiece::Cam(geometry()), &errors)
        .unwrap();
    let labels = PartLabels {
        machine: "M1".into(),
        part: part.into(),
        lobe: "IN1".into(),
    };
    sim.measure(&ground, &labels)
}

struct Fixture {
    nominal: LiftTable,
    limits: AxisLimits,
    params: LearningParams,
    bands: Vec<ToleranceBand>,
}

impl Fixture {
    fn new() -> Self {
        Self {
            nominal: LiftTable::parse_csv(INTAKE, "demo").unwrap(),
            limits: AxisLimits::default(),
            params: LearningParams::default(),
            bands: Vec::new(),
        }
    }

    fn setup(&self) -> TurnSetup<'_> {
        TurnSetup {
            lobe: LobeLoop {
                nominal: &self.nominal,
                feature: Feature::Cam(geometry()),
                request: TableRequest {
                    points: 360,
                    form: TableForm::Poly,
                    poly_tolerance_um: 0.1,
                },
                limits: &self.limits,
                params: &self.params,
            },
            bands: &self.bands,
            assembly: AssemblyLimits::default(),
            phase_deg: 0.0,
            plan: None,
        }
    }
}

fn finish(
    raw: &RawMeasurement,
    stock_mm: f64,
) -> Result<camloop_core::cycle::finish::FinishTable, FinishRefused> {
    finish_from(&LearningState::new(360), raw, stock_mm)
}

/// The finish table from `state`, the learning state of the table in force.
fn finish_from(
    state: &LearningState,
    raw: &RawMeasurement,
    stock_mm: f64,
) -> Result<camloop_core::cycle::finish::FinishTable, FinishRefused> {
    let f = Fixture::new();
    let setup = f.setup();
    let input = InProcess {
        setup: &setup,
        in_force: state,
        raw,
        part: "17",
        remaining_stock_mm: stock_mm,
        gain: 0.9,
    };
    finish_table(&input, "IN1")
}

#[test]
fn the_remaining_stock_is_a_known_size_offset() {
    // The same part ground without stock and with 20 µm on, read with the same noise: the
    // finish table's size beyond the stock is the finished part's own size error.
    let f = Fixture::new();
    let bare = turn::measure(&f.setup(), &measured(0.0, "17", 3)).unwrap();
    let done = finish(&measured(20.0, "17", 3), 0.020).unwrap();
    let d = done.size_over_stock_um - bare.report.base_radius_error_um;
    // The stock goes in as a wheel-centre offset, which a flat follower reads 1:1 as size;
    // 0.01 µm bounds the analysis's fit of two readings 20 µm apart.
    assert!(
        d.abs() < 0.01,
        "{} vs {}",
        done.size_over_stock_um,
        bare.report.base_radius_error_um
    );
    // The table differs from the nominal by what was learned: a correction was made.
    assert!(done.state.correction_um.iter().any(|c| c.abs() > 1.0));
    // The stock not taken out would be learned as 20 µm of size (refused by nothing, but
    // wrong): the offset is what keeps it out.
    let wrong = finish(&measured(20.0, "17", 3), 0.0).unwrap();
    assert!((wrong.size_over_stock_um - done.size_over_stock_um - 20.0).abs() < 1e-9);
}

#[test]
fn another_part_or_lobe_is_refused() {
    let raw = measured(20.0, "18", 4);
    assert_eq!(
        finish(&raw, 0.02).unwrap_err(),
        FinishRefused::WrongPart {
            expected: "17".into(),
            got: "18".into()
        }
    );
    let mut raw = measured(20.0, "17", 4);
    raw.header.lobe = "EX1".into();
    assert!(matches!(
        finish(&raw, 0.02),
        Err(FinishRefused::WrongFeature { .. })
    ));
}

#[test]
fn an_incomplete_or_faulty_measurement_is_refused() {
    // Two revolutions of four: the assembly refuses fewer than three.
    let mut raw = measured(20.0, "17", 5);
    raw.samples.retain(|s| s.revolution < 2);
    raw.header.revolutions = 2;
    let err = finish(&raw, 0.02).unwrap_err();
    assert!(matches!(err, FinishRefused::Measurement(_)), "{err}");
    // A reading that is not a number.
    let mut raw = measured(20.0, "17", 5);
    raw.samples[10].lift_mm = f64::NAN;
    assert!(matches!(
        finish(&raw, 0.02),
        Err(FinishRefused::Measurement(_))
    ));
    // A stock that is not a size.
    assert_eq!(
        finish(&measured(20.0, "17", 5), -0.01).unwrap_err(),
        FinishRefused::Stock(-0.01)
    );
}

/// The in-force state of a lobe some shafts into a run: the part-to-part loop has learned
/// a correction, a wheel wear of 0.8 µm per part, the last part's size disturbance, and
/// the recent parts' errors.
fn learned_state() -> LearningState {
    let mut s = LearningState::new(360);
    for (j, c) in s.correction_um.iter_mut().enumerate() {
        *c = -2.0 + 1.5 * (2.0 * (j as f64).to_radians()).cos();
    }
    s.size_drift_um_per_part = 0.8;
    s.last_size_disturbance_um = Some(3.1);
    s.last_size_disturbance_part = Some(16);
    s.dressing_offset_um = 0.4;
    s.iteration = 16;
    s.recent_max_error_um = vec![0.6, 0.5, 0.4];
    s
}

#[test]
fn the_same_part_step_moves_the_correction_and_nothing_of_the_part_to_part_loop() {
    // The finish is of the part just measured: the wheel's wear from part to part is not
    // anticipated in it, and the finished part's drift is measured against the previous
    // finished part, not against this part's own in-process reading. Before this held, the
    // demo camshaft's every finish was ground 0.5-0.6 µm undersize by the drift taken off.
    let raw = measured(20.0, "17", 6);
    let in_force = learned_state();
    let done = finish_from(&in_force, &raw, 0.020).unwrap();
    // The same measurement from the same correction with no drift learned: the same table.
    let no_drift = LearningState {
        size_drift_um_per_part: 0.0,
        last_size_disturbance_um: None,
        last_size_disturbance_part: None,
        ..in_force.clone()
    };
    let reference = finish_from(&no_drift, &raw, 0.020).unwrap();
    let most = done
        .state
        .correction_um
        .iter()
        .zip(&reference.state.correction_um)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    // Both are one learning law on one input: equal to the rounding of the correction's
    // quantisation, far below the 0.8 µm drift that would otherwise be taken off.
    assert!(most < 1e-9, "the drift moved the finish table by {most} µm");
    // The correction did move (the nominal-ground part reads several µm of error).
    let moved = done
        .state
        .correction_um
        .iter()
        .zip(&in_force.correction_um)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(moved > 1.0, "moved by {moved} µm");
    // The part-to-part loop's own memory is the in-force state's, untouched.
    let keep = |s: &LearningState| {
        (
            s.size_drift_um_per_part,
            s.last_size_disturbance_um,
            s.last_size_disturbance_part,
            s.dressing_offset_um,
            s.iteration,
            s.recent_max_error_um.clone(),
            s.best.clone(),
            s.frozen.clone(),
        )
    };
    assert_eq!(keep(&done.state), keep(&in_force));
}
