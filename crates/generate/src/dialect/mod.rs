//! Controller dialects: one file per control, all behind [`Dialect`].
//!
//! A generator builds a [`super::ir::Program`] once; a dialect only writes it. Adding a
//! controller means adding a variant here and one file beside this one: nothing in the
//! generators changes.

mod iso;
mod sinumerik;

use super::ir::{Axis, Compensation, Expr, MachineStmt, Program, expand};
use super::setup::{FeedMode, XMode};

/// The controls camloop writes programs for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// SINUMERIK 840D sl: `DEF REAL` variables, labels and `IF … GOTOB` loops.
    Sinumerik,
    /// ISO G-code with macro variables as LinuxCNC reads them: `#` numbers, `o… do` /
    /// `o… while` loops and `o… if` blocks.
    Iso,
}

/// Loop form (the control evaluates the curve) or expanded form (one block per move).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    Loop,
    Expanded,
}

/// Decimals written in move words.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decimals {
    /// Linear axes and arc centres, mm.
    pub linear: usize,
    /// Rotary axes, degrees.
    pub angle: usize,
}

impl Default for Decimals {
    /// 0.1 µm and 0.0001°, the resolution of the controls' default machine data.
    fn default() -> Self {
        Decimals {
            linear: 4,
            angle: 4,
        }
    }
}

impl Dialect {
    /// The program as text in this dialect and form.
    pub fn render(self, program: &Program, form: Form, decimals: Decimals) -> String {
        let expanded;
        let p = match form {
            Form::Loop => program,
            Form::Expanded => {
                expanded = expand(program);
                &expanded
            }
        };
        match self {
            Dialect::Sinumerik => sinumerik::render(p, decimals),
            Dialect::Iso => iso::render(p, decimals),
        }
    }
}

/// One file of a rendered program set.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedFile {
    /// The program's name (the main program's, or a subprogram's).
    pub name: String,
    /// True for a subprogram file (SINUMERIK `.SPF`).
    pub sub: bool,
    pub text: String,
}

impl Dialect {
    /// A main program and the subprograms it calls. SINUMERIK: one file each (the
    /// subprograms as `.SPF` with `RET`). ISO: one file, the subprograms first, as LinuxCNC
    /// needs a called subroutine defined before the call. `x_diameter` says whether the
    /// caller has X in diameter when the subprograms run.
    pub fn render_set(
        self,
        main: &Program,
        subs: &[Program],
        form: Form,
        decimals: Decimals,
        x_diameter: bool,
    ) -> Vec<RenderedFile> {
        let main_text = self.render(main, form, decimals);
        let sub_texts = subs.iter().map(|s| {
            let s = match form {
                Form::Loop => s.clone(),
                Form::Expanded => expand(s),
            };
            match self {
                Dialect::Sinumerik => sinumerik::render_sub(&s, decimals, x_diameter),
                Dialect::Iso => iso::render_sub(&s, decimals, x_diameter),
            }
        });
        match self {
            Dialect::Sinumerik => std::iter::once(RenderedFile {
                name: main.name.clone(),
                sub: false,
                text: main_text,
            })
            .chain(subs.iter().zip(sub_texts).map(|(p, text)| RenderedFile {
                name: p.name.clone(),
                sub: true,
                text,
            }))
            .collect(),
            Dialect::Iso => {
                let defs: String = sub_texts.collect();
                let text = match main_text.strip_prefix("%\n") {
                    Some(rest) => format!("%\n{defs}{rest}"),
                    None => format!("{defs}{main_text}"),
                };
                vec![RenderedFile {
                    name: main.name.clone(),
                    sub: false,
                    text,
                }]
            }
        }
    }
}

/// `v` with exactly `decimals` decimals, never `-0.000`: the curve tables' own formatter.
pub(crate) use camloop_core::program::fmt_fixed as fixed;

/// A constant inside an expression: the shortest text that reads back as the same `f64`,
/// so the control computes with exactly the value the generator used.
pub(crate) fn exact(v: f64) -> String {
    format!("{v}")
}

/// True when `e` is a binary operation, which needs brackets inside another one.
pub(crate) fn is_binary(e: &Expr) -> bool {
    matches!(
        e,
        Expr::Add(..) | Expr::Sub(..) | Expr::Mul(..) | Expr::Div(..)
    )
}

/// What a dialect tracks while it writes: the compensation waiting for its move, whether X
/// is written as a diameter, and the feed mode (F keeps 1 decimal in mm/min, 4 in mm/rev).
#[derive(Debug, Default)]
pub(crate) struct RenderState {
    pub(crate) pending: Option<Compensation>,
    diameter: bool,
    per_rev: bool,
}

impl RenderState {
    pub(crate) fn note(&mut self, m: &MachineStmt) {
        match m {
            MachineStmt::XMode(x) => self.diameter = *x == XMode::Diameter,
            MachineStmt::FeedMode(f) => self.per_rev = *f == FeedMode::PerRevolution,
            _ => {}
        }
    }
    /// True when this axis's words are written doubled (X in diameter mode).
    pub(crate) fn doubles(&self, axis: Axis) -> bool {
        self.diameter && axis == Axis::X
    }
    pub(crate) fn feed_text(&self, f: f64) -> String {
        fixed(f, if self.per_rev { 4 } else { 1 })
    }
}
