//! Shared support for the simulator tests: the demo lobe and crankpin, tables for them, and
//! the nominal lift to compare a ground part against.

pub mod brute;
pub use crate::support::golden;

use camloop::core::compensate::{AxisLimits, Feature, TableRequest};
use camloop::core::fit::TableForm;
use camloop::core::geometry::{CamGeometry, CrankpinGeometry, Follower, Part};
use camloop::core::learn::LearningParams;
use camloop::core::lift::{LiftCurve, LiftTable};
use camloop::core::speed_plan::SpeedPlanSettings;
use camloop::sim::cell::CellSetup;
use camloop::sim::{CommandedTable, GrinderConfig, SimGrinder, Workpiece};

pub const BASE_RADIUS_MM: f64 = 20.0;
pub const WHEEL_RADIUS_MM: f64 = 250.0;

/// The shipped demo lobe (8 mm lift, nose at 180°, nose radius 3.38 mm) as a LiftCurve.
pub fn demo_lift() -> LiftCurve {
    let text = include_str!("../../config/parts/demo-intake-lobe.csv");
    let table = LiftTable::parse_csv(text, "demo-intake-lobe.csv").expect("shipped table");
    LiftCurve::new(&table)
}

pub fn demo_geometry(follower: Follower) -> CamGeometry {
    CamGeometry {
        base_radius_mm: BASE_RADIUS_MM,
        follower,
        wheel_radius_mm: WHEEL_RADIUS_MM,
    }
}

pub fn demo_part(follower: Follower) -> Part {
    Part::cam(demo_geometry(follower), demo_lift()).expect("demo part is grindable")
}

pub fn demo_table(follower: Follower, points: usize, form: TableForm) -> CommandedTable {
    CommandedTable::nominal(&demo_part(follower), points, form).expect("nominal table")
}

pub fn demo_sim(config: GrinderConfig, follower: Follower, seed: u64) -> SimGrinder {
    SimGrinder::new(config, Workpiece::Cam(demo_geometry(follower)), seed).expect("sim")
}

/// The simulated cell on the demo lobe (flat follower, 20 mm base circle, 250 mm wheel), a
/// 360-point POLY table to 0.1 µm, the shipped learning, the demo camshaft's axis limits and the speed plan (off), on
/// `grinder` with noise `seed`. Tests change the one thing they study.
pub fn demo_cell(grinder: GrinderConfig, seed: u64) -> CellSetup {
    let text = include_str!("../../config/parts/demo-intake-lobe.csv");
    CellSetup {
        nominal: LiftTable::parse_csv(text, "demo-intake-lobe.csv").expect("shipped table"),
        feature: Feature::Cam(demo_geometry(Follower::Flat)),
        request: TableRequest {
            points: 360,
            form: TableForm::Poly,
            poly_tolerance_um: 0.1,
        },
        params: LearningParams::default(),
        limits: AxisLimits::default(),
        grinder,
        seed,
        speed_plan: SpeedPlanSettings::default(),
    }
}

/// Nominal lift at ψ_j = j·360°/n, mm.
pub fn nominal_on_grid(n: usize) -> Vec<f64> {
    let lift = demo_lift();
    (0..n)
        .map(|j| lift.lift_mm(j as f64 * 360.0 / n as f64))
        .collect()
}

/// Ground minus nominal on the grid, µm.
pub fn error_um(ground: &[f64], nominal: &[f64]) -> Vec<f64> {
    ground
        .iter()
        .zip(nominal)
        .map(|(g, n)| (g - n) * 1000.0)
        .collect()
}

/// Largest |value| and the grid index where it occurs.
pub fn max_abs(values: &[f64]) -> (f64, usize) {
    values.iter().enumerate().fold(
        (0.0, 0),
        |(m, at), (i, v)| if v.abs() > m { (v.abs(), i) } else { (m, at) },
    )
}

/// The crankpin used by the tests: throw 45 mm, pin radius 30 mm, wheel 300 mm.
pub fn pin_geometry() -> CrankpinGeometry {
    CrankpinGeometry {
        throw_mm: 45.0,
        pin_radius_mm: 30.0,
        wheel_radius_mm: 300.0,
    }
}

/// The brute-force oracle's view of what `sim` would do with `table`: the same table, X
/// zero, lag, harmonics and true wheel radius, handed over as plain numbers.
pub fn brute_path(sim: &SimGrinder, table: &CommandedTable) -> brute::BrutePath {
    use camloop::sim::TableShape;
    let cfg = sim.config();
    brute::BrutePath {
        table: match &table.shape {
            TableShape::G1(points) => {
                brute::BruteTable::G1(points.iter().map(|p| (p.c_deg, p.x_mm)).collect())
            }
            TableShape::Poly(segments) => brute::BruteTable::Poly(
                segments
                    .iter()
                    .map(|s| {
                        (
                            s.c_start_deg,
                            s.c_end_deg,
                            [s.x0_mm, s.a1_mm, s.a2_mm, s.a3_mm],
                        )
                    })
                    .collect(),
            ),
        },
        x_zero_mm: sim.x_zero_mm(table),
        lag_deg: cfg.c_speed_rpm * 6.0 * cfg.servo_lag_ms * 1e-3,
        harmonics: cfg
            .harmonics
            .iter()
            .map(|h| (f64::from(h.order), h.amplitude_um * 1e-3, h.phase_deg))
            .collect(),
        wheel_radius_mm: sim.wheel_radius_mm(),
        origin: [0.0, 0.0],
    }
}
