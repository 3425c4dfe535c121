//! Harmonic analysis of periodic per-angle data: a direct DFT on any number of equally
//! spaced points (no power-of-two restriction).
//!
//! Convention: for values `x_k` at `ψ_k = k·360°/N`, order `j` contributes
//! `amplitude · cos(j·ψ − phase)`. So `phase / j` is the angle (degrees) of the first maximum
//! of that component; amplitude is half its peak-to-valley. Orders run up to `N/2`; the
//! order `N/2` of an even `N` (Nyquist) can only be a cosine, its phase is 0° or 180°.

/// One harmonic of a per-angle error: `amplitude_um · cos(order·ψ − phase_deg)`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Harmonic {
    pub order: u32,
    /// Amplitude (half the peak-to-valley of the component), µm.
    pub amplitude_um: f64,
    /// Phase in degrees of the order-j argument, in (−180, 180].
    pub phase_deg: f64,
}

/// Cosines and sines of the N grid angles, so an order costs N multiply-adds and no
/// trigonometry (`j·k mod N` indexes the table exactly, with no drift of a recurrence).
pub struct DftTable {
    cos: Vec<f64>,
    sin: Vec<f64>,
}

impl DftTable {
    /// Table for `n` equally spaced points. Only the first half is computed; the second
    /// mirrors it (`cos(2π − x) = cos x`, `sin(2π − x) = −sin x`), which is also exact.
    pub fn new(n: usize) -> Self {
        let mut cos = vec![0.0; n];
        let mut sin = vec![0.0; n];
        for m in 0..(n / 2 + 1).min(n) {
            let (s, c) = (std::f64::consts::TAU * m as f64 / n as f64).sin_cos();
            cos[m] = c;
            sin[m] = s;
            if m > 0 && m < n - m {
                cos[n - m] = c;
                sin[n - m] = -s;
            }
        }
        Self { cos, sin }
    }

    pub fn len(&self) -> usize {
        self.cos.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cos.is_empty()
    }

    /// Fourier coefficients `(a, b)` of order `order` such that the component is
    /// `a·cos(j·ψ) + b·sin(j·ψ)`; order 0 gives `(mean, 0)`. On an equally spaced grid these
    /// are also the least-squares fit of that component. `None` when `values.len()` differs
    /// from the table, the grid is empty, or `order > N/2` (it would alias).
    pub fn coefficients(&self, values: &[f64], order: usize) -> Option<(f64, f64)> {
        let n = self.len();
        if values.len() != n || n == 0 || 2 * order > n {
            return None;
        }
        let (mut a, mut b) = (0.0, 0.0);
        let mut m = 0;
        for &x in values {
            a += x * self.cos[m];
            b += x * self.sin[m];
            m += order;
            if m >= n {
                m -= n;
            }
        }
        // Orders 0 and N/2 are real: their basis has norm² N, the others N/2.
        let scale = if order == 0 || 2 * order == n {
            1.0 / n as f64
        } else {
            2.0 / n as f64
        };
        Some((a * scale, b * scale))
    }

    /// `(cos ψ_k, sin ψ_k)` of grid angle `k`; `None` past the grid.
    pub(crate) fn cos_sin(&self, k: usize) -> Option<(f64, f64)> {
        Some((*self.cos.get(k)?, *self.sin.get(k)?))
    }

    /// Orders `1..=min(max_order, N/2)` of `values`, in the values' unit (named µm in the
    /// result because that is what the core feeds it). Empty when `values.len()` differs
    /// from the table.
    ///
    /// Real input folds in half: angles `ψ_k` and `ψ_{N−k}` share the cosine and have
    /// opposite sines, so `a_j` needs `x_k + x_{N−k}` and `b_j` needs `x_k − x_{N−k}` over
    /// `k = 1 … (N−1)/2` only (plus `x_0`, and `x_{N/2}·(−1)^j` for even N). Each order's
    /// `e^{i·j·ψ_k}` is the element-wise complex product of the previous order's with order 1,
    /// which vectorises (unlike the table gather of [`Self::coefficients`]); its rounding
    /// grows linearly with the order, ~1e-14 relative at order 50. Sums run in four
    /// independent lanes so the additions pipeline.
    pub fn harmonics(&self, values: &[f64], max_order: u32) -> Vec<Harmonic> {
        let n = self.len();
        if values.len() != n || n == 0 {
            return Vec::new();
        }
        let top = (max_order as usize).min(n / 2);
        let pairs = (n - 1) / 2;
        // Padded to whole lanes with zeros, which add nothing to the sums.
        let padded = pairs.div_ceil(LANES) * LANES;
        let fold = |f: fn(f64, f64) -> f64| {
            let mut v: Vec<f64> = (1..=pairs).map(|k| f(values[k], values[n - k])).collect();
            v.resize(padded, 0.0);
            v
        };
        let (even, odd) = (fold(|p, q| p + q), fold(|p, q| p - q));
        let pad = |t: &[f64]| {
            let mut v = t[1..=pairs].to_vec();
            v.resize(padded, 0.0);
            v
        };
        let (cos_1, sin_1) = (pad(&self.cos), pad(&self.sin));
        let (mut cos_j, mut sin_j) = (cos_1.clone(), sin_1.clone());
        let nyquist = if n.is_multiple_of(2) {
            values[n / 2]
        } else {
            0.0
        };
        let mut out = Vec::with_capacity(top);
        for j in 1..=top {
            if j > 1 {
                let rows = cos_j.iter_mut().zip(sin_j.iter_mut());
                for ((c, s), (c1, s1)) in rows.zip(cos_1.iter().zip(&sin_1)) {
                    let next_c = *c * c1 - *s * s1;
                    *s = *s * c1 + *c * s1;
                    *c = next_c;
                }
            }
            let mut acc_a = [0.0; LANES];
            let mut acc_b = [0.0; LANES];
            let lanes = cos_j
                .chunks_exact(LANES)
                .zip(sin_j.chunks_exact(LANES))
                .zip(even.chunks_exact(LANES).zip(odd.chunks_exact(LANES)));
            for ((c, s), (e, o)) in lanes {
                for i in 0..LANES {
                    acc_a[i] += e[i] * c[i];
                    acc_b[i] += o[i] * s[i];
                }
            }
            let signed_nyquist = if j % 2 == 0 { nyquist } else { -nyquist };
            let sum_a = values[0] + signed_nyquist + (acc_a[0] + acc_a[1]) + (acc_a[2] + acc_a[3]);
            let sum_b = (acc_b[0] + acc_b[1]) + (acc_b[2] + acc_b[3]);
            let scale = if 2 * j == n { 1.0 } else { 2.0 } / n as f64;
            let (a, b) = (scale * sum_a, scale * sum_b);
            out.push(Harmonic {
                order: j as u32,
                amplitude_um: a.hypot(b),
                phase_deg: wrap_deg(b.atan2(a).to_degrees()),
            });
        }
        out
    }
}

/// Independent partial sums in [`DftTable::harmonics`].
const LANES: usize = 4;

/// Harmonics `1..=min(max_order, N/2)` of per-angle values on an equally spaced grid.
pub fn harmonics_um(values_um: &[f64], max_order: u32) -> Vec<Harmonic> {
    DftTable::new(values_um.len()).harmonics(values_um, max_order)
}

/// An angle brought into (−180, 180], degrees.
pub fn wrap_deg(angle_deg: f64) -> f64 {
    let w = angle_deg.rem_euclid(360.0);
    if w > 180.0 { w - 360.0 } else { w }
}
