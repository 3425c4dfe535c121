//! Lift tables (follower angle ψ → lift from the base circle): parsing, validation, and
//! the periodic C2 interpolant the geometry works on.

use super::spline::PeriodicSpline;
use std::f64::consts::TAU;

/// Fewest points a lift table may have.
pub(crate) const MIN_POINTS: usize = 36;
/// Largest allowed gap between neighbouring angles, the wrap-around included (degrees).
pub(crate) const MAX_GAP_DEG: f64 = 10.0;
/// Lift below the base circle that is accepted as rounding or gauge noise (mm).
pub(crate) const NEGATIVE_LIFT_TOLERANCE_MM: f64 = 0.001;
/// A closing point at first angle + 360° must repeat the first lift to within this (mm).
const CLOSURE_TOLERANCE_MM: f64 = 0.001;

/// Why a lift table was refused. Every variant names the file (`file`) and where in it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LiftTableError {
    #[error("{file}:{line}: {reason}")]
    Syntax {
        file: String,
        line: usize,
        reason: String,
    },
    #[error("{file}: {count} points, at least {MIN_POINTS} are needed")]
    TooFewPoints { file: String, count: usize },
    #[error("{file}:{line}: angle {angle_deg}° is not finite")]
    NonFiniteAngle {
        file: String,
        line: usize,
        angle_deg: f64,
    },
    #[error("{file}:{line}: lift at {angle_deg}° is not a finite number")]
    NonFiniteLift {
        file: String,
        line: usize,
        angle_deg: f64,
    },
    #[error("{file}:{line}: duplicate angle {angle_deg}°")]
    DuplicateAngle {
        file: String,
        line: usize,
        angle_deg: f64,
    },
    #[error("{file}:{line}: angle {angle_deg}° comes after {previous_deg}°: angles must increase")]
    Unsorted {
        file: String,
        line: usize,
        angle_deg: f64,
        previous_deg: f64,
    },
    #[error(
        "{file}: gap of {gap_deg:.3}° between {from_deg}° and {to_deg}°, at most {MAX_GAP_DEG}° allowed"
    )]
    Gap {
        file: String,
        from_deg: f64,
        to_deg: f64,
        gap_deg: f64,
    },
    #[error(
        "{file}:{line}: angle {angle_deg}° is more than one revolution after the first angle {first_deg}°"
    )]
    SpansMoreThanOneRevolution {
        file: String,
        line: usize,
        angle_deg: f64,
        first_deg: f64,
    },
    #[error(
        "{file}:{line}: closing point at {angle_deg}° has lift {lift_mm} mm, the first point {first_lift_mm} mm"
    )]
    ClosureMismatch {
        file: String,
        line: usize,
        angle_deg: f64,
        lift_mm: f64,
        first_lift_mm: f64,
    },
    #[error(
        "{file}:{line}: negative lift {lift_mm} mm at {angle_deg}° (more than {NEGATIVE_LIFT_TOLERANCE_MM} mm below the base circle)"
    )]
    NegativeLift {
        file: String,
        line: usize,
        angle_deg: f64,
        lift_mm: f64,
    },
}

/// A validated lift table: angles strictly increasing within one revolution, no gap over
/// [`MAX_GAP_DEG`] (the wrap-around included), finite lifts not below the base circle.
#[derive(Debug, Clone, PartialEq)]
pub struct LiftTable {
    angles_deg: Vec<f64>,
    lifts_mm: Vec<f64>,
    origin: String,
    /// Probe radius given by an OPTICLINE-style file, mm.
    probe_radius_mm: Option<f64>,
}

impl LiftTable {
    /// Validates points given directly; errors name `origin` and the 1-based point number.
    pub fn from_points(
        angles_deg: Vec<f64>,
        lifts_mm: Vec<f64>,
        origin: &str,
    ) -> Result<Self, LiftTableError> {
        let lines = (1..=angles_deg.len()).collect();
        Self::validated(
            angles_deg,
            lifts_mm,
            lines,
            origin,
            None,
            -NEGATIVE_LIFT_TOLERANCE_MM,
        )
    }

