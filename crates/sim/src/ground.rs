//! A ground part and what a follower reads on it: flat-face support function, roller pitch
//! curve, knife-edge polar radius, each interpolated from the exact outline nodes.
//!
//! Every node carries a boundary point p and its outward normal N, which is all a follower
//! reading needs, with its derivative:
//! - flat face at normal angle ψ: h(ψ) = p·N and dh/dψ = p·N⊥ (N⊥ = N turned by +90°);
//! - roller of radius r (knife edge: r = 0): pitch point q = p + r·N at polar angle
//!   α = arg q, radius ρ = |q|, and dρ/dα = ρ·(q·N⊥)/(q × N⊥), since the pitch curve's
//!   tangent is ±N⊥.
//!
//! A reading on a grid is the cubic Hermite interpolant between consecutive nodes in that
//! variable, and where several node intervals cover the same angle the largest value wins:
//! the flat face rests on the outermost point (bridging any concave stretch, as a real flat
//! probe does) and the roller's centre on the outermost pitch point of its ray. On corners
//! and wheel arcs the nodes are at most 0.25° apart and the reading there is a sinusoid
//! (P·u(ψ)); on envelope pieces they are 1/16 of a table segment apart. The Hermite error
//! Δ⁴/384·max|y⁗| is then below 1e-9 mm with 1° tables (about 1e-7 mm for the polar radius
//! with 10° tables). The tests bound it independently against a brute-force disc sweep
//! (≤ 1.5e-7 mm observed, 1e-6 mm required).

use super::envelope::Node;
use camloop_core::geometry::{CamGeometry, CrankpinGeometry, Follower};
use std::f64::consts::TAU;

/// The part being ground and how the gauge reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Workpiece {
    /// A cam lobe, measured with its own follower type (flat, roller or knife edge) from
    /// the base circle. The wheel radius is the one the control starts out believing.
    Cam(CamGeometry),
    /// A crankpin, measured as a flat follower from the main axis: lift = support −
    /// (r_p − b), so that the nominal lift is b·(1 + cos ψ).
    Crankpin(CrankpinGeometry),
}

impl Workpiece {
    pub fn wheel_radius_mm(&self) -> f64 {
        match self {
            Workpiece::Cam(g) => g.wheel_radius_mm,
            Workpiece::Crankpin(g) => g.wheel_radius_mm,
        }
    }

    /// The gauge's probe and the reading that counts as zero lift.
    pub(crate) fn probe(&self) -> (Probe, f64) {
        match *self {
            Workpiece::Cam(g) => match g.follower {
                Follower::Flat => (Probe::Flat, g.base_radius_mm),
                Follower::Roller { radius_mm } => {
                    (Probe::Pitch { radius_mm }, g.base_radius_mm + radius_mm)
                }
                Follower::Knife => (Probe::Pitch { radius_mm: 0.0 }, g.base_radius_mm),
            },
            Workpiece::Crankpin(g) => (Probe::Flat, g.pin_radius_mm - g.throw_mm),
        }
    }
}

/// How a reading is taken from the outline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Probe {
    /// Support function (flat face), as a function of the normal angle.
    Flat,
    /// Outer parallel curve at `radius_mm` (roller; 0 for the outline itself), as a function
    /// of polar angle.
    Pitch { radius_mm: f64 },
}

/// A part as the simulated machine ground it.
#[derive(Debug, Clone)]
pub struct GroundPart {
    pub(crate) nodes: Vec<Node>,
    pub(crate) probe: Probe,
    pub(crate) zero_mm: f64,
    /// 1-based number of this part in the machine's life.
    pub part_number: u32,
    /// True wheel radius that ground it, mm.
    pub wheel_radius_mm: f64,
    /// Wheel radius the control believed, mm.
    pub believed_wheel_radius_mm: f64,
    /// X zero the control applied (table X + this = commanded wheel-centre distance), mm.
    pub x_zero_mm: f64,
}

/// Node values of one reading in its own variable, unwrapped, closed (last = first + 2π).
struct Curve {
    x: Vec<f64>,
    y: Vec<f64>,
    dy: Vec<f64>,
}

impl GroundPart {
    /// True lift (no noise) at `n` gauge angles ψ_j = j·360°/n, mm, read as the gauge does.
    /// O(nodes + n).
    pub fn lift_on_grid(&self, n: usize) -> Vec<f64> {
        let zero = self.zero_mm;
        self.read_on_grid(self.probe, n)
            .into_iter()
            .map(|v| v - zero)
            .collect()
    }

    /// True lift at one gauge angle, mm. O(nodes): use [`GroundPart::lift_on_grid`] for
    /// many angles.
    pub fn lift_mm(&self, psi_deg: f64) -> f64 {
        read_at(&curve(&self.nodes, self.probe), psi_deg.to_radians()) - self.zero_mm
    }

