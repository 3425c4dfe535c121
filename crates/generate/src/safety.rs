//! The safety check every generated program passes before camloop writes it: no cutting
//! move before tool, spindle and feed mode; no F before its unit; nothing behind a lathe's
//! axis; a rotary axis turned only with the tool clear (or in the cut it is coupled to);
//! spindle and coolant off at the end.
//!
//! It runs on the program expanded ([`crate::ir::expand`]): every loop run, every move with
//! its numbers, so what it proves is what the control will be asked to do. The machine's
//! own facts (which axes are rotary, where the tool is clear) come in as [`Rules`], so the
//! turning, turn-mill and planing generators share the one check.

use thiserror::Error;

use crate::ir::{Axis, Expr, MachineStmt, Motion, Plane, Program, Stmt, expand};
use crate::setup::Coolant;

/// Where the tool is clear of the part: it may turn a rotary axis there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Clear {
    /// The axis at or above the value (a lifted Z, an X retracted outwards).
    AtLeast { axis: Axis, mm: f64 },
    /// The axis at or below the value.
    AtMost { axis: Axis, mm: f64 },
    /// The tool at least this far from the rotary centre in the X–Y plane, √(X² + Y²).
    RadiusAtLeast { mm: f64 },
}

/// How a rotary axis may turn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rotary {
    pub axis: Axis,
    /// It may turn in a feed move together with a linear axis: the cut it is coupled to
    /// (planing's A following X). Otherwise it turns only with the tool clear.
    pub coupled_cut: bool,
}

/// The machine's facts the check needs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Rules {
    /// Lowest X any move may reach, in radius terms (a lathe: 0, the axis); `None` where X
    /// may be negative (milling).
    pub min_x_mm: Option<f64>,
    pub rotary: Vec<Rotary>,
    /// The tool is clear where any of these holds.
    pub clear: Vec<Clear>,
    /// A machine with no spindle (a planer): a cut needs tool and feed mode only.
    pub no_spindle: bool,
}

impl Rules {
    /// A lathe: X never below the axis, no rotary axis.
    pub fn lathe() -> Self {
        Rules {
            min_x_mm: Some(0.0),
            ..Rules::default()
        }
    }
}

/// One breach of the rules; `block` counts the statements of the expanded program from 1.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Violation {
    #[error("block {block}: a cutting move before {missing}")]
    CutBeforeSetup { block: usize, missing: &'static str },
    #[error("block {block}: an F word before the feed mode (G94/G95) is stated")]
    FeedBeforeMode { block: usize },
    #[error("block {block}: a cutting move with no feed programmed")]
    NoFeed { block: usize },
    #[error("block {block}: a cutting move after the spindle was stopped")]
    CutAfterStop { block: usize },
    #[error("block {block}: x = {x_mm} mm is behind the axis (the lowest allowed is {min_mm} mm)")]
    BehindAxis {
        block: usize,
        x_mm: f64,
        min_mm: f64,
    },
    #[error("block {block}: {axis} turns with the tool not clear of the part")]
    RotaryEngaged { block: usize, axis: char },
    #[error("the program ends with the spindle running")]
    SpindleLeftOn,
    #[error("the program ends with the coolant on")]
    CoolantLeftOn,
}

/// What the check went through.
#[derive(Debug, Clone, PartialEq)]
pub struct SafetyReport {
    pub moves: usize,
    pub cutting_moves: usize,
    /// Lowest X reached, arcs included (None: no X).
    pub min_x_mm: Option<f64>,
    /// Moves that turned a rotary axis, all with the tool clear or coupled to the cut.
    pub rotary_moves: usize,
}

/// The machine state as the check follows it.
#[derive(Debug, Default)]
struct State {
    tool: bool,
    spindle: bool,
    spindle_stopped: bool,
    feed_mode: bool,
    feed: bool,
    coolant: bool,
    /// Last commanded position per axis (X, Y, Z, A, C), unknown until commanded.
    pos: [Option<f64>; 5],
}