    /// Like [`LiftTable::from_points`], but lift may go down to `floor_mm` (< 0): for
    /// smoothed tables, whose small dip below the base circle is reported to the user.
    pub(super) fn from_points_with_floor(
        angles_deg: Vec<f64>,
        lifts_mm: Vec<f64>,
        origin: &str,
        floor_mm: f64,
    ) -> Result<Self, LiftTableError> {
        let lines = (1..=angles_deg.len()).collect();
        let floor = floor_mm.min(-NEGATIVE_LIFT_TOLERANCE_MM);
        Self::validated(angles_deg, lifts_mm, lines, origin, None, floor)
    }

    /// Parses `angle_deg,lift_mm` CSV: an optional header line, `#` comments, blank lines.
    pub fn parse_csv(text: &str, origin: &str) -> Result<Self, LiftTableError> {
        let (mut angles, mut lifts, mut lines) = (Vec::new(), Vec::new(), Vec::new());
        for (index, raw) in text.lines().enumerate() {
            let line = index + 1;
            let content = raw.split('#').next().unwrap_or("").trim();
            if content.is_empty() {
                continue;
            }
            // Hand-written on purpose, not the `csv` crate: numbers only (no quoting to
            // handle), and a line may end in a `# note`, which the crate's `comment` option
            // cannot express (it skips only lines that start with the comment byte). A split
            // keeps the line number and the field in every error without a second pass.
            let fields: Vec<&str> = content.split(',').map(str::trim).collect();
            let syntax = |reason: String| LiftTableError::Syntax {
                file: origin.to_string(),
                line,
                reason,
            };
            if fields.len() != 2 {
                return Err(syntax(format!(
                    "expected 2 fields `angle_deg,lift_mm`, found {}",
                    fields.len()
                )));
            }
            match (fields[0].parse::<f64>(), fields[1].parse::<f64>()) {
                (Ok(a), Ok(l)) => {
                    angles.push(a);
                    lifts.push(l);
                    lines.push(line);
                }
                // The first non-comment line may be a header such as `angle_deg,lift_mm`.
                _ if angles.is_empty() && fields.iter().all(|f| f.parse::<f64>().is_err()) => {}
                (Err(_), _) => {
                    return Err(syntax(format!("angle `{}` is not a number", fields[0])));
                }
                (_, Err(_)) => return Err(syntax(format!("lift `{}` is not a number", fields[1]))),
            }
        }
        Self::validated(
            angles,
            lifts,
            lines,
            origin,
            None,
            -NEGATIVE_LIFT_TOLERANCE_MM,
        )
    }

