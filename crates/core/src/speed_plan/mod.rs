//! The C speed plan: C speed against C angle for a feature's finish revolution, as fast as
//! the X axis (velocity, acceleration, jerk), the C axis (speed, acceleration) and the
//! specific removal rate Q′w allow, closing on itself over 360°.
//!
//! How (see the manual's "Speed plan" chapter for the formulas):
//! 1. The exact X(C), its derivatives and the wheel–part contact are sampled every 0.1°
//!    ([`ProfileSamples`]).
//! 2. The phase-plane passes ([`topp`]) give the fastest ω(C) under the velocity-type limits
//!    (X velocity, C speed, Q′w, and the parts of X acceleration and jerk at constant speed)
//!    and the acceleration-type ones (X and C acceleration), all held with a small margin.
//! 3. C(t) is made a C² cubic B-spline in time from the profile ([`TimeLaw`]): that is the
//!    motion the control runs, with bounded jerk. Its pieces are no shorter than 1 ms, nor
//!    than the room for the written tables' rounding needs ([`shortest_piece_s`]).
//! 4. Jerk (third order, outside the phase plane) and the spline's departure from the
//!    passes' piecewise-constant acceleration are handled by iteration: every limit is
//!    evaluated on the 0.1° grid along the spline, exactly by the chain rule
//!    (Ẋ = X′ω, Ẍ = X″ω² + X′α, X⃛ = X‴ω³ + 3X″ωα + X′·dα/dt), and where one is exceeded
//!    the speed cap and the acceleration bounds are lowered over ±3° and the passes run
//!    again. Accelerations are accepted only below their limits less the room the written
//!    tables' rounding needs (`Room`, [`knots`]). A plan is returned only once every limit
//!    holds at every grid point; if that does not happen within the rounds allowed, the
//!    plan is the fastest constant speed, which holds them by construction.

mod check;
pub mod guard;
pub mod knots;
pub mod plot;
pub mod profile;
pub mod render;
pub mod tables;
pub mod time_law;
pub mod topp;

pub use check::{Constraint, PlanPoint};
pub use profile::{ProfileSample, ProfileSamples};
pub use time_law::{CMotion, TimeLaw};

use crate::geometry::{GeometryError, Part};
use check::{Usage, evaluate, fastest_constant};
use std::f64::consts::TAU;

/// The limits a plan keeps. Units in the names; Q′w in mm³ per mm of wheel width per second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedLimits {
    pub x_velocity_mm_s: f64,
    pub x_acceleration_mm_s2: f64,
    pub x_jerk_mm_s3: f64,
    pub c_max_speed_rpm: f64,
    pub c_max_accel_deg_s2: f64,
    /// Largest specific removal rate Q′w, mm³/(mm·s).
    pub q_w_max_mm3_mm_s: f64,
    /// Stock the finish revolution takes off, mm, as a uniform offset along the normal.
    pub stock_mm: f64,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpeedPlanError {
    #[error("speed plan limit {name} = {value} is invalid: must be a finite number > 0")]
    InvalidLimit { name: &'static str, value: f64 },
    #[error("speed plan: {0}")]
    Geometry(#[from] GeometryError),
}

impl SpeedLimits {
    /// Every limit must be finite and positive; the first that is not is named.
    pub fn check(&self) -> Result<(), SpeedPlanError> {
        let named = [
            ("x_velocity_mm_s", self.x_velocity_mm_s),
            ("x_acceleration_mm_s2", self.x_acceleration_mm_s2),
            ("x_jerk_mm_s3", self.x_jerk_mm_s3),
            ("c_max_speed_rpm", self.c_max_speed_rpm),
            ("c_max_accel_deg_s2", self.c_max_accel_deg_s2),
            ("q_w_max_mm3_mm_s", self.q_w_max_mm3_mm_s),
            ("stock_mm", self.stock_mm),
        ];
        match named.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
            Some(&(name, value)) => Err(SpeedPlanError::InvalidLimit { name, value }),
            None => Ok(()),
        }
    }
}

/// A recipe's `[speed_plan]`: whether the finish revolution runs a planned C speed, and the
/// removal limit it keeps (the X and C limits come from `[axis_limits]`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SpeedPlanSettings {
    pub enabled: bool,
    /// Largest specific removal rate Q′w, mm³/(mm·s).
    pub q_w_max_mm3_mm_s: f64,
    /// Stock the finish revolution removes, mm.
    pub stock_mm: f64,
}

