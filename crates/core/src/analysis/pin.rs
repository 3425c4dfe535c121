//! Crankpin analysis: size, throw, index angle and roundness of a pin measured as a flat
//! follower seen from the main axis.
//!
//! A round pin of radius `r_p` whose centre sits at distance `b` (the throw) in direction
//! `θ` (the index angle) from the main axis has the support function
//! `s(ψ) = b·cos(ψ − θ) + r_p`. The gauge, mastered on the nominal part, reports
//! `lift(ψ) = s(ψ) − (r_p,nom − b_nom)`, zero at the nominal's lowest point. So the mean of
//! the measured lift is `b_nom + Δr_p`, its first harmonic is `b·cos(ψ − θ)`, and everything
//! of order ≥ 2 is form error. On an equally spaced grid the DFT coefficients of orders 0
//! and 1 are exactly the least-squares fit of `c + a·cos ψ + b·sin ψ`.

use super::{AnalysisError, check_measurement};
use crate::harmonics::{DftTable, Harmonic, wrap_deg};
use crate::measure::{AveragedMeasurement, DroppedRevolution};

/// The nominal pin, as in the part drawing.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PinNominal {
    /// Distance from the main axis to the pin centre, mm (positive).
    pub throw_mm: f64,
    /// Pin radius, mm (positive).
    pub pin_radius_mm: f64,
    /// Direction of the pin centre in the part frame, degrees.
    pub index_deg: f64,
}

/// Everything reported about one pin; serialised as the JSON measurement report.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PinReport {
    pub origin: String,
    /// The angle grid, degrees: `k·360/N`.
    pub angle_deg: Vec<f64>,
    /// Measured − nominal lift per angle, nothing fitted, µm.
    pub error_um: Vec<f64>,
    /// Measured lift minus its fitted orders 0 and 1, µm: the form of the pin.
    pub residual_um: Vec<f64>,
    /// `2·(mean lift − b_nom)`: measured minus nominal diameter, µm.
    pub diameter_error_um: f64,
    /// First-harmonic amplitude minus the nominal throw, µm.
    pub throw_error_um: f64,
    /// Direction of the measured pin centre (phase of the first harmonic), degrees in
    /// (−180, 180].
    pub index_angle_deg: f64,
    /// `index_angle_deg − index_deg` of the nominal, degrees in (−180, 180]; positive when
    /// the pin lies further in the positive sense of ψ.
    pub index_error_deg: f64,
    /// Peak-to-valley of `residual_um` (orders 0 and 1 removed), µm.
    pub roundness_um: f64,
    /// Harmonics 1..=max order (capped at N/2) of `error_um`; order 1 carries the throw and
    /// index errors, orders ≥ 2 the form.
    pub harmonics: Vec<Harmonic>,
    /// Per-angle sample standard deviation (1σ, n − 1) over the revolutions used, µm.
    pub repeatability_um: Vec<f64>,
    /// Per-angle range (max − min) over the revolutions used, µm.
    pub repeatability_range_um: Vec<f64>,
    pub revolutions_used: Vec<u32>,
    pub dropped_revolutions: Vec<DroppedRevolution>,
}

impl PinNominal {
    /// The nominal lift at `angle_deg`: `b·cos(ψ − θ) + b`, mm.
    pub fn lift_mm(&self, angle_deg: f64) -> f64 {
        self.throw_mm * ((angle_deg - self.index_deg).to_radians().cos() + 1.0)
    }

    fn validate(&self) -> Result<(), AnalysisError> {
        let checks = [
            ("throw_mm", self.throw_mm, self.throw_mm > 0.0),
            (
                "pin_radius_mm",
                self.pin_radius_mm,
                self.pin_radius_mm > 0.0,
            ),
            ("index_deg", self.index_deg, true),
        ];
        for (field, value, ok) in checks {
            if !(value.is_finite() && ok) {
                return Err(AnalysisError::InvalidParameter {
                    field,
                    value,
                    reason: "pin nominal values must be finite, throw and radius positive",
                });
            }
        }
        Ok(())
    }
}

/// Analyses an averaged crankpin measurement against the nominal pin.
pub fn analyse_pin(
    avg: &AveragedMeasurement,
    nominal: &PinNominal,
    max_harmonic_order: u32,
) -> Result<PinReport, AnalysisError> {
    let n = check_measurement(avg)?;
    nominal.validate()?;
    let angle_deg: Vec<f64> = (0..n).map(|k| avg.angle_deg(k as u32)).collect();
    let lift_mm = &avg.mean_lift_mm;
    let table = DftTable::new(n);
    let (mean_mm, _) = table
        .coefficients(lift_mm, 0)
        .expect("checked: table matches, N ≥ 8");
    let (a_mm, b_mm) = table
        .coefficients(lift_mm, 1)
        .expect("checked: table matches, N ≥ 8");
    let residual_um: Vec<f64> = angle_deg
        .iter()
        .zip(lift_mm)
        .map(|(&psi, &m)| {
            let (s, c) = psi.to_radians().sin_cos();
            (m - mean_mm - a_mm * c - b_mm * s) * 1000.0
        })
        .collect();
    let error_um: Vec<f64> = angle_deg
        .iter()
        .zip(lift_mm)
        .map(|(&psi, &m)| (m - nominal.lift_mm(psi)) * 1000.0)
        .collect();
    let hi = residual_um
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let lo = residual_um.iter().copied().fold(f64::INFINITY, f64::min);
    let index_angle_deg = wrap_deg(b_mm.atan2(a_mm).to_degrees());
    Ok(PinReport {
        origin: avg.origin.clone(),
        harmonics: table.harmonics(&error_um, max_harmonic_order),
        diameter_error_um: 2.0 * (mean_mm - nominal.throw_mm) * 1000.0,
        throw_error_um: (a_mm.hypot(b_mm) - nominal.throw_mm) * 1000.0,
        index_angle_deg,
        index_error_deg: wrap_deg(index_angle_deg - nominal.index_deg),
        roundness_um: hi - lo,
        residual_um,
        error_um,
        angle_deg,
        repeatability_um: avg.repeatability_std_um.clone(),
        repeatability_range_um: avg.repeatability_range_um.clone(),
        revolutions_used: avg.revolutions_used.clone(),
        dropped_revolutions: avg.dropped_revolutions.clone(),
    })
}
