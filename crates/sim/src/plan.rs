//! C following a virtual leading axis by the speed plan's table C = f(VA), and the servo lag
//! such a grind leaves.
//!
//! The virtual axis VA turns at constant speed ω_VA; C runs along f, X along g = X(f(VA)).
//! The X servo lags its setpoint by the same time τ as at constant speed, so X runs
//! g(VA − ω_VA·τ): a constant lag in VA, which in C is f(v) − f(v − ω_VA·τ) ≈ ω_C(c)·τ,
//! the actual C speed at that angle times τ. At angle c the machine's X is therefore
//! g(f⁻¹(c) − ω_VA·τ), evaluated exactly here with its first two derivatives in c. With
//! f the identity (C turning at constant speed) this is X(c − ω·τ), the constant-speed model.

use super::SimError;
use super::table::{TablePath, XSample};
use camloop_core::table::PolySegment;
use std::f64::consts::TAU;

/// Largest C step (degrees) tolerated where two pieces of C = f(VA) meet, and largest VA gap.
const JOIN_DEG: f64 = 1e-6;
/// Steps of the inverse's bisection: 60 halvings of a piece take u below 1e-18.
const INVERSE_STEPS: usize = 60;

/// A planned C speed as the control runs it: the table C = f(VA) and VA's constant speed.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedSpeed {
    /// C = f(VA): POLY segments over VA in degrees (`c_*_deg`), C in degrees in the `_mm`
    /// fields; C rises 360° over one turn of VA.
    pub c_law: Vec<PolySegment>,
    /// The virtual axis' constant speed, rev/min.
    pub va_speed_rpm: f64,
}

/// One cubic piece of C(VA), radians: c = c0 + a1·u + a2·u² + a3·u³, u = (va − va0)/len.
#[derive(Debug, Clone, Copy)]
struct Piece {
    va0: f64,
    len: f64,
    c: [f64; 4],
}

impl Piece {
    /// C and its first two derivatives in VA.
    fn eval(&self, u: f64) -> [f64; 3] {
        let [c0, a1, a2, a3] = self.c;
        let k = 1.0 / self.len;
        [
            c0 + u * (a1 + u * (a2 + u * a3)),
            (a1 + u * (2.0 * a2 + 3.0 * a3 * u)) * k,
            (2.0 * a2 + 6.0 * a3 * u) * k * k,
        ]
    }
}

/// C = f(VA) checked (contiguous, rising) and ready to evaluate and invert, periodic with
/// f(v + 2π) = f(v) + 2π.
#[derive(Debug, Clone)]
pub(crate) struct CLaw {
    pieces: Vec<Piece>,
}

impl CLaw {
    pub fn new(plan: &PlannedSpeed) -> Result<Self, SimError> {
        let law = &plan.c_law;
        let invalid = |reason: String| SimError::CLaw { reason };
        if law.len() < 3 {
            return Err(SimError::TooFewTableEntries { count: law.len() });
        }
        if !(plan.va_speed_rpm.is_finite() && plan.va_speed_rpm > 0.0) {
            return Err(invalid(format!(
                "the virtual axis' speed {} rpm must be a finite number > 0",
                plan.va_speed_rpm
            )));
        }
        let (first, last) = (&law[0], &law[law.len() - 1]);
        if ((last.c_end_deg - first.c_start_deg) - 360.0).abs() > JOIN_DEG {
            return Err(invalid(
                "C's table must span one turn of the virtual axis".into(),
            ));
        }
        for (i, s) in law.iter().enumerate() {
            let next = law.get(i + 1);
            let (next_va, next_c) = next.map_or((f64::NAN, f64::NAN), |n| (n.c_start_deg, n.x0_mm));
            let joins = next.is_none()
                || ((s.c_end_deg - next_va).abs() <= JOIN_DEG
                    && (s.x_end_mm() - next_c).abs() <= JOIN_DEG);
            let rising = (0..=4).all(|k| {
                let u = f64::from(k) / 4.0;
                s.a1_mm + u * (2.0 * s.a2_mm + 3.0 * s.a3_mm * u) > 0.0
            });
            if !(s.is_finite() && s.c_end_deg > s.c_start_deg && joins && rising) {
                return Err(invalid(format!(
                    "piece {i} at VA = {}° is not finite, empty, apart from the next or not rising",
                    s.c_start_deg
                )));
            }
        }
        if ((last.x_end_mm() - first.x0_mm) - 360.0).abs() > JOIN_DEG {
            return Err(invalid(
                "C must rise by 360° over one turn of the virtual axis".into(),
            ));
        }
        let pieces = law
            .iter()
            .map(|s| Piece {
                va0: s.c_start_deg.to_radians(),
                len: (s.c_end_deg - s.c_start_deg).to_radians(),
                c: [s.x0_mm, s.a1_mm, s.a2_mm, s.a3_mm].map(f64::to_radians),
            })
            .collect();
        Ok(Self { pieces })
    }

    /// C and dC/dVA, d²C/dVA² at `va` (radians, any turn).
    pub fn forward(&self, va: f64) -> [f64; 3] {
        let start = self.pieces[0].va0;
        let turns = ((va - start) / TAU).floor();
        let v = va - turns * TAU;
        let i = self
            .pieces
            .partition_point(|p| p.va0 <= v)
            .saturating_sub(1);
        let p = &self.pieces[i];
        let [c, c1, c2] = p.eval(((v - p.va0) / p.len).clamp(0.0, 1.0));
        [c + turns * TAU, c1, c2]
    }

    /// VA and dVA/dC, d²VA/dC² at C = `c` (radians, any turn): the piece holding c, then
    /// bisection in it (f rises, so the root is unique).
    pub fn inverse(&self, c: f64) -> [f64; 3] {
        let start = self.pieces[0].c[0];
        let turns = ((c - start) / TAU).floor();
        let cc = c - turns * TAU;
        let i = self
            .pieces
            .partition_point(|p| p.c[0] <= cc)
            .saturating_sub(1);
        let p = &self.pieces[i];
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..INVERSE_STEPS {
            let mid = 0.5 * (lo + hi);
            if p.eval(mid)[0] < cc {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let u = 0.5 * (lo + hi);
        let [_, c1, c2] = p.eval(u);
        [
            p.va0 + u * p.len + turns * TAU,
            1.0 / c1,
            -c2 / (c1 * c1 * c1),
        ]
    }
}

/// X of a table over VA seen at C angles, with the servo lag a constant angle of VA.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PlanLag<'a> {
    pub law: &'a CLaw,
    /// ω_VA·τ, radians of VA.
    pub va_lag_rad: f64,
}

impl PlanLag<'_> {
    /// X of table segment `i` at C = `c` (radians) and its derivatives in c.
    pub fn x_at(&self, table: &TablePath, i: usize, c: f64) -> XSample {
        let [va, dva, d2va] = self.law.inverse(c);
        let xs = table.eval(i, va - self.va_lag_rad);
        XSample {
            x: xs.x,
            x1: xs.x1 * dva,
            x2: xs.x2 * dva * dva + xs.x1 * d2va,
        }
    }

    /// The C range of table segment `i` (a VA range) on the real path, radians.
    pub fn range(&self, table: &TablePath, i: usize) -> (f64, f64) {
        let (a, b) = table.range_rad(i);
        (
            self.law.forward(a + self.va_lag_rad)[0],
            self.law.forward(b + self.va_lag_rad)[0],
        )
    }
}
