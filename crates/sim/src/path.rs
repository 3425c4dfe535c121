//! The machine's real wheel-centre path, evaluated exactly with its derivatives, and the
//! small plane-vector helpers the outline construction uses.

use super::plan::PlanLag;
use super::table::TablePath;

/// The machine's real wheel-centre path: d(c) = X_table(c − lag) + x_zero + Σ harmonics,
/// W(c) = d(c)·u(c), and the wheel radius that runs along it. With a speed plan the table
/// is over the virtual axis and X at c is the plan's (see [`PlanLag`]); `lag_rad` is then
/// only the lag that does not come from the X servo.
#[derive(Debug, Clone)]
pub(crate) struct MachinePath<'a> {
    pub table: &'a TablePath,
    pub lag_rad: f64,
    pub plan: Option<PlanLag<'a>>,
    pub x_zero_mm: f64,
    /// (order k, amplitude mm, phase rad).
    pub harmonics: Vec<(f64, f64, f64)>,
    pub wheel_radius_mm: f64,
}

/// Path and envelope at one parameter c (radians).
#[derive(Debug, Clone, Copy)]
pub(crate) struct PathSample {
    pub w: [f64; 2],
    /// Path curvature, 1/mm (positive where the path turns about the axis' side).
    pub kappa: f64,
    /// Unit outward normal of the path (and of the envelope).
    pub n: [f64; 2],
    /// Envelope point W − R·N.
    pub p: [f64; 2],
    /// dp/dc = W'·(1 − R·κ), mm/rad.
    pub dp: [f64; 2],
}

impl MachinePath<'_> {
    /// The path of table segment `i` at `c` (radians; the segment's own C range shifted by
    /// the lag, or slightly beyond it as its analytic continuation).
    pub(crate) fn at(&self, i: usize, c: f64) -> PathSample {
        let xs = match &self.plan {
            None => self.table.eval(i, c - self.lag_rad),
            Some(plan) => plan.x_at(self.table, i, c - self.lag_rad),
        };
        let (mut d, mut d1, mut d2) = (xs.x + self.x_zero_mm, xs.x1, xs.x2);
        for &(k, a, phi) in &self.harmonics {
            let (s, co) = (k * c + phi).sin_cos();
            d += a * co;
            d1 -= a * k * s;
            d2 -= a * k * k * co;
        }
        let (sin, cos) = c.sin_cos();
        let u = [cos, sin];
        let up = [-sin, cos];
        let w = scale(u, d);
        let dw = add(scale(u, d1), scale(up, d));
        let speed2 = d * d + d1 * d1;
        let speed = speed2.sqrt();
        let kappa = (speed2 + d1 * d1 - d * d2) / (speed2 * speed);
        let n = scale(sub(scale(u, d), scale(up, d1)), 1.0 / speed);
        let r = self.wheel_radius_mm;
        PathSample {
            w,
            kappa,
            n,
            p: sub(w, scale(n, r)),
            dp: scale(dw, 1.0 - r * kappa),
        }
    }

    /// C range of segment `i` of the real path (the table's, shifted by the lag), radians.
    pub(crate) fn range(&self, i: usize) -> (f64, f64) {
        let (a, b) = match &self.plan {
            None => self.table.range_rad(i),
            Some(plan) => plan.range(self.table, i),
        };
        (a + self.lag_rad, b + self.lag_rad)
    }
}

pub(crate) fn angle(v: [f64; 2]) -> f64 {
    v[1].atan2(v[0])
}

pub(crate) fn add(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] + b[0], a[1] + b[1]]
}

pub(crate) fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

pub(crate) fn scale(a: [f64; 2], k: f64) -> [f64; 2] {
    [a[0] * k, a[1] * k]
}

pub(crate) fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

pub(crate) fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

pub(crate) fn norm(a: [f64; 2]) -> f64 {
    a[0].hypot(a[1])
}
