//! What the plan needs from the part at every angle of its grid: the exact X(C) with its
//! first three derivatives, and the wheel–part contact (the contact point's surface speed
//! per radian of C and the profile's curvature there).

use crate::geometry::{GeometryError, Part};
use std::f64::consts::{PI, TAU};

/// Grid step of the plan and of every limit check, degrees of C.
pub const GRID_STEP_DEG: f64 = 0.1;
/// The geometry is sampled twice as finely as the grid, so each grid angle has its central
/// differences from neighbours 0.05° away: the truncation error of the five-point third
/// difference is h²/4·|X⁽⁵⁾|, below 1e-4 of |X‴| for any profile whose features span more
/// than a degree.
const SUBSTEPS: usize = 2;

/// One grid angle of a part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileSample {
    pub c_deg: f64,
    /// Program X (`d − x_zero`), mm.
    pub x_mm: f64,
    /// dX/dC, mm/rad.
    pub x1_mm_rad: f64,
    /// d²X/dC², mm/rad².
    pub x2_mm_rad2: f64,
    /// d³X/dC³, mm/rad³, from behind and from ahead (one-sided third differences over
    /// 0.15°). A lift table is a cubic spline, so X‴ steps at its knots; the jerk is checked
    /// with both sides and the larger counts, so a step is never averaged away.
    pub x3_sides_mm_rad3: [f64; 2],
    /// ds/dC: the arc length the contact point runs along the finished profile per radian of
    /// C, mm/rad. Times ω it is the part's surface speed at the contact.
    pub surface_mm_rad: f64,
    /// Signed curvature of the finished profile at the contact, 1/mm (positive convex).
    pub curvature_per_mm: f64,
}

/// The part sampled on the plan's grid (`GRID_STEP_DEG`, starting at C = 0°).
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileSamples {
    pub samples: Vec<ProfileSample>,
    pub wheel_radius_mm: f64,
}

impl ProfileSamples {
    /// Samples `part` at every grid angle. X comes from the exact geometry at twice the
    /// grid's density and its derivatives are five-point central differences of those exact
    /// values; the contact's motion comes from exact contact points close either side. Every
    /// follower and the crankpin go through this one code path.
    pub fn new(part: &Part) -> Result<Self, GeometryError> {
        let n = grid_points();
        let m = n * SUBSTEPS;
        let h_rad = TAU / m as f64;
        let x_zero = part.x_zero_mm();
        let x = (0..m)
            .map(|k| Ok(part.d_at_c_deg(k as f64 * 360.0 / m as f64)? - x_zero))
            .collect::<Result<Vec<f64>, GeometryError>>()?;
        let at = |k: isize| x[k.rem_euclid(m as isize) as usize];
        let samples = (0..n)
            .map(|i| {
                let k = (i * SUBSTEPS) as isize;
                let (xm2, xm1, x0, xp1, xp2) = (at(k - 2), at(k - 1), at(k), at(k + 1), at(k + 2));
                let c_deg = i as f64 * GRID_STEP_DEG;
                let (surface_mm_rad, curvature_per_mm) = contact_motion(part, c_deg)?;
                Ok(ProfileSample {
                    c_deg,
                    x_mm: x0,
                    x1_mm_rad: (8.0 * (xp1 - xm1) - (xp2 - xm2)) / (12.0 * h_rad),
                    x2_mm_rad2: (xp1 - 2.0 * x0 + xm1) / (h_rad * h_rad),
                    x3_sides_mm_rad3: [
                        (x0 - 3.0 * xm1 + 3.0 * xm2 - at(k - 3)) / h_rad.powi(3),
                        (at(k + 3) - 3.0 * xp2 + 3.0 * xp1 - x0) / h_rad.powi(3),
                    ],
                    surface_mm_rad,
                    curvature_per_mm,
                })
            })
            .collect::<Result<Vec<_>, GeometryError>>()?;
        Ok(Self {
            samples,
            wheel_radius_mm: part.wheel_radius_mm(),
        })
    }
}

/// The contact's arc length per radian of C (mm/rad) and the profile's curvature (1/mm) at
/// `c_deg`, from the exact contact points and normals 0.001° either side: close enough that
/// a kink in the profile's curvature (a C² lift table's knots) is not averaged away.
fn contact_motion(part: &Part, c_deg: f64) -> Result<(f64, f64), GeometryError> {
    const EPS_DEG: f64 = 1e-3;
    let (wm, pm) = part.contact_at_c_deg(c_deg - EPS_DEG)?;
    let (wp, pp) = part.contact_at_c_deg(c_deg + EPS_DEG)?;
    let span_rad = (2.0 * EPS_DEG).to_radians();
    let surface = (pp[0] - pm[0]).hypot(pp[1] - pm[1]) / span_rad;
    let normal = |w: [f64; 2], p: [f64; 2]| (w[1] - p[1]).atan2(w[0] - p[0]);
    let turn = wrap_pi(normal(wp, pp) - normal(wm, pm));
    let curvature = if surface > 0.0 {
        turn / span_rad / surface
    } else {
        0.0
    };
    Ok((surface, curvature))
}

/// Grid angles per revolution.
pub fn grid_points() -> usize {
    (360.0 / GRID_STEP_DEG).round() as usize
}

fn wrap_pi(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// Material removed per unit width and per mm the contact runs along the finished profile,
/// mm²/mm, when a stock of `stock_mm` (a uniform offset along the normal) comes off at once:
/// the area between a curve of curvature κ and its offset by δ is δ·(1 + δκ/2) per unit arc
/// length (exact for the osculating circle: ((ρ + δ)² − ρ²)/(2ρ)).
pub fn removal_per_arc_mm(stock_mm: f64, curvature_per_mm: f64) -> f64 {
    stock_mm * (1.0 + 0.5 * stock_mm * curvature_per_mm)
}

/// Geometric contact length (mm) of a wheel of radius `wheel_radius_mm` touching the finished
/// profile (osculating radius ρ = 1/κ) and cutting a stock δ: the arc of the wheel inside
/// the circle of radius ρ + δ concentric with the osculating circle. For a flat stretch
/// (κ = 0) it is the chord of a wheel dipping δ into a half plane.
pub fn contact_length_mm(wheel_radius_mm: f64, stock_mm: f64, curvature_per_mm: f64) -> f64 {
    let r = wheel_radius_mm;
    if curvature_per_mm.abs() < 1e-9 {
        return r * (1.0 - stock_mm / r).clamp(-1.0, 1.0).acos();
    }
    let rho = 1.0 / curvature_per_mm;
    let centres = r + rho;
    let outer = rho + stock_mm;
    let cos = (r * r + centres * centres - outer * outer) / (2.0 * r * centres);
    r * cos.clamp(-1.0, 1.0).acos()
}