fn slot(axis: Axis) -> Option<usize> {
    match axis {
        Axis::X => Some(0),
        Axis::Y => Some(1),
        Axis::Z => Some(2),
        Axis::A => Some(3),
        Axis::C => Some(4),
        _ => None,
    }
}

/// Checks `program` (expanded first) against `rules`; every violation, in order, or what
/// was checked.
pub fn check(program: &Program, rules: &Rules) -> Result<SafetyReport, Vec<Violation>> {
    let expanded = expand(program);
    let mut st = State::default();
    let mut v = Vec::new();
    let mut report = SafetyReport {
        moves: 0,
        cutting_moves: 0,
        min_x_mm: None,
        rotary_moves: 0,
    };
    for (i, s) in expanded.body.iter().enumerate() {
        let block = i + 1;
        match s {
            Stmt::Machine(m) => machine(&mut st, m),
            Stmt::Move {
                motion,
                words,
                feed,
            } => {
                report.moves += 1;
                let cutting = *motion != Motion::Rapid;
                if feed.is_some() {
                    if !st.feed_mode {
                        v.push(Violation::FeedBeforeMode { block });
                    }
                    st.feed = true;
                }
                if cutting {
                    report.cutting_moves += 1;
                    setup_before_cut(&st, rules, block, &mut v);
                }
                let before = st.pos;
                let value = |a: Axis| {
                    words.iter().find_map(|(w, e)| match e {
                        Expr::Num(x) if *w == a => Some(*x),
                        _ => None,
                    })
                };
                for (a, _) in words {
                    if let (Some(k), Some(x)) = (slot(*a), value(*a)) {
                        st.pos[k] = Some(x);
                    }
                }
                let low = lowest_x(expanded.plane, *motion, &before, &st.pos, words);
                if let Some(x) = low {
                    report.min_x_mm = Some(report.min_x_mm.map_or(x, |m: f64| m.min(x)));
                    if let Some(min) = rules.min_x_mm
                        && x < min - 1e-9
                    {
                        v.push(Violation::BehindAxis {
                            block,
                            x_mm: x,
                            min_mm: min,
                        });
                    }
                }
                rotary(rules, block, *motion, words, &before, &st.pos, &mut v)
                    .then(|| report.rotary_moves += 1);
            }
            // A call left in place (its body unknown here) or the control's stock removal:
            // both cut, so both need the set-up.
            Stmt::Call(_) => setup_before_cut(&st, rules, i + 1, &mut v),
            Stmt::StockRemoval(_) => {
                report.cutting_moves += 1;
                st.feed = st.feed_mode;
                setup_before_cut(&st, rules, i + 1, &mut v);
            }
            _ => {}
        }
    }
    if st.spindle {
        v.push(Violation::SpindleLeftOn);
    }
    if st.coolant {
        v.push(Violation::CoolantLeftOn);
    }
    if v.is_empty() { Ok(report) } else { Err(v) }
}

fn machine(st: &mut State, m: &MachineStmt) {
    match m {
        MachineStmt::Tool(_) => st.tool = true,
        MachineStmt::SpindleOn(_) => {
            st.spindle = true;
            st.spindle_stopped = false;
        }
        MachineStmt::SpindleOff => {
            st.spindle = false;
            st.spindle_stopped = true;
        }
        MachineStmt::FeedMode(_) => {
            st.feed_mode = true;
            // A new unit voids the F in force: the next cut must state its own.
            st.feed = false;
        }
        MachineStmt::Coolant(c) => st.coolant = *c != Coolant::Off,
        MachineStmt::WorkOffset(_) | MachineStmt::XMode(_) | MachineStmt::MFunction { .. } => {}
    }
}

fn setup_before_cut(st: &State, rules: &Rules, block: usize, v: &mut Vec<Violation>) {
    let missing = [
        (st.tool, "the tool call"),
        (
            st.spindle || st.spindle_stopped || rules.no_spindle,
            "the spindle start",
        ),
        (st.feed_mode, "the feed mode"),
    ];
    for (ok, what) in missing {
        if !ok {
            v.push(Violation::CutBeforeSetup {
                block,
                missing: what,
            });
        }
    }
    if st.spindle_stopped {
        v.push(Violation::CutAfterStop { block });
    }
    if st.feed_mode && !st.feed {
        v.push(Violation::NoFeed { block });
    }
}

