//! The control's program state (variables, the subprogram parameter, how a level ends) and
//! the statements that need no machine state: definitions, `PROC`, argument reading.

use std::collections::BTreeMap;

use super::{Control, ControlError, ControlFault, Coupled};
use camloop_core::program::ParsedShape;
use camloop_core::program::syntax::{Expr, Param};

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Value {
    Int(i64),
    Real(f64),
}

/// One program level: its variables, declared subprograms and, in a subprogram, its `VAR`
/// parameters (copied in from the caller's variables at the call, back at `RET`).
pub(super) struct Frame {
    pub(super) program: String,
    pub(super) vars: BTreeMap<String, Value>,
    /// Declared subprograms and how many `VAR INT` parameters each takes.
    pub(super) externs: BTreeMap<String, usize>,
    /// The caller's values for the parameters, in order; updated at `RET`.
    pub(super) arguments: Vec<Value>,
    /// The parameters' names once `PROC` has named them.
    pub(super) params: Vec<String>,
    /// A statement other than a definition has run: definitions must come first.
    pub(super) executed: bool,
}

impl Frame {
    pub(super) fn new(program: &str, arguments: Vec<Value>) -> Self {
        Self {
            program: program.to_owned(),
            vars: BTreeMap::new(),
            externs: BTreeMap::new(),
            arguments,
            params: Vec::new(),
            executed: false,
        }
    }
}

/// How a program level ended.
pub(super) enum End {
    M30,
    Ret,
}

/// Why a statement stopped the run: a fault at its own line, at another line of the same
/// program (a table block), or an error already located in a called program.
pub(super) enum Halt {
    Here(ControlFault),
    Line(ControlFault, usize),
    Nested(ControlError),
}

impl From<ControlFault> for Halt {
    fn from(f: ControlFault) -> Self {
        Halt::Here(f)
    }
}

pub(super) type Step = Result<Option<End>, Halt>;

pub(super) struct Run<'c> {
    pub(super) control: &'c mut Control,
    pub(super) load: &'c dyn Fn(&str) -> Option<String>,
    /// Every grind of the run, in order.
    pub(super) ground: Vec<Coupled>,
    /// The cycle's events, in order.
    pub(super) events: Vec<super::CycleEvent>,
    /// Jumps made (`GOTOB`, `GOTOF`), bounded so a wait without end is a fault.
    pub(super) jumps: usize,
}

/// `DEF REAL a, b` / `DEF INT a`.
pub(super) fn define(code: &str, kind: &str, names: &[&str], frame: &mut Frame) -> Step {
    let value = match kind {
        "REAL" => Value::Real(0.0),
        "INT" => Value::Int(0),
        _ => return Err(unsupported(code).into()),
    };
    for name in names {
        if !is_name(name) || frame.vars.insert((*name).to_owned(), value).is_some() {
            return Err(invalid(&format!("`{name}` cannot be defined here")).into());
        }
    }
    Ok(None)
}

/// True for `VAR INT` (with a name in `PROC`, without in `EXTERN`).
fn is_var_int(p: &Param<'_>, named: bool) -> bool {
    p.by_reference && p.kind == "INT" && p.name.is_some() == named
}

