//! Periodic cubic interpolating splines (C2) on uniform or non-uniform knots.
//!
//! Used for lift tables (ψ → lift) and for POLY curve tables (C → X). The spline passes
//! through every knot, and value, slope and curvature are continuous everywhere, including
//! across the period boundary.

/// A periodic cubic spline `s(x)` with `s(x + period) = s(x)`.
#[derive(Debug, Clone)]
pub(crate) struct PeriodicSpline {
    /// Knot positions, strictly increasing, spanning less than one period.
    knots: Vec<f64>,
    period: f64,
    /// Per interval i (from knot i to knot i+1, the last one wrapping to knots[0] + period):
    /// `s = c0 + c1·t + c2·t² + c3·t³` with `t = x − knots[i]`.
    coeffs: Vec<[f64; 4]>,
    /// Knot spacing when the knots are uniform, for O(1) interval lookup.
    uniform_step: Option<f64>,
}

/// Value and first three derivatives of a spline at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SplineSample {
    pub value: f64,
    pub d1: f64,
    pub d2: f64,
    pub d3: f64,
}

impl PeriodicSpline {
    /// Builds the interpolating periodic spline through `(knots[i], values[i])`.
    ///
    /// Contract (checked by callers, asserted here in debug builds): at least 3 knots,
    /// strictly increasing, `knots[n−1] − knots[0] < period`, all finite.
    pub fn new(knots: &[f64], values: &[f64], period: f64) -> Self {
        let n = knots.len();
        debug_assert!(n >= 3 && values.len() == n);
        debug_assert!(knots.windows(2).all(|w| w[1] > w[0]));
        debug_assert!(knots[n - 1] - knots[0] < period);
        let h: Vec<f64> = (0..n)
            .map(|i| next_knot(knots, period, i) - knots[i])
            .collect();
        let slope = |i: usize| (values[(i + 1) % n] - values[i]) / h[i];
        // Second derivatives M_i from the cyclic tridiagonal system
        // h[i−1]·M[i−1] + 2(h[i−1] + h[i])·M[i] + h[i]·M[i+1] = 6(slope[i] − slope[i−1]).
        let sub: Vec<f64> = (0..n).map(|i| h[(i + n - 1) % n]).collect();
        let diag: Vec<f64> = (0..n).map(|i| 2.0 * (h[(i + n - 1) % n] + h[i])).collect();
        let sup: Vec<f64> = h.clone();
        let rhs: Vec<f64> = (0..n)
            .map(|i| 6.0 * (slope(i) - slope((i + n - 1) % n)))
            .collect();
        let m = solve_cyclic_tridiagonal(&sub, &diag, &sup, &rhs);
        let coeffs = (0..n)
            .map(|i| {
                let (m0, m1) = (m[i], m[(i + 1) % n]);
                [
                    values[i],
                    slope(i) - h[i] * (2.0 * m0 + m1) / 6.0,
                    m0 / 2.0,
                    (m1 - m0) / (6.0 * h[i]),
                ]
            })
            .collect();
        let step = period / n as f64;
        let uniform = h.iter().all(|&hi| (hi - step).abs() <= 1e-12 * period);
        Self {
            knots: knots.to_vec(),
            period,
            coeffs,
            uniform_step: uniform.then_some(step),
        }
    }

    pub(crate) fn knots(&self) -> &[f64] {
        &self.knots
    }

    /// Polynomial coefficients of interval `i`, in powers of `x − knots[i]`.
    pub(crate) fn interval_coeffs(&self, i: usize) -> [f64; 4] {
        self.coeffs[i]
    }

    /// Length of interval `i` (the last one wraps around the period).
    pub(crate) fn interval_len(&self, i: usize) -> f64 {
        next_knot(&self.knots, self.period, i) - self.knots[i]
    }

    /// Value and derivatives at `x` (any real; reduced into the period).
    pub fn eval(&self, x: f64) -> SplineSample {
        let (i, t) = self.locate(x);
        let [c0, c1, c2, c3] = self.coeffs[i];
        SplineSample {
            value: c0 + t * (c1 + t * (c2 + t * c3)),
            d1: c1 + t * (2.0 * c2 + t * 3.0 * c3),
            d2: 2.0 * c2 + 6.0 * c3 * t,
            d3: 6.0 * c3,
        }
    }

    /// Interval index and offset into it for `x`.
    fn locate(&self, x: f64) -> (usize, f64) {
        let x0 = self.knots[0];
        // Callers are almost always within one period of the first knot: wrap by one add or
        // subtract and keep the (slow, software) remainder for the rest.
        let mut r = x - x0;
        if r < 0.0 {
            r += self.period;
        } else if r >= self.period {
            r -= self.period;
        }
        if !(0.0..self.period).contains(&r) {
            r = (x - x0).rem_euclid(self.period);
        }
        let n = self.knots.len();
        let i = match self.uniform_step {
            Some(step) => ((r / step) as usize).min(n - 1),
            None => self
                .knots
                .partition_point(|&k| k - x0 <= r)
                .saturating_sub(1),
        };
        (i, r - (self.knots[i] - x0))
    }
}

fn next_knot(knots: &[f64], period: f64, i: usize) -> f64 {
    if i + 1 < knots.len() {
        knots[i + 1]
    } else {
        knots[0] + period
    }
}

