//! Independent wheel-centre oracle: the part outline is built by brute force from the lift
//! function alone (no lift derivatives, no offset curves), grown by the wheel radius, and the
//! wheel-centre distance read off as the radial function of the grown outline.
//!
//! Method (the "independent check" of the geometry notes), all angles in radians inside:
//! - Cam outline as a radial function r(θ), a minimum over all follower positions ψ:
//!   - flat face: the cam is ∩ {x : x·u(ψ) ≤ Rb + h(ψ)}, so r(θ) = min (Rb + h(ψ)) / cos(θ − ψ)
//!     over cos(θ − ψ) > 0;
//!   - roller of radius r: the cam is what no roller disc (centre q(ψ) = (Rb + r + h(ψ))·u(ψ))
//!     overlaps, so r(θ) = min over ψ of the first hit of the ray at θ on disc ψ,
//!     t = q·e − sqrt(r² − (q·e⊥)²) where |q·e⊥| ≤ r;
//!   - knife edge: r(θ) = Rb + h(θ).
//! - Crankpin outline: the pin circle (radius r_p, centre (b, 0)), parametrised by its own angle.
//! - Wheel-centre distance: d(c) = max over outline points p with |p·e⊥| ≤ R of
//!   p·e + sqrt(R² − (p·e⊥)²), e = u(c).
//!
//! Every minimum and maximum is found by a dense scan followed by golden-section refinement of
//! the best sample's bracket down to δ = 1e-8 rad. Near a smooth optimum the value error is
//! ½·|f''|·δ² ≤ 1e-13 mm for |f''| ≤ 2000 mm/rad² (the sharpest nose met here is far
//! gentler), so the oracle's own error is at the level of floating-point rounding
//! (~1e-13 mm), as its self-tests show.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Outline samples around the revolution for the outer scan: one every 0.05°.
pub const OUTLINE_SAMPLES: usize = 7200;

/// Golden-section refinement stops when the bracket is this narrow, rad.
const ARG_TOL_RAD: f64 = 1e-8;

/// Coarse scan step over a follower window, rad (0.5°). The bound along a ray has one basin
/// per face or roller that can touch it, so the coarse scan only has to land in the right
/// basin; the fine scan and golden section do the rest.
const COARSE_STEP_RAD: f64 = 0.5 * PI / 180.0;

/// Fine scan step around the coarse optimum and inside narrowed windows, rad (0.01°).
const FINE_STEP_RAD: f64 = 0.01 * PI / 180.0;

/// Half-width of the flat-face search window around θ, rad. The contact normal leaves the
/// ray by atan(h' / (Rb + h)), far less than this for any valid cam; reaching the window edge
/// is reported as an oracle failure.
const FLAT_WINDOW_RAD: f64 = 80.0 * PI / 180.0;

/// The follower a cam oracle models.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OracleFollower {
    /// Flat-faced follower (also the flat gauge probe).
    Flat,
    /// Roller follower of the given radius, mm.
    Roller { radius_mm: f64 },
    /// Knife-edge (point) follower.
    Knife,
}

/// Minimum of `f` on `[a, b]` to [`ARG_TOL_RAD`]: (argument, value).
pub fn golden_min(f: impl Fn(f64) -> f64, a: f64, b: f64) -> (f64, f64) {
    super::golden::golden_min(f, a, b, ARG_TOL_RAD)
}

/// Best sample of `f` on `n + 1` evenly spaced points of `[lo, hi]`: (index, argument, value).
fn scan_min(f: &impl Fn(f64) -> f64, lo: f64, hi: f64, n: usize) -> (usize, f64, f64) {
    let step = (hi - lo) / n as f64;
    let mut best = (0, lo, f(lo));
    for i in 1..=n {
        let x = lo + step * i as f64;
        let v = f(x);
        if v < best.2 {
            best = (i, x, v);
        }
    }
    best
}

/// Minimum of `f` on `[lo, hi]`: scan at `step`, then golden-section on the best sample's
/// bracket. `None` when the best sample is a window end (the minimum may lie outside).
fn scan_refine_min(f: &impl Fn(f64) -> f64, lo: f64, hi: f64, step: f64) -> Option<(f64, f64)> {
    let n = (((hi - lo) / step).ceil() as usize).max(4);
    let h = (hi - lo) / n as f64;
    let (i, x, v) = scan_min(f, lo, hi, n);
    if i == 0 || i == n {
        return None;
    }
    let (xr, vr) = golden_min(f, x - h, x + h);
    Some(if vr <= v { (xr, vr) } else { (x, v) })
}