    /// Parses the OPTICLINE-style nominal file used by cam gauges: line 1 the probe radius
    /// (mm), line 2 the number of steps N, then N rows `angle lift marker` separated by
    /// white space (the marker is optional and ignored). Trailing blank lines are allowed.
    pub fn parse_opticline(text: &str, origin: &str) -> Result<Self, LiftTableError> {
        let syntax = |line: usize, reason: String| LiftTableError::Syntax {
            file: origin.to_string(),
            line,
            reason,
        };
        let mut rows = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
        let mut header = |what: &str| match rows.next() {
            Some((line, content)) => Ok((line, content)),
            None => Err(syntax(1, format!("file ends before the {what} line"))),
        };
        let (line, content) = header("probe radius")?;
        let probe_radius_mm: f64 = content
            .parse()
            .map_err(|_| syntax(line, format!("probe radius `{content}` is not a number")))?;
        if !(probe_radius_mm.is_finite() && probe_radius_mm >= 0.0) {
            return Err(syntax(
                line,
                format!("probe radius {probe_radius_mm} mm must be ≥ 0"),
            ));
        }
        let (line, content) = header("step count")?;
        let steps: usize = content.parse().map_err(|_| {
            syntax(
                line,
                format!("step count `{content}` is not a whole number"),
            )
        })?;
        let (mut angles, mut lifts, mut lines) = (Vec::new(), Vec::new(), Vec::new());
        let mut last_line = line;
        for (line, content) in rows {
            last_line = line;
            if content.is_empty() {
                continue;
            }
            if angles.len() == steps {
                return Err(syntax(
                    line,
                    format!("more rows than the {steps} steps announced on line 2"),
                ));
            }
            let fields: Vec<&str> = content.split_whitespace().collect();
            if !(2..=3).contains(&fields.len()) {
                return Err(syntax(
                    line,
                    format!(
                        "expected `angle lift [marker]`, found {} fields",
                        fields.len()
                    ),
                ));
            }
            let angle = fields[0]
                .parse::<f64>()
                .map_err(|_| syntax(line, format!("angle `{}` is not a number", fields[0])))?;
            let lift = fields[1]
                .parse::<f64>()
                .map_err(|_| syntax(line, format!("lift `{}` is not a number", fields[1])))?;
            angles.push(angle);
            lifts.push(lift);
            lines.push(line);
        }
        if angles.len() != steps {
            return Err(syntax(
                last_line,
                format!("{} rows, but line 2 announced {steps} steps", angles.len()),
            ));
        }
        Self::validated(
            angles,
            lifts,
            lines,
            origin,
            Some(probe_radius_mm),
            -NEGATIVE_LIFT_TOLERANCE_MM,
        )
    }

    fn validated(
        mut angles_deg: Vec<f64>,
        mut lifts_mm: Vec<f64>,
        mut lines: Vec<usize>,
        origin: &str,
        probe_radius_mm: Option<f64>,
        floor_mm: f64,
    ) -> Result<Self, LiftTableError> {
        let file = || origin.to_string();
        check_finite_and_rising(&angles_deg, &lifts_mm, &lines, origin)?;
        drop_closing_point(&mut angles_deg, &mut lifts_mm, &mut lines, origin)?;
        if angles_deg.len() < MIN_POINTS {
            return Err(LiftTableError::TooFewPoints {
                file: file(),
                count: angles_deg.len(),
            });
        }
        let n = angles_deg.len();
        for i in 0..n {
            let from_deg = angles_deg[i];
            let to_deg = if i + 1 < n {
                angles_deg[i + 1]
            } else {
                angles_deg[0] + 360.0
            };
            if to_deg - from_deg > MAX_GAP_DEG + 1e-9 {
                return Err(LiftTableError::Gap {
                    file: file(),
                    from_deg,
                    to_deg,
                    gap_deg: to_deg - from_deg,
                });
            }
        }
        for ((&angle_deg, &lift_mm), &line) in angles_deg.iter().zip(&lifts_mm).zip(&lines) {
            if lift_mm < floor_mm {
                return Err(LiftTableError::NegativeLift {
                    file: file(),
                    line,
                    angle_deg,
                    lift_mm,
                });
            }
        }
        Ok(Self {
            angles_deg,
            lifts_mm,
            origin: origin.to_string(),
            probe_radius_mm,
        })
    }

    pub fn angles_deg(&self) -> &[f64] {
        &self.angles_deg
    }

    pub fn lifts_mm(&self) -> &[f64] {
        &self.lifts_mm
    }

    /// Where the table came from (file name or label), for messages.
    pub fn origin(&self) -> &str {
        &self.origin
    }

    pub fn probe_radius_mm(&self) -> Option<f64> {
        self.probe_radius_mm
    }
}

/// Lift and its derivatives with respect to ψ in radians at one angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiftSample {
    pub h_mm: f64,
    /// dh/dψ, mm/rad.
    pub dh_mm: f64,
    /// d²h/dψ², mm/rad².
    pub d2h_mm: f64,
}

