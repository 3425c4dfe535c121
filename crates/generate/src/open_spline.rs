//! Natural cubic interpolating spline `y(s)` on strictly increasing knots, for explicit
//! profiles read from CSV (the periodic spline in `core::spline` closes on itself; a turned
//! profile has two free ends).
//!
//! End conditions: zero second derivative at both ends (natural). The second derivatives
//! come from the tridiagonal system solved by the Thomas algorithm, which is stable here
//! because the matrix is strictly diagonally dominant.

/// A natural cubic spline through `(s[i], y[i])`.
#[derive(Debug, Clone)]
pub struct OpenSpline {
    knots: Vec<f64>,
    /// Per interval: `y = c0 + c1·t + c2·t² + c3·t³`, `t = s − knots[i]`.
    coeffs: Vec<[f64; 4]>,
}

impl OpenSpline {
    /// Contract (checked by the caller): at least 3 knots, strictly increasing, all finite.
    pub fn new(knots: &[f64], values: &[f64]) -> Self {
        let n = knots.len();
        debug_assert!(n >= 3 && values.len() == n);
        let h: Vec<f64> = knots.windows(2).map(|w| w[1] - w[0]).collect();
        let slope = |i: usize| (values[i + 1] - values[i]) / h[i];
        // Interior equations i = 1..n−2:
        // h[i−1]·M[i−1] + 2(h[i−1] + h[i])·M[i] + h[i]·M[i+1] = 6(slope[i] − slope[i−1]).
        let m_inner = n - 2;
        let mut diag: Vec<f64> = (1..n - 1).map(|i| 2.0 * (h[i - 1] + h[i])).collect();
        let mut rhs: Vec<f64> = (1..n - 1)
            .map(|i| 6.0 * (slope(i) - slope(i - 1)))
            .collect();
        for k in 1..m_inner {
            // Row k's sub-diagonal is h[k] (between M[k] and M[k+1] in 1-based knots).
            let w = h[k] / diag[k - 1];
            diag[k] -= w * h[k];
            rhs[k] -= w * rhs[k - 1];
        }
        let mut m = vec![0.0; n];
        for k in (0..m_inner).rev() {
            let upper = if k + 1 < m_inner {
                h[k + 1] * m[k + 2]
            } else {
                0.0
            };
            m[k + 1] = (rhs[k] - upper) / diag[k];
        }
        let coeffs = (0..n - 1)
            .map(|i| {
                let (m0, m1) = (m[i], m[i + 1]);
                [
                    values[i],
                    slope(i) - h[i] * (2.0 * m0 + m1) / 6.0,
                    m0 / 2.0,
                    (m1 - m0) / (6.0 * h[i]),
                ]
            })
            .collect();
        Self {
            knots: knots.to_vec(),
            coeffs,
        }
    }

    pub fn first(&self) -> f64 {
        self.knots[0]
    }

    pub fn last(&self) -> f64 {
        self.knots[self.knots.len() - 1]
    }

    pub fn knots(&self) -> &[f64] {
        &self.knots
    }

