//! The analytic cam the analysis tests and benchmark measure against: cycloidal rise over
//! 70° from 110°, immediate cycloidal return over 70° (C2: acceleration is continuous and
//! zero at the ends), 9 mm lift, nose at 180°.

#![allow(dead_code)]

pub const LIFT_MM: f64 = 9.0;
pub const RISE_FROM_DEG: f64 = 110.0;
pub const RISE_DEG: f64 = 70.0;

/// Lift (mm) and its slope (mm/°) at `angle_deg`.
pub fn cam(angle_deg: f64) -> (f64, f64) {
    let psi = angle_deg.rem_euclid(360.0);
    let cycloid = |u: f64| {
        let w = std::f64::consts::TAU * u;
        (
            LIFT_MM * (u - w.sin() / std::f64::consts::TAU),
            LIFT_MM * (1.0 - w.cos()) / RISE_DEG,
        )
    };
    let top = RISE_FROM_DEG + RISE_DEG;
    if (RISE_FROM_DEG..=top).contains(&psi) {
        cycloid((psi - RISE_FROM_DEG) / RISE_DEG)
    } else if psi > top && psi <= top + RISE_DEG {
        let (h, dh) = cycloid((top + RISE_DEG - psi) / RISE_DEG);
        (h, -dh)
    } else {
        (0.0, 0.0)
    }
}
