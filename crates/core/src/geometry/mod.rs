//! Exact wheel-centre geometry: from a part (cam lobe with its follower, or crankpin) to
//! the wheel-centre distance `d` at any table angle `c`, with grindability checks.
//!
//! Conventions (see the domain notes): ψ is the follower direction in the part frame, `c`
//! the direction of the wheel centre in the same angular sense, `d` the distance from the
//! rotation axis to the wheel centre. No small-angle shortcut is taken anywhere.

use super::lift::LiftCurve;
use super::table::TablePoint;
use std::f64::consts::{FRAC_PI_2, TAU};

mod grindable;
mod x_offset;

/// Table sizes accepted per revolution.
pub const POINTS_RANGE: std::ops::RangeInclusive<usize> = 36..=36_000;
/// Largest angular step of the grindability scan (degrees). Every knot is scanned too: the
/// spline's h'' is linear between knots, so its extremes sit at knots, and 0.1° between them
/// sees any bad stretch of a tenth of a 1° table step.
const SCAN_STEP_DEG: f64 = 0.1;

/// The cam follower the lift table was designed for (and the gauge reads with).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Follower {
    /// Flat-faced follower: lift is the support function minus the base radius.
    Flat,
    /// Roller follower of the given radius.
    Roller { radius_mm: f64 },
    /// Knife-edge follower: lift is the polar radius minus the base radius.
    Knife,
}

impl Follower {
    pub fn name(&self) -> &'static str {
        match self {
            Follower::Flat => "flat",
            Follower::Roller { .. } => "roller",
            Follower::Knife => "knife",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CamGeometry {
    pub base_radius_mm: f64,
    pub follower: Follower,
    pub wheel_radius_mm: f64,
}

/// A crankpin: a circle of radius `pin_radius_mm` whose centre lies `throw_mm` from the main
/// axis, at angle 0° of the part frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CrankpinGeometry {
    pub throw_mm: f64,
    pub pin_radius_mm: f64,
    pub wheel_radius_mm: f64,
}

/// Why a part cannot be turned into a wheel-head table.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    #[error("{name} = {value} is invalid: {reason}")]
    InvalidParameter {
        name: &'static str,
        value: f64,
        reason: &'static str,
    },
    #[error(
        "negative radius of curvature for a flat follower between {from_deg:.2}° and {to_deg:.2}° (minimum ρ = Rb + h + h'' = {min_radius_mm:.4} mm): the profile would have a cusp{}",
        stretch_note(stretches)
    )]
    NegativeCurvature {
        from_deg: f64,
        to_deg: f64,
        min_radius_mm: f64,
        stretches: usize,
    },
    #[error(
        "roller of radius {roller_radius_mm} mm undercuts the profile between {from_deg:.2}° and {to_deg:.2}° (pitch-curve radius down to {min_pitch_radius_mm:.4} mm){}",
        stretch_note(stretches)
    )]
    Undercut {
        from_deg: f64,
        to_deg: f64,
        min_pitch_radius_mm: f64,
        roller_radius_mm: f64,
        stretches: usize,
    },
    #[error(
        "concave stretch between {from_deg:.2}° and {to_deg:.2}° has a radius down to {min_concave_radius_mm:.4} mm, smaller than the wheel radius {wheel_radius_mm} mm: the wheel cannot reach it{}",
        stretch_note(stretches)
    )]
    ConcaveTooTight {
        from_deg: f64,
        to_deg: f64,
        min_concave_radius_mm: f64,
        wheel_radius_mm: f64,
        stretches: usize,
    },
    #[error("base radius plus lift is not positive at {angle_deg:.2}°")]
    ProfileThroughAxis { angle_deg: f64 },
    #[error("{points} points per revolution is outside {}..={}", POINTS_RANGE.start(), POINTS_RANGE.end())]
    PointCount { points: usize },
    #[error("no follower angle found for table angle {c_deg:.6}° (geometry degenerate there)")]
    NoSolution { c_deg: f64 },
}

/// The wheel-centre position and its derivative with respect to the path parameter.
#[derive(Debug, Clone, Copy)]
struct PathPoint {
    w: [f64; 2],
    dw: [f64; 2],
    /// Unit normal from the contact point towards the wheel centre.
    normal: [f64; 2],
    /// Direction u(s) of the path parameter, to measure c − ψ against.
    u: [f64; 2],
}

