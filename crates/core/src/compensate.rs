//! From a lift-domain correction to the next table, through the exact geometry, with the
//! guards a table must pass before it may go to the control.

use super::fit::{self, Deviation, Motion, TableForm};
use super::geometry::{CamGeometry, CrankpinGeometry, GeometryError, Part};
use super::learn::{self, LearnError, LearningParams, LearningState, PartError, StepOutcome};
use super::lift::{LiftCurve, LiftTable, LiftTableError};
use super::spline::PeriodicSpline;
use super::table::{PolySegment, TablePoint};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// What is ground: a cam lobe, or a crankpin (learned through its support function, which a
/// flat probe reads as lift, see [`Part::shaped_pin`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Feature {
    Cam(CamGeometry),
    Pin(CrankpinGeometry),
}

/// Wheel radii a dressing report may carry, mm: grinding wheels of X–C machines sit well
/// inside this; a value outside is a typo or a wrong unit, refused before the geometry.
pub(crate) const WHEEL_RADIUS_RANGE_MM: std::ops::RangeInclusive<f64> = 5.0..=1000.0;

/// A dressing report whose wheel radius cannot be right.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error(
    "wheel radius {shown} mm is not a plausible dressed radius ({min}–{max} mm)",
    shown = shown_mm(*.0),
    min = WHEEL_RADIUS_RANGE_MM.start(),
    max = WHEEL_RADIUS_RANGE_MM.end()
)]
pub struct WheelRadiusError(pub f64);

/// A value as an error shows it: plainly while short, else in exponent form, so a client's
/// `1e308` comes back as `1e308`, not 309 digits.
fn shown_mm(v: f64) -> String {
    if v.is_finite() && v.abs() < 1e9 {
        v.to_string()
    } else {
        format!("{v:e}")
    }
}

/// Checks a dressed wheel radius from the control's feed, a dropped file or the API. Whether
/// the part can be ground with it is the regenerated table's guards' call.
pub fn check_wheel_radius(wheel_radius_mm: f64) -> Result<f64, WheelRadiusError> {
    if WHEEL_RADIUS_RANGE_MM.contains(&wheel_radius_mm) {
        Ok(wheel_radius_mm)
    } else {
        Err(WheelRadiusError(wheel_radius_mm))
    }
}

impl Feature {
    pub fn wheel_radius_mm(&self) -> f64 {
        match self {
            Feature::Cam(g) => g.wheel_radius_mm,
            Feature::Pin(g) => g.wheel_radius_mm,
        }
    }

    /// The same feature on a wheel of another radius (after dressing).
    pub fn with_wheel_radius(self, wheel_radius_mm: f64) -> Self {
        match self {
            Feature::Cam(g) => Feature::Cam(CamGeometry {
                wheel_radius_mm,
                ..g
            }),
            Feature::Pin(g) => Feature::Pin(CrankpinGeometry {
                wheel_radius_mm,
                ..g
            }),
        }
    }

    /// Program X zero: `R + Rb` for cams, `R + r_p` for pins.
    pub fn x_zero_mm(&self) -> f64 {
        match self {
            Feature::Cam(g) => g.wheel_radius_mm + g.base_radius_mm,
            Feature::Pin(g) => g.wheel_radius_mm + g.pin_radius_mm,
        }
    }

    /// The part ground from a commanded lift.
    pub fn part(&self, commanded: &LiftTable) -> Result<Part, GeometryError> {
        match self {
            Feature::Cam(g) => Part::cam(*g, LiftCurve::new(commanded)),
            Feature::Pin(g) => Part::shaped_pin(*g, LiftCurve::new(commanded)),
        }
    }
}

