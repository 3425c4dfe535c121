//! ISO G-code with macro variables, as LinuxCNC's interpreter reads it: `#n` variables,
//! `[…]` expressions, `o<n> do … o<n> while […]` loops and `o<n> if … o<n> endif`.

use std::fmt::Write as _;

use super::{Decimals, RenderState, exact, fixed, is_binary};
use crate::ir::{Axis, Compensation, Cond, Expr, Motion, Plane, Program, Stmt};
use crate::setup::{
    Coolant, FeedMode, MachineStmt, SpindleDirection, SpindleSpeed, ToolCall, XMode,
};

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
        Plane::Zx => "G18 G90 G21 G40 (Z-X plane, absolute, mm)",
    };
    out.push_str(plane);
    out.push('\n');
    let mut state = RenderState::default();
    stmts(&mut out, &p.body, d, &mut state);
    out.push_str("M30\n%\n");
    out
}

/// A subprogram as LinuxCNC reads it in the file that calls it: `o<name> sub` …
/// `o<name> endsub`, placed before the main program's first block.
pub(super) fn render_sub(p: &Program, d: Decimals, x_diameter: bool) -> String {
    let mut out = String::new();
    let name = p.name.to_lowercase();
    let _ = writeln!(out, "o<{name}> sub");
    for c in &p.comments {
        let _ = writeln!(out, "({})", paren_safe(c));
    }
    let mut state = RenderState::default();
    if x_diameter {
        state.note(&MachineStmt::XMode(XMode::Diameter));
    }
    stmts(&mut out, &p.body, d, &mut state);
    let _ = writeln!(out, "o<{name}> endsub");
    out
}

/// Comments end at `)`: replace brackets inside them.
fn paren_safe(c: &str) -> String {
    c.replace('(', "[").replace(')', "]")
}

fn var(index: u16) -> String {
    format!("#{}", FIRST_VAR + index)
}

fn stmts(out: &mut String, body: &[Stmt], d: Decimals, state: &mut RenderState) {
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
            Stmt::Comp(c) => state.pending = Some(*c),
            Stmt::Call(name) => {
                let _ = writeln!(out, "o<{}> call (contour subprogram)", name.to_lowercase());
            }
            Stmt::StockRemoval(_) => {
                // No ISO form here: stop rather than let the finish pass cut the full stock.
                out.push_str(
                    "M0 (CYCLE95 stock removal has no ISO form: rough with camloop passes)\n",
                );
            }
            Stmt::Machine(m) => {
                state.note(m);
                let _ = writeln!(out, "{}", machine(m));
            }
            Stmt::Move {
                motion,
                words,
                feed,
            } => {
                let mut line = String::new();
                if let Some(c) = state.pending.take() {
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
                    let w = word(*axis, e, d, state.doubles(*axis));
                    let _ = write!(line, " {}{w}", axis.letter());
                }
                if let Some(f) = feed {
                    let _ = write!(line, " F{}", state.feed_text(*f));
                }
                let _ = writeln!(out, "{line}");
            }
            Stmt::DoWhile { label, body, cond } => {
                let _ = writeln!(out, "o{} do", 100 + label);
                stmts(out, body, d, state);
                let _ = writeln!(out, "o{} while {}", 100 + label, cond_text(cond));
            }
            Stmt::If { label, cond, body } => {
                let _ = writeln!(out, "o{} if {}", 500 + label, cond_text(cond));
                stmts(out, body, d, state);
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

/// A move word; X doubled under G7 (the program's values are radii).
fn word(axis: Axis, e: &Expr, d: Decimals, double: bool) -> String {
    match e {
        Expr::Num(v) if axis.is_rotary() => fixed(*v, d.angle),
        Expr::Num(v) if double => fixed(2.0 * v, d.linear),
        Expr::Num(v) => fixed(*v, d.linear),
        other if double => format!("[2*[{}]]", expr(other)),
        other => format!("[{}]", expr(other)),
    }
}

/// A machine-state block as LinuxCNC reads it, with a comment saying what it does.
fn machine(m: &MachineStmt) -> String {
    match *m {
        MachineStmt::WorkOffset(n) => format!("G{} (work offset)", 53 + u32::from(n)),
        MachineStmt::XMode(XMode::Radius) => "G8 (X as a radius)".to_owned(),
        MachineStmt::XMode(XMode::Diameter) => "G7 (X as a diameter)".to_owned(),
        // LinuxCNC loads a tool only with M6; G43 H applies the offset's length.
        MachineStmt::Tool(ToolCall { number, offset, .. }) => {
            format!("T{number} M6 G43 H{offset} (tool {number}, offset {offset})")
        }
        MachineStmt::FeedMode(FeedMode::PerRevolution) => "G95 (F in mm per revolution)".to_owned(),
        MachineStmt::FeedMode(FeedMode::PerMinute) => "G94 (F in mm per minute)".to_owned(),
        MachineStmt::SpindleOn(s) => {
            let m = match s.direction {
                SpindleDirection::Cw => "M3",
                SpindleDirection::Ccw => "M4",
            };
            match s.speed {
                SpindleSpeed::ConstantSurface {
                    speed_m_min,
                    limit_rpm,
                } => format!(
                    "G96 D{} S{} {m} (constant cutting speed in m/min, D: spindle limit in rpm)",
                    exact(limit_rpm),
                    exact(speed_m_min)
                ),
                SpindleSpeed::Rpm(rpm) => format!("G97 S{} {m} (spindle in rpm)", exact(rpm)),
            }
        }
        MachineStmt::SpindleOff => "M5 (spindle off)".to_owned(),
        MachineStmt::MFunction { code, p, what } => match p {
            Some(p) => format!("M{code} P{p} ({what})"),
            None => format!("M{code} ({what})"),
        },
        MachineStmt::Coolant(Coolant::Flood) => "M8 (coolant on)".to_owned(),
        MachineStmt::Coolant(Coolant::Mist) => "M7 (mist coolant on)".to_owned(),
        MachineStmt::Coolant(Coolant::Off) => "M9 (coolant off)".to_owned(),
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
