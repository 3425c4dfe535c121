//! Curve-table forms and their quality: G1 chords or fitted POLY cubics between table points,
//! the largest deviation from the exact wheel path between points, and the X motion
//! (velocity, acceleration, jerk) each form asks of the axis at a given C speed.

use super::geometry::{GeometryError, Part};
use super::spline::PeriodicSpline;
use super::table::{PolySegment, TablePoint};

/// Interior samples per segment when measuring deviation from the exact path. The error of a
/// chord or cubic between knots is a smooth bump about one segment wide (a chord's sag peaks
/// at u = 0.5, which is sampled); 7 samples at u = k/8 are never more than 1/16 from its
/// peak, so they see it to within 1 − cos(π/16) ≈ 2 % of its height.
pub const DEVIATION_SAMPLES: usize = 7;
/// POLY refinement rounds before giving up on the tolerance.
const MAX_REFINEMENTS: usize = 8;

/// The two ways a curve table can run between its points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableForm {
    /// Straight lines in X(C) between points (G1).
    G1,
    /// Cubic polynomials in X(C) with continuous velocity and acceleration (POLY).
    Poly,
}

/// Where the table strays furthest from the exact X(C) between its points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deviation {
    pub max_um: f64,
    pub at_c_deg: f64,
}

/// X motion implied by a table at a constant C speed. G1 tables have velocity steps at every
/// point (acceleration and jerk unbounded), which is reported instead.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    pub c_speed_rpm: f64,
    pub velocity_max_mm_s: f64,
    /// Largest velocity step at a table point (G1 only), mm/s.
    pub velocity_step_max_mm_s: Option<f64>,
    pub acceleration_max_mm_s2: Option<f64>,
    pub jerk_max_mm_s3: Option<f64>,
}

/// Periodic C2 cubic segments through the table points, one per gap (the last closing the
/// period at first C + 360°). `points` must have C strictly increasing within one turn.
pub fn fit_poly(points: &[TablePoint]) -> Vec<PolySegment> {
    let c: Vec<f64> = points.iter().map(|p| p.c_deg).collect();
    let x: Vec<f64> = points.iter().map(|p| p.x_mm).collect();
    let spline = PeriodicSpline::new(&c, &x, 360.0);
    (0..points.len())
        .map(|i| {
            let [c0, c1, c2, c3] = spline.interval_coeffs(i);
            let h = spline.interval_len(i);
            PolySegment {
                c_start_deg: c[i],
                c_end_deg: c[i] + h,
                x0_mm: c0,
                a1_mm: c1 * h,
                a2_mm: c2 * h * h,
                a3_mm: c3 * h * h * h,
            }
        })
        .collect()
}

/// Fits POLY segments and, where a segment strays more than `tolerance_um` from the exact
/// path, inserts the exact midpoint and fits again. Returns the final points (original
/// points plus any inserted), the segments and the achieved deviation.
pub fn fit_poly_within(
    part: &Part,
    points: &[TablePoint],
    tolerance_um: f64,
) -> Result<(Vec<TablePoint>, Vec<PolySegment>, Deviation), GeometryError> {
    let mut points = points.to_vec();
    let x_zero = part.x_zero_mm();
    for _ in 0..MAX_REFINEMENTS {
        let segments = fit_poly(&points);
        let per_segment = segment_deviations(part, &segments)?;
        let worst = worst_of(&per_segment);
        if worst.max_um <= tolerance_um {
            return Ok((points, segments, worst));
        }
        let mut refined = Vec::with_capacity(points.len() * 2);
        for (point, (segment, dev)) in points.iter().zip(segments.iter().zip(&per_segment)) {
            refined.push(*point);
            if dev.max_um > tolerance_um {
                let c_deg = 0.5 * (segment.c_start_deg + segment.c_end_deg);
                let d_mm = part.d_at_c_deg(c_deg)?;
                refined.push(TablePoint {
                    c_deg,
                    d_mm,
                    x_mm: d_mm - x_zero,
                });
            }
        }
        points = refined;
    }
    let segments = fit_poly(&points);
    let worst = worst_of(&segment_deviations(part, &segments)?);
    Ok((points, segments, worst))
}

/// Largest deviation of straight chords between the points from the exact path.
pub fn g1_deviation(part: &Part, points: &[TablePoint]) -> Result<Deviation, GeometryError> {
    let chords = chords(points);
    Ok(worst_of(&segment_deviations(part, &chords)?))
}

