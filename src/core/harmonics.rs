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
    /// Table for `n` equally spaced points.
    pub fn new(n: usize) -> Self {
        let (sin, cos) = (0..n)
            .map(|m| (std::f64::consts::TAU * m as f64 / n as f64).sin_cos())
            .unzip();
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

    /// Orders `1..=min(max_order, N/2)` of `values`, in the values' unit (named µm in the
    /// result because that is what the core feeds it).
    pub fn harmonics(&self, values: &[f64], max_order: u32) -> Vec<Harmonic> {
        let top = (max_order as usize).min(self.len() / 2);
        (1..=top)
            .filter_map(|j| {
                let (a, b) = self.coefficients(values, j)?;
                Some(Harmonic {
                    order: j as u32,
                    amplitude_um: a.hypot(b),
                    phase_deg: wrap_deg(b.atan2(a).to_degrees()),
                })
            })
            .collect()
    }
}

/// Harmonics `1..=min(max_order, N/2)` of per-angle values on an equally spaced grid.
pub fn harmonics_um(values_um: &[f64], max_order: u32) -> Vec<Harmonic> {
    DftTable::new(values_um.len()).harmonics(values_um, max_order)
}

/// An angle brought into (−180, 180], degrees.
pub fn wrap_deg(angle_deg: f64) -> f64 {
    let w = angle_deg.rem_euclid(360.0);
    if w > 180.0 { w - 360.0 } else { w }
}
