//! The same-part finish table: the remaining stock is taken out as a known size offset, and
//! a measurement of another part, another lobe, too few revolutions or a faulty gauge is
//! refused (the finish then grinds with the table in force, nothing learned). The same-part
//! step moves the correction only: drift, dressing offset and part history stay the
//! part-to-part loop's.

use camloop_core::analysis::ToleranceBand;
use camloop_core::compensate::{AxisLimits, Feature, LobeLoop, TableRequest};
use camloop_core::cycle::finish::{FinishRefused, InProcess, finish_table};
use camloop_core::fit::TableForm;
use camloop_core::geometry::{CamGeometry, CrankpinGeometry, Follower, Part};
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

/// The demo crankpin (demo-crankshaft.toml): 45 mm throw, 27 mm pin, 300 mm wheel.
fn pin() -> CrankpinGeometry {
    CrankpinGeometry {
        throw_mm: 45.0,
        pin_radius_mm: 27.0,
        wheel_radius_mm: 300.0,
    }
}

/// The demo lobe ground with its nominal table, `stock_um` still on, as the gauge reads it.
fn measured(stock_um: f64, part: &str, seed: u64) -> RawMeasurement {
    measured_feature(Feature::Cam(geometry()), stock_um, part, seed)
}

/// `feature` ground with its nominal table, the wheel path `stock_um` out (as the stock is
/// left: X stops that far above the finished path), as the gauge reads it.
fn measured_feature(feature: Feature, stock_um: f64, part: &str, seed: u64) -> RawMeasurement {
    let (p, workpiece) = match feature {
        Feature::Cam(g) => {
            let nominal = LiftTable::parse_csv(INTAKE, "demo").unwrap();
            (
                Part::cam(g, LiftCurve::new(&nominal)).unwrap(),
                Workpiece::Cam(g),
            )
        }
        Feature::Pin(g) => (Part::crankpin(g).unwrap(), Workpiece::Crankpin(g)),
    };
    let table = CommandedTable::nominal(&p, 360, TableForm::Poly).unwrap();
    let mut sim = SimGrinder::new(GrinderConfig::default(), workpiece, seed).unwrap();
    let errors = StationErrors {
        size_um: stock_um,
        ..StationErrors::default()
    };
    let ground = sim.grind_station(&table, &workpiece, &errors).unwrap();
    let labels = PartLabels {
        machine: "M1".into(),
        part: part.into(),
        lobe: "IN1".into(),
    };
    sim.measure(&ground, &labels)
}

struct Fixture {
    feature: Feature,
    nominal: LiftTable,
    limits: AxisLimits,
    params: LearningParams,
    bands: Vec<ToleranceBand>,
}

impl Fixture {
    fn new() -> Self {
        Self::of(Feature::Cam(geometry()))
    }

    fn of(feature: Feature) -> Self {
        let nominal = match feature {
            Feature::Cam(_) => LiftTable::parse_csv(INTAKE, "demo").unwrap(),
            Feature::Pin(g) => camloop_core::compensate::pin_nominal_lift(&g),
        };
        Self {
            feature,
            nominal,
            limits: AxisLimits::default(),
            params: LearningParams::default(),
            bands: Vec::new(),
        }
    }

