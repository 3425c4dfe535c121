//! Base-circle runout and roundness of a lobe's profile error.

use crate::harmonics::{DftTable, wrap_deg};

pub(super) struct BaseCircle {
    pub(super) runout_um: Option<f64>,
    pub(super) runout_phase_deg: Option<f64>,
    pub(super) roundness_um: Option<f64>,
    pub(super) points: u32,
}

/// Fits `c + a·cos ψ + b·sin ψ` to the profile error on the base-circle angles by least
/// squares. A flat probe sees a part displaced by `ε` towards `θ` as `ε·cos(ψ − θ)` added
/// to its support function, exactly; so `2·hypot(a, b)` is the total indicated runout. The
/// nominal is flat there, so the phase fit does not leak into it.
/// `table` is the grid's DFT table (its cosines and sines are those of the grid angles).
pub(super) fn fit(
    table: &DftTable,
    profile_error_um: &[f64],
    nominal_mm: &[f64],
    max_lift_mm: f64,
) -> BaseCircle {
    // (cos ψ, sin ψ, error µm) of the base-circle angles
    let picked: Vec<(f64, f64, f64)> = profile_error_um
        .iter()
        .zip(nominal_mm)
        .enumerate()
        .filter(|&(_, (_, &h))| h <= max_lift_mm)
        .filter_map(|(k, (&e, _))| {
            let (c, s) = table.cos_sin(k)?;
            Some((c, s, e))
        })
        .collect();
    let points = picked.len() as u32;
    let none = BaseCircle {
        runout_um: None,
        runout_phase_deg: None,
        roundness_um: None,
        points,
    };
    if 4 * picked.len() < profile_error_um.len() {
        return none;
    }
    // Normal equations in the basis (1, cos, sin).
    let mut ata = [[0.0; 3]; 3];
    let mut atb = [0.0; 3];
    for &(c, s, e) in &picked {
        let row = [1.0, c, s];
        for i in 0..3 {
            for j in 0..3 {
                ata[i][j] += row[i] * row[j];
            }
            atb[i] += row[i] * e;
        }
    }
    let Some([c, a, b]) = solve3(ata, atb) else {
        return none;
    };
    let (lo, hi) = picked.iter().fold(
        (f64::INFINITY, f64::NEG_INFINITY),
        |(lo, hi), &(cos, sin, e)| {
            let r = e - c - a * cos - b * sin;
            (lo.min(r), hi.max(r))
        },
    );
    BaseCircle {
        runout_um: Some(2.0 * a.hypot(b)),
        runout_phase_deg: Some(wrap_deg(b.atan2(a).to_degrees())),
        roundness_um: Some(hi - lo),
        points,
    }
}

/// Solves a 3×3 system by Cramer's rule; `None` when it is singular to working precision
/// (the base-circle angles do not determine a first harmonic).
fn solve3(m: [[f64; 3]; 3], v: [f64; 3]) -> Option<[f64; 3]> {
    let det = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let scale = m.iter().flatten().fold(0.0_f64, |s, x| s.max(x.abs()));
    let d = det(m);
    if !d.is_finite() || d.abs() <= 1e-12 * scale * scale * scale {
        return None;
    }
    let mut x = [0.0; 3];
    for (col, xc) in x.iter_mut().enumerate() {
        let mut mc = m;
        for (row, vr) in v.iter().enumerate() {
            mc[row][col] = *vr;
        }
        *xc = det(mc) / d;
    }
    Some(x)
}
