//! SINUMERIK 840D sl text: `DEF REAL` variables, `LABEL:` with `IF … GOTOB` loops, axis
//! words as `X=<expr>`.

use std::fmt::Write as _;

use super::{Decimals, RenderState, exact, fixed, is_binary};
use crate::ir::{Axis, Compensation, Cond, Expr, Motion, Plane, Program, Stmt};
use crate::setup::{
    Coolant, FeedMode, MachineStmt, SpindleDirection, SpindleSpeed, ToolCall, XMode,
};

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
        Plane::Zx => "G18 G90 G71 ; Z-X plane, absolute, metric",
    };
    out.push_str(plane);
    out.push('\n');
    let mut state = RenderState::default();
    stmts(&mut out, &p.body, d, &mut state);
    out.push_str("M30\n");
    out
}

/// A subprogram: the contour a main program calls (and `CYCLE95` reads), ended by `RET`.
/// X words follow the caller's DIAMON/DIAMOF, stated in `x_diameter`.
pub(super) fn render_sub(p: &Program, d: Decimals, x_diameter: bool) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "%_N_{}_SPF", p.name);
    out.push_str(";$PATH=/_N_SPF_DIR\n");
    for c in &p.comments {
        let _ = writeln!(out, "; {c}");
    }
    let mut state = RenderState::default();
    if x_diameter {
        state.note(&MachineStmt::XMode(XMode::Diameter));
    }
    stmts(&mut out, &p.body, d, &mut state);
    out.push_str("RET\n");
    out
}

fn stmts(out: &mut String, body: &[Stmt], d: Decimals, state: &mut RenderState) {
    for s in body {
        match s {
            Stmt::Comment(c) => {
                let _ = writeln!(out, "; {c}");
            }
            Stmt::Assign(v, e) => {
                let _ = writeln!(out, "{}={}", v.name, expr(e));
            }
            Stmt::Comp(c) => state.pending = Some(*c),
            Stmt::Call(name) => {
                let _ = writeln!(out, "{name} ; contour subprogram");
            }
            Stmt::StockRemoval(c) => {
                // 802D order [?]: NPP, MID, FALZ, FALX, FAL, FF1, FF2, FF3, VARI, DT, DAM,
                // _VRT; VARI 1 = longitudinal, outside, roughing only.
                let _ = writeln!(
                    out,
                    "CYCLE95(\"{}\",{},0,{},{},{},{},{},1,0,0,1) ; stock removal down to the allowance",
                    c.contour,
                    exact(c.depth_mm),
                    exact(c.allowance_mm),
                    exact(c.allowance_mm),
                    state.feed_text(c.feed),
                    state.feed_text(c.feed),
                    state.feed_text(c.feed),
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
                    let _ = write!(line, " {}={w}", axis.letter());
                }
                if let Some(f) = feed {
                    let _ = write!(line, " F{}", state.feed_text(*f));
                }
                let _ = writeln!(out, "{line}");
            }
            Stmt::DoWhile { label, body, cond } => {
                let _ = writeln!(out, "LOOP_{label}:");
                stmts(out, body, d, state);
                let _ = writeln!(out, "IF {} GOTOB LOOP_{label}", cond_text(cond, false));
            }
            Stmt::If { label, cond, body } => {
                let _ = writeln!(out, "IF {} GOTOF SKIP_{label}", cond_text(cond, true));
                stmts(out, body, d, state);
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

/// A move word: a fixed-decimal number, or an expression the control evaluates; doubled
/// for X under DIAMON (the program's values are radii).
fn word(axis: Axis, e: &Expr, d: Decimals, double: bool) -> String {
    match e {
        Expr::Num(v) if axis.is_rotary() => fixed(*v, d.angle),
        Expr::Num(v) if double => fixed(2.0 * v, d.linear),
        Expr::Num(v) => fixed(*v, d.linear),
        other if double => format!("2*({})", expr(other)),
        other => expr(other),
    }
}

/// A machine-state block with a comment saying what it does.
fn machine(m: &MachineStmt) -> String {
    match *m {
        MachineStmt::WorkOffset(n) => format!("G{} ; work offset", 53 + u32::from(n)),
        MachineStmt::XMode(XMode::Radius) => "DIAMOF ; X as a radius".to_owned(),
        MachineStmt::XMode(XMode::Diameter) => "DIAMON ; X as a diameter".to_owned(),
        MachineStmt::Tool(ToolCall {
            number,
            offset,
            change,
        }) => format!(
            "T{number} D{offset}{} ; tool {number}, offset {offset}",
            if change { " M6" } else { "" }
        ),
        MachineStmt::FeedMode(FeedMode::PerRevolution) => "G95 ; F in mm per revolution".to_owned(),
        MachineStmt::FeedMode(FeedMode::PerMinute) => "G94 ; F in mm per minute".to_owned(),
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
                    "G96 S{} LIMS={} {m} ; constant cutting speed in m/min, spindle limit in rpm",
                    exact(speed_m_min),
                    exact(limit_rpm)
                ),
                SpindleSpeed::Rpm(rpm) => format!("G97 S{} {m} ; spindle in rpm", exact(rpm)),
            }
        }
        MachineStmt::SpindleOff => "M5 ; spindle off".to_owned(),
        // SINUMERIK has no P word on an M function: the generators refuse one before this.
        MachineStmt::MFunction { code, what, .. } => format!("M{code} ; {what}"),
        MachineStmt::Coolant(Coolant::Flood) => "M8 ; coolant on".to_owned(),
        MachineStmt::Coolant(Coolant::Mist) => "M7 ; mist coolant on".to_owned(),
        MachineStmt::Coolant(Coolant::Off) => "M9 ; coolant off".to_owned(),
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