/// Minimum of `f` over a wide window: coarse scan, fine scan around the coarse best, golden.
fn wide_min(f: &impl Fn(f64) -> f64, lo: f64, hi: f64) -> Option<(f64, f64)> {
    let n = (((hi - lo) / COARSE_STEP_RAD).ceil() as usize).max(4);
    let (i, x, _) = scan_min(f, lo, hi, n);
    if i == 0 || i == n {
        return None;
    }
    let pad = (hi - lo) / n as f64;
    scan_refine_min(f, (x - pad).max(lo), (x + pad).min(hi), FINE_STEP_RAD)
}

/// How far a wheel of radius `wheel_mm` centred in direction (cos c, sin c) must stand from
/// the axis to clear point `p`, mm; −∞ when the point is out of the wheel's reach sideways.
fn reach_mm(p: [f64; 2], cos_c: f64, sin_c: f64, wheel_mm: f64) -> f64 {
    let along = p[0] * cos_c + p[1] * sin_c;
    let across = -p[0] * sin_c + p[1] * cos_c;
    if across.abs() > wheel_mm {
        f64::NEG_INFINITY
    } else {
        along + (wheel_mm * wheel_mm - across * across).sqrt()
    }
}

/// Radial function of an outline grown by `wheel_mm` in direction `c_rad`: scan the outline
/// samples (`samples[k]` is the point at parameter k·2π/n), then refine the best one's bracket
/// with `point(s, k)` (the exact point at parameter s, k the bracket's sample index).
fn envelope_mm(
    samples: &[[f64; 2]],
    point: impl Fn(f64, usize) -> [f64; 2],
    wheel_mm: f64,
    c_rad: f64,
) -> f64 {
    let (sin_c, cos_c) = c_rad.sin_cos();
    // A sparse pass first, so that the full pass can skip most points on the bound
    // reach ≤ p·e + R without evaluating the square root.
    let mut best = (0, f64::NEG_INFINITY);
    for (k, &p) in samples.iter().enumerate().step_by(20) {
        let v = reach_mm(p, cos_c, sin_c, wheel_mm);
        if v > best.1 {
            best = (k, v);
        }
    }
    for (k, p) in samples.iter().enumerate() {
        if p[0] * cos_c + p[1] * sin_c + wheel_mm <= best.1 {
            continue;
        }
        let v = reach_mm(*p, cos_c, sin_c, wheel_mm);
        if v > best.1 {
            best = (k, v);
        }
    }
    let step = TAU / samples.len() as f64;
    let s_k = step * best.0 as f64;
    let neg_reach = |s: f64| -reach_mm(point(s, best.0), cos_c, sin_c, wheel_mm);
    let (_, neg_v) = golden_min(neg_reach, s_k - step, s_k + step);
    best.1.max(-neg_v)
}

/// Wheel-centre oracle for any outline given explicitly as a closed curve p(s), s ∈ [0, 2π)
/// (knife-edge cam, crankpin pin circle, roller pitch curve).
pub struct CurveOracle<P: Fn(f64) -> [f64; 2]> {
    point: P,
    wheel_radius_mm: f64,
    samples: Vec<[f64; 2]>,
}

impl<P: Fn(f64) -> [f64; 2]> CurveOracle<P> {
    /// `point(s)` is the outline point at parameter s (rad, any real, 2π-periodic), mm.
    pub fn new(point: P, wheel_radius_mm: f64) -> Self {
        let step = TAU / OUTLINE_SAMPLES as f64;
        let samples = (0..OUTLINE_SAMPLES)
            .map(|k| point(step * k as f64))
            .collect();
        CurveOracle {
            point,
            wheel_radius_mm,
            samples,
        }
    }

    /// Wheel-centre distance at wheel direction `c_deg`, mm.
    pub fn d_mm(&self, c_deg: f64) -> f64 {
        envelope_mm(
            &self.samples,
            |s, _| (self.point)(s),
            self.wheel_radius_mm,
            c_deg.to_radians(),
        )
    }
}

/// Crankpin oracle: the pin circle (radius `pin_radius_mm`, centre at `throw_mm` on the 0°
/// direction) as an explicit outline.
pub fn crankpin_oracle(
    throw_mm: f64,
    pin_radius_mm: f64,
    wheel_radius_mm: f64,
) -> CurveOracle<impl Fn(f64) -> [f64; 2]> {
    CurveOracle::new(
        move |s: f64| {
            let (sin_s, cos_s) = s.sin_cos();
            [throw_mm + pin_radius_mm * cos_s, pin_radius_mm * sin_s]
        },
        wheel_radius_mm,
    )
}