impl Default for SpeedPlanSettings {
    fn default() -> Self {
        Self {
            enabled: false,
            q_w_max_mm3_mm_s: 2.36,
            stock_mm: 0.02,
        }
    }
}

impl SpeedPlanSettings {
    /// The plan's limits: these with the X and C limits of `axis`.
    pub fn limits(&self, axis: &crate::compensate::AxisLimits) -> SpeedLimits {
        SpeedLimits {
            x_velocity_mm_s: axis.velocity_mm_s,
            x_acceleration_mm_s2: axis.acceleration_mm_s2,
            x_jerk_mm_s3: axis.jerk_mm_s3,
            c_max_speed_rpm: axis.c_max_speed_rpm,
            c_max_accel_deg_s2: axis.c_max_accel_deg_s2,
            q_w_max_mm3_mm_s: self.q_w_max_mm3_mm_s,
            stock_mm: self.stock_mm,
        }
    }
}

/// The fastest constant C speed under the same limits, for comparison.
#[derive(Debug, Clone, PartialEq)]
pub struct ConstantSpeed {
    pub speed_rpm: f64,
    pub revolution_s: f64,
    /// The limit reached first, and where.
    pub binding: Constraint,
    pub at_c_deg: f64,
    /// Every grid angle at that speed.
    pub points: Vec<PlanPoint>,
}

/// A planned finish revolution.
#[derive(Debug, Clone)]
pub struct SpeedPlan {
    /// Every grid angle (0.1°) along the plan: speed, Q′w and each limit's usage.
    pub points: Vec<PlanPoint>,
    pub law: TimeLaw,
    pub constant: ConstantSpeed,
    /// True when no varying plan held every limit and the plan is the constant speed.
    pub is_constant: bool,
    /// Rounds of the passes it took.
    pub rounds: usize,
}

/// A stretch of the revolution where one limit is (nearly) reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BindingStretch {
    pub constraint: Constraint,
    pub from_deg: f64,
    pub to_deg: f64,
}

/// Margins the passes keep below each limit, so the spline through their time law lands
/// inside: 0.5 % on speeds, 0.1 % on removal, 2 % on accelerations (the spline's acceleration
/// overshoots the passes' bang-bang steps by a few percent).
const SPEED_MARGIN: f64 = 0.995;
/// The removal rate's margin is smaller: Q′w is first order in ω and its profile varies
/// slowly, so the spline keeps it within 0.1 % (every 0.1° grid angle is checked all the
/// same). Where removal binds all round (a crankpin) this margin is the whole gap to the
/// removal bound: 0.995 left 0.4 points of the pin's 12.1 % on the table.
const REMOVAL_MARGIN: f64 = 0.999;
const ACCEL_MARGIN: f64 = 0.98;
/// Largest X jerk usage accepted at the grid angles.
const JERK_ACCEPT: f64 = 0.98;
/// Rounds of lowering before the plan falls back to constant speed.
const MAX_ROUNDS: usize = 40;
/// Most control points of the time law per revolution: one per 0.5° on average, so the law's
/// averaging spans about 2° of the profile.
pub const LAW_POINTS: usize = 720;
/// Shortest piece of the time law, s, whatever the limits. A piece shorter than the
/// control's interpolation cycle (0.5–2 ms) holds detail the control cannot run, and the
/// B-spline's jerk (its acceleration's change over about two pieces) grows as the pieces
/// shorten: with 720 pieces in a 0.21 s revolution (0.29 ms each) the X jerk where C's
/// acceleration turns was 2.4 times its limit, and lowering the speed round it until it
/// held cost 12 % of the revolution. At 1 ms it holds at once.
pub const MIN_PIECE_S: f64 = 1e-3;
/// Largest share of an acceleration limit the rounding of the written tables may take
/// (see [`Room`]); the pieces are made long enough for it.
const ROOM_SHARE: f64 = 0.02;
/// Fewest control points of the time law per revolution.
const MIN_LAW_POINTS: usize = 36;

