//! The planned motion of C in time, as the control runs it: C(t) is a periodic uniform cubic
//! B-spline in time whose control points are the phase-plane profile's C at equal time
//! steps, plus the mean speed (C gains 360° every revolution).
//!
//! Why a B-spline and not the interpolating spline: the profile's acceleration is bang-bang
//! (it jumps between bounds), and an interpolating cubic overshoots such steps by a quarter
//! of the jump. The B-spline's acceleration is, at every instant, a weighted average (weights
//! ≥ 0, summing to 1) of the control points' second differences over h², each of which is an
//! average of the profile's acceleration over two steps; so it never leaves the range the
//! profile's acceleration takes within two steps. Its speed is likewise an average of the
//! profile's speed, and its jerk is constant on each step and bounded by 2·|α|max/h. It is
//! C² (speed and acceleration continuous) and each step is one cubic: a POLY curve table
//! C = f(VA) under a virtual axis at constant speed runs exactly this.

use std::f64::consts::TAU;

/// C, its speed, acceleration and jerk at one time (radians and seconds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CMotion {
    pub c_rad: f64,
    pub omega_rad_s: f64,
    pub alpha_rad_s2: f64,
    pub jerk_rad_s3: f64,
}

/// C(t) over one revolution of `period_s`.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeLaw {
    /// Control points of C(t) − 2π·t/T at t = k·h, radians, periodic.
    residual: Vec<f64>,
    period_s: f64,
    /// C of the spline at each knot t = k·h, radians, increasing (for locating an angle).
    knot_c_rad: Vec<f64>,
}

impl TimeLaw {
    /// The law with control points `c_rad[k]` (C at t = k·T/M, unwrapped, c_rad[0] = 0 and
    /// increasing, the next period starting at 2π) over `period_s`. At least 4 points.
    pub fn new(c_rad: &[f64], period_s: f64) -> Self {
        let m = c_rad.len();
        let residual: Vec<f64> = (0..m)
            .map(|k| c_rad[k] - TAU * k as f64 / m as f64)
            .collect();
        let mut law = Self {
            residual,
            period_s,
            knot_c_rad: Vec::new(),
        };
        law.knot_c_rad = (0..m)
            .map(|k| law.at(k as f64 * law.step_s()).c_rad)
            .collect();
        law
    }

    /// A constant speed: one revolution in `period_s`.
    pub fn constant(period_s: f64, points: usize) -> Self {
        let m = points.max(4);
        let c: Vec<f64> = (0..m).map(|k| TAU * k as f64 / m as f64).collect();
        Self::new(&c, period_s)
    }

    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// Time between knots, s.
    pub fn step_s(&self) -> f64 {
        self.period_s / self.residual.len() as f64
    }

    /// Number of cubic pieces (knot intervals) per revolution.
    pub fn pieces(&self) -> usize {
        self.residual.len()
    }

    /// Piece `k` (from t = k·h to (k+1)·h) of C(t) in degrees as c0 + c1·u + c2·u² + c3·u³,
    /// u ∈ [0, 1]: the form a POLY block takes. C(0) of piece 0 is near 0°; C runs on past
    /// 360° in the last pieces.
    pub fn piece_deg(&self, k: usize) -> [f64; 4] {
        let m = self.residual.len();
        let p = |j: isize| {
            let i = (k as isize + j).rem_euclid(m as isize) as usize;
            // Unwrapped: the mean slope carries points beyond the period a turn further.
            self.residual[i] + TAU * (k as isize + j) as f64 / m as f64
        };
        let (p0, p1, p2, p3) = (p(-1), p(0), p(1), p(2));
        let c = [
            (p0 + 4.0 * p1 + p2) / 6.0,
            (p2 - p0) / 2.0,
            (p0 - 2.0 * p1 + p2) / 2.0,
            (-p0 + 3.0 * p1 - 3.0 * p2 + p3) / 6.0,
        ];
        c.map(f64::to_degrees)
    }

    /// C and its derivatives at time `t_s` (C unwrapped: it runs on past 2π after a period).
    pub fn at(&self, t_s: f64) -> CMotion {
        let m = self.residual.len();
        let h = self.step_s();
        let turns = (t_s / self.period_s).floor();
        let local = t_s - turns * self.period_s;
        let k = ((local / h).floor() as usize).min(m - 1);
        let u = local / h - k as f64;
        let r = |j: isize| self.residual[(k as isize + j).rem_euclid(m as isize) as usize];
        let (p0, p1, p2, p3) = (r(-1), r(0), r(1), r(2));
        let value = ((1.0 - u).powi(3) * p0
            + (3.0 * u.powi(3) - 6.0 * u * u + 4.0) * p1
            + (-3.0 * u.powi(3) + 3.0 * u * u + 3.0 * u + 1.0) * p2
            + u.powi(3) * p3)
            / 6.0;
        let d1 = (-(1.0 - u).powi(2) * p0
            + (3.0 * u * u - 4.0 * u) * p1
            + (-3.0 * u * u + 2.0 * u + 1.0) * p2
            + u * u * p3)
            / (2.0 * h);
        let d2 = ((1.0 - u) * p0 + (3.0 * u - 2.0) * p1 + (1.0 - 3.0 * u) * p2 + u * p3) / (h * h);
        let d3 = (-p0 + 3.0 * p1 - 3.0 * p2 + p3) / (h * h * h);
        let mean = TAU / self.period_s;
        CMotion {
            c_rad: value + mean * t_s,
            omega_rad_s: d1 + mean,
            alpha_rad_s2: d2,
            jerk_rad_s3: d3,
        }
    }

    /// The time in [0, T) at which C reaches `c_deg` (reduced into the revolution). C(t) is
    /// increasing wherever the plan was checked (ω > 0), so the knots bracket the answer;
    /// Newton's method is kept inside the bracket by bisection.
    pub fn time_at(&self, c_deg: f64) -> f64 {
        let first = self.knot_c_rad[0];
        let target = first + (c_deg.to_radians() - first).rem_euclid(TAU);
        let k = self.knot_c_rad.partition_point(|&c| c <= target).max(1) - 1;
        let h = self.step_s();
        let (mut lo, mut hi) = (k as f64 * h, (k + 1) as f64 * h);
        let mut t = 0.5 * (lo + hi);
        for _ in 0..80 {
            let m = self.at(t);
            let f = m.c_rad - target;
            if f.abs() < 1e-13 || hi - lo < 1e-15 * self.period_s {
                break;
            }
            if f > 0.0 {
                hi = t;
            } else {
                lo = t;
            }
            let newton = t - f / m.omega_rad_s;
            t = if m.omega_rad_s > 0.0 && newton > lo && newton < hi {
                newton
            } else {
                0.5 * (lo + hi)
            };
        }
        t.rem_euclid(self.period_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_at_inverts_a_constant_law() {
        let law = TimeLaw::constant(2.0, 360);
        for c in [0.0, 0.3, 1.7, 359.95] {
            let t = law.time_at(c);
            assert!((t - 2.0 * c / 360.0).abs() < 1e-12, "{c}: {t}");
        }
    }
}
