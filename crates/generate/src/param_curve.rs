//! Curves typed as expressions: `x(t)` and `z(t)` over a range of t, or `x(z)` over a range
//! of z, evaluated by `exmex` (arithmetic and the usual functions, angles in radians; no
//! code runs but the expression).
//!
//! The study's tangent curve, Z = 3·tan θ − 20 and X = −10·θ + 87.781, is
//! `z = "3*tan(t) - 20"`, `x = "-10*t + 87.781"`.

use exmex::prelude::*;
use thiserror::Error;

use crate::curve::Jet;

/// Why an expression is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ExprError {
    #[error("{key} = `{text}`: {reason}")]
    Parse {
        key: &'static str,
        text: String,
        reason: String,
    },
    #[error("{key} = `{text}` uses `{name}`: only `{allowed}` is known here")]
    Variable {
        key: &'static str,
        text: String,
        name: String,
        allowed: &'static str,
    },
    #[error("{key} = `{text}` is {value} at {var} = {at}: it must be a finite number")]
    NotFinite {
        key: &'static str,
        text: String,
        var: &'static str,
        at: f64,
        value: f64,
    },
}

/// One expression in one variable.
#[derive(Debug, Clone)]
struct Fn1 {
    key: &'static str,
    text: String,
    ex: FlatEx<f64>,
    /// False for a constant (no variable at all): evaluated with no argument.
    has_var: bool,
}

impl Fn1 {
    fn parse(key: &'static str, text: &str, var: &'static str) -> Result<Self, ExprError> {
        let ex = exmex::parse::<f64>(text).map_err(|e| ExprError::Parse {
            key,
            text: text.to_owned(),
            reason: e.to_string(),
        })?;
        if let Some(name) = ex.var_names().iter().find(|n| n.as_str() != var) {
            return Err(ExprError::Variable {
                key,
                text: text.to_owned(),
                name: name.clone(),
                allowed: var,
            });
        }
        let has_var = !ex.var_names().is_empty();
        Ok(Fn1 {
            key,
            text: text.to_owned(),
            ex,
            has_var,
        })
    }

    fn at(&self, v: f64) -> f64 {
        let args: &[f64] = if self.has_var { &[v] } else { &[] };
        self.ex.eval(args).unwrap_or(f64::NAN)
    }
}

/// A curve given by expressions, on a parameter u from 0 to its span.
#[derive(Debug, Clone)]
pub struct ParamCurve {
    x: Fn1,
    /// `None`: x is a function of z, and z runs from `from` to `to`.
    z: Option<Fn1>,
    from: f64,
    to: f64,
}

impl ParamCurve {
    /// `x(t)`, `z(t)` for t from `t_start` to `t_end`.
    pub fn parametric(x: &str, z: &str, t_start: f64, t_end: f64) -> Result<Self, ExprError> {
        let c = ParamCurve {
            x: Fn1::parse("x", x, "t")?,
            z: Some(Fn1::parse("z", z, "t")?),
            from: t_start,
            to: t_end,
        };
        c.check("t")?;
        Ok(c)
    }

    /// `x(z)` for z from `z_start` to `z_end`.
    pub fn graph(x: &str, z_start: f64, z_end: f64) -> Result<Self, ExprError> {
        let c = ParamCurve {
            x: Fn1::parse("x", x, "z")?,
            z: None,
            from: z_start,
            to: z_end,
        };
        c.check("z")?;
        Ok(c)
    }

    /// Finite along the whole range (sampled densely), so a pole or a root of a negative
    /// number is refused with where it is.
    fn check(&self, var: &'static str) -> Result<(), ExprError> {
        for i in 0..=2000 {
            let at = self.from + (self.to - self.from) * f64::from(i) / 2000.0;
            for f in std::iter::once(&self.x).chain(self.z.as_ref()) {
                let value = f.at(at);
                if !value.is_finite() {
                    return Err(ExprError::NotFinite {
                        key: f.key,
                        text: f.text.clone(),
                        var,
                        at,
                        value,
                    });
                }
            }
        }
        Ok(())
    }

    pub fn span(&self) -> f64 {
        (self.to - self.from).abs()
    }

    /// The point at u (t or z = from ± u).
    fn point(&self, u: f64) -> (f64, f64) {
        let d = if self.to >= self.from { 1.0 } else { -1.0 };
        let v = self.from + d * u;
        match &self.z {
            Some(z) => (z.at(v), self.x.at(v)),
            None => (v, self.x.at(v)),
        }
    }

    /// Point and derivatives in u by central differences (step 1e-4 of the span: the
    /// truncation error is then about 1e-8 of the second derivative, far below what the
    /// chord check, which measures the exact points, can see).
    pub fn jet(&self, u: f64) -> Jet {
        let h = 1e-4 * self.span().max(1e-3);
        let (z, x) = self.point(u);
        let (zm, xm) = self.point(u - h);
        let (zp, xp) = self.point(u + h);
        Jet {
            z,
            x,
            dz: (zp - zm) / (2.0 * h),
            dx: (xp - xm) / (2.0 * h),
            ddz: (zp - 2.0 * z + zm) / (h * h),
            ddx: (xp - 2.0 * x + xm) / (h * h),
        }
    }
}