    /// Support function of the part (a flat face's distance from the axis) at `n` normal
    /// angles j·360°/n, mm.
    pub fn support_on_grid(&self, n: usize) -> Vec<f64> {
        self.read_on_grid(Probe::Flat, n)
    }

    /// Polar radius of the outline at one angle, mm. Meaningful for outlines that enclose
    /// the axis (cams); a crankpin whose throw exceeds its radius does not, and a ray that
    /// misses it reads −∞.
    pub fn radius_mm(&self, theta_deg: f64) -> f64 {
        read_at(
            &curve(&self.nodes, Probe::Pitch { radius_mm: 0.0 }),
            theta_deg.to_radians(),
        )
    }

    fn read_on_grid(&self, probe: Probe, n: usize) -> Vec<f64> {
        let c = curve(&self.nodes, probe);
        let step = TAU / n.max(1) as f64;
        let mut out = vec![f64::NEG_INFINITY; n];
        for i in 0..c.x.len() - 1 {
            let (lo, hi) = (c.x[i].min(c.x[i + 1]), c.x[i].max(c.x[i + 1]));
            // Only exactly empty intervals are skipped: a grid angle may fall into a gap of
            // a few ulps between two nodes, and the neighbours do not cover it.
            if hi == lo {
                continue;
            }
            let first = (lo / step).ceil() as i64;
            let last = (hi / step).floor() as i64;
            for j in first..=last {
                let v = hermite(&c, i, j as f64 * step);
                let slot = &mut out[j.rem_euclid(n as i64) as usize];
                *slot = slot.max(v);
            }
        }
        out
    }

    /// Total turn of the reading's variable once round the outline, radians: 2π when the
    /// outline encloses the axis once and is read by `probe` without folding back overall.
    pub(crate) fn turn_rad(&self, probe: Probe) -> f64 {
        let c = curve(&self.nodes, probe);
        c.x[c.x.len() - 1] - c.x[0]
    }
}

fn curve(nodes: &[Node], probe: Probe) -> Curve {
    let count = nodes.len() + 1;
    let mut c = Curve {
        x: Vec::with_capacity(count),
        y: Vec::with_capacity(count),
        dy: Vec::with_capacity(count),
    };
    for node in nodes.iter().chain(nodes.first()) {
        let t = [-node.n[1], node.n[0]];
        let (raw, y, dy) = match probe {
            Probe::Flat => (
                node.n[1].atan2(node.n[0]),
                dot(node.p, node.n),
                dot(node.p, t),
            ),
            Probe::Pitch { radius_mm } => {
                let q = [
                    node.p[0] + radius_mm * node.n[0],
                    node.p[1] + radius_mm * node.n[1],
                ];
                let rho = q[0].hypot(q[1]);
                let across = q[0] * t[1] - q[1] * t[0];
                // A tangent through the axis has no finite slope; such a node only ever
                // bounds a zero-length interval (a knife edge on a corner), which is skipped.
                let slope = if across.abs() > 1e-12 * rho {
                    rho * dot(q, t) / across
                } else {
                    0.0
                };
                (q[1].atan2(q[0]), rho, slope)
            }
        };
        let x = match c.x.last() {
            Some(&previous) => previous + super::table::wrap_pi(raw - previous),
            None => raw,
        };
        c.x.push(x);
        c.y.push(y);
        c.dy.push(dy);
    }
    c
}

/// Cubic Hermite interpolant on interval `i` of the curve at `x` (inside the interval).
fn hermite(c: &Curve, i: usize, x: f64) -> f64 {
    let h = c.x[i + 1] - c.x[i];
    let t = (x - c.x[i]) / h;
    let (t2, t3) = (t * t, t * t * t);
    let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
    let h10 = t3 - 2.0 * t2 + t;
    let h01 = -2.0 * t3 + 3.0 * t2;
    let h11 = t3 - t2;
    h00 * c.y[i] + h10 * h * c.dy[i] + h01 * c.y[i + 1] + h11 * h * c.dy[i + 1]
}

/// The reading at one angle: the largest interpolant over the intervals that cover it.
fn read_at(c: &Curve, angle_rad: f64) -> f64 {
    let mut best = f64::NEG_INFINITY;
    for i in 0..c.x.len() - 1 {
        let (lo, hi) = (c.x[i].min(c.x[i + 1]), c.x[i].max(c.x[i + 1]));
        if hi == lo {
            continue;
        }
        let mid = 0.5 * (lo + hi);
        let x = angle_rad + TAU * ((mid - angle_rad) / TAU).round();
        if (lo..=hi).contains(&x) {
            best = best.max(hermite(c, i, x));
        }
    }
    best
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}
