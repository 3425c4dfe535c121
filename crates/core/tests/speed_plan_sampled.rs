//! The speed plan's tables as the control runs them: the table program as written (rounded
//! values and coefficients) read back with the program reader, both tables sampled at the
//! control's interpolation cycle (0.5, 1 and 2 ms) with VA turning at its constant speed,
//! and X and C velocity, acceleration and X jerk taken from the sampled positions by
//! differences, as the control's setpoints give them.
//!
//! Tolerance: none. A difference quotient over a cycle is an average of the derivative over
//! that cycle (the first difference of the velocity over Δ, the second of the acceleration
//! over 2Δ with a triangular weight, the third of the jerk over 3Δ), so on a curve that keeps
//! a limit everywhere it keeps the limit too; what can break it is a step in the written
//! curve's slope at a joint (the rounding), which a difference turns into s/Δ. The plan
//! keeps room for that (`Room` in the planner), and this test checks that room suffices.

use camloop_core::geometry::{CamGeometry, Follower, Part};
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::program::{ParsedTable, parse_table_program};
use camloop_core::speed_plan::render::{VaProgramSettings, render_va_table_program};
use camloop_core::speed_plan::{self, SpeedLimits};

const INTAKE: &str = include_str!("../../../config/parts/demo-intake-lobe.csv");
const EXHAUST: &str = include_str!("../../../config/parts/demo-exhaust-lobe.csv");

fn lobe(text: &str) -> Part {
    let table = LiftTable::parse_csv(text, "demo lobe").unwrap();
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    };
    Part::cam(geometry, LiftCurve::new(&table)).unwrap()
}

fn demo_limits() -> SpeedLimits {
    SpeedLimits {
        x_velocity_mm_s: 200.0,
        x_acceleration_mm_s2: 10_000.0,
        x_jerk_mm_s3: 10_000_000.0,
        c_max_speed_rpm: 120.0,
        c_max_accel_deg_s2: 3600.0,
        q_w_max_mm3_mm_s: 2.36,
        stock_mm: 0.02,
    }
}

/// No removal limit, C up to 600 rpm and 36 000 °/s²: the X axis binds.
fn x_bound_limits() -> SpeedLimits {
    SpeedLimits {
        c_max_speed_rpm: 600.0,
        c_max_accel_deg_s2: 36_000.0,
        q_w_max_mm3_mm_s: 1e9,
        ..demo_limits()
    }
}

/// The X and C tables of the written program, read back.
fn written_tables(part: &Part, limits: &SpeedLimits) -> (ParsedTable, ParsedTable, f64) {
    let plan = speed_plan::plan(part, limits).unwrap();
    assert!(!plan.is_constant);
    let tables = speed_plan::tables::va_tables(part, &plan.law, 0.1).unwrap();
    let text = render_va_table_program(&tables, &VaProgramSettings::default()).unwrap();
    // The program defines X's table, then C's; the reader reads the last table of a text.
    let cut = text.find("CTABEND").unwrap() + "CTABEND\n".len();
    let x = parse_table_program(&text[..cut]).unwrap();
    let c = parse_table_program(&text[cut..]).unwrap();
    (x, c, 60.0 / tables.va_speed_rpm)
}

/// Largest usage of C speed, C acceleration, X velocity, X acceleration, X jerk along two
/// revolutions sampled every `dt_s`.
fn sampled_usage(
    x: &ParsedTable,
    c: &ParsedTable,
    period_s: f64,
    limits: &SpeedLimits,
    dt_s: f64,
) -> [f64; 5] {
    // C unwrapped: the C table rises 360° per turn of VA and is reduced into its period.
    let c_at = |t: f64| {
        let va = 360.0 * t / period_s;
        let turns = (va / 360.0).floor();
        let v = c.x_at(va).unwrap();
        let local = va - 360.0 * turns;
        v + 360.0 * turns - if v - local > 180.0 { 360.0 } else { 0.0 }
    };
    let x_at = |t: f64| x.x_at(360.0 * t / period_s).unwrap();
    let n = (2.0 * period_s / dt_s) as usize;
    let mut worst = [0.0f64; 5];
    for k in 0..n {
        // An offset off the knots, so samples fall inside segments and across joints.
        let t = k as f64 * dt_s + 0.123e-3;
        let cs: Vec<f64> = (0..3).map(|j| c_at(t + j as f64 * dt_s)).collect();
        let xs: Vec<f64> = (0..4).map(|j| x_at(t + j as f64 * dt_s)).collect();
        let usage = [
            (cs[1] - cs[0]).abs() / dt_s / (6.0 * limits.c_max_speed_rpm),
            (cs[2] - 2.0 * cs[1] + cs[0]).abs() / dt_s.powi(2) / limits.c_max_accel_deg_s2,
            (xs[1] - xs[0]).abs() / dt_s / limits.x_velocity_mm_s,
            (xs[2] - 2.0 * xs[1] + xs[0]).abs() / dt_s.powi(2) / limits.x_acceleration_mm_s2,
            (xs[3] - 3.0 * xs[2] + 3.0 * xs[1] - xs[0]).abs() / dt_s.powi(3) / limits.x_jerk_mm_s3,
        ];
        for (w, u) in worst.iter_mut().zip(usage) {
            *w = w.max(u);
        }
    }
    worst
}

fn assert_written_tables_keep_the_limits(name: &str, part: &Part, limits: &SpeedLimits) {
    let (x, c, period_s) = written_tables(part, limits);
    let names = [
        "C speed",
        "C acceleration",
        "X velocity",
        "X acceleration",
        "X jerk",
    ];
    for dt_s in [0.5e-3, 1e-3, 2e-3] {
        let usage = sampled_usage(&x, &c, period_s, limits, dt_s);
        eprintln!("{name}, every {} ms: {usage:.4?}", dt_s * 1e3);
        for (u, what) in usage.iter().zip(names) {
            assert!(
                *u <= 1.0,
                "{name}: {what} at {:.2} % of its limit sampled every {} ms",
                u * 100.0,
                dt_s * 1e3
            );
        }
    }
}

#[test]
fn demo_intake_tables_keep_every_limit_at_every_interpolation_cycle() {
    assert_written_tables_keep_the_limits("demo intake", &lobe(INTAKE), &demo_limits());
}

#[test]
fn demo_exhaust_tables_keep_every_limit_at_every_interpolation_cycle() {
    assert_written_tables_keep_the_limits("demo exhaust", &lobe(EXHAUST), &demo_limits());
}

#[test]
fn x_bound_tables_keep_every_limit_at_every_interpolation_cycle() {
    assert_written_tables_keep_the_limits("X-bound intake", &lobe(INTAKE), &x_bound_limits());
}
