//! Every limit's usage along a plan, at every grid angle: the X motion by the chain rule
//! from the exact X(C) derivatives and the C motion of the time law, the removal rate from
//! the contact's surface speed.

use super::profile::{GRID_STEP_DEG, ProfileSample, ProfileSamples, removal_per_arc_mm};
use super::{BindingStretch, ConstantSpeed, SpeedLimits, TimeLaw, rad_s, rpm};
use std::f64::consts::TAU;

/// The limits of a plan, in the order of [`PlanPoint::usage`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Constraint {
    XVelocity = 0,
    XAcceleration = 1,
    XJerk = 2,
    CSpeed = 3,
    CAcceleration = 4,
    RemovalRate = 5,
}

impl Constraint {
    pub const ALL: [Constraint; 6] = [
        Constraint::XVelocity,
        Constraint::XAcceleration,
        Constraint::XJerk,
        Constraint::CSpeed,
        Constraint::CAcceleration,
        Constraint::RemovalRate,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Constraint::XVelocity => "X velocity",
            Constraint::XAcceleration => "X acceleration",
            Constraint::XJerk => "X jerk",
            Constraint::CSpeed => "C speed",
            Constraint::CAcceleration => "C acceleration",
            Constraint::RemovalRate => "removal rate Q'w",
        }
    }
}

/// One grid angle of a plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanPoint {
    pub c_deg: f64,
    pub speed_rpm: f64,
    /// Specific removal rate, mm³/(mm·s).
    pub q_w_mm3_mm_s: f64,
    /// Value over limit for each [`Constraint`] (1 = at the limit), indexed by `as usize`.
    pub usage: [f64; 6],
}

/// The speed-type bounds at one sample.
pub(crate) struct Usage;

impl Usage {
    /// The largest ω (rad/s) each limit allows at constant speed at `s`, with `margin` (≤ 1)
    /// taken off the speed, removal and jerk limits, and X acceleration `x_accel_mm_s2`.
    pub(crate) fn speed_limits(
        s: &ProfileSample,
        limits: &SpeedLimits,
        (margin, removal_margin): (f64, f64),
        x_accel_mm_s2: f64,
    ) -> [(Constraint, f64); 5] {
        let removal = removal_per_arc_mm(limits.stock_mm, s.curvature_per_mm) * s.surface_mm_rad;
        [
            (
                Constraint::XVelocity,
                margin * limits.x_velocity_mm_s / s.x1_mm_rad.abs(),
            ),
            (
                Constraint::XAcceleration,
                (x_accel_mm_s2 / s.x2_mm_rad2.abs()).sqrt(),
            ),
            (
                Constraint::XJerk,
                (margin * limits.x_jerk_mm_s3 / x3_max(s)).cbrt(),
            ),
            (Constraint::CSpeed, margin * rad_s(limits.c_max_speed_rpm)),
            (
                Constraint::RemovalRate,
                removal_margin * limits.q_w_max_mm3_mm_s / removal.abs(),
            ),
        ]
    }
}

fn x3_max(s: &ProfileSample) -> f64 {
    s.x3_sides_mm_rad3[0].abs().max(s.x3_sides_mm_rad3[1].abs())
}

/// The usage of every limit at sample `s` with C moving at ω, α, dα/dt (rad, s).
pub fn point_at(
    s: &ProfileSample,
    limits: &SpeedLimits,
    omega: f64,
    alpha: f64,
    jerk_c: f64,
) -> PlanPoint {
    let (x1, x2) = (s.x1_mm_rad, s.x2_mm_rad2);
    let q_w = removal_per_arc_mm(limits.stock_mm, s.curvature_per_mm) * s.surface_mm_rad * omega;
    let x_jerk = s
        .x3_sides_mm_rad3
        .map(|x3| (x3 * omega.powi(3) + 3.0 * x2 * omega * alpha + x1 * jerk_c).abs());
    let x_jerk = x_jerk[0].max(x_jerk[1]);
    PlanPoint {
        c_deg: s.c_deg,
        speed_rpm: rpm(omega),
        q_w_mm3_mm_s: q_w,
        usage: [
            (x1 * omega).abs() / limits.x_velocity_mm_s,
            (x2 * omega * omega + x1 * alpha).abs() / limits.x_acceleration_mm_s2,
            x_jerk / limits.x_jerk_mm_s3,
            omega / rad_s(limits.c_max_speed_rpm),
            alpha.abs() / limits.c_max_accel_deg_s2.to_radians(),
            q_w.abs() / limits.q_w_max_mm3_mm_s,
        ],
    }
}

