//! Angle-dependent tolerance bands on a per-angle error, and the pass/fail verdict.

use super::AnalysisError;

/// Slack on band ends so a grid angle computed as 59.999999999° still counts as 60°, degrees.
const ANGLE_SLACK_DEG: f64 = 1e-9;

/// Limits on the error between two angles. The band runs in the positive sense from
/// `from_deg` to `to_deg`, both ends included; `to_deg < from_deg` wraps through 360°
/// (300 → 60 covers 120°), `0 → 360` covers the whole revolution.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ToleranceBand {
    pub from_deg: f64,
    pub to_deg: f64,
    /// Lowest allowed error, µm (usually negative).
    pub lower_um: f64,
    /// Highest allowed error, µm.
    pub upper_um: f64,
}

/// The worst point outside its band.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Violation {
    pub angle_index: u32,
    pub angle_deg: f64,
    /// The error at that angle, µm.
    pub value_um: f64,
    /// How far outside the band, µm (positive).
    pub excess_um: f64,
    /// The band it breaks (the one broken most, if several cover the angle).
    pub band: ToleranceBand,
}

/// Pass/fail of a per-angle error against its bands.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Verdict {
    /// True when every checked angle lies within every band covering it.
    pub pass: bool,
    /// Smallest distance from a checked value to a limit, µm; negative when failing.
    pub margin_um: f64,
    /// The point furthest outside its band; `None` when passing.
    pub worst_violation: Option<Violation>,
    /// Angles no band covers (they are not judged).
    pub unchecked_points: u32,
    /// The bands that were applied.
    pub bands: Vec<ToleranceBand>,
}

impl ToleranceBand {
    /// `±half_width_um` over the whole revolution.
    pub fn everywhere(half_width_um: f64) -> Self {
        Self {
            from_deg: 0.0,
            to_deg: 360.0,
            lower_um: -half_width_um,
            upper_um: half_width_um,
        }
    }

    /// Angular extent, degrees.
    fn span_deg(&self) -> f64 {
        let span = self.to_deg - self.from_deg;
        if span < 0.0 { span + 360.0 } else { span }
    }

    fn problem(&self) -> Option<&'static str> {
        let values = [self.from_deg, self.to_deg, self.lower_um, self.upper_um];
        if values.iter().any(|v| !v.is_finite()) {
            Some("all four values must be finite")
        } else if self.lower_um > self.upper_um {
            Some("lower limit above upper limit")
        } else if self.span_deg() <= 0.0 {
            Some("band covers no angle (from equals to)")
        } else if self.span_deg() > 360.0 {
            Some("band is longer than one revolution")
        } else {
            None
        }
    }

    /// Whether the band covers `angle_deg` (any real angle, taken modulo 360°).
    pub fn contains(&self, angle_deg: f64) -> bool {
        Arc::of(self).contains(angle_deg.rem_euclid(360.0))
    }
}

/// A band's angles, reduced once: start in [0, 360), extent in (0, 360].
#[derive(Clone, Copy)]
struct Arc {
    start_deg: f64,
    span_deg: f64,
}

impl Arc {
    fn of(band: &ToleranceBand) -> Self {
        Self {
            start_deg: band.from_deg.rem_euclid(360.0),
            span_deg: band.span_deg(),
        }
    }

    /// `angle_deg` in [0, 360].
    fn contains(self, angle_deg: f64) -> bool {
        let mut d = angle_deg - self.start_deg;
        if d < -ANGLE_SLACK_DEG {
            d += 360.0;
        }
        d <= self.span_deg + ANGLE_SLACK_DEG || d >= 360.0 - ANGLE_SLACK_DEG
    }
}

/// Checks bands before any work is done on them.
pub(crate) fn validate(bands: &[ToleranceBand]) -> Result<(), AnalysisError> {
    for (index, band) in bands.iter().enumerate() {
        if let Some(reason) = band.problem() {
            return Err(AnalysisError::InvalidBand {
                index,
                band: *band,
                reason,
            });
        }
    }
    Ok(())
}

/// Judges `values_um[k]` at `angle_deg[k]` against every band covering that angle.
///
/// Fails with [`AnalysisError::InvalidBand`] for a malformed band and
/// [`AnalysisError::BandsCoverNoPoint`] when no angle is covered at all (a verdict on
/// nothing would be a silent pass).
pub fn judge(
    angle_deg: &[f64],
    values_um: &[f64],
    bands: &[ToleranceBand],
) -> Result<Verdict, AnalysisError> {
    validate(bands)?;
    let arcs: Vec<(Arc, &ToleranceBand)> = bands.iter().map(|b| (Arc::of(b), b)).collect();
    let mut margin_um = f64::INFINITY;
    let mut worst: Option<Violation> = None;
    let mut unchecked_points = 0u32;
    for (k, (&angle, &value)) in angle_deg.iter().zip(values_um).enumerate() {
        let mut covered = false;
        let reduced = if (0.0..=360.0).contains(&angle) {
            angle
        } else {
            angle.rem_euclid(360.0)
        };
        for &(_, band) in arcs.iter().filter(|(arc, _)| arc.contains(reduced)) {
            covered = true;
            // A non-finite value is outside every band.
            let m = if value.is_finite() {
                (value - band.lower_um).min(band.upper_um - value)
            } else {
                f64::NEG_INFINITY
            };
            if m < margin_um {
                margin_um = m;
                if m < 0.0 {
                    worst = Some(Violation {
                        angle_index: k as u32,
                        angle_deg: angle,
                        value_um: value,
                        excess_um: -m,
                        band: *band,
                    });
                }
            }
        }
        if !covered {
            unchecked_points += 1;
        }
    }
    if margin_um == f64::INFINITY {
        return Err(AnalysisError::BandsCoverNoPoint {
            points: angle_deg.len(),
        });
    }
    Ok(Verdict {
        pass: margin_um >= 0.0,
        margin_um,
        worst_violation: worst,
        unchecked_points,
        bands: bands.to_vec(),
    })
}
