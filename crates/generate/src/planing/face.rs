//! The rotor's end face as the planer cuts it: one circular arc per segment in the face's
//! developed section at the pitch radius, from a lobe peak down to the valley and back up
//! to the next peak, and the control points of a stroke placed so that the straight
//! (X, A, Z) moves between them stay within the tolerance of that arc.
//!
//! Along a stroke A follows X by the ratio K, so the rotor angle under the tool, and with it
//! the developed length `s = R_p·θ` and the face height `z(s)`, are functions of X. Between
//! two control points the control interpolates Z linearly in X; the height error of such a
//! chord is at most `Δx²/8·max|d²z/dX²|`, and the arc's curvature is greatest at its ends,
//! where `d²z/ds² = ρ²/(ρ − h)³`.

use super::PlaningError;

/// The end face: `segments` identical arcs round the rotor.
#[derive(Debug, Clone, PartialEq)]
pub struct RotorFace {
    /// Arcs round the end face (six in the common design), at least 1.
    pub segments: u32,
    /// Radius at which the developed section is taken, mm.
    pub pitch_radius_mm: f64,
    /// Z of the lobe peaks (segment boundaries) and of the valley (mid-segment), mm.
    pub z_peak_mm: f64,
    pub z_valley_mm: f64,
}

impl RotorFace {
    /// Angle one arc spans, degrees.
    pub fn period_deg(&self) -> f64 {
        360.0 / f64::from(self.segments)
    }

    /// Developed length of one arc at the pitch radius, mm.
    pub fn arc_length_mm(&self) -> f64 {
        self.pitch_radius_mm * self.period_deg().to_radians()
    }

    /// Rise from valley to peak, mm.
    pub fn rise_mm(&self) -> f64 {
        self.z_peak_mm - self.z_valley_mm
    }

    /// Radius of the arc through peak, valley and next peak, mm; `None` for a flat face.
    pub fn arc_radius_mm(&self) -> Option<f64> {
        let (half, h) = (self.arc_length_mm() / 2.0, self.rise_mm());
        (h > 0.0).then(|| (half * half + h * h) / (2.0 * h))
    }

    pub(crate) fn check(&self) -> Result<(), PlaningError> {
        let bad = |field, value, rule| Err(PlaningError::Value { field, value, rule });
        if self.segments == 0 {
            return bad("segments", 0.0, "at least 1");
        }
        if !(self.pitch_radius_mm.is_finite() && self.pitch_radius_mm > 0.0) {
            return bad("pitch radius", self.pitch_radius_mm, "it must be > 0");
        }
        for (field, v) in [("z peak", self.z_peak_mm), ("z valley", self.z_valley_mm)] {
            if !v.is_finite() {
                return bad(field, v, "it must be a finite number");
            }
        }
        if self.rise_mm() < 0.0 {
            return bad(
                "z valley",
                self.z_valley_mm,
                "the valley must not be above the peak",
            );
        }
        if self.rise_mm() > self.arc_length_mm() / 2.0 {
            return bad(
                "z peak - z valley",
                self.rise_mm(),
                "the rise exceeds half the arc's developed length: the arc would turn back",
            );
        }
        Ok(())
    }

    /// Face height at rotor angle `theta_deg` (any angle: the face repeats every period).
    pub fn z_at(&self, theta_deg: f64) -> f64 {
        let Some(rho) = self.arc_radius_mm() else {
            return self.z_peak_mm;
        };
        let period = self.period_deg();
        let within = theta_deg.rem_euclid(period);
        let u = self.pitch_radius_mm * within.to_radians() - self.arc_length_mm() / 2.0;
        self.z_valley_mm + rho - (rho * rho - u * u).max(0.0).sqrt()
    }

    /// Largest `|d²z/ds²|` on the arc (at its ends), 1/mm.
    fn max_curvature_per_mm(&self) -> f64 {
        match self.arc_radius_mm() {
            Some(rho) => {
                let d = rho - self.rise_mm();
                // A rise of exactly half the length makes the ends vertical: no finite
                // chord holds the tolerance there; the check above keeps d > 0 otherwise.
                if d > 0.0 {
                    rho * rho / (d * d * d)
                } else {
                    f64::INFINITY
                }
            }
            None => 0.0,
        }
    }
}

/// Control points of one stroke: X positions from `x_start` to `x_end` (both included),
/// evenly spaced, as many as the tolerance needs and at least `min_points`.
pub fn stroke_points(
    face: &RotorFace,
    ratio_deg_per_mm: f64,
    x_start_mm: f64,
    x_end_mm: f64,
    tolerance_mm: f64,
    min_points: u32,
) -> Result<Vec<f64>, PlaningError> {
    // ds/dX: developed length per mm of ram travel.
    let ds_dx = face.pitch_radius_mm * ratio_deg_per_mm.abs().to_radians();
    let curvature = face.max_curvature_per_mm() * ds_dx * ds_dx;
    let length = x_end_mm - x_start_mm;
    let intervals = if curvature > 0.0 {
        (length / (8.0 * tolerance_mm / curvature).sqrt()).ceil()
    } else {
        1.0
    };
    let intervals = intervals.max(f64::from(min_points.max(2) - 1));
    if !(intervals.is_finite() && intervals <= MAX_POINTS as f64) {
        return Err(PlaningError::TooManyPoints {
            needed: intervals,
            max: MAX_POINTS,
        });
    }
    let n = intervals as usize;
    Ok((0..=n)
        .map(|i| x_start_mm + length * i as f64 / n as f64)
        .collect())
}

/// Control points per stroke at most: a stroke of more blocks than this is a tolerance
/// typed in the wrong unit, not a program a control should load.
pub const MAX_POINTS: usize = 5000;