/// The closed-form crankpin wheel-centre distance of the geometry notes,
/// d(α) = b·cos α + sqrt((R + r_p)² − (b·sin α)²), with the pin at 0° so α = c, mm.
pub fn crankpin_closed_form_d_mm(
    throw_mm: f64,
    pin_radius_mm: f64,
    wheel_radius_mm: f64,
    c_deg: f64,
) -> f64 {
    let (sin_a, cos_a) = c_deg.to_radians().sin_cos();
    let reach = wheel_radius_mm + pin_radius_mm;
    throw_mm * cos_a + (reach * reach - (throw_mm * sin_a).powi(2)).sqrt()
}

/// Wheel-centre oracle for a cam given by its lift function and follower.
pub struct CamOracle<L: Fn(f64) -> f64> {
    lift_mm: L,
    base_radius_mm: f64,
    follower: OracleFollower,
    wheel_radius_mm: f64,
    /// Outline points at θ_k = k·2π/n, mm.
    points: Vec<[f64; 2]>,
    /// Minimising follower position at θ_k as an offset ψ* − θ_k, rad (0 for the knife edge).
    psi_offsets_rad: Vec<f64>,
}

impl<L: Fn(f64) -> f64> CamOracle<L> {
    /// `lift_mm(ψ)` is the lift at follower direction ψ (rad, called with ψ ∈ [0, 2π)), mm.
    /// Builds the dense outline (7200 samples) up front.
    ///
    /// Panics when a follower search ends at its window edge (the cam is not one this oracle
    /// can model, e.g. an undercut roller cam).
    pub fn new(
        lift_mm: L,
        base_radius_mm: f64,
        follower: OracleFollower,
        wheel_radius_mm: f64,
    ) -> Self {
        let mut oracle = CamOracle {
            lift_mm,
            base_radius_mm,
            follower,
            wheel_radius_mm,
            points: Vec::with_capacity(OUTLINE_SAMPLES),
            psi_offsets_rad: Vec::with_capacity(OUTLINE_SAMPLES),
        };
        let step = TAU / OUTLINE_SAMPLES as f64;
        for k in 0..OUTLINE_SAMPLES {
            let theta = step * k as f64;
            let (r, psi) = oracle.outline_wide(theta);
            oracle.points.push(polar(r, theta));
            oracle.psi_offsets_rad.push(psi - theta);
        }
        oracle
    }

    /// Lift at any ψ (rad), wrapped into [0, 2π) for the lift function.
    fn lift_at(&self, psi_rad: f64) -> f64 {
        (self.lift_mm)(psi_rad.rem_euclid(TAU))
    }

    /// Distance along the ray at `theta` to where follower position `psi` bounds the cam, mm
    /// (+∞ when that follower position does not cross the ray).
    fn bound_along_ray(&self, theta: f64, psi: f64) -> f64 {
        let rb = self.base_radius_mm;
        match self.follower {
            OracleFollower::Flat => {
                let cos_d = (theta - psi).cos();
                if cos_d <= 0.0 {
                    f64::INFINITY
                } else {
                    (rb + self.lift_at(psi)) / cos_d
                }
            }
            OracleFollower::Roller { radius_mm } => {
                let rho = rb + radius_mm + self.lift_at(psi);
                let (sin_d, cos_d) = (psi - theta).sin_cos();
                let along = rho * cos_d;
                let across = rho * sin_d;
                if along <= 0.0 || across.abs() > radius_mm {
                    f64::INFINITY
                } else {
                    along - (radius_mm * radius_mm - across * across).sqrt()
                }
            }
            // The knife edge bounds the ray only at ψ = θ; it is never searched.
            OracleFollower::Knife => rb + self.lift_at(theta),
        }
    }

    /// Follower search window around θ, rad.
    fn window(&self, theta: f64) -> (f64, f64) {
        match self.follower {
            OracleFollower::Flat => (theta - FLAT_WINDOW_RAD, theta + FLAT_WINDOW_RAD),
            // A disc centred at ≥ Rb + r from the axis meets the ray only within
            // asin(r / (Rb + r)) < 90° of it.
            _ => (theta - FRAC_PI_2, theta + FRAC_PI_2),
        }
    }