/// A round pin's nominal lift as a flat probe on the main axis reads it, index at 0°:
/// `b·(1 + cos ψ)` (support `b·cos ψ + r_p` minus its minimum `r_p − b`), at 0.5° steps.
pub fn pin_nominal_lift(pin: &CrankpinGeometry) -> LiftTable {
    let angles: Vec<f64> = (0..720).map(|k| f64::from(k) * 0.5).collect();
    let lifts = angles
        .iter()
        .map(|a| pin.throw_mm * (1.0 + a.to_radians().cos()))
        .collect();
    LiftTable::from_points(angles, lifts, "round pin")
        .expect("720 finite, non-negative points on a uniform grid form a valid table")
}

/// X-axis limits the table's motion must respect at the configured C speed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AxisLimits {
    /// C speed while grinding, rev/min.
    pub c_speed_rpm: f64,
    pub velocity_mm_s: f64,
    pub acceleration_mm_s2: f64,
    pub jerk_mm_s3: f64,
    /// C speed limit, rev/min: what a speed plan may reach.
    pub c_max_speed_rpm: f64,
    /// C acceleration limit, degrees/s², for a speed plan.
    pub c_max_accel_deg_s2: f64,
}

impl Default for AxisLimits {
    fn default() -> Self {
        Self {
            c_speed_rpm: 30.0,
            velocity_mm_s: 200.0,
            acceleration_mm_s2: 10_000.0,
            jerk_mm_s3: 1.0e7,
            c_max_speed_rpm: 120.0,
            c_max_accel_deg_s2: 3600.0,
        }
    }
}

/// How the table is to be made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableRequest {
    pub points: usize,
    pub form: TableForm,
    pub poly_tolerance_um: f64,
}

/// A table that passed every guard, ready to render.
#[derive(Debug, Clone)]
pub struct GuardedTable {
    /// G1 points, or the knots of the POLY segments.
    pub points: Vec<TablePoint>,
    pub segments: Option<Vec<PolySegment>>,
    pub motion: Motion,
    /// Largest deviation of the table's interpolation from the exact path between points.
    pub deviation: Deviation,
    /// The learned timing correction, degrees: added to the feature's C offset when the
    /// table is rendered (the points stay in the part frame).
    pub timing_offset_deg: f64,
}

impl GuardedTable {
    /// The table program for `settings`, with the learned timing added to their C offset:
    /// the one way a guarded table becomes program text.
    pub fn render(
        &self,
        settings: &super::program::ProgramSettings,
    ) -> Result<String, super::program::TableError> {
        let mut settings = settings.clone();
        settings.c_offset_deg += self.timing_offset_deg;
        match &self.segments {
            Some(s) => super::program::render_poly_table(s, &settings),
            None => super::program::render_g1_table(&self.points, &settings),
        }
    }
}

/// Why a table was refused. A refused table is never pushed; the reason is recorded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GuardError {
    #[error("corrected lift is not a valid table: {0}")]
    Lift(#[from] LiftTableError),
    #[error("corrected part cannot be ground: {0}")]
    Geometry(#[from] GeometryError),
    #[error(
        "X {quantity} {value:.1} {unit} exceeds the axis limit {limit} {unit} at C = {c_speed_rpm} rpm"
    )]
    Motion {
        quantity: &'static str,
        value: f64,
        limit: f64,
        unit: &'static str,
        c_speed_rpm: f64,
    },
    #[error(
        "with the speed plan, X {quantity} {value:.1} {unit} exceeds the axis limit {limit} {unit} at C = {c_deg:.2} deg (VA = {va_deg:.2} deg)"
    )]
    PlanMotion {
        quantity: &'static str,
        value: f64,
        limit: f64,
        unit: &'static str,
        c_deg: f64,
        va_deg: f64,
    },
}

/// Rounding slack below the deepest correction, mm (see [`commanded_lift`]).
const FLOOR_SLACK_MM: f64 = 1e-6;

