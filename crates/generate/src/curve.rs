//! The exact turning contours: ellipse, parabola, sine, tangent and an explicit CSV profile,
//! in lathe coordinates (z along the axis, x the radius), each on a parameter u running
//! from 0 to its span.
//!
//! Each analytic curve also gives its point as an [`Expr`] in the loop variable, so the
//! control can evaluate the same curve the generator proves.

pub use super::analytic::{Ellipse, Parabola, Sine, Tangent};
use super::ir::{Expr, Var};
use super::open_spline::OpenSpline;
use super::param_curve::ParamCurve;

/// A contour. Angles in degrees, lengths in mm.
#[derive(Debug, Clone)]
pub enum Curve {
    Ellipse(Ellipse),
    Parabola(Parabola),
    Sine(Sine),
    Tangent(Tangent),
    /// `x(z)` through the points of a profile (natural cubic spline), run from the first
    /// point to the last.
    Profile {
        spline: OpenSpline,
        reversed: bool,
    },
    /// `x(t)`, `z(t)` or `x(z)` typed as expressions (expanded form only: the control
    /// does not evaluate them).
    Param(Box<ParamCurve>),
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
            Curve::Ellipse(e) => (e.end_deg - e.start_deg).abs(),
            Curve::Parabola(p) => (p.x_end_mm - p.x_start_mm).abs(),
            Curve::Sine(Sine {
                z_start_mm,
                z_end_mm,
                ..
            })
            | Curve::Tangent(Tangent {
                z_start_mm,
                z_end_mm,
                ..
            }) => (z_end_mm - z_start_mm).abs(),
            Curve::Profile { spline, .. } => spline.last() - spline.first(),
            Curve::Param(p) => p.span(),
        }
    }

    /// Exact point and derivatives at u.
    pub fn jet(&self, u: f64) -> Jet {
        match self {
            Curve::Ellipse(e) => ellipse_jet(e, u),
            Curve::Parabola(p) => parabola_jet(p, u),
            Curve::Sine(k) => sine_jet(k, u),
            Curve::Tangent(k) => tangent_jet(k, u),
            Curve::Profile { spline, reversed } => {
                let (z, d) = if *reversed {
                    (spline.last() - u, -1.0)
                } else {
                    (spline.first() + u, 1.0)
                };
                graph(z, d, spline.eval(z))
            }
            Curve::Param(p) => p.jet(u),
        }
    }

    /// The point `(z, x)` and the weight as expressions in the loop variable `u` and the
    /// temporaries `t1`, `t2` (set by `pre` from u first), for the loop form; `None` for a
    /// profile, which the control cannot evaluate. The temporaries keep every block short
    /// (LinuxCNC refuses lines over 256 characters, the 802D over 200).
    pub(crate) fn exprs(&self, u: Var, t1: Var, t2: Var) -> Option<CurveExprs> {
        Some(match self {
            Curve::Ellipse(e) => ellipse_exprs(e, [u, t1, t2]),
            Curve::Parabola(p) => parabola_exprs(p, [u, t1]),
            Curve::Sine(k) => sine_exprs(k, [u, t1, t2]),
            Curve::Tangent(k) => tangent_exprs(k, [u, t1, t2]),
            Curve::Profile { .. } | Curve::Param(_) => return None,
        })
    }
}

/// `start + d·u` with d = ±1, written as a sum or a difference.
fn along(start: f64, d: f64, u: Var) -> Expr {
    if d > 0.0 {
        Expr::num(start).add(Expr::var(u))
    } else {
        Expr::num(start).sub(Expr::var(u))
    }
}

/// The ellipse's jet at u.
fn ellipse_jet(e: &Ellipse, u: f64) -> Jet {
    let d = Curve::direction(e.start_deg, e.end_deg);
    let t = (e.start_deg + d * u) * RAD;
    let (s, c) = t.sin_cos();
    Jet {
        z: e.centre_z_mm + e.a_mm * c,
        x: e.centre_x_mm + e.b_mm * s,
        dz: -e.a_mm * s * d * RAD,
        dx: e.b_mm * c * d * RAD,
        ddz: -e.a_mm * c * RAD * RAD,
        ddx: -e.b_mm * s * RAD * RAD,
    }
}

/// The parabola's jet at u, x running from its start to its end.
fn parabola_jet(p: &Parabola, u: f64) -> Jet {
    let d = Curve::direction(p.x_start_mm, p.x_end_mm);
    let x = p.x_start_mm + d * u;
    let w = x - p.vertex_x_mm;
    // Along is x, across is z here: z = z0 + w²/(2p).
    let z = p.vertex_z_mm + w * w / (2.0 * p.p_mm);
    Jet {
        z,
        x,
        dz: w / p.p_mm * d,
        dx: d,
        ddz: 1.0 / p.p_mm,
        ddx: 0.0,
    }
}

/// The sine's jet at u, z running from its start to its end.
fn sine_jet(k: &Sine, u: f64) -> Jet {
    let d = Curve::direction(k.z_start_mm, k.z_end_mm);
    let z = k.z_start_mm + d * u;
    let w = 360.0 / k.wavelength_mm * RAD;
    let arg = (360.0 * z / k.wavelength_mm + k.phase_deg) * RAD;
    let y = [
        k.mean_x_mm + k.amplitude_mm * arg.sin(),
        k.amplitude_mm * w * arg.cos(),
        -k.amplitude_mm * w * w * arg.sin(),
    ];
    graph(z, d, y)
}

