//! The exact turning contours: ellipse, parabola, sine, tangent and an explicit CSV profile,
//! in lathe coordinates (z along the axis, x the radius), each on a parameter u running
//! from 0 to its span.
//!
//! Each analytic curve also gives its point as an [`Expr`] in the loop variable, so the
//! control can evaluate the same curve the generator proves.

use super::ir::{Expr, Var};
use super::open_spline::OpenSpline;

/// A contour. Angles in degrees, lengths in mm.
#[derive(Debug, Clone)]
pub enum Curve {
    /// `z = zc + a·cos θ`, `x = xc + b·sin θ`, θ from `start_deg` to `end_deg`.
    Ellipse {
        centre_z_mm: f64,
        centre_x_mm: f64,
        a_mm: f64,
        b_mm: f64,
        start_deg: f64,
        end_deg: f64,
    },
    /// `(x − x0)² = 2p·(z − z0)`, run along x from `x_start_mm` to `x_end_mm`.
    Parabola {
        vertex_z_mm: f64,
        vertex_x_mm: f64,
        p_mm: f64,
        x_start_mm: f64,
        x_end_mm: f64,
    },
    /// `x = x0 + A·sin(360·z/λ + φ)`, run along z.
    Sine {
        mean_x_mm: f64,
        amplitude_mm: f64,
        wavelength_mm: f64,
        phase_deg: f64,
        z_start_mm: f64,
        z_end_mm: f64,
    },
    /// `x = x0 + A·tan(ω·(z − zc))`, ω in degrees per mm, run along z; the argument must
    /// stay inside (−90°, 90°).
    Tangent {
        mean_x_mm: f64,
        amplitude_mm: f64,
        rate_deg_per_mm: f64,
        centre_z_mm: f64,
        z_start_mm: f64,
        z_end_mm: f64,
    },
    /// `x(z)` through the points of a profile (natural cubic spline), run from the first
    /// point to the last.
    Profile { spline: OpenSpline, reversed: bool },
}

/// Point and parameter derivatives (per unit of u).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jet {
    pub z: f64,
    pub x: f64,
    pub dz: f64,
    pub dx: f64,
    pub ddz: f64,
    pub ddx: f64,
}

impl Jet {
    /// Signed curvature, positive when the contour turns left (towards +x when it runs +z).
    pub fn curvature(&self) -> f64 {
        (self.dz * self.ddx - self.dx * self.ddz) / (self.dz.hypot(self.dx)).powi(3)
    }

    /// κ·|p′|², the chord-height rate: a chord over a parameter step Δu rises about
    /// `weight·Δu²/8` from the curve.
    pub fn weight(&self) -> f64 {
        (self.dz * self.ddx - self.dx * self.ddz).abs() / self.dz.hypot(self.dx)
    }
}

const RAD: f64 = std::f64::consts::PI / 180.0;

/// Graph `x(z)` with z = z0 + d·u (d = ±1): the jet in u.
fn graph(z: f64, d: f64, x: [f64; 3]) -> Jet {
    Jet {
        z,
        x: x[0],
        dz: d,
        dx: x[1] * d,
        ddz: 0.0,
        ddx: x[2],
    }
}

impl Curve {
    /// Direction of the parameter along its natural coordinate: +1 or −1.
    fn direction(from: f64, to: f64) -> f64 {
        if to >= from { 1.0 } else { -1.0 }
    }

    /// Parameter span: u runs from 0 to this.
    pub fn span(&self) -> f64 {
        match self {
            Curve::Ellipse {
                start_deg, end_deg, ..
            } => (end_deg - start_deg).abs(),
            Curve::Parabola {
                x_start_mm,
                x_end_mm,
                ..
            } => (x_end_mm - x_start_mm).abs(),
            Curve::Sine {
                z_start_mm,
                z_end_mm,
                ..
            }
            | Curve::Tangent {
                z_start_mm,
                z_end_mm,
                ..
            } => (z_end_mm - z_start_mm).abs(),
            Curve::Profile { spline, .. } => spline.last() - spline.first(),
        }
    }

    /// Exact point and derivatives at u.
    pub fn jet(&self, u: f64) -> Jet {
        match *self {
            Curve::Ellipse {
                centre_z_mm,
                centre_x_mm,
                a_mm,
                b_mm,
                start_deg,
                end_deg,
            } => {
                let d = Self::direction(start_deg, end_deg);
                let t = (start_deg + d * u) * RAD;
                let (s, c) = t.sin_cos();
                Jet {
                    z: centre_z_mm + a_mm * c,
                    x: centre_x_mm + b_mm * s,
                    dz: -a_mm * s * d * RAD,
                    dx: b_mm * c * d * RAD,
                    ddz: -a_mm * c * RAD * RAD,
                    ddx: -b_mm * s * RAD * RAD,
                }
            }
            Curve::Parabola {
                vertex_z_mm,
                vertex_x_mm,
                p_mm,
                x_start_mm,
                x_end_mm,
            } => {
                let d = Self::direction(x_start_mm, x_end_mm);
                let x = x_start_mm + d * u;
                let w = x - vertex_x_mm;
                // Along is x, across is z here: z = z0 + w²/(2p).
                let z = vertex_z_mm + w * w / (2.0 * p_mm);
                Jet {
                    z,
                    x,
                    dz: w / p_mm * d,
                    dx: d,
                    ddz: 1.0 / p_mm,
                    ddx: 0.0,
                }
            }
            Curve::Sine {
                mean_x_mm,
                amplitude_mm,
                wavelength_mm,
                phase_deg,
                z_start_mm,
                z_end_mm,
            } => {
                let d = Self::direction(z_start_mm, z_end_mm);
                let z = z_start_mm + d * u;
                let w = 360.0 / wavelength_mm * RAD;
                let arg = (360.0 * z / wavelength_mm + phase_deg) * RAD;
                let y = [
                    mean_x_mm + amplitude_mm * arg.sin(),
                    amplitude_mm * w * arg.cos(),
                    -amplitude_mm * w * w * arg.sin(),
                ];
                graph(z, d, y)
            }
            Curve::Tangent {
                mean_x_mm,
                amplitude_mm,
                rate_deg_per_mm,
                centre_z_mm,
                z_start_mm,
                z_end_mm,
            } => {
                let d = Self::direction(z_start_mm, z_end_mm);
                let z = z_start_mm + d * u;
                let w = rate_deg_per_mm * RAD;
                let t = ((z - centre_z_mm) * rate_deg_per_mm * RAD).tan();
                let sec2 = 1.0 + t * t;
                let y = [
                    mean_x_mm + amplitude_mm * t,
                    amplitude_mm * w * sec2,
                    2.0 * amplitude_mm * w * w * sec2 * t,
                ];
                graph(z, d, y)
            }
            Curve::Profile {
                ref spline,
                reversed,
            } => {
                let (z, d) = if reversed {
                    (spline.last() - u, -1.0)
                } else {
                    (spline.first() + u, 1.0)
                };
                graph(z, d, spline.eval(z))
            }
        }
    }

