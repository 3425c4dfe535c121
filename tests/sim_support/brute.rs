//! Brute-force oracle for the ground part, sharing no code with the simulator's envelope:
//! the real wheel path is recomputed here from the table with plain formulas, and the part
//! is what no wheel disc along it covers.
//!
//! - Radial function about an origin O inside the part (the axis for cams, the pin centre for
//!   crankpins): r(θ) = min over wheel positions c of the first hit of the ray from O at θ
//!   on the disc of radius R around W(c): t = w·e − sqrt(R² − (w·e⊥)²), w = W(c) − O,
//!   e = u(θ).
//! - Flat reading (support function): s(ψ) = max over θ of p(θ)·u(ψ), p(θ) = O + r(θ)·u(θ).
//! - Roller reading: the roller centre on the ray at ψ stands at
//!   max over θ of (p·e + sqrt(r² − (p·e⊥)²)), p = r(θ)·u(θ), e = u(ψ).
//!
//! Each optimum: a coarse scan (c every 0.25°, θ every 1°), a fine scan twelve times finer
//! over ±4 coarse steps around every coarse local optimum, then golden-section refinement of
//! every fine local optimum down to a 1e-11 rad bracket, keeping the best. Where two wheel
//! positions meet at a corner of the outline they are up to about 0.8° of c apart (nose of
//! a lobe, or a crankpin, from a 1° G1 table): the coarse scan may see them as one basin,
//! the ±1° fine scan separates them. (With ±1.5 coarse steps it missed one of them on a
//! crankpin flank and read the outline 0.01 µm too far out.) At a smooth optimum the
//! refinement leaves ½·|f''|·(1e-11)² (nothing); at a kink (a corner, a wheel position at a
//! table point) |f'|·1e-11 < 1e-8 mm.

use std::f64::consts::TAU;

/// Half-width of the window of wheel positions searched around θ (rad). The contact point
/// on the demo lobe's flanks lies up to ~20° of polar angle from its wheel's direction.
const C_WINDOW: f64 = 0.6;
const C_STEP: f64 = 0.25 * TAU / 360.0;
/// Half-width of the window of polar angles searched around ψ (rad).
const THETA_WINDOW: f64 = 0.6;
const THETA_STEP: f64 = 1.0 * TAU / 360.0;
const GOLDEN_TOL: f64 = 1e-11;

/// X(C) as the control would run it, evaluated the plain way.
#[derive(Debug, Clone)]
pub enum BruteTable {
    /// (c_deg, x_mm) points; X linear in C between them, periodic.
    G1(Vec<(f64, f64)>),
    /// (c_start_deg, c_end_deg, [x0, a1, a2, a3]) segments in u = (c − c_start)/(c_end − c_start).
    Poly(Vec<(f64, f64, [f64; 4])>),
}

impl BruteTable {
    /// X at `c_deg` (any real).
    pub fn x_mm(&self, c_deg: f64) -> f64 {
        match self {
            BruteTable::G1(points) => {
                let c0 = points[0].0;
                let c = c0 + (c_deg - c0).rem_euclid(360.0);
                let n = points.len();
                let i = points.partition_point(|p| p.0 <= c) - 1;
                let (ca, xa) = points[i];
                let (cb, xb) = if i + 1 < n {
                    points[i + 1]
                } else {
                    (points[0].0 + 360.0, points[0].1)
                };
                xa + (xb - xa) * (c - ca) / (cb - ca)
            }
            BruteTable::Poly(segments) => {
                let c0 = segments[0].0;
                let c = c0 + (c_deg - c0).rem_euclid(360.0);
                let (cs, ce, [x0, a1, a2, a3]) = *segments
                    .iter()
                    .rev()
                    .find(|s| s.0 <= c)
                    .expect("c at or after the first segment start");
                let u = (c - cs) / (ce - cs);
                x0 + a1 * u + a2 * u * u + a3 * u * u * u
            }
        }
    }
}

/// The machine's real wheel path and wheel.
#[derive(Debug, Clone)]
pub struct BrutePath {
    pub table: BruteTable,
    pub x_zero_mm: f64,
    pub lag_deg: f64,
    /// (order, amplitude mm, phase deg).
    pub harmonics: Vec<(f64, f64, f64)>,
    pub wheel_radius_mm: f64,
    /// Centre of the polar description of the outline: the axis for cams, the pin centre
    /// for a crankpin (whose outline need not enclose the axis).
    pub origin: [f64; 2],
}

impl BrutePath {
    /// Wheel centre at C = `c` (rad), mm.
    pub fn centre(&self, c: f64) -> [f64; 2] {
        let c_deg = c.to_degrees();
        let mut d = self.table.x_mm(c_deg - self.lag_deg) + self.x_zero_mm;
        for &(k, a, phi_deg) in &self.harmonics {
            d += a * (k * c + phi_deg.to_radians()).cos();
        }
        [d * c.cos(), d * c.sin()]
    }

