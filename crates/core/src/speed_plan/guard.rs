//! The tables a guarded (corrected) table is delivered as with a speed plan, and the X
//! limits re-checked on them: the correction changes X(C), so the plan made for the nominal
//! part does not prove the corrected X table. The check is on the X table as written, over
//! VA: VA turns at constant speed ω, so on a POLY segment of length L (degrees of VA),
//! X = x0 + a1·u + a2·u² + a3·u³ with u = (VA − VA0)/L gives exactly
//! Ẋ = (a1 + 2a2·u + 3a3·u²)·k, Ẍ = (2a2 + 6a3·u)·k², X⃛ = 6a3·k³ with k = ω/L.
//! The velocity's largest magnitude is at an end or at its vertex, the acceleration's at an
//! end, the jerk is constant: the maxima are exact, not sampled.

use super::TimeLaw;
use super::tables::{VaTables, va_tables};
use crate::compensate::{AxisLimits, GuardError, GuardedTable};
use crate::geometry::Part;
use crate::table::PolySegment;

/// The C and X tables over VA for `table` (made for the commanded part `commanded`) with the
/// time law `law`: the learned timing moves C's table as it moves the constant-speed table's
/// C. Refused (never delivered) when X exceeds a limit of `limits` anywhere along them.
pub fn planned_tables(
    table: &GuardedTable,
    commanded: &Part,
    law: &TimeLaw,
    tolerance_um: f64,
    limits: &AxisLimits,
) -> Result<VaTables, GuardError> {
    let mut tables = va_tables(commanded, law, tolerance_um)?;
    for s in &mut tables.c_segments {
        s.x0_mm += table.timing_offset_deg;
    }
    check_x_over_va(&tables, limits)?;
    Ok(tables)
}

/// The largest |X velocity|, |acceleration| and |jerk| of the X table over VA at VA's speed
/// (mm/s, mm/s², mm/s³), each with the VA angle (degrees) where it is reached.
pub fn x_maxima(tables: &VaTables) -> [(f64, f64); 3] {
    let omega_deg_s = tables.va_speed_rpm * 6.0;
    let mut worst = [(0.0f64, 0.0f64); 3];
    for s in &tables.x_segments {
        let len = s.c_end_deg - s.c_start_deg;
        for (w, (value, u)) in worst.iter_mut().zip(extremes(s, omega_deg_s / len)) {
            // A NaN counts as exceeded: it never passes a limit.
            if value.abs() > w.0 || value.is_nan() {
                *w = (value.abs(), s.c_start_deg + u * len);
            }
        }
    }
    worst
}

/// The X table's maxima over VA must be within `limits`; the first exceeded is named with
/// its VA and C angles.
pub fn check_x_over_va(tables: &VaTables, limits: &AxisLimits) -> Result<(), GuardError> {
    let named = [
        ("velocity", "mm/s", limits.velocity_mm_s),
        ("acceleration", "mm/s²", limits.acceleration_mm_s2),
        ("jerk", "mm/s³", limits.jerk_mm_s3),
    ];
    for ((value, va_deg), (quantity, unit, limit)) in x_maxima(tables).into_iter().zip(named) {
        if value > limit || value.is_nan() {
            return Err(GuardError::PlanMotion {
                quantity,
                value,
                limit,
                unit,
                c_deg: c_at_va(tables, va_deg).rem_euclid(360.0),
                va_deg,
            });
        }
    }
    Ok(())
}

/// (largest |value|, u where) of X velocity, acceleration and jerk on segment `s`.
fn extremes(s: &PolySegment, k: f64) -> [(f64, f64); 3] {
    let (a1, a2, a3) = (s.a1_mm, s.a2_mm, s.a3_mm);
    let velocity = |u: f64| (a1 + 2.0 * a2 * u + 3.0 * a3 * u * u) * k;
    let mut candidates = vec![0.0, 1.0];
    if a3 != 0.0 {
        let vertex = -a2 / (3.0 * a3);
        if (0.0..=1.0).contains(&vertex) {
            candidates.push(vertex);
        }
    }
    let v = candidates
        .into_iter()
        .map(|u| (velocity(u), u))
        .fold(
            (0.0f64, 0.0),
            |m, (v, u)| if v.abs() > m.0.abs() { (v, u) } else { m },
        );
    let accel = |u: f64| (2.0 * a2 + 6.0 * a3 * u) * k * k;
    let a = if accel(1.0).abs() > accel(0.0).abs() {
        (accel(1.0), 1.0)
    } else {
        (accel(0.0), 0.0)
    };
    [v, a, (6.0 * a3 * k * k * k, 0.5)]
}

/// C (degrees) of C's table at `va_deg`.
fn c_at_va(tables: &VaTables, va_deg: f64) -> f64 {
    tables
        .c_segments
        .iter()
        .find(|s| va_deg <= s.c_end_deg)
        .or(tables.c_segments.last())
        .map_or(va_deg, |s| {
            let u = ((va_deg - s.c_start_deg) / (s.c_end_deg - s.c_start_deg)).clamp(0.0, 1.0);
            s.x0_mm + u * (s.a1_mm + u * (s.a2_mm + u * s.a3_mm))
        })
}