/// `EXTERN NAME()`, `EXTERN NAME(VAR INT)` or `EXTERN NAME(VAR INT, VAR INT)` (the speed
/// plan's table program returns two numbers).
pub(super) fn declare(code: &str, name: &str, params: &[Param<'_>], frame: &mut Frame) -> Step {
    if !is_name(name) || !params.iter().all(|p| is_var_int(p, false)) {
        return Err(unsupported(code).into());
    }
    frame.externs.insert(name.to_owned(), params.len());
    Ok(None)
}

/// `PROC NAME` or `PROC NAME(VAR INT p, VAR INT q …)`, optionally ` SAVE`, first in a
/// subprogram.
pub(super) fn proc_line(
    code: &str,
    name: &str,
    params: &[Param<'_>],
    frame: &mut Frame,
    depth: usize,
) -> Step {
    let names: Vec<&str> = params.iter().filter_map(|p| p.name).collect();
    let all_var_int = params.iter().all(|p| is_var_int(p, true));
    if depth == 0 || name != frame.program || !all_var_int || !names.iter().all(|p| is_name(p)) {
        return Err(unsupported(code).into());
    }
    // A PROC without parameters is refused after the call returns, naming the caller.
    if !names.is_empty() && names.len() != frame.arguments.len() {
        return Err(invalid(&format!(
            "{name} is called with {} arguments for {} parameters",
            frame.arguments.len(),
            names.len()
        ))
        .into());
    }
    for (p, value) in names.iter().zip(frame.arguments.clone()) {
        if !matches!(value, Value::Int(_)) {
            return Err(invalid(&format!("the argument for {p} is not an INT variable")).into());
        }
        frame.vars.insert((*p).to_owned(), value);
        frame.params.push((*p).to_owned());
    }
    Ok(None)
}

/// A whole-number literal or the value of an INT variable.
pub(super) fn int_arg(e: &Expr<'_>, frame: &Frame) -> Result<i64, ControlFault> {
    if let Some(v) = e.number() {
        return if v.fract() == 0.0 && v.abs() < 1e15 {
            Ok(v as i64)
        } else {
            Err(invalid(&format!("{v} is not a whole number")))
        };
    }
    let Some(name) = e.name() else {
        return Err(invalid(
            "an INT argument is a whole number or an INT variable",
        ));
    };
    match frame.vars.get(name) {
        Some(Value::Int(n)) => Ok(*n),
        Some(Value::Real(_)) => Err(invalid(&format!("{name} is not an INT variable"))),
        None => Err(undefined_variable(name)),
    }
}

/// A number literal or the value of a REAL variable.
pub(super) fn real_arg(e: &Expr<'_>, frame: &Frame) -> Result<f64, ControlFault> {
    match (e.number(), e.name()) {
        (Some(v), _) => Ok(v),
        (None, Some(name)) => real_var(name, frame),
        (None, None) => Err(invalid("a REAL argument is a number or a REAL variable")),
    }
}

/// The value of a REAL variable.
pub(super) fn real_var(text: &str, frame: &Frame) -> Result<f64, ControlFault> {
    match frame.vars.get(text) {
        Some(Value::Real(v)) => Ok(*v),
        Some(Value::Int(_)) => Err(invalid(&format!("{text} is not a REAL variable"))),
        None => Err(undefined_variable(text)),
    }
}

/// A curve table number: 1 or more.
pub(super) fn table_number(n: i64) -> Result<u32, ControlFault> {
    u32::try_from(n)
        .ok()
        .filter(|&n| n >= 1)
        .ok_or(ControlFault::UndefinedTable { number: n })
}

/// The leading value must increase in every block (alarm 10949).
pub(super) fn check_increasing(number: u32, shape: &ParsedShape) -> Result<(), ControlFault> {
    let leading: Vec<f64> = match shape {
        ParsedShape::G1(points) => points.iter().map(|p| p.0).collect(),
        ParsedShape::Poly(segments) => segments
            .first()
            .map(|s| s.c_start_deg)
            .into_iter()
            .chain(segments.iter().map(|s| s.c_end_deg))
            .collect(),
    };
    if leading.len() < 2 {
        return Err(invalid(&format!(
            "curve table {number} has fewer than 2 points"
        )));
    }
    match leading.windows(2).find(|w| w[1] <= w[0]) {
        Some(w) => Err(ControlFault::LeadingNotIncreasing {
            number,
            c_deg: w[1],
        }),
        None => Ok(()),
    }
}

/// A variable, program or axis name: a letter, then letters, digits and `_`.
pub(super) fn is_name(text: &str) -> bool {
    let mut chars = text.chars();
    chars.next().is_some_and(|c| c.is_ascii_uppercase())
        && chars.all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
}

pub(super) fn undefined_variable(name: &str) -> ControlFault {
    ControlFault::UndefinedVariable {
        name: name.to_owned(),
    }
}

pub(super) fn unsupported(code: &str) -> ControlFault {
    ControlFault::Unsupported {
        statement: code.to_owned(),
    }
}

pub(super) fn invalid(reason: &str) -> ControlFault {
    ControlFault::Invalid {
        reason: reason.to_owned(),
    }
}