/// The commanded lift: nominal plus the correction (µm on a uniform gauge grid), evaluated on
/// the nominal's knots, or on the gauge grid when that is finer. The correction is carried
/// between grids by its periodic spline. Lift may go below the base circle by as much as the
/// correction asks (a part ground oversize there is corrected by a negative lift).
pub fn commanded_lift(
    nominal: &LiftTable,
    correction_um: &[f64],
) -> Result<LiftTable, LiftTableError> {
    let n = correction_um.len();
    let nominal_curve = LiftCurve::new(nominal);
    let grid: Vec<f64> = (0..n).map(|j| j as f64 * TAU / n as f64).collect();
    let correction = PeriodicSpline::new(&grid, correction_um, TAU);
    let angles_deg: Vec<f64> = if nominal.angles_deg().len() >= n {
        nominal.angles_deg().to_vec()
    } else {
        (0..n).map(|j| j as f64 * 360.0 / n as f64).collect()
    };
    let lifts: Vec<f64> = angles_deg
        .iter()
        .map(|a| nominal_curve.lift_mm(*a) + correction.eval(a.to_radians()).value / 1000.0)
        .collect();
    // The largest |correction| is the deepest the lift may go. Where it falls on the base
    // circle, the nominal spline's value there (0 up to rounding, ±1e-18 mm) must not make
    // the lift read below it: 1 nm of slack, far below any table's resolution.
    let floor_mm =
        -correction_um.iter().fold(0.0f64, |m, u| m.max(u.abs())) / 1000.0 - FLOOR_SLACK_MM;
    LiftTable::from_points_with_floor(angles_deg, lifts, nominal.origin(), floor_mm)
}

/// Builds the table for `geometry` from the commanded lift and checks it: grindable, and the
/// X motion within `limits`. G1 tables have velocity steps at every point; their acceleration
/// and jerk are judged by the second and third differences of X over the points, which is the
/// motion of the smooth path the table samples.
pub(crate) fn guarded_table(
    feature: Feature,
    commanded: &LiftTable,
    request: TableRequest,
    limits: &AxisLimits,
) -> Result<GuardedTable, GuardError> {
    let part = feature.part(commanded)?;
    guarded_part_table(&part, request, limits)
}

/// Like [`guarded_table`] for a part already built (a crankpin, or a cam).
pub(crate) fn guarded_part_table(
    part: &Part,
    request: TableRequest,
    limits: &AxisLimits,
) -> Result<GuardedTable, GuardError> {
    let points = part.wheel_table(request.points)?;
    let (points, segments, motion, deviation) = match request.form {
        TableForm::G1 => {
            let deviation = fit::g1_deviation(part, &points)?;
            let mut motion = fit::g1_motion(&points, limits.c_speed_rpm);
            let (a, j) = sampled_acceleration_and_jerk(&points, limits.c_speed_rpm);
            motion.acceleration_max_mm_s2 = Some(a);
            motion.jerk_max_mm_s3 = Some(j);
            (points, None, motion, deviation)
        }
        TableForm::Poly => {
            let (points, segments, deviation) =
                fit::fit_poly_within(part, &points, request.poly_tolerance_um)?;
            let motion = fit::poly_motion(&segments, limits.c_speed_rpm);
            (points, Some(segments), motion, deviation)
        }
    };
    let check = |quantity, value: Option<f64>, limit: f64, unit| match value {
        Some(v) if v > limit => Err(GuardError::Motion {
            quantity,
            value: v,
            limit,
            unit,
            c_speed_rpm: limits.c_speed_rpm,
        }),
        _ => Ok(()),
    };
    check(
        "velocity",
        Some(motion.velocity_max_mm_s),
        limits.velocity_mm_s,
        "mm/s",
    )?;
    check(
        "acceleration",
        motion.acceleration_max_mm_s2,
        limits.acceleration_mm_s2,
        "mm/s²",
    )?;
    check("jerk", motion.jerk_max_mm_s3, limits.jerk_mm_s3, "mm/s³")?;
    Ok(GuardedTable {
        points,
        segments,
        motion,
        deviation,
        timing_offset_deg: 0.0,
    })
}