/// Solves a cyclic tridiagonal system: row i reads
/// `sub[i]·x[i−1] + diag[i]·x[i] + sup[i]·x[i+1] = rhs[i]` with indices modulo n.
/// Sherman–Morrison on top of the Thomas algorithm; the spline systems are strictly
/// diagonally dominant, so no pivoting is needed.
fn solve_cyclic_tridiagonal(sub: &[f64], diag: &[f64], sup: &[f64], rhs: &[f64]) -> Vec<f64> {
    let n = diag.len();
    let (beta, alpha) = (sub[0], sup[n - 1]); // corners A[0][n−1] and A[n−1][0]
    let gamma = -diag[0];
    let mut bb = diag.to_vec();
    bb[0] = diag[0] - gamma;
    bb[n - 1] = diag[n - 1] - alpha * beta / gamma;
    let x = solve_tridiagonal(sub, &bb, sup, rhs);
    let mut u = vec![0.0; n];
    u[0] = gamma;
    u[n - 1] = alpha;
    let z = solve_tridiagonal(sub, &bb, sup, &u);
    let fact = (x[0] + beta * x[n - 1] / gamma) / (1.0 + z[0] + beta * z[n - 1] / gamma);
    x.iter().zip(&z).map(|(xi, zi)| xi - fact * zi).collect()
}

/// Thomas algorithm; `sub[0]` and `sup[n−1]` are ignored.
fn solve_tridiagonal(sub: &[f64], diag: &[f64], sup: &[f64], rhs: &[f64]) -> Vec<f64> {
    let n = diag.len();
    let mut c_prime = vec![0.0; n];
    let mut x = vec![0.0; n];
    let mut denom = diag[0];
    x[0] = rhs[0] / denom;
    for i in 1..n {
        c_prime[i - 1] = sup[i - 1] / denom;
        denom = diag[i] - sub[i] * c_prime[i - 1];
        x[i] = (rhs[i] - sub[i] * x[i - 1]) / denom;
    }
    for i in (0..n - 1).rev() {
        x[i] -= c_prime[i] * x[i + 1];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// A trigonometric polynomial is periodic and smooth; the spline must reproduce it to
    /// O(h⁴) in value. With h = 1° (0.01745 rad) and f'''' ≤ 3⁴·0.5 + 1 ≈ 41.5, the classic
    /// bound 5/384·h⁴·max|f''''| gives 5.0e-8, so 1e-7 is a fair tolerance.
    #[test]
    fn reproduces_smooth_periodic_function_on_uniform_knots() {
        let f = |x: f64| x.sin() + 0.5 * (3.0 * x).cos();
        let knots: Vec<f64> = (0..360).map(|i| i as f64 * TAU / 360.0).collect();
        let values: Vec<f64> = knots.iter().map(|&x| f(x)).collect();
        let s = PeriodicSpline::new(&knots, &values, TAU);
        let worst = (0..10_000)
            .map(|k| k as f64 * TAU / 10_000.0 - 3.0)
            .map(|x| (s.eval(x).value - f(x)).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-7, "worst value error {worst}");
    }

    #[test]
    fn interpolates_knots_and_is_c2_across_the_seam_on_non_uniform_knots() {
        let knots = [0.0, 0.7, 1.1, 2.9, 3.0, 4.4, 5.8];
        let values = [1.0, 2.0, -1.0, 0.5, 0.25, 3.0, 0.0];
        let s = PeriodicSpline::new(&knots, &values, TAU);
        for (k, v) in knots.iter().zip(values) {
            assert!((s.eval(*k).value - v).abs() < 1e-12);
            assert!((s.eval(*k + TAU).value - v).abs() < 1e-12);
        }
        // Continuity of value, slope and curvature at every knot, the seam included:
        // compare the left interval's polynomial at its end with the right one's start.
        for i in 0..knots.len() {
            let [c0, c1, c2, c3] = s.interval_coeffs(i);
            let h = s.interval_len(i);
            let next = s.interval_coeffs((i + 1) % knots.len());
            let end = [
                c0 + h * (c1 + h * (c2 + h * c3)),
                c1 + h * (2.0 * c2 + 3.0 * c3 * h),
                2.0 * c2 + 6.0 * c3 * h,
            ];
            let start = [next[0], next[1], 2.0 * next[2]];
            for (a, b) in end.iter().zip(start) {
                assert!((a - b).abs() < 1e-9, "knot {i}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn cyclic_solver_matches_dense_multiplication() {
        let sub = [1.0, 0.5, 0.2, 0.3, 0.9];
        let diag = [4.0, 3.0, 5.0, 4.5, 6.0];
        let sup = [0.7, 0.4, 1.1, 0.6, 0.8];
        let rhs = [1.0, -2.0, 0.5, 3.0, 2.0];
        let x = solve_cyclic_tridiagonal(&sub, &diag, &sup, &rhs);
        let n = 5;
        for i in 0..n {
            let lhs = sub[i] * x[(i + n - 1) % n] + diag[i] * x[i] + sup[i] * x[(i + 1) % n];
            assert!((lhs - rhs[i]).abs() < 1e-12, "row {i}: {lhs} vs {}", rhs[i]);
        }
    }
}
