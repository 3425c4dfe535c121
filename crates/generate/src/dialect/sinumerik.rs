//! SINUMERIK 840D sl text: `DEF REAL` variables, `LABEL:` with `IF … GOTOB` loops, axis
//! words as `X=<expr>`.

use std::fmt::Write as _;

use super::{Decimals, exact, fixed, is_binary};
use crate::ir::{Axis, Compensation, Cond, Expr, Motion, Plane, Program, Stmt};

pub(super) fn render(p: &Program, d: Decimals) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "%_N_{}_MPF", p.name);
    out.push_str(";$PATH=/_N_MPF_DIR\n");
    for c in &p.comments {
        let _ = writeln!(out, "; {c}");
    }
    if !p.vars.is_empty() {
        // DEF lines come first in a program, before any statement.
        let names: Vec<&str> = p.vars.iter().map(|v| v.name).collect();
        let _ = writeln!(out, "DEF REAL {}", names.join(","));
    }
    let plane = match p.plane {
        Plane::Xy => "G17 G90 G71 ; X-Y plane, absolute, metric",
        Plane::Zx => "G18 G90 G71 DIAMOF ; Z-X plane, absolute, metric, X as a radius",
    };
    out.push_str(plane);
    out.push('\n');
    let mut pending = None;
    stmts(&mut out, &p.body, d, &mut pending);
    out.push_str("M30\n");
    out
}

fn stmts(out: &mut String, body: &[Stmt], d: Decimals, pending: &mut Option<Compensation>) {
    for s in body {
        match s {
            Stmt::Comment(c) => {
                let _ = writeln!(out, "; {c}");
            }
            Stmt::Assign(v, e) => {
                let _ = writeln!(out, "{}={}", v.name, expr(e));
            }
            Stmt::Comp(c) => *pending = Some(*c),
            Stmt::Move {
                motion,
                words,
                feed_mm_min,
            } => {
                let mut line = String::new();
                if let Some(c) = pending.take() {
                    line.push_str(match c {
                        Compensation::Off => "G40 ",
                        Compensation::Left => "G41 ",
                        Compensation::Right => "G42 ",
                    });
                }
                line.push_str(match motion {
                    Motion::Rapid => "G0",
                    Motion::Linear => "G1",
                    Motion::ArcCw => "G2",
                    Motion::ArcCcw => "G3",
                });
                for (axis, e) in words {
                    let _ = write!(line, " {}={}", axis.letter(), word(*axis, e, d));
                }
                if let Some(f) = feed_mm_min {
                    let _ = write!(line, " F{}", fixed(*f, 1));
                }
                let _ = writeln!(out, "{line}");
            }
            Stmt::DoWhile { label, body, cond } => {
                let _ = writeln!(out, "LOOP_{label}:");
                stmts(out, body, d, pending);
                let _ = writeln!(out, "IF {} GOTOB LOOP_{label}", cond_text(cond, false));
            }
            Stmt::If { label, cond, body } => {
                let _ = writeln!(out, "IF {} GOTOF SKIP_{label}", cond_text(cond, true));
                stmts(out, body, d, pending);
                let _ = writeln!(out, "SKIP_{label}:");
            }
            Stmt::Mark { var, value, text } => {
                // The block preparation runs ahead of motion: without STOPRE the mark
                // would be written before the stroke it records has ended.
                out.push_str("STOPRE ; the mark waits for the motion before it to end\n");
                let _ = writeln!(out, "{}={} ; {text}", var.name, exact(*value));
            }
        }
    }
}

/// A move word: a fixed-decimal number, or an expression the control evaluates.
fn word(axis: Axis, e: &Expr, d: Decimals) -> String {
    match e {
        Expr::Num(v) if axis.is_rotary() => fixed(*v, d.angle),
        Expr::Num(v) => fixed(*v, d.linear),
        other => expr(other),
    }
}

/// `cond`, or its negation when `negate` (to jump over a block).
fn cond_text(c: &Cond, negate: bool) -> String {
    let op = match (c.less, negate) {
        (true, false) => "<",
        (true, true) => ">=",
        (false, false) => ">",
        (false, true) => "<=",
    };
    format!("{}{op}{}", expr(&c.left), expr(&c.right))
}

/// An expression in SINUMERIK syntax; binary operations inside others are bracketed.
pub(crate) fn expr(e: &Expr) -> String {
    let sub = |e: &Expr| {
        if is_binary(e) || matches!(e, Expr::Num(v) if *v < 0.0) {
            format!("({})", expr(e))
        } else {
            expr(e)
        }
    };
    match e {
        Expr::Num(v) => exact(*v),
        Expr::Var(v) => v.name.to_owned(),
        Expr::Add(a, b) => format!("{}+{}", sub(a), sub(b)),
        Expr::Sub(a, b) => format!("{}-{}", sub(a), sub(b)),
        Expr::Mul(a, b) => format!("{}*{}", sub(a), sub(b)),
        Expr::Div(a, b) => format!("{}/{}", sub(a), sub(b)),
        Expr::Neg(a) => format!("-{}", sub(a)),
        Expr::Sin(a) => format!("SIN({})", expr(a)),
        Expr::Cos(a) => format!("COS({})", expr(a)),
        Expr::Tan(a) => format!("TAN({})", expr(a)),
        Expr::Sqrt(a) => format!("SQRT({})", expr(a)),
        Expr::Abs(a) => format!("ABS({})", expr(a)),
    }
}