/// What stays fixed in one lobe's loop.
#[derive(Debug, Clone, Copy)]
pub struct LobeLoop<'a> {
    pub nominal: &'a LiftTable,
    /// Geometry with the wheel radius the control currently believes in.
    pub feature: Feature,
    pub request: TableRequest,
    pub limits: &'a AxisLimits,
    pub params: &'a LearningParams,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CycleError {
    #[error("learning refused: {0}")]
    Learn(#[from] LearnError),
    #[error("table refused: {0}")]
    Guard(#[from] GuardError),
}

/// The table for the correction currently in `state` (the nominal one for a new state; after
/// a dressing, the same correction on the new wheel).
pub fn current_table(
    state: &LearningState,
    lobe: &LobeLoop<'_>,
) -> Result<GuardedTable, GuardError> {
    let commanded = commanded_lift(lobe.nominal, &state.correction_um)?;
    let mut table = guarded_table(lobe.feature, &commanded, lobe.request, lobe.limits)?;
    table.timing_offset_deg = state.timing_correction_deg;
    Ok(table)
}

/// One turn of the loop: learn from the part just measured, then regenerate and guard the
/// next table. `state` changes only when that table passed every guard; otherwise the
/// previous table stays in force and the error says why.
pub fn learn_and_regenerate(
    state: &mut LearningState,
    part: &PartError<'_>,
    lobe: &LobeLoop<'_>,
) -> Result<(StepOutcome, GuardedTable), CycleError> {
    let mut next = state.clone();
    let outcome = learn::step(&mut next, part, lobe.params)?;
    let table = current_table(&next, lobe)?;
    *state = next;
    Ok((outcome, table))
}

/// Largest |acceleration| and |jerk| of X from central differences over uniform table points.
fn sampled_acceleration_and_jerk(points: &[TablePoint], c_speed_rpm: f64) -> (f64, f64) {
    let n = points.len();
    let dt = 360.0 / n as f64 / (c_speed_rpm * 6.0);
    let x = |i: usize| points[i % n].x_mm;
    let (mut a_max, mut j_max) = (0.0f64, 0.0f64);
    for i in 0..n {
        let a = (x(i + 2) - 2.0 * x(i + 1) + x(i)) / (dt * dt);
        let j = (x(i + 3) - 3.0 * x(i + 2) + 3.0 * x(i + 1) - x(i)) / (dt * dt * dt);
        a_max = a_max.max(a.abs());
        j_max = j_max.max(j.abs());
    }
    (a_max, j_max)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_huge_wheel_radius_is_not_echoed_at_length() {
        let e = check_wheel_radius(1e308).unwrap_err().to_string();
        assert!(e.starts_with("wheel radius 1e308 mm"), "{e}");
        assert!(e.len() < 80, "{} characters: {e}", e.len());
        let small = check_wheel_radius(2.5).unwrap_err().to_string();
        assert!(small.starts_with("wheel radius 2.5 mm"), "{small}");
        let nan = check_wheel_radius(f64::NAN).unwrap_err().to_string();
        assert!(nan.starts_with("wheel radius NaN mm"), "{nan}");
    }

    use super::*;
    use crate::geometry::Follower;

    fn nominal() -> LiftTable {
        let angles: Vec<f64> = (0..360).map(f64::from).collect();
        let lifts = angles
            .iter()
            .map(|&a| {
                let x: f64 = (a - 180.0) / 80.0;
                if x.abs() < 1.0 {
                    8.0 * (1.0 - x * x).powi(3)
                } else {
                    0.0
                }
            })
            .collect();
        LiftTable::from_points(angles, lifts, "demo").unwrap()
    }

    /// The deepest correction anywhere, the base circle included: the corrected lift is a
    /// valid table at every position of it (the service once refused such a table on the
    /// demo exhaust lobe, by a rounding hair at 353°; the floor now has 1 nm of slack).
    #[test]
    fn the_deepest_correction_on_the_base_circle_is_a_valid_lift() {
        let text = include_str!("../../../config/parts/demo-exhaust-lobe.csv");
        let nominal = LiftTable::parse_csv(text, "exhaust").unwrap();
        for at in 0..360 {
            let correction: Vec<f64> = (0..360)
                .map(|j| if j == at { -3.7614780203374214 } else { -3.0 })
                .collect();
            let cmd =
                commanded_lift(&nominal, &correction).unwrap_or_else(|e| panic!("{at}°: {e}"));
            let j = cmd
                .angles_deg()
                .iter()
                .position(|a| *a == f64::from(at))
                .unwrap();
            let expected = nominal.lifts_mm()[j] - 3.7614780203374214e-3;
            assert!((cmd.lifts_mm()[j] - expected).abs() < 1e-12);
        }
    }

    #[test]
    fn commanded_lift_adds_the_correction_in_mm() {
        let correction: Vec<f64> = (0..360)
            .map(|j| -2.0 + (j as f64).to_radians().cos())
            .collect();
        let cmd = commanded_lift(&nominal(), &correction).unwrap();
        for (j, (c, n)) in cmd.lifts_mm().iter().zip(nominal().lifts_mm()).enumerate() {
            assert!((c - n - correction[j] / 1000.0).abs() < 1e-12);
        }
    }

    #[test]
    fn a_uniform_correction_shrinks_the_table_by_that_much_on_the_base_circle() {
        let geometry = CamGeometry {
            base_radius_mm: 20.0,
            follower: Follower::Flat,
            wheel_radius_mm: 250.0,
        };
        let request = TableRequest {
            points: 360,
            form: TableForm::Poly,
            poly_tolerance_um: 0.1,
        };
        let plain = guarded_table(
            Feature::Cam(geometry),
            &nominal(),
            request,
            &AxisLimits::default(),
        )
        .unwrap();
        let cmd = commanded_lift(&nominal(), &vec![-3.0; 360]).unwrap();
        let shrunk = guarded_table(
            Feature::Cam(geometry),
            &cmd,
            request,
            &AxisLimits::default(),
        )
        .unwrap();
        // A uniform lift change grows the outline uniformly. Where the wheel rests on the
        // base circle (the lobe spans 100°–260°) d moves by it exactly; on the lobe the wheel
        // centre is off the contact normal by γ (a few degrees), so d moves by δ/cos γ,
        // slightly more than δ.
        assert_eq!(plain.points.len(), shrunk.points.len());
        for (a, b) in plain.points.iter().zip(&shrunk.points) {
            let change_mm = a.x_mm - b.x_mm;
            if a.c_deg < 90.0 || a.c_deg > 270.0 {
                assert!(
                    (change_mm - 0.003).abs() < 1e-12,
                    "{}: {change_mm}",
                    a.c_deg
                );
            } else {
                assert!(
                    (0.003 - 1e-12..0.003 * 1.01).contains(&change_mm),
                    "{}: {change_mm}",
                    a.c_deg
                );
            }
        }
    }

    #[test]
    fn motion_guard_refuses_a_table_too_fast_for_the_axis() {
        let geometry = CamGeometry {
            base_radius_mm: 20.0,
            follower: Follower::Flat,
            wheel_radius_mm: 250.0,
        };
        let request = TableRequest {
            points: 360,
            form: TableForm::Poly,
            poly_tolerance_um: 0.1,
        };
        let limits = AxisLimits {
            velocity_mm_s: 20.0,
            ..AxisLimits::default()
        };
        let e = guarded_table(Feature::Cam(geometry), &nominal(), request, &limits).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("X velocity 30.9 mm/s exceeds the axis limit 20 mm/s"),
            "{e}"
        );
    }
}
