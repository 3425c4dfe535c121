//! ISO G-code with macro variables, as LinuxCNC's interpreter reads it: `#n` variables,
//! `[…]` expressions, `o<n> do … o<n> while […]` loops and `o<n> if … o<n> endif`.

use std::fmt::Write as _;

use super::{Decimals, exact, fixed, is_binary};
use crate::ir::{Axis, Compensation, Cond, Expr, Motion, Plane, Program, Stmt};

/// ISO variable numbers start here (100 and up are free for programs on both FANUC and
/// LinuxCNC).
const FIRST_VAR: u16 = 100;

pub(super) fn render(p: &Program, d: Decimals) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "%\n({})", p.name);
    for c in &p.comments {
        let _ = writeln!(out, "({})", paren_safe(c));
    }
    let plane = match p.plane {
        Plane::Xy => "G17 G90 G21 G40 (X-Y plane, absolute, mm)",
        Plane::Zx => "G18 G90 G21 G40 (Z-X plane, absolute, mm, X as a radius)",
    };
    out.push_str(plane);
    out.push('\n');
    let mut pending = None;
    stmts(&mut out, &p.body, d, &mut pending);
    out.push_str("M30\n%\n");
    out
}

/// Comments end at `)`: replace brackets inside them.
fn paren_safe(c: &str) -> String {
    c.replace('(', "[").replace(')', "]")
}

fn var(index: u16) -> String {
    format!("#{}", FIRST_VAR + index)
}

fn stmts(out: &mut String, body: &[Stmt], d: Decimals, pending: &mut Option<Compensation>) {
    for s in body {
        match s {
            Stmt::Comment(c) => {
                let _ = writeln!(out, "({})", paren_safe(c));
            }
            Stmt::Assign(v, e) => {
                // A value with operators must be one bracketed expression.
                let value = if is_binary(e) {
                    format!("[{}]", expr(e))
                } else {
                    expr(e)
                };
                let _ = writeln!(out, "{}={value}", var(v.index));
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
                    let _ = write!(line, " {}{}", axis.letter(), word(*axis, e, d));
                }
                if let Some(f) = feed_mm_min {
                    let _ = write!(line, " F{}", fixed(*f, 1));
                }
                let _ = writeln!(out, "{line}");
            }
            Stmt::DoWhile { label, body, cond } => {
                let _ = writeln!(out, "o{} do", 100 + label);
                stmts(out, body, d, pending);
                let _ = writeln!(out, "o{} while {}", 100 + label, cond_text(cond));
            }
            Stmt::If { label, cond, body } => {
                let _ = writeln!(out, "o{} if {}", 500 + label, cond_text(cond));
                stmts(out, body, d, pending);
                let _ = writeln!(out, "o{} endif", 500 + label);
            }
            Stmt::Mark {
                var: mark,
                value,
                text,
            } => {
                // The interpreter reads ahead of motion: M66 (read input 0, no wait) makes
                // LinuxCNC finish the queued motion first, so the mark follows the stroke.
                out.push_str("M66 P0 L0 (the mark waits for the motion before it to end)\n");
                let _ = writeln!(
                    out,
                    "{}={} ({})",
                    var(mark.index),
                    exact(*value),
                    paren_safe(text)
                );
            }
        }
    }
}

fn word(axis: Axis, e: &Expr, d: Decimals) -> String {
    match e {
        Expr::Num(v) if axis.is_rotary() => fixed(*v, d.angle),
        Expr::Num(v) => fixed(*v, d.linear),
        other => format!("[{}]", expr(other)),
    }
}

fn cond_text(c: &Cond) -> String {
    let op = if c.less { "LT" } else { "GT" };
    format!("[{} {op} {}]", expr(&c.left), expr(&c.right))
}

/// An expression in ISO macro syntax; binary operations inside others are bracketed.
pub(crate) fn expr(e: &Expr) -> String {
    let sub = |e: &Expr| {
        if is_binary(e) || matches!(e, Expr::Num(v) if *v < 0.0) {
            format!("[{}]", expr(e))
        } else {
            expr(e)
        }
    };
    match e {
        Expr::Num(v) => exact(*v),
        Expr::Var(v) => var(v.index),
        Expr::Add(a, b) => format!("{}+{}", sub(a), sub(b)),
        Expr::Sub(a, b) => format!("{}-{}", sub(a), sub(b)),
        Expr::Mul(a, b) => format!("{}*{}", sub(a), sub(b)),
        Expr::Div(a, b) => format!("{}/{}", sub(a), sub(b)),
        Expr::Neg(a) => format!("-{}", sub(a)),
        Expr::Sin(a) => format!("SIN[{}]", expr(a)),
        Expr::Cos(a) => format!("COS[{}]", expr(a)),
        Expr::Tan(a) => format!("TAN[{}]", expr(a)),
        Expr::Sqrt(a) => format!("SQRT[{}]", expr(a)),
        Expr::Abs(a) => format!("ABS[{}]", expr(a)),
    }
}