    /// Outline radius and minimising follower position at θ, searching the whole window.
    fn outline_wide(&self, theta: f64) -> (f64, f64) {
        if self.follower == OracleFollower::Knife {
            return (self.base_radius_mm + self.lift_at(theta), theta);
        }
        let (lo, hi) = self.window(theta);
        let f = |psi: f64| self.bound_along_ray(theta, psi);
        let (psi, r) = wide_min(&f, lo, hi).unwrap_or_else(|| {
            panic!(
                "oracle: follower search at θ = {:.4}° ended at its window edge",
                theta.to_degrees()
            )
        });
        (r, psi)
    }

    /// Outline radius at θ within the bracket of outline sample `k`: the follower search is
    /// narrowed to the minimisers of samples k−1, k, k+1 (the contact moves monotonically
    /// along a valid cam), with a fallback to the whole window.
    fn outline_near(&self, theta: f64, k: usize) -> f64 {
        if self.follower == OracleFollower::Knife {
            return self.base_radius_mm + self.lift_at(theta);
        }
        let step = TAU / OUTLINE_SAMPLES as f64;
        let theta_k = step * k as f64;
        let n = OUTLINE_SAMPLES as isize;
        let psi_of = |j: isize| {
            let offset = self.psi_offsets_rad[(k as isize + j).rem_euclid(n) as usize];
            theta_k + step * j as f64 + offset
        };
        let candidates = [psi_of(-1), psi_of(0), psi_of(1)];
        let pad = 5.0 * FINE_STEP_RAD;
        let lo = candidates.iter().copied().fold(f64::INFINITY, f64::min) - pad;
        let hi = candidates.iter().copied().fold(f64::NEG_INFINITY, f64::max) + pad;
        let f = |psi: f64| self.bound_along_ray(theta, psi);
        match scan_refine_min(&f, lo, hi, FINE_STEP_RAD) {
            Some((_, r)) => r,
            None => self.outline_wide(theta).0,
        }
    }

    /// Wheel-centre distance at wheel direction `c_deg`, mm.
    pub fn d_mm(&self, c_deg: f64) -> f64 {
        envelope_mm(
            &self.points,
            |theta, k| polar(self.outline_near(theta, k), theta),
            self.wheel_radius_mm,
            c_deg.to_radians(),
        )
    }
}

/// Point at radius `r` in direction `theta` (rad).
fn polar(r: f64, theta: f64) -> [f64; 2] {
    let (s, c) = theta.sin_cos();
    [r * c, r * s]
}

/// Second method for a flat-faced follower, valid because the cam is convex: the cam grown by
/// R has support function Rb + h + R, so its radial function is
/// d(c) = min over ψ of (Rb + h(ψ) + R) / cos(c − ψ). `lift_mm` as for [`CamOracle::new`].
pub fn flat_support_d_mm(
    lift_mm: impl Fn(f64) -> f64,
    base_radius_mm: f64,
    wheel_radius_mm: f64,
    c_deg: f64,
) -> f64 {
    let c = c_deg.to_radians();
    let f = |psi: f64| {
        let cos_d = (c - psi).cos();
        (base_radius_mm + lift_mm(psi.rem_euclid(TAU)) + wheel_radius_mm) / cos_d
    };
    let window = 60f64.to_radians();
    wide_min(&f, c - window, c + window)
        .expect("the wheel's contact normal is within 60° of its direction")
        .1
}

/// Second method for a roller follower whose pitch curve has no convex radius below r: the
/// cam grown by r is the region inside the pitch curve, so the cam grown by R is that region
/// grown by R − r. Returns the oracle over the pitch curve q(ψ) = (Rb + r + h(ψ))·u(ψ).
pub fn roller_pitch_oracle<L: Fn(f64) -> f64>(
    lift_mm: L,
    base_radius_mm: f64,
    roller_radius_mm: f64,
    wheel_radius_mm: f64,
) -> CurveOracle<impl Fn(f64) -> [f64; 2]> {
    CurveOracle::new(
        move |psi: f64| {
            polar(
                base_radius_mm + roller_radius_mm + lift_mm(psi.rem_euclid(TAU)),
                psi,
            )
        },
        wheel_radius_mm - roller_radius_mm,
    )
}

/// Radial function of a circle of radius `radius_mm` centred at (`offset_mm`, 0), which
/// contains the origin (`offset_mm < radius_mm`), at direction θ (rad), mm.
pub fn eccentric_circle_radius_mm(offset_mm: f64, radius_mm: f64, theta_rad: f64) -> f64 {
    let (s, c) = theta_rad.sin_cos();
    offset_mm * c + (radius_mm * radius_mm - (offset_mm * s).powi(2)).sqrt()
}