/// Lowest X of a move: its end, or for a Z–X arc the lowest point the arc passes.
fn lowest_x(
    plane: Plane,
    motion: Motion,
    before: &[Option<f64>; 5],
    after: &[Option<f64>; 5],
    words: &[(Axis, Expr)],
) -> Option<f64> {
    let end_x = after[0]?;
    if !words.iter().any(|(a, _)| matches!(a, Axis::X | Axis::Z)) {
        return None;
    }
    let arc = matches!(motion, Motion::ArcCw | Motion::ArcCcw);
    let (Some(x0), Some(z0), Some(z1), true, Plane::Zx) =
        (before[0], before[2], after[2], arc, plane)
    else {
        return Some(end_x);
    };
    let off = |a: Axis| {
        words.iter().find_map(|(w, e)| match e {
            Expr::Num(v) if *w == a => Some(*v),
            _ => None,
        })
    };
    let (ci, ck) = (off(Axis::I).unwrap_or(0.0), off(Axis::K).unwrap_or(0.0));
    let (cx, cz) = (x0 + ci, z0 + ck);
    let r = ci.hypot(ck);
    // In (z, x) with z right and x up (G18 seen from +Y), G2 turns clockwise: the angle
    // atan2(x − cx, z − cz) falls. The lowest point is at −90°.
    let a0 = (x0 - cx).atan2(z0 - cz);
    let a1 = (end_x - cx).atan2(z1 - cz);
    let tau = std::f64::consts::TAU;
    let sweep = if motion == Motion::ArcCcw {
        (a1 - a0).rem_euclid(tau)
    } else {
        -(a0 - a1).rem_euclid(tau)
    };
    let bottom = -std::f64::consts::FRAC_PI_2;
    let to_bottom = if sweep >= 0.0 {
        (bottom - a0).rem_euclid(tau)
    } else {
        -(a0 - bottom).rem_euclid(tau)
    };
    let passes = to_bottom.abs() <= sweep.abs() && to_bottom.signum() == sweep.signum();
    Some(if passes { cx - r } else { end_x.min(x0) })
}

/// True when the move turned a rotary axis; records a violation if the tool was not clear.
fn rotary(
    rules: &Rules,
    block: usize,
    motion: Motion,
    words: &[(Axis, Expr)],
    before: &[Option<f64>; 5],
    after: &[Option<f64>; 5],
    v: &mut Vec<Violation>,
) -> bool {
    let linear = words
        .iter()
        .any(|(a, _)| matches!(a, Axis::X | Axis::Y | Axis::Z));
    let mut turned = false;
    for r in &rules.rotary {
        let Some(k) = slot(r.axis) else { continue };
        if !words.iter().any(|(a, _)| *a == r.axis) || before[k] == after[k] {
            continue;
        }
        turned = true;
        let coupled = r.coupled_cut && motion != Motion::Rapid && linear;
        let clear = is_clear(rules, before) && is_clear(rules, after);
        if !(coupled || clear) {
            v.push(Violation::RotaryEngaged {
                block,
                axis: r.axis.letter(),
            });
        }
    }
    turned
}

/// True when a clearance rule holds at `pos`; an axis not yet commanded is not clear.
fn is_clear(rules: &Rules, pos: &[Option<f64>; 5]) -> bool {
    let at = |a: Axis| slot(a).and_then(|k| pos[k]);
    rules.clear.iter().any(|c| match *c {
        Clear::AtLeast { axis, mm } => at(axis).is_some_and(|x| x >= mm),
        Clear::AtMost { axis, mm } => at(axis).is_some_and(|x| x <= mm),
        Clear::RadiusAtLeast { mm } => match (at(Axis::X), at(Axis::Y)) {
            (Some(x), Some(y)) => x.hypot(y) >= mm,
            _ => false,
        },
    })
}

#[cfg(test)]
mod tests;