    /// The point `(z, x)` and the weight as expressions in the loop variable `u`, for the
    /// loop form; `None` for a profile, which the control cannot evaluate.
    pub fn exprs(&self, u: Var) -> Option<CurveExprs> {
        let u = || Expr::var(u);
        let n = Expr::num;
        Some(match *self {
            Curve::Ellipse {
                centre_z_mm,
                centre_x_mm,
                a_mm,
                b_mm,
                start_deg,
                end_deg,
            } => {
                let d = Self::direction(start_deg, end_deg);
                let t = || n(start_deg).add(n(d).mul(u()));
                let rate = a_mm * a_mm * RAD * RAD;
                let rate_b = b_mm * b_mm * RAD * RAD;
                CurveExprs {
                    z: n(centre_z_mm).add(n(a_mm).mul(t().cos())),
                    x: n(centre_x_mm).add(n(b_mm).mul(t().sin())),
                    // ab·RAD³ / (RAD·sqrt(a² sin² + b² cos²)), as in Jet::weight.
                    weight: n(a_mm * b_mm * RAD * RAD * RAD).div(
                        n(rate)
                            .mul(t().sin().mul(t().sin()))
                            .add(n(rate_b).mul(t().cos().mul(t().cos())))
                            .sqrt(),
                    ),
                }
            }
            Curve::Parabola {
                vertex_z_mm,
                vertex_x_mm,
                p_mm,
                x_start_mm,
                x_end_mm,
            } => {
                let d = Self::direction(x_start_mm, x_end_mm);
                let x = || n(x_start_mm).add(n(d).mul(u()));
                let w = || x().sub(n(vertex_x_mm));
                CurveExprs {
                    z: n(vertex_z_mm).add(w().mul(w()).div(n(2.0 * p_mm))),
                    x: x(),
                    weight: n(1.0 / p_mm.abs())
                        .div(n(1.0).add(w().mul(w()).div(n(p_mm * p_mm))).sqrt()),
                }
            }
            Curve::Sine {
                mean_x_mm,
                amplitude_mm,
                wavelength_mm,
                phase_deg,
                z_start_mm,
                z_end_mm,
            } => {
                let d = Self::direction(z_start_mm, z_end_mm);
                let z = || n(z_start_mm).add(n(d).mul(u()));
                let arg = || n(360.0 / wavelength_mm).mul(z()).add(n(phase_deg));
                let w = 360.0 / wavelength_mm * RAD;
                let slope = || n(amplitude_mm * w).mul(arg().cos());
                CurveExprs {
                    z: z(),
                    x: n(mean_x_mm).add(n(amplitude_mm).mul(arg().sin())),
                    weight: n(amplitude_mm * w * w)
                        .mul(arg().sin())
                        .abs()
                        .div(n(1.0).add(slope().mul(slope())).sqrt()),
                }
            }
            Curve::Tangent {
                mean_x_mm,
                amplitude_mm,
                rate_deg_per_mm,
                centre_z_mm,
                z_start_mm,
                z_end_mm,
            } => {
                let d = Self::direction(z_start_mm, z_end_mm);
                let z = || n(z_start_mm).add(n(d).mul(u()));
                let t = || z().sub(n(centre_z_mm)).mul(n(rate_deg_per_mm)).tan();
                let w = rate_deg_per_mm * RAD;
                let sec2 = || n(1.0).add(t().mul(t()));
                let slope = || n(amplitude_mm * w).mul(sec2());
                CurveExprs {
                    z: z(),
                    x: n(mean_x_mm).add(n(amplitude_mm).mul(t())),
                    weight: n(2.0 * amplitude_mm * w * w)
                        .mul(sec2())
                        .mul(t())
                        .abs()
                        .div(n(1.0).add(slope().mul(slope())).sqrt()),
                }
            }
            Curve::Profile { .. } => return None,
        })
    }
}

/// A curve written for the control.
#[derive(Debug, Clone)]
pub struct CurveExprs {
    pub z: Expr,
    pub x: Expr,
    /// κ·|p′|², as [`Jet::weight`].
    pub weight: Expr,
}
