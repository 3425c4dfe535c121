//! Analytic test lifts: a single cam lobe with C3 polynomial rise and return, its 1° table,
//! and curvature margins per follower (finite differences, used only to check that a test
//! part is a valid, grindable one).

use std::f64::consts::{PI, TAU};

/// A lobe on a base circle: dwell (zero lift), rise over `rise_deg` to the nose at `nose_deg`
/// (lift `lift_mm`), return over `return_deg`, dwell.
///
/// Rise: h = L·P(x), x = (ψ − ψ_open)/β_rise ∈ [0, 1], with the degree-7 polynomial
/// P(x) = x⁴·(c0 + c1·x + c2·x² + c3·x³) fixed by P(1) = 1, P'(1) = 0, P'''(1) = 0,
/// P''(1) = −a (a = `nose_accel`), and P = P' = P'' = P''' = 0 at x = 0. The return mirrors it
/// with its own duration and a_return = a·(β_return/β_rise)², so h'' agrees at the nose. The
/// lift is therefore C3 everywhere (C∞ inside each piece), and asymmetric when the durations
/// differ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolyLobe {
    pub lift_mm: f64,
    pub nose_deg: f64,
    pub rise_deg: f64,
    pub return_deg: f64,
    pub nose_accel: f64,
}

/// The polynomial P(x) of [`PolyLobe`] for nose acceleration `a`. Coefficients: the 4-5-6-7
/// polynomial (35, −84, 70, −20) plus a·(−5/2, 7, −13/2, 2), the solution of the four end
/// conditions at x = 1 (checked in the oracle self-tests).
pub fn rise_polynomial(x: f64, a: f64) -> f64 {
    let c0 = 35.0 - 2.5 * a;
    let c1 = -84.0 + 7.0 * a;
    let c2 = 70.0 - 6.5 * a;
    let c3 = -20.0 + 2.0 * a;
    let x2 = x * x;
    x2 * x2 * (c0 + x * (c1 + x * (c2 + x * c3)))
}

impl PolyLobe {
    /// Lift at follower direction `psi_rad` (any real, 2π-periodic), mm.
    pub fn lift_at_rad(&self, psi_rad: f64) -> f64 {
        // Offset from the nose, wrapped into (−π, π].
        let mut delta = (psi_rad - self.nose_deg.to_radians()).rem_euclid(TAU);
        if delta > PI {
            delta -= TAU;
        }
        let rise = self.rise_deg.to_radians();
        let ret = self.return_deg.to_radians();
        if delta <= 0.0 && delta >= -rise {
            self.lift_mm * rise_polynomial((delta + rise) / rise, self.nose_accel)
        } else if delta > 0.0 && delta <= ret {
            let a_return = self.nose_accel * (ret / rise).powi(2);
            self.lift_mm * rise_polynomial((ret - delta) / ret, a_return)
        } else {
            0.0
        }
    }

    /// Lift at follower direction `psi_deg`, mm.
    pub fn lift_at_deg(&self, psi_deg: f64) -> f64 {
        self.lift_at_rad(psi_deg.to_radians())
    }

    /// Whether follower direction `psi_deg` is on the base circle (outside rise and return).
    pub fn on_base_circle(&self, psi_deg: f64) -> bool {
        let delta = (psi_deg - self.nose_deg + 180.0).rem_euclid(360.0) - 180.0;
        delta < -self.rise_deg || delta > self.return_deg
    }

    /// The lobe sampled at 0°, 1°, …, 359°: (angles_deg, lifts_mm).
    pub fn table_1deg(&self) -> (Vec<f64>, Vec<f64>) {
        let angles: Vec<f64> = (0..360).map(f64::from).collect();
        let lifts = angles.iter().map(|&a| self.lift_at_deg(a)).collect();
        (angles, lifts)
    }
}

/// Periodic linear interpolation of a 1° table (`lifts_mm[k]` at k°), at `psi_rad`, mm.
pub fn linear_1deg_lift_at_rad(lifts_mm: &[f64], psi_rad: f64) -> f64 {
    let n = lifts_mm.len();
    let x = psi_rad.to_degrees().rem_euclid(n as f64);
    let k = (x.floor() as usize).min(n - 1);
    let t = x - k as f64;
    lifts_mm[k] * (1.0 - t) + lifts_mm[(k + 1) % n] * t
}

/// Finite-difference step for the curvature checks, rad. Truncation ~h''''·δ²/12 and rounding
/// ~ε·h/δ² are both far below the margins the tests ask for.
const FD_STEP_RAD: f64 = 1e-4;

/// (h, h', h'') at ψ by central differences (mm, mm/rad, mm/rad²).
fn derivatives(lift: &impl Fn(f64) -> f64, psi: f64) -> (f64, f64, f64) {
    let (hm, h0, hp) = (lift(psi - FD_STEP_RAD), lift(psi), lift(psi + FD_STEP_RAD));
    (
        h0,
        (hp - hm) / (2.0 * FD_STEP_RAD),
        (hp - 2.0 * h0 + hm) / (FD_STEP_RAD * FD_STEP_RAD),
    )
}

/// Signed curvature of the polar curve ρ(ψ) (1/mm, positive where convex).
fn polar_curvature(rho: f64, d1: f64, d2: f64) -> f64 {
    (rho * rho + 2.0 * d1 * d1 - rho * d2) / (rho * rho + d1 * d1).powf(1.5)
}

/// Checks 0.1° apart over the revolution.
fn check_angles() -> impl Iterator<Item = f64> {
    (0..3600).map(|i| (f64::from(i) * 0.1).to_radians())
}

/// Flat follower: minimum radius of curvature Rb + h + h'' over the revolution, mm
/// (the cam is valid when positive).
pub fn flat_min_radius_mm(lift: impl Fn(f64) -> f64, base_radius_mm: f64) -> f64 {
    check_angles()
        .map(|psi| {
            let (h, _, h2) = derivatives(&lift, psi);
            base_radius_mm + h + h2
        })
        .fold(f64::INFINITY, f64::min)
}

/// Knife edge: minimum signed curvature of the outline r = Rb + h, 1/mm. A wheel of radius R
/// can grind it when this is ≥ −1/R (no concave stretch tighter than R).
pub fn knife_min_curvature_per_mm(lift: impl Fn(f64) -> f64, base_radius_mm: f64) -> f64 {
    check_angles()
        .map(|psi| {
            let (h, h1, h2) = derivatives(&lift, psi);
            polar_curvature(base_radius_mm + h, h1, h2)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Roller follower: (minimum, maximum) signed curvature of the pitch curve
/// q = (Rb + r + h)·u, 1/mm. The roller does not undercut when the maximum is < 1/r; the cam's
/// concave stretches have radius 1/|κ| + r, so a wheel of radius R can grind it when the
/// minimum is ≥ −1/(R − r).
pub fn roller_pitch_curvature_range_per_mm(
    lift: impl Fn(f64) -> f64,
    base_radius_mm: f64,
    roller_radius_mm: f64,
) -> (f64, f64) {
    check_angles()
        .map(|psi| {
            let (h, h1, h2) = derivatives(&lift, psi);
            polar_curvature(base_radius_mm + roller_radius_mm + h, h1, h2)
        })
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), k| {
            (lo.min(k), hi.max(k))
        })
}
