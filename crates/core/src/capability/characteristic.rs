//! The characteristics a feature is judged on, and each one's value from a part's
//! analysed measurement.
//!
//! A pin is analysed like a lobe (its nominal lift in its own frame is b·(1 + cos ψ), b the
//! throw), so its own characteristics come from the unfitted error e(ψ) = measured −
//! nominal lift: the mean of e is the radius error (diameter error = 2·mean), order 1 along
//! the pin's direction (the cosine coefficient a₁ in its own frame) is the throw error (stroke error = 2·a₁; exact to b₁²/2b, under
//! 0.001 µm for a 45 mm throw and b₁ ≤ 10 µm), and e without orders 0 and 1 is the form,
//! whose peak to valley is the roundness. The index angle error is the timing.

use crate::harmonics::DftTable;

/// A quality characteristic of a lobe or a pin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Characteristic {
    /// Lobe: largest |measured − nominal lift| with nothing fitted, µm.
    MaxError,
    /// Lobe: largest |profile error| after the datum fit, µm.
    ProfileError,
    /// Lobe: base-circle radius error, µm.
    Size,
    /// Lobe: timing (phase) error, degrees.
    Timing,
    /// Pin: peak to valley of the form (orders 0 and 1 removed), µm.
    Roundness,
    /// Pin: index angle error, degrees.
    IndexAngle,
    /// Pin: stroke error (twice the throw error), µm.
    Stroke,
    /// Pin: diameter error, µm.
    Diameter,
}

/// What a stored part gives: the summary values and the unfitted error per angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartValues<'a> {
    pub max_profile_error_um: f64,
    pub base_radius_error_um: f64,
    pub phase_error_deg: f64,
    /// Measured − nominal lift per equally spaced angle of the gauge (the shaft's frame),
    /// µm; empty when unknown.
    pub error_um: &'a [f64],
    /// Where the feature's 0° is on the shaft, degrees (a pin's nominal direction).
    pub phase_deg: f64,
}

impl Characteristic {
    /// The name in APIs and files.
    pub fn as_str(self) -> &'static str {
        match self {
            Characteristic::MaxError => "max_error",
            Characteristic::ProfileError => "profile_error",
            Characteristic::Size => "size",
            Characteristic::Timing => "timing",
            Characteristic::Roundness => "roundness",
            Characteristic::IndexAngle => "index_angle",
            Characteristic::Stroke => "stroke",
            Characteristic::Diameter => "diameter",
        }
    }

    pub fn unit(self) -> &'static str {
        match self {
            Characteristic::Timing | Characteristic::IndexAngle => "°",
            _ => "µm",
        }
    }

    /// One-sided and bounded at zero: judged by a fitted distribution, upper limit only.
    pub fn bounded_at_zero(self) -> bool {
        matches!(
            self,
            Characteristic::MaxError | Characteristic::ProfileError | Characteristic::Roundness
        )
    }

    /// The magnitudes bounded at zero are each the largest of a profile's hundreds of
    /// readings: their chart takes the Gumbel limits of a maximum, the others the normal's.
    pub fn chart_shape(self) -> super::chart::Shape {
        if self.bounded_at_zero() {
            super::chart::Shape::LargestOfMany
        } else {
            super::chart::Shape::Normal
        }
    }

    /// This characteristic's value of a part; `None` when the part lacks what it needs
    /// (an unfitted error on fewer than 8 angles).
    pub fn value(self, part: &PartValues<'_>) -> Option<f64> {
        match self {
            Characteristic::MaxError => (!part.error_um.is_empty())
                .then(|| part.error_um.iter().fold(0.0f64, |a, e| a.max(e.abs()))),
            Characteristic::ProfileError => Some(part.max_profile_error_um),
            Characteristic::Size => Some(part.base_radius_error_um),
            Characteristic::Timing | Characteristic::IndexAngle => Some(part.phase_error_deg),
            Characteristic::Roundness => pin_terms(part).map(|t| t.roundness_um),
            Characteristic::Stroke => pin_terms(part).map(|t| 2.0 * t.throw_error_um),
            Characteristic::Diameter => pin_terms(part).map(|t| 2.0 * t.mean_um),
        }
    }
}

struct PinTerms {
    mean_um: f64,
    throw_error_um: f64,
    roundness_um: f64,
}

/// The error's orders 0 and 1 and form. The gauge reads in the shaft's frame, where the
/// pin's nominal is b·(1 + cos(ψ − φ)), φ its phase: the throw error is order 1 along φ.
fn pin_terms(part: &PartValues<'_>) -> Option<PinTerms> {
    let error_um = part.error_um;
    let n = error_um.len();
    if n < 8 {
        return None;
    }
    let table = DftTable::new(n);
    let (mean_um, _) = table.coefficients(error_um, 0)?;
    let (a1, b1) = table.coefficients(error_um, 1)?;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (k, e) in error_um.iter().enumerate() {
        let (c, s) = table.cos_sin(k)?;
        let form = e - mean_um - a1 * c - b1 * s;
        lo = lo.min(form);
        hi = hi.max(form);
    }
    let (sin_phi, cos_phi) = part.phase_deg.to_radians().sin_cos();
    Some(PinTerms {
        mean_um,
        throw_error_um: a1 * cos_phi + b1 * sin_phi,
        roundness_um: hi - lo,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pin 3 µm oversize in radius, 2 µm long in throw, turned 1 µm sideways, with a
    /// 0.8 µm order-3 form: the characteristics come out as built (exact on the grid).
    #[test]
    fn pin_characteristics_come_from_the_error_harmonics() {
        let error_um: Vec<f64> = (0..360)
            .map(|k| {
                let psi = f64::from(k).to_radians();
                3.0 + 2.0 * psi.cos() + 1.0 * psi.sin() + 0.4 * (3.0 * psi).cos()
            })
            .collect();
        let part = PartValues {
            max_profile_error_um: 0.0,
            base_radius_error_um: 0.0,
            phase_error_deg: 0.01,
            error_um: &error_um,
            phase_deg: 0.0,
        };
        let v = |c: Characteristic| c.value(&part).unwrap();
        assert!((v(Characteristic::Diameter) - 6.0).abs() < 1e-9);
        assert!((v(Characteristic::Stroke) - 4.0).abs() < 1e-9);
        assert!((v(Characteristic::Roundness) - 0.8).abs() < 1e-9);
        assert_eq!(v(Characteristic::IndexAngle), 0.01);
        // The same pin at 180° on the shaft: its throw error reads as −cos in the shaft's frame.
        let turned: Vec<f64> = error_um
            .iter()
            .enumerate()
            .map(|(k, e)| e - 4.0 * f64::from(k as u32).to_radians().cos())
            .collect();
        let at_180 = PartValues {
            error_um: &turned,
            phase_deg: 180.0,
            ..part
        };
        assert!((Characteristic::Stroke.value(&at_180).unwrap() - 4.0).abs() < 1e-9);
    }
}