    /// Outline radius at polar angle `theta` (rad) about `origin`, mm.
    pub fn radius_mm(&self, theta: f64) -> f64 {
        let (s, co) = theta.sin_cos();
        let r = self.wheel_radius_mm;
        let o = self.origin;
        let hit = |c: f64| {
            let w = self.centre(c);
            let w = [w[0] - o[0], w[1] - o[1]];
            let along = w[0] * co + w[1] * s;
            let across = -w[0] * s + w[1] * co;
            if across.abs() > r {
                f64::INFINITY
            } else {
                along - (r * r - across * across).sqrt()
            }
        };
        optimum(hit, theta - C_WINDOW, theta + C_WINDOW, C_STEP, false)
    }

    /// Outline point at polar angle `theta` (rad) about `origin`, in part coordinates.
    pub fn point(&self, theta: f64) -> [f64; 2] {
        let r = self.radius_mm(theta);
        [
            self.origin[0] + r * theta.cos(),
            self.origin[1] + r * theta.sin(),
        ]
    }

    /// Support function (flat face distance) in direction `psi` (rad), mm.
    pub fn support_mm(&self, psi: f64) -> f64 {
        let (s, co) = psi.sin_cos();
        let f = |theta: f64| {
            let p = self.point(theta);
            p[0] * co + p[1] * s
        };
        optimum(f, psi - THETA_WINDOW, psi + THETA_WINDOW, THETA_STEP, true)
    }

    /// Roller centre distance on the ray at `psi` (rad) for a roller of `roller_mm`, mm.
    pub fn roller_centre_mm(&self, psi: f64, roller_mm: f64) -> f64 {
        let (s, co) = psi.sin_cos();
        let f = |theta: f64| {
            let p = self.point(theta);
            let along = p[0] * co + p[1] * s;
            let across = -p[0] * s + p[1] * co;
            if across.abs() > roller_mm {
                f64::NEG_INFINITY
            } else {
                along + (roller_mm * roller_mm - across * across).sqrt()
            }
        };
        // The roller touches within asin(r/ρ) of its ray: well inside ±0.6 rad here.
        optimum(f, psi - THETA_WINDOW, psi + THETA_WINDOW, THETA_STEP, true)
    }
}

/// Minimum (or maximum) of `f` on `[lo, hi]`: a coarse scan at `coarse`, a fine scan at
/// `coarse / 12` over ±4 coarse steps around every local optimum of the coarse scan,
/// golden-section refinement of every local optimum of the fine scans; the best wins.
/// Panics if the best coarse sample sits on the window edge.
pub fn optimum(f: impl Fn(f64) -> f64, lo: f64, hi: f64, coarse: f64, maximise: bool) -> f64 {
    let sign = if maximise { -1.0 } else { 1.0 };
    let g = |x: f64| sign * f(x);
    let (xs, vs) = scan(&g, lo, hi, coarse);
    let n = xs.len() - 1;
    let best_coarse = (0..=n)
        .min_by(|&a, &b| vs[a].total_cmp(&vs[b]))
        .expect("non-empty scan");
    assert!(
        best_coarse > 0 && best_coarse < n,
        "brute-force optimum at the window edge (sample {best_coarse} of {n})"
    );
    let mut best = f64::INFINITY;
    for i in local_minima(&vs) {
        let (fx, fv) = scan(
            &g,
            xs[i] - 4.0 * coarse,
            xs[i] + 4.0 * coarse,
            coarse / 12.0,
        );
        for j in local_minima(&fv) {
            let h = fx[1] - fx[0];
            best = best.min(golden_min(g, fx[j] - h, fx[j] + h).min(fv[j]));
        }
    }
    sign * best
}

fn scan(g: &impl Fn(f64) -> f64, lo: f64, hi: f64, step: f64) -> (Vec<f64>, Vec<f64>) {
    let n = ((hi - lo) / step).ceil() as usize;
    let h = (hi - lo) / n as f64;
    let xs: Vec<f64> = (0..=n).map(|i| lo + h * i as f64).collect();
    let vs = xs.iter().map(|&x| g(x)).collect();
    (xs, vs)
}

/// Interior samples no larger than their neighbours (finite ones only).
fn local_minima(vs: &[f64]) -> Vec<usize> {
    (1..vs.len() - 1)
        .filter(|&i| vs[i].is_finite() && vs[i] <= vs[i - 1] && vs[i] <= vs[i + 1])
        .collect()
}

/// Minimum value of `f` on `[a, b]`, to [`GOLDEN_TOL`] in the argument.
pub fn golden_min(f: impl Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    super::golden::golden_min(f, a, b, GOLDEN_TOL).1
}