    /// Value, first and second derivative at `s` (clamped into the knot range).
    pub fn eval(&self, s: f64) -> [f64; 3] {
        let s = s.clamp(self.first(), self.last());
        let i = match self.knots.partition_point(|&k| k <= s) {
            0 => 0,
            p => (p - 1).min(self.coeffs.len() - 1),
        };
        let t = s - self.knots[i];
        let [c0, c1, c2, c3] = self.coeffs[i];
        [
            c0 + t * (c1 + t * (c2 + t * c3)),
            c1 + t * (2.0 * c2 + t * 3.0 * c3),
            2.0 * c2 + 6.0 * c3 * t,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::OpenSpline;

    /// Independent method: the same spline from its defining conditions (interpolation at
    /// both ends of every piece, C1 and C2 at interior knots, natural ends) as one dense
    /// 4(n−1) system solved by Gaussian elimination with partial pivoting.
    fn dense_spline(s: &[f64], y: &[f64]) -> Vec<[f64; 4]> {
        let p = s.len() - 1;
        let size = 4 * p;
        let mut a = vec![vec![0.0; size + 1]; size];
        let mut row = 0;
        let put =
            |row: usize, piece: usize, t: f64, order: usize, sign: f64, a: &mut Vec<Vec<f64>>| {
                let powers = [
                    [1.0, t, t * t, t * t * t],
                    [0.0, 1.0, 2.0 * t, 3.0 * t * t],
                    [0.0, 0.0, 2.0, 6.0 * t],
                ];
                for k in 0..4 {
                    a[row][4 * piece + k] += sign * powers[order][k];
                }
            };
        for i in 0..p {
            let h = s[i + 1] - s[i];
            put(row, i, 0.0, 0, 1.0, &mut a);
            a[row][size] = y[i];
            row += 1;
            put(row, i, h, 0, 1.0, &mut a);
            a[row][size] = y[i + 1];
            row += 1;
        }
        for i in 0..p - 1 {
            let h = s[i + 1] - s[i];
            for order in 1..3 {
                put(row, i, h, order, 1.0, &mut a);
                put(row, i + 1, 0.0, order, -1.0, &mut a);
                row += 1;
            }
        }
        put(row, 0, 0.0, 2, 1.0, &mut a);
        row += 1;
        put(row, p - 1, s[p] - s[p - 1], 2, 1.0, &mut a);
        row += 1;
        assert_eq!(row, size);
        for c in 0..size {
            let piv = (c..size)
                .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
                .unwrap();
            a.swap(c, piv);
            for r in 0..size {
                if r != c {
                    let f = a[r][c] / a[c][c];
                    let pivot_row = a[c].clone();
                    for (v, p) in a[r][c..].iter_mut().zip(&pivot_row[c..]) {
                        *v -= f * p;
                    }
                }
            }
        }
        (0..p)
            .map(|i| std::array::from_fn(|k| a[4 * i + k][size] / a[4 * i + k][4 * i + k]))
            .collect()
    }

    #[test]
    fn agrees_with_the_dense_solution_of_its_defining_conditions() {
        let s = [0.0, 0.7, 1.1, 2.5, 3.0, 4.2, 5.0];
        let y: Vec<f64> = s.iter().map(|v: &f64| (v * 1.3).sin() * 10.0 + v).collect();
        let spline = OpenSpline::new(&s, &y);
        let dense = dense_spline(&s, &y);
        for (i, d) in dense.iter().enumerate() {
            for (k, dk) in d.iter().enumerate() {
                // Values O(10); the dense elimination loses a few digits: 1e-9 is far above
                // rounding and far below any error that matters (1e-4 mm written).
                assert!(
                    (spline.coeffs[i][k] - dk).abs() < 1e-9,
                    "piece {i} coefficient {k}: {} vs {dk}",
                    spline.coeffs[i][k]
                );
            }
        }
    }

    #[test]
    fn reproduces_lines_and_converges_on_a_smooth_function() {
        let s: Vec<f64> = (0..11).map(|i| f64::from(i) * 0.5).collect();
        let line: Vec<f64> = s.iter().map(|v| 2.0 - 0.3 * v).collect();
        let sp = OpenSpline::new(&s, &line);
        for i in 0..=100 {
            let v = f64::from(i) * 0.05;
            assert!((sp.eval(v)[0] - (2.0 - 0.3 * v)).abs() < 1e-12);
            assert!((sp.eval(v)[1] + 0.3).abs() < 1e-12);
        }
        // Away from the natural ends the error of a cubic spline falls as h⁴: halving the
        // step must cut the interior error of sin by about 16 (at least 10).
        let err = |n: i32| {
            let s: Vec<f64> = (0..=n).map(|i| f64::from(i) * 3.0 / f64::from(n)).collect();
            let y: Vec<f64> = s.iter().map(|v| v.sin()).collect();
            let sp = OpenSpline::new(&s, &y);
            (0..=200)
                .map(|i| 1.0 + f64::from(i) / 200.0)
                .map(|v| (sp.eval(v)[0] - v.sin()).abs())
                .fold(0.0, f64::max)
        };
        let (e1, e2) = (err(24), err(48));
        assert!(e1 / e2 > 10.0, "{e1} / {e2}");
    }
}
