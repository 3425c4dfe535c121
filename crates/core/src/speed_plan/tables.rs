//! The plan as the control is to run it: a virtual leading axis VA turning at constant speed
//! (360° of VA per planned revolution) leads two POLY curve tables, C = f(VA) and X = g(VA).
//!
//! Why a virtual axis and two tables rather than a feed profile on C (`FLIN`/`FCUB` under
//! G93/G94): a feed profile runs through the path interpolation's look-ahead and block cycle,
//! so the speed between blocks depends on the control's smoothing, and the limits proven on
//! the plan would not be what the axis does; a POLY table holds the plan's cubics exactly,
//! and both tables go through the same table programs and numbering as today's.
//! Unconfirmed on a control (see the manual's "Speed plan"): a simulated leading axis
//! leading two `LEADON` couplings at once with C as a following axis, the machine data that
//! axis needs, starting both couplings together, and the limits of 720-piece tables.
//!
//! C = f(VA) is the time law itself: each of its cubic pieces is one POLY segment, exact.
//! X = g(VA) is a periodic C² cubic spline through the exact X at C(VA), refined like the
//! constant-speed tables (a midpoint inserted wherever a segment strays further than the
//! tolerance from the exact X(C(VA)) at 7 interior samples).

use super::TimeLaw;
use crate::fit::{DEVIATION_SAMPLES, fit_poly};
use crate::geometry::{GeometryError, Part};
use crate::table::{PolySegment, TablePoint};

/// Refinement rounds of the X table before it is returned as it is.
const MAX_REFINEMENTS: usize = 8;

/// The two tables over VA (degrees, 0 to 360 per revolution).
#[derive(Debug, Clone, PartialEq)]
pub struct VaTables {
    /// C (degrees, from about 0 to 360) against VA: one segment per piece of the time law.
    /// The `_mm` fields hold degrees of C here.
    pub c_segments: Vec<PolySegment>,
    /// X (program X, mm) against VA; `c_deg` of a point is its VA.
    pub x_points: Vec<TablePoint>,
    pub x_segments: Vec<PolySegment>,
    /// Largest distance of the X table from the exact X(C(VA)) between its points, µm.
    pub x_deviation_um: f64,
    /// VA's constant speed, rev/min.
    pub va_speed_rpm: f64,
}

/// The tables of `law` for `part`, the X table within `tolerance_um` where 8 refinements
/// reach it.
pub fn va_tables(part: &Part, law: &TimeLaw, tolerance_um: f64) -> Result<VaTables, GeometryError> {
    let pieces = law.pieces();
    let va_step = 360.0 / pieces as f64;
    let c_segments = (0..pieces)
        .map(|k| {
            let [c0, c1, c2, c3] = law.piece_deg(k);
            PolySegment {
                c_start_deg: k as f64 * va_step,
                c_end_deg: (k + 1) as f64 * va_step,
                x0_mm: c0,
                a1_mm: c1,
                a2_mm: c2,
                a3_mm: c3,
            }
        })
        .collect();
    let x_at = |va_deg: f64| -> Result<TablePoint, GeometryError> {
        let c_deg = law.at(va_deg / 360.0 * law.period_s()).c_rad.to_degrees();
        let d_mm = part.d_at_c_deg(c_deg.rem_euclid(360.0))?;
        Ok(TablePoint {
            c_deg: va_deg,
            d_mm,
            x_mm: d_mm - part.x_zero_mm(),
        })
    };
    let mut points = (0..pieces)
        .map(|k| x_at(k as f64 * va_step))
        .collect::<Result<Vec<_>, _>>()?;
    let mut round = 0;
    loop {
        let segments = fit_poly(&points);
        let deviations = segments
            .iter()
            .map(|s| segment_deviation_um(s, &x_at))
            .collect::<Result<Vec<f64>, _>>()?;
        let worst = deviations.iter().fold(0.0f64, |m, &d| m.max(d));
        round += 1;
        if worst <= tolerance_um || round > MAX_REFINEMENTS {
            return Ok(VaTables {
                c_segments,
                x_points: points,
                x_segments: segments,
                x_deviation_um: worst,
                va_speed_rpm: 60.0 / law.period_s(),
            });
        }
        let mut refined = Vec::with_capacity(points.len() * 2);
        for (point, (segment, dev)) in points.iter().zip(segments.iter().zip(&deviations)) {
            refined.push(*point);
            if *dev > tolerance_um {
                refined.push(x_at(0.5 * (segment.c_start_deg + segment.c_end_deg))?);
            }
        }
        points = refined;
    }
}

/// Largest distance (µm) of segment `s` from the exact X at 7 interior samples.
fn segment_deviation_um(
    s: &PolySegment,
    x_at: &impl Fn(f64) -> Result<TablePoint, GeometryError>,
) -> Result<f64, GeometryError> {
    let mut worst = 0.0f64;
    for k in 1..=DEVIATION_SAMPLES {
        let u = k as f64 / (DEVIATION_SAMPLES + 1) as f64;
        let va = s.c_start_deg + u * (s.c_end_deg - s.c_start_deg);
        let table_x = s.x0_mm + u * (s.a1_mm + u * (s.a2_mm + u * s.a3_mm));
        worst = worst.max((table_x - x_at(va)?.x_mm).abs() * 1000.0);
    }
    Ok(worst)
}