#[derive(Debug, Clone)]
enum Kind {
    /// A cam lobe; with `pin` set, a crankpin described by its support function as the lift
    /// of a flat follower (see [`Part::shaped_pin`]).
    Cam {
        geometry: CamGeometry,
        lift: LiftCurve,
        pin: Option<CrankpinGeometry>,
    },
    Crankpin(CrankpinGeometry),
}

/// A part whose geometry has been checked: every table angle has exactly one wheel position.
#[derive(Debug, Clone)]
pub struct Part {
    kind: Kind,
}

impl Part {
    /// A cam lobe. Refuses geometry the wheel cannot grind (cusps, undercut, concave
    /// stretches tighter than the wheel), naming the angle range and the worst radius.
    pub fn cam(geometry: CamGeometry, lift: LiftCurve) -> Result<Self, GeometryError> {
        positive("base radius", geometry.base_radius_mm)?;
        positive("wheel radius", geometry.wheel_radius_mm)?;
        if let Follower::Roller { radius_mm } = geometry.follower {
            positive("roller radius", radius_mm)?;
        }
        let part = Self {
            kind: Kind::Cam {
                geometry,
                lift,
                pin: None,
            },
        };
        part.check_cam()?;
        Ok(part)
    }

    /// A crankpin ground to a corrected shape. Seen from the main axis its support function
    /// is `b·cos ψ + r_p + u(ψ)`, which is the lift `h = b·(1 + cos ψ) + u` of a flat follower
    /// on a base radius `r_p − b` (negative when the pin does not surround the axis; the flat
    /// follower's geometry holds all the same). `lift` is that h. Program X stays
    /// `d − R − r_p`, as for the round pin.
    pub(crate) fn shaped_pin(
        pin: CrankpinGeometry,
        lift: LiftCurve,
    ) -> Result<Self, GeometryError> {
        Self::crankpin(pin)?;
        let geometry = CamGeometry {
            base_radius_mm: pin.pin_radius_mm - pin.throw_mm,
            follower: Follower::Flat,
            wheel_radius_mm: pin.wheel_radius_mm,
        };
        let part = Self {
            kind: Kind::Cam {
                geometry,
                lift,
                pin: Some(pin),
            },
        };
        part.check_cam()?;
        Ok(part)
    }

    /// A crankpin. The wheel must be able to reach every side of the pin: `b < R + r_p`.
    pub fn crankpin(geometry: CrankpinGeometry) -> Result<Self, GeometryError> {
        positive("pin radius", geometry.pin_radius_mm)?;
        positive("wheel radius", geometry.wheel_radius_mm)?;
        if !(geometry.throw_mm.is_finite() && geometry.throw_mm >= 0.0) {
            return Err(GeometryError::InvalidParameter {
                name: "throw",
                value: geometry.throw_mm,
                reason: "must be a finite number ≥ 0",
            });
        }
        if geometry.throw_mm >= geometry.wheel_radius_mm + geometry.pin_radius_mm {
            return Err(GeometryError::InvalidParameter {
                name: "throw",
                value: geometry.throw_mm,
                reason: "must be smaller than wheel radius + pin radius",
            });
        }
        Ok(Self {
            kind: Kind::Crankpin(geometry),
        })
    }

    pub fn wheel_radius_mm(&self) -> f64 {
        match &self.kind {
            Kind::Cam { geometry, .. } => geometry.wheel_radius_mm,
            Kind::Crankpin(g) => g.wheel_radius_mm,
        }
    }

    /// Program X is `d − x_zero_mm`: `R + Rb` for cams, `R + r_p` for crankpins.
    pub fn x_zero_mm(&self) -> f64 {
        match &self.kind {
            Kind::Cam { pin: Some(g), .. } | Kind::Crankpin(g) => {
                g.wheel_radius_mm + g.pin_radius_mm
            }
            Kind::Cam { geometry, .. } => geometry.wheel_radius_mm + geometry.base_radius_mm,
        }
    }

