//! The table the simulated control is given, and X(C) between its points as the control
//! interpolates it: straight in X(C) between G1 points, the cubic of each POLY segment.

use super::SimError;
use super::plan::PlannedSpeed;
use camloop_core::fit::{TableForm, fit_poly};
use camloop_core::geometry::{GeometryError, Part};
use camloop_core::table::{PolySegment, TablePoint};
use std::f64::consts::TAU;

/// Largest C gap (degrees) tolerated between one POLY segment's end and the next one's start.
const POLY_C_GAP_DEG: f64 = 1e-6;
/// Largest X jump (mm) tolerated where two POLY segments meet: a jump is a position step
/// the axis cannot make, so it is refused rather than smoothed over.
const POLY_X_JUMP_MM: f64 = 1e-6;

/// The points or segments of a curve table, in the part frame (`c_deg` in the lift table's
/// sense), periodic over 360°.
#[derive(Debug, Clone, PartialEq)]
pub enum TableShape {
    /// G1: X runs straight (linear in C) from each point to the next, the last to the first.
    /// Only `c_deg` and `x_mm` are used (the control knows nothing of `d_mm`).
    G1(Vec<TablePoint>),
    /// POLY: each segment's cubic in its own C range; the segments must tile one turn.
    Poly(Vec<PolySegment>),
}

/// What the control runs: the table and the reference it was made with.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandedTable {
    pub shape: TableShape,
    /// X zero reference the table's X values assume: d = X + x_zero (`R + Rb` for cams,
    /// `R + r_p` for crankpins), mm.
    pub x_zero_mm: f64,
    /// Wheel radius R the table was computed for, mm.
    pub wheel_radius_mm: f64,
    /// With a speed plan: C's table and the virtual axis' speed; `shape` is then X over the
    /// virtual axis (`c_deg` holds VA). `None`: C turns at the grinder's constant speed.
    pub plan: Option<PlannedSpeed>,
}

impl CommandedTable {
    /// The nominal table of `part` at `points` uniform C angles, as G1 points or fitted
    /// POLY segments, for the part's wheel radius.
    pub fn nominal(part: &Part, points: usize, form: TableForm) -> Result<Self, GeometryError> {
        let table = part.wheel_table(points)?;
        let shape = match form {
            TableForm::G1 => TableShape::G1(table),
            TableForm::Poly => TableShape::Poly(fit_poly(&table)),
        };
        Ok(Self {
            shape,
            x_zero_mm: part.x_zero_mm(),
            wheel_radius_mm: part.wheel_radius_mm(),
            plan: None,
        })
    }
}

/// One cubic piece of X(C): `x = x0 + a1·u + a2·u² + a3·u³`, `u = (c − c0)/len`, c in rad.
#[derive(Debug, Clone, Copy)]
struct Cubic {
    c0_rad: f64,
    len_rad: f64,
    x0: f64,
    a1: f64,
    a2: f64,
    a3: f64,
}

/// X(C) checked and ready to evaluate: segments in C order tiling one turn.
#[derive(Debug, Clone)]
pub(crate) struct TablePath {
    segments: Vec<Cubic>,
}

/// X and its first two derivatives with respect to C in radians (mm, mm/rad, mm/rad²).
#[derive(Debug, Clone, Copy)]
pub(crate) struct XSample {
    pub x: f64,
    pub x1: f64,
    pub x2: f64,
}

impl TablePath {
    pub fn new(shape: &TableShape) -> Result<Self, SimError> {
        let segments = match shape {
            TableShape::G1(points) => g1_segments(points)?,
            TableShape::Poly(segments) => poly_segments(segments)?,
        };
        Ok(Self { segments })
    }

    pub fn len(&self) -> usize {
        self.segments.len()
    }

    /// Start and end of segment `i` in C, radians (the last one ends one turn after the
    /// first one starts).
    pub(crate) fn range_rad(&self, i: usize) -> (f64, f64) {
        let s = &self.segments[i];
        (s.c0_rad, s.c0_rad + s.len_rad)
    }