/// Every grid angle along `law`.
pub fn evaluate(samples: &ProfileSamples, limits: &SpeedLimits, law: &TimeLaw) -> Vec<PlanPoint> {
    samples
        .samples
        .iter()
        .map(|s| {
            let m = law.at(law.time_at(s.c_deg));
            point_at(s, limits, m.omega_rad_s, m.alpha_rad_s2, m.jerk_rad_s3)
        })
        .collect()
}

/// Every grid angle at the constant speed `omega` (rad/s).
pub fn constant_points(
    samples: &ProfileSamples,
    limits: &SpeedLimits,
    omega: f64,
) -> Vec<PlanPoint> {
    samples
        .samples
        .iter()
        .map(|s| point_at(s, limits, omega, 0.0, 0.0))
        .collect()
}

/// The fastest constant C speed that keeps every limit at every grid angle.
pub fn fastest_constant(samples: &ProfileSamples, limits: &SpeedLimits) -> ConstantSpeed {
    let mut best = (f64::INFINITY, super::Constraint::CSpeed, 0.0);
    for s in &samples.samples {
        for (c, omega) in Usage::speed_limits(s, limits, (1.0, 1.0), limits.x_acceleration_mm_s2) {
            if omega < best.0 {
                best = (omega, c, s.c_deg);
            }
        }
    }
    let (omega, binding, at_c_deg) = best;
    ConstantSpeed {
        speed_rpm: rpm(omega),
        revolution_s: TAU / omega,
        binding,
        at_c_deg,
        points: constant_points(samples, limits, omega),
    }
}

/// Stretches of at least 0.5° where the most-used limit is above `threshold`.
pub fn binding_stretches(points: &[PlanPoint], threshold: f64) -> Vec<BindingStretch> {
    let top = |p: &PlanPoint| {
        let (c, u) = Constraint::ALL
            .iter()
            .map(|&c| (c, p.usage[c as usize]))
            .fold((Constraint::CSpeed, f64::NEG_INFINITY), |a, b| {
                if b.1 > a.1 { b } else { a }
            });
        (u >= threshold).then_some(c)
    };
    let labels: Vec<Option<Constraint>> = points.iter().map(top).collect();
    let mut runs: Vec<(Constraint, usize, usize)> = Vec::new();
    for (i, label) in labels.iter().enumerate() {
        match (label, runs.last_mut()) {
            (Some(c), Some(run)) if run.0 == *c && run.2 + 1 == i => run.2 = i,
            (Some(c), _) => runs.push((*c, i, i)),
            (None, _) => {}
        }
    }
    // A run through 360° is one stretch.
    let n = points.len();
    if runs.len() > 1 {
        let (first, last) = (runs[0], runs[runs.len() - 1]);
        if first.0 == last.0 && first.1 == 0 && last.2 == n - 1 {
            runs[0].1 = last.1;
            runs.pop();
        }
    }
    let min_len = (0.5 / GRID_STEP_DEG).round() as usize;
    runs.into_iter()
        .filter(|r| (r.2 + n - r.1) % n + 1 >= min_len)
        .map(|(constraint, from, to)| BindingStretch {
            constraint,
            from_deg: points[from].c_deg,
            to_deg: points[to].c_deg + GRID_STEP_DEG,
        })
        .collect()
}