/// The periodic C2 interpolant of a lift table (a periodic cubic spline in ψ radians).
///
/// Linear interpolation is not good enough: at 1° steps its slope jumps at every point and
/// the wheel-centre path it implies is off by more than 1 µm on the flanks.
#[derive(Debug, Clone)]
pub struct LiftCurve {
    spline: PeriodicSpline,
    origin: String,
}

impl LiftCurve {
    pub fn new(table: &LiftTable) -> Self {
        let knots: Vec<f64> = table.angles_deg.iter().map(|a| a.to_radians()).collect();
        Self {
            spline: PeriodicSpline::new(&knots, &table.lifts_mm, TAU),
            origin: table.origin.clone(),
        }
    }

    /// Lift and derivatives at `psi_rad` (any real angle).
    pub fn eval(&self, psi_rad: f64) -> LiftSample {
        let s = self.spline.eval(psi_rad);
        LiftSample {
            h_mm: s.value,
            dh_mm: s.d1,
            d2h_mm: s.d2,
        }
    }

    /// Lift in mm at `psi_deg` degrees.
    pub fn lift_mm(&self, psi_deg: f64) -> f64 {
        self.spline.eval(psi_deg.to_radians()).value
    }

    /// Knot angles in radians (the table's angles), for scans that must not miss a knot.
    pub(crate) fn knots_rad(&self) -> &[f64] {
        self.spline.knots()
    }

    pub fn origin(&self) -> &str {
        &self.origin
    }
}

/// Every angle and lift a finite number, the angles strictly rising.
fn check_finite_and_rising(
    angles_deg: &[f64],
    lifts_mm: &[f64],
    lines: &[usize],
    origin: &str,
) -> Result<(), LiftTableError> {
    let file = || origin.to_string();
    for ((&a, &l), &line) in angles_deg.iter().zip(lifts_mm).zip(lines) {
        if !a.is_finite() {
            return Err(LiftTableError::NonFiniteAngle {
                file: file(),
                line,
                angle_deg: a,
            });
        }
        if !l.is_finite() {
            return Err(LiftTableError::NonFiniteLift {
                file: file(),
                line,
                angle_deg: a,
            });
        }
    }
    for i in 1..angles_deg.len() {
        let (previous_deg, angle_deg, line) = (angles_deg[i - 1], angles_deg[i], lines[i]);
        if angle_deg == previous_deg {
            return Err(LiftTableError::DuplicateAngle {
                file: file(),
                line,
                angle_deg,
            });
        }
        if angle_deg < previous_deg {
            return Err(LiftTableError::Unsorted {
                file: file(),
                line,
                angle_deg,
                previous_deg,
            });
        }
    }
    Ok(())
}

/// A last point one full turn after the first closes the table: checked against the first
/// and dropped; a table reaching further than one turn is refused.
fn drop_closing_point(
    angles_deg: &mut Vec<f64>,
    lifts_mm: &mut Vec<f64>,
    lines: &mut Vec<usize>,
    origin: &str,
) -> Result<(), LiftTableError> {
    let file = || origin.to_string();
    if let (Some(&first), Some(&last)) = (angles_deg.first(), angles_deg.last()) {
        let n = angles_deg.len();
        if (last - first - 360.0).abs() < 1e-9 {
            if (lifts_mm[n - 1] - lifts_mm[0]).abs() > CLOSURE_TOLERANCE_MM {
                return Err(LiftTableError::ClosureMismatch {
                    file: file(),
                    line: lines[n - 1],
                    angle_deg: last,
                    lift_mm: lifts_mm[n - 1],
                    first_lift_mm: lifts_mm[0],
                });
            }
            angles_deg.pop();
            lifts_mm.pop();
            lines.pop();
        } else if let Some(i) = angles_deg.iter().position(|&a| a - first >= 360.0) {
            return Err(LiftTableError::SpansMoreThanOneRevolution {
                file: file(),
                line: lines[i],
                angle_deg: angles_deg[i],
                first_deg: first,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