    /// X of segment `i`'s polynomial at `c_rad` (used slightly outside the segment too, as
    /// its analytic continuation, by the corner search).
    pub fn eval(&self, i: usize, c_rad: f64) -> XSample {
        let s = &self.segments[i];
        let k = 1.0 / s.len_rad;
        let u = (c_rad - s.c0_rad) * k;
        XSample {
            x: s.x0 + u * (s.a1 + u * (s.a2 + u * s.a3)),
            x1: (s.a1 + u * (2.0 * s.a2 + 3.0 * s.a3 * u)) * k,
            x2: (2.0 * s.a2 + 6.0 * s.a3 * u) * k * k,
        }
    }
}

fn g1_segments(points: &[TablePoint]) -> Result<Vec<Cubic>, SimError> {
    let n = points.len();
    if n < 3 {
        return Err(SimError::TooFewTableEntries { count: n });
    }
    for (index, p) in points.iter().enumerate() {
        if !(p.c_deg.is_finite() && p.x_mm.is_finite()) {
            return Err(SimError::NonFiniteTableEntry {
                index,
                c_deg: p.c_deg,
            });
        }
    }
    check_c_order(&points.iter().map(|p| p.c_deg).collect::<Vec<_>>())?;
    Ok((0..n)
        .map(|i| {
            let (p, q) = (points[i], points[(i + 1) % n]);
            let end_deg = if i + 1 < n { q.c_deg } else { q.c_deg + 360.0 };
            Cubic {
                c0_rad: p.c_deg.to_radians(),
                len_rad: (end_deg - p.c_deg).to_radians(),
                x0: p.x_mm,
                a1: q.x_mm - p.x_mm,
                a2: 0.0,
                a3: 0.0,
            }
        })
        .collect())
}

fn poly_segments(segments: &[PolySegment]) -> Result<Vec<Cubic>, SimError> {
    let n = segments.len();
    if n < 3 {
        return Err(SimError::TooFewTableEntries { count: n });
    }
    for (index, s) in segments.iter().enumerate() {
        if !s.is_finite() {
            return Err(SimError::NonFiniteTableEntry {
                index,
                c_deg: s.c_start_deg,
            });
        }
        if s.c_end_deg <= s.c_start_deg {
            return Err(SimError::EmptySegment {
                index,
                c_start_deg: s.c_start_deg,
                c_end_deg: s.c_end_deg,
            });
        }
    }
    check_c_order(&segments.iter().map(|s| s.c_start_deg).collect::<Vec<_>>())?;
    for i in 0..n {
        let (s, next) = (&segments[i], &segments[(i + 1) % n]);
        let next_start_deg = if i + 1 < n {
            next.c_start_deg
        } else {
            next.c_start_deg + 360.0
        };
        if (s.c_end_deg - next_start_deg).abs() > POLY_C_GAP_DEG {
            return Err(SimError::PolyGap {
                index: i,
                c_end_deg: s.c_end_deg,
                next_start_deg,
            });
        }
        if (s.x_end_mm() - next.x0_mm).abs() > POLY_X_JUMP_MM {
            return Err(SimError::PolyJump {
                index: i,
                c_deg: s.c_end_deg,
                x_end_mm: s.x_end_mm(),
                next_x_mm: next.x0_mm,
            });
        }
    }
    // The gap check above makes the segments tile the turn to within POLY_C_GAP_DEG.
    Ok(segments
        .iter()
        .map(|s| Cubic {
            c0_rad: s.c_start_deg.to_radians(),
            len_rad: (s.c_end_deg - s.c_start_deg).to_radians(),
            x0: s.x0_mm,
            a1: s.a1_mm,
            a2: s.a2_mm,
            a3: s.a3_mm,
        })
        .collect())
}

/// C strictly increasing within less than one turn.
fn check_c_order(c_deg: &[f64]) -> Result<(), SimError> {
    for i in 1..c_deg.len() {
        if c_deg[i] <= c_deg[i - 1] {
            return Err(SimError::TableOrder {
                index: i,
                c_deg: c_deg[i],
                previous_deg: c_deg[i - 1],
            });
        }
    }
    let span = c_deg[c_deg.len() - 1] - c_deg[0];
    if span >= 360.0 {
        return Err(SimError::TableSpan { span_deg: span });
    }
    Ok(())
}

/// Reduces an angle difference to (−π, π].
pub(crate) fn wrap_pi(a: f64) -> f64 {
    let r = a.rem_euclid(TAU);
    if r > std::f64::consts::PI { r - TAU } else { r }
}