/// Shortest piece of the time law under `limits`, s: [`MIN_PIECE_S`], or longer where the
/// rounding of the written tables would otherwise take more than [`ROOM_SHARE`] of an
/// acceleration limit (q/(h·Δ) ≤ share·a, so h ≥ q/(share·Δ·a)): 2.8 ms under the demo's
/// 3600 °/s² for C, 5 ms under 2000 mm/s² for X.
pub fn shortest_piece_s(limits: &SpeedLimits) -> f64 {
    let a = limits.x_acceleration_mm_s2.min(limits.c_max_accel_deg_s2);
    MIN_PIECE_S.max(WRITTEN_RESOLUTION / (ROOM_SHARE * SHORTEST_CYCLE_S * a))
}

/// Control points of the time law of a revolution of `period_s`: as many as [`LAW_POINTS`]
/// allows with no piece shorter than `shortest_s`, and a count that divides 3 600 000, so
/// every knot of VA (360°/count) is exact in the table's four decimals (a rounded knot would
/// change a piece's length, and with it the speed, by up to 1e-4 of the piece's own speed).
pub fn law_points(period_s: f64, shortest_s: f64) -> usize {
    let most = (period_s / shortest_s).floor();
    let most = if most.is_finite() {
        most as usize
    } else {
        LAW_POINTS
    };
    (MIN_LAW_POINTS..=most.clamp(MIN_LAW_POINTS, LAW_POINTS))
        .rev()
        .find(|m| 3_600_000 % m == 0)
        .unwrap_or(MIN_LAW_POINTS)
}

/// Half-width of the stretch lowered round a violation, grid nodes (3°).
const LOWER_HALF_WIDTH: usize = 30;

impl SpeedPlan {
    pub fn revolution_s(&self) -> f64 {
        self.law.period_s()
    }

    /// Fraction of the constant speed's revolution time saved (0.25 = 25 % shorter).
    pub fn time_saved(&self) -> f64 {
        1.0 - self.revolution_s() / self.constant.revolution_s
    }

    /// Largest usage of each limit along the plan.
    pub fn max_usage(&self, constraint: Constraint) -> f64 {
        self.points
            .iter()
            .map(|p| p.usage[constraint as usize])
            .fold(0.0, f64::max)
    }

    /// The stretches (at least 0.5° long) where the limit used most is used above
    /// `threshold` (e.g. 0.97), in angle order.
    pub fn binding_stretches(&self, threshold: f64) -> Vec<BindingStretch> {
        check::binding_stretches(&self.points, threshold)
    }
}

/// Plans the finish revolution of `part` under `limits`.
pub fn plan(part: &Part, limits: &SpeedLimits) -> Result<SpeedPlan, SpeedPlanError> {
    limits.check()?;
    let samples = ProfileSamples::new(part)?;
    Ok(plan_samples(&samples, limits))
}

/// Plans from sampled geometry (limits already checked).
pub fn plan_samples(samples: &ProfileSamples, limits: &SpeedLimits) -> SpeedPlan {
    let n = samples.samples.len();
    let constant = fastest_constant(samples, limits);
    let mut omega_cap = vec![f64::INFINITY; n];
    let mut accel_scale = vec![1.0; n];
    for round in 1..=MAX_ROUNDS {
        let problem = phase_problem(samples, limits, &omega_cap, &accel_scale, 1);
        let b = topp::time_optimal_profile(&problem);
        let Some(law) = time_law_of(&b, problem.step_rad, shortest_piece_s(limits)) else {
            break;
        };
        let points = evaluate(samples, limits, &law);
        let room = Room::of(limits, law.step_s());
        let worst = points
            .iter()
            .flat_map(|p| Constraint::ALL.map(|c| room.accepted(c, p.usage[c as usize])))
            .fold(0.0, f64::max);
        if worst <= 1.0 {
            if law.period_s() >= constant.revolution_s {
                break;
            }
            return SpeedPlan {
                points,
                law,
                constant,
                is_constant: false,
                rounds: round,
            };
        }
        lower_where_exceeded(&points, &room, &mut omega_cap, &mut accel_scale);
    }
    constant_plan(constant)
}