/// G1 table motion at `c_speed_rpm`: chord velocities and the steps between them.
pub fn g1_motion(points: &[TablePoint], c_speed_rpm: f64) -> Motion {
    let omega_deg_s = c_speed_rpm * 6.0;
    let v: Vec<f64> = chords(points)
        .iter()
        .map(|s| s.a1_mm / (s.c_end_deg - s.c_start_deg) * omega_deg_s)
        .collect();
    let n = v.len();
    Motion {
        c_speed_rpm,
        velocity_max_mm_s: v.iter().fold(0.0, |m, x| m.max(x.abs())),
        velocity_step_max_mm_s: Some(
            (0..n).fold(0.0, |m, i| m.max((v[i] - v[(i + n - 1) % n]).abs())),
        ),
        acceleration_max_mm_s2: None,
        jerk_max_mm_s3: None,
    }
}

/// POLY table motion at `c_speed_rpm`, exact for the cubic segments.
pub fn poly_motion(segments: &[PolySegment], c_speed_rpm: f64) -> Motion {
    let omega_deg_s = c_speed_rpm * 6.0;
    let (mut v_max, mut a_max, mut j_max) = (0.0f64, 0.0f64, 0.0f64);
    for s in segments {
        let du_dt = omega_deg_s / (s.c_end_deg - s.c_start_deg);
        let (a1, a2, a3) = (s.a1_mm, s.a2_mm, s.a3_mm);
        let velocity = |u: f64| (a1 + 2.0 * a2 * u + 3.0 * a3 * u * u) * du_dt;
        let mut candidates = vec![velocity(0.0), velocity(1.0)];
        if a3 != 0.0 {
            let vertex = -a2 / (3.0 * a3);
            if (0.0..=1.0).contains(&vertex) {
                candidates.push(velocity(vertex));
            }
        }
        v_max = candidates.iter().fold(v_max, |m, x| m.max(x.abs()));
        let accel = |u: f64| (2.0 * a2 + 6.0 * a3 * u) * du_dt * du_dt;
        a_max = a_max.max(accel(0.0).abs()).max(accel(1.0).abs());
        j_max = j_max.max((6.0 * a3 * du_dt.powi(3)).abs());
    }
    Motion {
        c_speed_rpm,
        velocity_max_mm_s: v_max,
        velocity_step_max_mm_s: None,
        acceleration_max_mm_s2: Some(a_max),
        jerk_max_mm_s3: Some(j_max),
    }
}

/// The G1 chords written as (linear) segments.
fn chords(points: &[TablePoint]) -> Vec<PolySegment> {
    let n = points.len();
    (0..n)
        .map(|i| {
            let (p, q) = (points[i], points[(i + 1) % n]);
            let c_end_deg = if i + 1 < n { q.c_deg } else { q.c_deg + 360.0 };
            PolySegment {
                c_start_deg: p.c_deg,
                c_end_deg,
                x0_mm: p.x_mm,
                a1_mm: q.x_mm - p.x_mm,
                a2_mm: 0.0,
                a3_mm: 0.0,
            }
        })
        .collect()
}

fn poly_x(s: &PolySegment, u: f64) -> f64 {
    s.x0_mm + u * (s.a1_mm + u * (s.a2_mm + u * s.a3_mm))
}

fn segment_deviations(
    part: &Part,
    segments: &[PolySegment],
) -> Result<Vec<Deviation>, GeometryError> {
    let x_zero = part.x_zero_mm();
    // The samples walk round in C order: each solve starts from the previous one's path
    // parameter advanced by the C step, which is within a fraction of a degree of the root.
    let mut guess = segments.first().map_or(0.0, |s| s.c_start_deg.to_radians());
    let mut last_c_deg = segments.first().map_or(0.0, |s| s.c_start_deg);
    segments
        .iter()
        .map(|s| {
            let mut worst = Deviation {
                max_um: 0.0,
                at_c_deg: s.c_start_deg,
            };
            for k in 1..=DEVIATION_SAMPLES {
                let u = k as f64 / (DEVIATION_SAMPLES + 1) as f64;
                let c_deg = s.c_start_deg + u * (s.c_end_deg - s.c_start_deg);
                let (d_mm, psi) =
                    part.d_at_c_deg_near(c_deg, guess + (c_deg - last_c_deg).to_radians())?;
                (guess, last_c_deg) = (psi, c_deg);
                let dev_um = (poly_x(s, u) - (d_mm - x_zero)).abs() * 1000.0;
                if dev_um > worst.max_um {
                    worst = Deviation {
                        max_um: dev_um,
                        at_c_deg: c_deg.rem_euclid(360.0),
                    };
                }
            }
            Ok(worst)
        })
        .collect()
}

fn worst_of(devs: &[Deviation]) -> Deviation {
    devs.iter().copied().fold(
        Deviation {
            max_um: 0.0,
            at_c_deg: 0.0,
        },
        |a, b| if b.max_um > a.max_um { b } else { a },
    )
}