    /// A circle worth drawing for orientation: the base circle of a cam, the main journal
    /// axis orbit of a crankpin's centre. Centre, radius (mm) and a label.
    pub(crate) fn reference_circle(&self) -> Option<([f64; 2], f64, String)> {
        match &self.kind {
            Kind::Cam { pin: Some(g), .. } => {
                Some(([0.0, 0.0], g.throw_mm, "pin-centre orbit".to_string()))
            }
            Kind::Cam { geometry, .. } => Some((
                [0.0, 0.0],
                geometry.base_radius_mm,
                "base circle".to_string(),
            )),
            Kind::Crankpin(g) if g.throw_mm > 0.0 => {
                Some(([0.0, 0.0], g.throw_mm, "pin-centre orbit".to_string()))
            }
            Kind::Crankpin(_) => None,
        }
    }

    /// The same part with another wheel radius (after dressing), checked again.
    pub fn with_wheel_radius(&self, wheel_radius_mm: f64) -> Result<Self, GeometryError> {
        match &self.kind {
            Kind::Cam {
                pin: Some(g), lift, ..
            } => Self::shaped_pin(
                CrankpinGeometry {
                    wheel_radius_mm,
                    ..*g
                },
                lift.clone(),
            ),
            Kind::Cam { geometry, lift, .. } => Self::cam(
                CamGeometry {
                    wheel_radius_mm,
                    ..*geometry
                },
                lift.clone(),
            ),
            Kind::Crankpin(g) => Self::crankpin(CrankpinGeometry {
                wheel_radius_mm,
                ..*g
            }),
        }
    }

    /// The table at `points` uniform angles `c = k·360/points`, k = 0..points.
    pub fn wheel_table(&self, points: usize) -> Result<Vec<TablePoint>, GeometryError> {
        if !POINTS_RANGE.contains(&points) {
            return Err(GeometryError::PointCount { points });
        }
        let x_zero = self.x_zero_mm();
        let step_deg = 360.0 / points as f64;
        let mut table = Vec::with_capacity(points);
        // Walk round in order, starting each solve from the previous ψ advanced by the table
        // step over dc/dψ there: the guess is then off by O(step²) and Newton needs one or
        // two steps.
        let mut guess = -self.c_minus_psi(self.path_point(0.0));
        for k in 0..points {
            let c_deg = k as f64 * step_deg;
            let (s, d_mm, p) = self.wheel_at(c_deg, guess)?;
            let dc_dpsi = cross(p.w, p.dw) / dot(p.w, p.w);
            guess = s + step_deg.to_radians() / dc_dpsi;
            table.push(TablePoint {
                c_deg,
                d_mm,
                x_mm: d_mm - x_zero,
            });
        }
        Ok(table)
    }

    /// Exact wheel-centre distance (mm) at table angle `c_deg`.
    pub fn d_at_c_deg(&self, c_deg: f64) -> Result<f64, GeometryError> {
        Ok(self.wheel_at_c_deg(c_deg)?.0)
    }

    /// Exact wheel-centre distance (mm) at table angle `c_deg`, starting the search from the
    /// path parameter of a nearby solution (`guess_rad`, e.g. the previous point of a walk).
    /// Returns d and the parameter found, to pass on as the next guess. Same result as
    /// [`Part::d_at_c_deg`]; only faster when the guess is close.
    pub(crate) fn d_at_c_deg_near(
        &self,
        c_deg: f64,
        guess_rad: f64,
    ) -> Result<(f64, f64), GeometryError> {
        let (s, d, _) = self.wheel_at(c_deg, guess_rad)?;
        Ok((d, s))
    }

    /// Wheel centre and contact point (part frame, mm) with the wheel at table angle `c_deg`.
    pub fn contact_at_c_deg(&self, c_deg: f64) -> Result<([f64; 2], [f64; 2]), GeometryError> {
        let (_, p) = self.wheel_at_c_deg(c_deg)?;
        let r = self.wheel_radius_mm();
        Ok((p.w, [p.w[0] - r * p.normal[0], p.w[1] - r * p.normal[1]]))
    }

    /// The part outline as `samples` points (part frame, mm), counter-clockwise.
    pub(crate) fn outline(&self, samples: usize) -> Vec<[f64; 2]> {
        let r = self.wheel_radius_mm();
        (0..samples)
            .map(|k| {
                let p = self.path_point(k as f64 * TAU / samples as f64);
                [p.w[0] - r * p.normal[0], p.w[1] - r * p.normal[1]]
            })
            .collect()
    }