/// The phase-plane problem on every `every`-th grid node (1 for the plan; coarser for the
/// independent check), with each node's speed cap (rad/s) and acceleration scale applied.
pub fn phase_problem(
    samples: &ProfileSamples,
    limits: &SpeedLimits,
    omega_cap: &[f64],
    accel_scale: &[f64],
    every: usize,
) -> topp::PhaseProblem {
    let step_rad = (profile::GRID_STEP_DEG * every as f64).to_radians();
    let nodes = samples
        .samples
        .iter()
        .enumerate()
        .step_by(every)
        .map(|(i, s)| {
            let a = limits.x_acceleration_mm_s2 * ACCEL_MARGIN * accel_scale[i];
            let speed_limits = Usage::speed_limits(s, limits, (SPEED_MARGIN, REMOVAL_MARGIN), a);
            let omega = speed_limits
                .iter()
                .fold(omega_cap[i], |m, &(_, w)| m.min(w));
            topp::PhaseNode {
                b_max: omega * omega,
                x1: s.x1_mm_rad,
                x2: s.x2_mm_rad2,
                x_accel_max: a,
                c_accel_max: limits.c_max_accel_deg_s2.to_radians() * ACCEL_MARGIN * accel_scale[i],
            }
        })
        .collect();
    topp::PhaseProblem { step_rad, nodes }
}

/// The time law of the profile: its C at [`law_points`] equal time steps as the B-spline's
/// control points. On each grid interval ω² is linear in C, so α is constant there and C(t)
/// is a parabola, evaluated exactly. None when the profile stops somewhere (zero speed: no
/// finite revolution).
fn time_law_of(b: &[f64], step_rad: f64, shortest_s: f64) -> Option<TimeLaw> {
    let n = b.len();
    let omega: Vec<f64> = b.iter().map(|v| v.max(0.0).sqrt()).collect();
    let mut t = Vec::with_capacity(n + 1);
    t.push(0.0);
    for i in 0..n {
        let w = omega[i] + omega[(i + 1) % n];
        if w.is_nan() || w <= 0.0 {
            return None;
        }
        t.push(t[i] + 2.0 * step_rad / w);
    }
    let period = t[n];
    if !period.is_finite() {
        return None;
    }
    let points = law_points(period, shortest_s);
    let mut i = 0;
    let c: Vec<f64> = (0..points)
        .map(|k| {
            let tk = period * k as f64 / points as f64;
            while i + 1 < n && t[i + 1] <= tk {
                i += 1;
            }
            let dt = t[i + 1] - t[i];
            let alpha = (omega[(i + 1) % n] - omega[i]) / dt;
            let s = tk - t[i];
            i as f64 * step_rad + omega[i] * s + 0.5 * alpha * s * s
        })
        .collect();
    Some(TimeLaw::new(&c, period))
}