/// The tangent curve's jet at u, z running from its start to its end.
fn tangent_jet(k: &Tangent, u: f64) -> Jet {
    let d = Curve::direction(k.z_start_mm, k.z_end_mm);
    let z = k.z_start_mm + d * u;
    let w = k.rate_deg_per_mm * RAD;
    let t = ((z - k.centre_z_mm) * k.rate_deg_per_mm * RAD).tan();
    let sec2 = 1.0 + t * t;
    let y = [
        k.mean_x_mm + k.amplitude_mm * t,
        k.amplitude_mm * w * sec2,
        2.0 * k.amplitude_mm * w * w * sec2 * t,
    ];
    graph(z, d, y)
}

/// The ellipse for the control, in the loop variable and the temporaries `[u, t1, t2]`.
fn ellipse_exprs(e: &Ellipse, [u, t1, t2]: [Var; 3]) -> CurveExprs {
    let (n, v) = (Expr::num, Expr::var);
    let d = Curve::direction(e.start_deg, e.end_deg);
    let (ra, rb) = (e.a_mm * e.a_mm * RAD * RAD, e.b_mm * e.b_mm * RAD * RAD);
    CurveExprs {
        pre: vec![
            (t1, along(e.start_deg, d, u).sin()),
            (t2, along(e.start_deg, d, u).cos()),
        ],
        z: n(e.centre_z_mm).add(n(e.a_mm).mul(v(t2))),
        x: n(e.centre_x_mm).add(n(e.b_mm).mul(v(t1))),
        // ab·RAD³ / (RAD·sqrt(a² sin² + b² cos²)), as in Jet::weight.
        weight: n(e.a_mm * e.b_mm * RAD * RAD * RAD).div(
            n(ra)
                .mul(v(t1).mul(v(t1)))
                .add(n(rb).mul(v(t2).mul(v(t2))))
                .sqrt(),
        ),
    }
}

/// The parabola for the control, in the loop variable and the temporary `[u, t1]`.
fn parabola_exprs(p: &Parabola, [u, t1]: [Var; 2]) -> CurveExprs {
    let (n, v) = (Expr::num, Expr::var);
    let d = Curve::direction(p.x_start_mm, p.x_end_mm);
    let p_mm = p.p_mm;
    CurveExprs {
        pre: vec![(t1, along(p.x_start_mm - p.vertex_x_mm, d, u))],
        z: n(p.vertex_z_mm).add(v(t1).mul(v(t1)).div(n(2.0 * p_mm))),
        x: n(p.vertex_x_mm).add(v(t1)),
        weight: n(1.0 / p_mm.abs()).div(n(1.0).add(v(t1).mul(v(t1)).div(n(p_mm * p_mm))).sqrt()),
    }
}

/// The sine for the control, in the loop variable and the temporaries `[u, t1, t2]`.
fn sine_exprs(k: &Sine, [u, t1, t2]: [Var; 3]) -> CurveExprs {
    let (n, v) = (Expr::num, Expr::var);
    let d = Curve::direction(k.z_start_mm, k.z_end_mm);
    let arg = || {
        n(360.0 / k.wavelength_mm)
            .mul(along(k.z_start_mm, d, u))
            .add(n(k.phase_deg))
    };
    let w = 360.0 / k.wavelength_mm * RAD;
    let slope = || n(k.amplitude_mm * w).mul(v(t2));
    CurveExprs {
        pre: vec![(t1, arg().sin()), (t2, arg().cos())],
        z: along(k.z_start_mm, d, u),
        x: n(k.mean_x_mm).add(n(k.amplitude_mm).mul(v(t1))),
        weight: n(k.amplitude_mm * w * w)
            .mul(v(t1))
            .abs()
            .div(n(1.0).add(slope().mul(slope())).sqrt()),
    }
}

/// The tangent curve for the control, in the loop variable and the temporaries `[u, t1, t2]`.
fn tangent_exprs(k: &Tangent, [u, t1, t2]: [Var; 3]) -> CurveExprs {
    let (n, v) = (Expr::num, Expr::var);
    let d = Curve::direction(k.z_start_mm, k.z_end_mm);
    let w = k.rate_deg_per_mm * RAD;
    // t1 = tan, t2 = sec² = 1 + tan².
    let slope = || n(k.amplitude_mm * w).mul(v(t2));
    CurveExprs {
        pre: vec![
            (
                t1,
                along(k.z_start_mm - k.centre_z_mm, d, u)
                    .mul(n(k.rate_deg_per_mm))
                    .tan(),
            ),
            (t2, n(1.0).add(v(t1).mul(v(t1)))),
        ],
        z: along(k.z_start_mm, d, u),
        x: n(k.mean_x_mm).add(n(k.amplitude_mm).mul(v(t1))),
        weight: n(2.0 * k.amplitude_mm * w * w)
            .mul(v(t2))
            .mul(v(t1))
            .abs()
            .div(n(1.0).add(slope().mul(slope())).sqrt()),
    }
}

/// A curve written for the control.
#[derive(Debug, Clone)]
pub(crate) struct CurveExprs {
    /// Temporaries assigned from u, in order, before z, x and the weight are evaluated.
    pub pre: Vec<(Var, Expr)>,
    pub z: Expr,
    pub x: Expr,
    /// κ·|p′|², as [`Jet::weight`].
    pub weight: Expr,
}

impl CurveExprs {
    /// The variables at u, as the loop has them when it evaluates z, x and the weight.
    pub(crate) fn vars_at(&self, u_var: Var, u: f64) -> super::ir::Vars {
        let mut vars = super::ir::Vars::default();
        vars.set(u_var, u);
        for (t, e) in &self.pre {
            let value = e.eval(&vars);
            vars.set(*t, value);
        }
        vars
    }
}