    fn wheel_at_c_deg(&self, c_deg: f64) -> Result<(f64, PathPoint), GeometryError> {
        let target = c_deg.to_radians();
        // First guess: ψ = c − (c − ψ) evaluated at ψ = c.
        let guess = target - self.c_minus_psi(self.path_point(target));
        self.wheel_at(c_deg, guess).map(|(_, d, p)| (d, p))
    }

    /// Wheel position at table angle `c_deg` from a first guess of the path parameter;
    /// returns the parameter found, d and the path point.
    fn wheel_at(&self, c_deg: f64, guess: f64) -> Result<(f64, f64, PathPoint), GeometryError> {
        let target = c_deg.to_radians();
        let (s, p) = match &self.kind {
            // The crankpin path is parameterised by c itself.
            Kind::Crankpin(_) => (target, self.path_point(target)),
            Kind::Cam { .. } => self
                .solve_psi(target, guess)
                .ok_or(GeometryError::NoSolution { c_deg })?,
        };
        Ok((s, p.w[0].hypot(p.w[1]), p))
    }

    /// Finds ψ with c(ψ) = `c_target` (radians, unwrapped so that c(ψ) − ψ ∈ (−π/2, π/2)),
    /// starting from `guess`, and returns the wheel position there.
    ///
    /// Newton on the analytic dc/dψ, safeguarded by bisection on a bracket: c(ψ) is strictly
    /// increasing on a checked part, and |c − ψ| < π/2 brackets the root. It stops once the
    /// Newton step is below 1e-11 rad; d then differs from its value at the root by at most
    /// |dd/dψ|·1e-11, below 1e-6 µm for any real part (|dd/dψ| < 100 mm/rad).
    fn solve_psi(&self, c_target: f64, guess: f64) -> Option<(f64, PathPoint)> {
        let (mut lo, mut hi) = (c_target - FRAC_PI_2, c_target + FRAC_PI_2);
        let mut psi = guess.clamp(lo, hi);
        for _ in 0..100 {
            let p = self.path_point(psi);
            let f = psi + self.c_minus_psi(p) - c_target;
            if f < 0.0 {
                lo = psi;
            } else {
                hi = psi;
            }
            let dc = cross(p.w, p.dw) / dot(p.w, p.w);
            let step = f / dc;
            if dc > 0.0 && step.abs() < 1e-11 {
                return Some((psi, p));
            }
            let newton = psi - step;
            psi = if dc > 0.0 && newton > lo && newton < hi {
                newton
            } else {
                0.5 * (lo + hi)
            };
            if hi - lo < 1e-15 {
                return Some((psi, self.path_point(psi)));
            }
        }
        None
    }

    /// Angle from the follower direction u(s) to the wheel centre, in (−π/2, π/2).
    fn c_minus_psi(&self, p: PathPoint) -> f64 {
        cross(p.u, p.w).atan2(dot(p.w, p.u))
    }

    /// Wheel centre and its derivative at path parameter `s` (ψ for cams, c for crankpins).
    fn path_point(&self, s: f64) -> PathPoint {
        let (sin, cos) = s.sin_cos();
        let u = [cos, sin];
        let up = [-sin, cos];
        match &self.kind {
            Kind::Crankpin(g) => {
                // Wheel centre on the ray at angle c, distance from the pin centre R + r_p.
                let (b, rr) = (g.throw_mm, g.wheel_radius_mm + g.pin_radius_mm);
                let root = (rr * rr - (b * sin).powi(2)).sqrt();
                let d = b * cos + root;
                let dd = -b * sin - b * b * sin * cos / root;
                let w = scale(u, d);
                let pin = [b, 0.0];
                let to_w = [w[0] - pin[0], w[1] - pin[1]];
                PathPoint {
                    w,
                    dw: add(scale(u, dd), scale(up, d)),
                    normal: scale(to_w, 1.0 / rr),
                    u,
                }
            }
            Kind::Cam { geometry, lift, .. } => {
                let l = lift.eval(s);
                let (h, h1, h2) = (l.h_mm, l.dh_mm, l.d2h_mm);
                let (rb, big_r) = (geometry.base_radius_mm, geometry.wheel_radius_mm);
                match geometry.follower {
                    Follower::Flat => {
                        // Contact p = (Rb + h)u + h'u⊥ with normal u; w = p + R·u.
                        let a = rb + h + big_r;
                        PathPoint {
                            w: add(scale(u, a), scale(up, h1)),
                            dw: scale(up, a + h2),
                            normal: u,
                            u,
                        }
                    }
                    Follower::Roller { radius_mm } => {
                        pitch_offset(u, up, rb + radius_mm + h, h1, h2, big_r - radius_mm)
                    }
                    Follower::Knife => pitch_offset(u, up, rb + h, h1, h2, big_r),
                }
            }
        }
    }
}