/// Lowers the speed cap and the acceleration bounds round every grid node where a limit is
/// exceeded: the cap to the speed there times the usage's own root (a speed limit scales with
/// ω, an acceleration with ω², jerk with ω³), 1 % more (0.5 % for an acceleration), and for
/// accelerations and jerk the acceleration bounds by the usage, 1.5 % more (accelerations)
/// or 3 % (jerk). An acceleration is lowered less than before the rounding's room was kept
/// (1 % and 3 %): it is now mostly exceeded by a fraction of a percent, and lowering it 3 %
/// round ±3° cost 0.3 % of the X-bound revolution.
fn lower_where_exceeded(
    points: &[PlanPoint],
    room: &Room,
    omega_cap: &mut [f64],
    accel_scale: &mut [f64],
) {
    let n = points.len();
    let accel_before = accel_scale.to_vec();
    for (i, p) in points.iter().enumerate() {
        for c in Constraint::ALL {
            let u = room.accepted(c, p.usage[c as usize]);
            if u <= 1.0 {
                continue;
            }
            let (speed_factor, accel_factor) = match c {
                Constraint::XVelocity | Constraint::CSpeed | Constraint::RemovalRate => {
                    (0.99 / u, 1.0)
                }
                Constraint::XAcceleration | Constraint::CAcceleration => {
                    (0.995 / u.sqrt(), 0.985 / u)
                }
                Constraint::XJerk => (0.99 / u.cbrt(), 0.97 / u),
            };
            let omega = rad_s(p.speed_rpm) * speed_factor;
            for d in 0..=2 * LOWER_HALF_WIDTH {
                let k = (i + n + d - LOWER_HALF_WIDTH) % n;
                omega_cap[k] = omega_cap[k].min(omega);
                accel_scale[k] = accel_scale[k].min(accel_before[i] * accel_factor);
            }
        }
    }
}

/// The share of each acceleration limit left for the rounding of the written tables: the
/// knot values are written to [`WRITTEN_RESOLUTION`], the control takes each segment's slope
/// from them, and a slope step s at a joint shows as s/Δ in the acceleration sampled at an
/// interpolation cycle Δ. With the knots chosen up or down so the steps are smallest
/// ([`knots::knot_values`]), the steps stay within about one resolution step per piece
/// (q/h for a piece of h seconds), so the plan keeps q/(h·Δ) free at the shortest cycle,
/// [`SHORTEST_CYCLE_S`]: on the demo intake lobe (h = 3 ms) 67 °/s², 1.9 % of its C
/// acceleration limit; where the X axis binds (h = 1.05 ms) 190 mm/s², 1.9 % of X's. The
/// pieces are made long enough that it is never above 2 % ([`shortest_piece_s`]).
struct Room {
    x_accel: f64,
    c_accel: f64,
}

/// Resolution of the values a speed-plan table writes: four decimals of mm and degrees (the
/// tables' default and the CLI's, a control with `INT_INCR_PER_MM` = 10 000).
pub const WRITTEN_RESOLUTION: f64 = 1e-4;
/// The shortest interpolation cycle the written tables are checked at, s.
pub const SHORTEST_CYCLE_S: f64 = 0.5e-3;

impl Room {
    fn of(limits: &SpeedLimits, piece_s: f64) -> Self {
        let rounding = WRITTEN_RESOLUTION / (piece_s * SHORTEST_CYCLE_S);
        Self {
            x_accel: (rounding / limits.x_acceleration_mm_s2).min(0.5),
            c_accel: (rounding / limits.c_max_accel_deg_s2).min(0.5),
        }
    }

    /// Usage as the acceptance test sees it: accelerations with the rounding's share kept
    /// free; the jerk, checked at the grid angles only while it varies between them by up
    /// to about 1 % of its limit (through X‴ and the C jerk's steps at the law's knots),
    /// within 98 % there.
    fn accepted(&self, c: Constraint, usage: f64) -> f64 {
        match c {
            Constraint::XJerk => usage / JERK_ACCEPT,
            Constraint::XAcceleration => usage / (1.0 - self.x_accel),
            Constraint::CAcceleration => usage / (1.0 - self.c_accel),
            _ => usage,
        }
    }
}

/// The constant speed as a plan.
fn constant_plan(constant: ConstantSpeed) -> SpeedPlan {
    SpeedPlan {
        points: constant.points.clone(),
        law: TimeLaw::constant(constant.revolution_s, LAW_POINTS),
        constant,
        is_constant: true,
        rounds: MAX_ROUNDS,
    }
}

/// ω in rad/s of a speed in rev/min.
pub fn rad_s(rpm: f64) -> f64 {
    rpm * TAU / 60.0
}

/// A speed in rev/min of ω in rad/s.
pub fn rpm(rad_s: f64) -> f64 {
    rad_s * 60.0 / TAU
}