    fn setup(&self) -> TurnSetup<'_> {
        TurnSetup {
            lobe: LobeLoop {
                nominal: &self.nominal,
                feature: self.feature,
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

fn finish_of(
    f: &Fixture,
    state: &LearningState,
    raw: &RawMeasurement,
    stock_mm: f64,
) -> Result<camloop_core::cycle::finish::FinishTable, FinishRefused> {
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

/// The finish table from `state`, the learning state of the table in force.
fn finish_from(
    state: &LearningState,
    raw: &RawMeasurement,
    stock_mm: f64,
) -> Result<camloop_core::cycle::finish::FinishTable, FinishRefused> {
    finish_of(&Fixture::new(), state, raw, stock_mm)
}

/// The largest difference between the error the finish table learns from (the in-process
/// reading of `feature` with 20 µm of stock, the stock taken out) and the lift error of the
/// same part ground without stock, read with the same noise, µm; and the same with the
/// stock taken out as a uniform size instead.
fn stock_taken_out(feature: Feature, seed: u64) -> (f64, f64) {
    let f = Fixture::of(feature);
    let bare = turn::measure(&f.setup(), &measured_feature(feature, 0.0, "17", seed)).unwrap();
    let bare_um: Vec<f64> = bare
        .report
        .profile_error_um
        .iter()
        .map(|e| e + bare.report.base_radius_error_um)
        .collect();
    let raw = measured_feature(feature, 20.0, "17", seed);
    let state = LearningState::new(360);
    let done = finish_of(&f, &state, &raw, 0.020).unwrap();
    let uniform = finish_of(&f, &state, &raw, 0.0).unwrap();
    let worst = |error: &[f64], less_um: f64| {
        error
            .iter()
            .zip(&bare_um)
            .fold(0.0f64, |m, (e, b)| m.max((e - less_um - b).abs()))
    };
    (worst(&done.error_um, 0.0), worst(&uniform.error_um, 20.0))
}

#[test]
fn the_remaining_stock_is_a_known_wheel_centre_offset_read_angle_by_angle() {
    // The sim grinds the envelope of the wheel with its path moved out by the stock and
    // reads it with its gauge: an independent method from the core's gain (the contact
    // normal against the line of centres). Same seed, same noise: what differs is the
    // stock alone. 0.01 µm bounds the analysis's fit of two readings 20 µm apart (its
    // timing and centre fits move by the reading's change).
    let (cam, cam_uniform) = stock_taken_out(Feature::Cam(geometry()), 3);
    assert!(cam < 0.01, "cam lobe: {cam} µm");
    // On the lobe the contact leans from the line of centres by at most atan(h'/(Rb+h+R)),
    // under 2°: the uniform offset is right there to a few nm.
    assert!(cam_uniform < 0.05, "cam lobe, uniform: {cam_uniform} µm");
    let (pin, pin_uniform) = stock_taken_out(Feature::Pin(pin()), 3);
    assert!(pin < 0.01, "crankpin: {pin} µm");
    // On the pin it leans by up to asin(45/327) = 7.9°: 20 µm·(1 − cos 7.9°) = 0.19 µm of
    // error the finish would be ground with, were the stock taken as a uniform size.
    assert!(
        (0.15..0.25).contains(&pin_uniform),
        "crankpin, uniform: {pin_uniform} µm"
    );
    // The stock not taken out at all would be learned as 20 µm of error.
    let f = Fixture::new();
    let raw = measured(20.0, "17", 3);
    let wrong = finish_of(&f, &LearningState::new(360), &raw, 0.0).unwrap();
    let done = finish_of(&f, &LearningState::new(360), &raw, 0.020).unwrap();
    assert!((wrong.size_over_stock_um - done.size_over_stock_um - 20.0).abs() < 0.05);
    // The table differs from the nominal by what was learned: a correction was made.
    assert!(done.state.correction_um.iter().any(|c| c.abs() > 1.0));
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

#[test]
fn the_in_process_gauge_settings_are_checked_naming_the_key() {
    let mut config = GrinderConfig::default();
    config.gauge.in_process.handover_s = -1.0;
    config.gauge.in_process.faults = vec![camloop_sim::GaugeFault::Offset {
        revolution: 9,
        offset_um: 30.0,
    }];
    let problems = config.problems();
    assert_eq!(
        problems,
        [
            "gauge.in_process.handover_s = -1 must be within 0..=3600",
            "gauge.in_process.faults[0].revolution = 9 must be below gauge.revolutions",
        ],
    );
    config.gauge.in_process.handover_s = f64::NAN;
    config.gauge.in_process.faults.clear();
    assert_eq!(
        config.problems(),
        ["gauge.in_process.handover_s = NaN must be within 0..=3600"]
    );
}