/// " (the worst of N stretches)" when there is more than one.
fn stretch_note(stretches: &usize) -> String {
    if *stretches > 1 {
        format!(" (the worst of {stretches} such stretches)")
    } else {
        String::new()
    }
}

/// Signed curvature of the polar curve q = ρ(ψ)·u(ψ) (positive where convex).
fn pitch_curvature(rho: f64, rho1: f64, rho2: f64) -> f64 {
    (rho * rho + 2.0 * rho1 * rho1 - rho * rho2) / (rho * rho + rho1 * rho1).powf(1.5)
}

/// Wheel centre on the offset of the polar curve q = ρ(ψ)·u(ψ) by `offset` along its outward
/// normal n = (ρ·u − ρ'·u⊥)/|q'|. Since dn/dψ = κ·q', the centre moves with w' = (1 + offset·κ)·q'.
fn pitch_offset(
    u: [f64; 2],
    up: [f64; 2],
    rho: f64,
    rho1: f64,
    rho2: f64,
    offset: f64,
) -> PathPoint {
    let dq = add(scale(u, rho1), scale(up, rho));
    let speed = rho.hypot(rho1);
    let normal = scale(add(scale(u, rho), scale(up, -rho1)), 1.0 / speed);
    let kappa = pitch_curvature(rho, rho1, rho2);
    PathPoint {
        w: add(scale(u, rho), scale(normal, offset)),
        dw: scale(dq, 1.0 + offset * kappa),
        normal,
        u,
    }
}

fn positive(name: &'static str, value: f64) -> Result<(), GeometryError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(GeometryError::InvalidParameter {
            name,
            value,
            reason: "must be a finite number > 0",
        })
    }
}

fn add(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] + b[0], a[1] + b[1]]
}

fn scale(a: [f64; 2], k: f64) -> [f64; 2] {
    [a[0] * k, a[1] * k]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::LiftTable;

    /// A shaped pin with no correction is the round pin: its table must match the crankpin
    /// closed form d(c) = b·cos c + √((R + r_p)² − (b·sin c)²). The lift b·(1 + cos ψ) is
    /// sampled at 0.5° and splined (error ≤ 5/384·h⁴·b ≈ 5e-8 µm), so 1e-6 mm is generous.
    /// b > r_p: the pin does not surround the axis, the base radius r_p − b is negative.
    #[test]
    fn uncorrected_shaped_pin_is_the_round_pin() {
        let pin = CrankpinGeometry {
            throw_mm: 45.0,
            pin_radius_mm: 30.0,
            wheel_radius_mm: 300.0,
        };
        let angles: Vec<f64> = (0..720).map(|k| k as f64 * 0.5).collect();
        let lifts = angles
            .iter()
            .map(|a| 45.0 * (1.0 + a.to_radians().cos()))
            .collect();
        let table = LiftTable::from_points(angles, lifts, "pin").unwrap();
        let shaped = Part::shaped_pin(pin, LiftCurve::new(&table)).unwrap();
        let round = Part::crankpin(pin).unwrap();
        assert_eq!(shaped.x_zero_mm(), round.x_zero_mm());
        for (a, b) in shaped
            .wheel_table(360)
            .unwrap()
            .iter()
            .zip(round.wheel_table(360).unwrap())
        {
            let c = a.c_deg.to_radians();
            let exact = 45.0 * c.cos() + (330.0f64.powi(2) - (45.0 * c.sin()).powi(2)).sqrt();
            assert!(
                (a.d_mm - exact).abs() < 1e-6,
                "{}: {} vs {exact}",
                a.c_deg,
                a.d_mm
            );
            assert!((a.x_mm - b.x_mm).abs() < 1e-6);
        }
    }
}
