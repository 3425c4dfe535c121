//! Operations on a correction over the gauge grid: the low-pass Q and the nanometre step.

use crate::harmonics::DftTable;
use std::f64::consts::PI;

/// The step a learned correction is kept in, µm: 1 nm. The table writes X to 0.1 µm and the
/// gauge reads 0.1 µm, so digits below a nanometre change no table (but at a rounding tie)
/// and carry nothing the next part could confirm; kept at whole nanometres, a correction
/// prints with at most three decimals, and its history (every table version and learning
/// snapshot keeps it exactly) takes a fraction of the bytes of full f64 digits.
pub(crate) const CORRECTION_STEP_UM: f64 = 0.001;

/// Rounds a correction to whole [`CORRECTION_STEP_UM`], never beyond `±limit_um`.
pub fn quantise_correction(correction_um: &mut [f64], limit_um: f64) {
    let steps = 1.0 / CORRECTION_STEP_UM;
    let limit = (limit_um * steps).floor() / steps;
    for u in correction_um {
        *u = ((*u * steps).round() / steps).clamp(-limit, limit);
    }
}

/// Zero-phase low-pass Q: keeps orders ≤ `cutoff`, tapers with a half cosine over the next
/// `rolloff` orders, drops the rest. Gains are real and non-negative, so no phase shift.
pub(crate) fn low_pass(values: &[f64], cutoff: u32, rolloff: u32) -> Vec<f64> {
    let n = values.len();
    let table = DftTable::new(n);
    let top = ((cutoff + rolloff) as usize).min(n / 2);
    let mut out = vec![0.0; n];
    for order in 0..=top {
        let gain = q_gain(order as u32, cutoff, rolloff);
        if gain == 0.0 {
            continue;
        }
        let Some((a, b)) = table.coefficients(values, order) else {
            continue;
        };
        for (k, o) in out.iter_mut().enumerate() {
            let Some((c, s)) = table.cos_sin((k * order) % n) else {
                continue;
            };
            *o += gain * (a * c + b * s);
        }
    }
    out
}

pub(super) fn q_gain(order: u32, cutoff: u32, rolloff: u32) -> f64 {
    if order <= cutoff {
        1.0
    } else if order < cutoff + rolloff {
        0.5 * (1.0 + (PI * f64::from(order - cutoff) / f64::from(rolloff)).cos())
    } else {
        0.0
    }
}
