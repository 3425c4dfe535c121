//! A simulated SINUMERIK control that runs the main program camloop writes as the control
//! would: it calls the table subprogram, keeps every curve table it defines by number (across
//! runs, as the NC memory does), and reports the table `LEADON` actually couples.
//!
//! It interprets exactly the subset camloop writes, strictly; anything else is an error naming
//! the program and line. Alarms the real control raises are errors too: `LEADON` or `CTAB` on
//! an undefined table, redefining the coupled table, programming the coupled axis, a leading
//! value that does not increase in a table (10949). Table blocks are read by the same reader
//! as [`crate::core::program::parse_table_program`].
//!
//! Not modelled: modal G states (`G90`, `G71`, `SAVE` restore), feeds and timing, the
//! synchronising move of `LEADON`, work offsets (`$AA_IW` is the programmed setpoint).

use std::collections::BTreeMap;

use super::TableShape;
use crate::core::program::{ParsedShape, ParsedTable, TableBlocks, parse_ctabdef};
use crate::core::table::TablePoint;

/// Deepest subprogram nesting accepted (camloop needs 1).
const MAX_CALL_DEPTH: usize = 8;
/// `$AA_COUP_ACT` of a following axis in a master-value coupling [K].
const COUP_ACT_MASTER_VALUE: i64 = 16;

/// The simulated control: curve tables by number, the active coupling and axis setpoints
/// persist between runs; variables live for one program run.
#[derive(Debug, Clone, Default)]
pub struct Control {
    tables: BTreeMap<u32, ParsedTable>,
    coupling: Option<Coupling>,
    /// Setpoints by axis name (mm or degrees); an axis never moved is at 0.
    positions: BTreeMap<String, f64>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct Coupling {
    following: String,
    leading: String,
    table: u32,
}

/// What one run ground: the table coupled while C turned, and how C turned.
#[derive(Debug, Clone, PartialEq)]
pub struct Coupled {
    pub table_number: u32,
    /// In program axes, as [`table_shape`] builds it from the table's blocks.
    pub shape: TableShape,
    pub c_speed_rpm: f64,
    pub revolutions: f64,
}

/// A run stopped at `line` (1-based) of `program` (its name, or `main`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{program} line {line}: {fault}")]
pub struct ControlError {
    pub program: String,
    pub line: usize,
    pub fault: ControlFault,
}

/// What stopped a run. Variants starting with "alarm" are alarms of the real control.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControlFault {
    #[error("`{statement}` is not in the subset camloop writes")]
    Unsupported { statement: String },
    #[error("{reason}")]
    Invalid { reason: String },
    #[error("variable {name} is not defined")]
    UndefinedVariable { name: String },
    #[error("program {name} not found")]
    ProgramNotFound { name: String },
    #[error("the program ends without {what}")]
    NoEnd { what: &'static str },
    #[error("the program ran to its end without turning C while coupled")]
    NotGround,
    #[error("alarm: curve table {number} is not defined")]
    UndefinedTable { number: i64 },
    #[error("alarm: curve table {number} is active in a coupling and cannot be redefined")]
    TableInUse { number: u32 },
    #[error("alarm: {axis} is already coupled")]
    AlreadyCoupled { axis: String },
    #[error("alarm: {axis} is coupled and cannot be programmed")]
    AxisCoupled { axis: String },
    #[error(
        "alarm 10949: the leading value does not increase at C={c_deg} in curve table {number}"
    )]
    LeadingNotIncreasing { number: u32, c_deg: f64 },
}

impl ControlFault {
    /// An alarm of the real control (rather than a statement outside the subset).
    pub fn is_alarm(&self) -> bool {
        self.to_string().starts_with("alarm")
    }
}

/// The shape the simulated grinder runs for a table read from a program: POLY segments as
/// they are, G1 points without the closing point at first C + 360°.
pub fn table_shape(shape: &ParsedShape) -> TableShape {
    match shape {
        ParsedShape::Poly(segments) => TableShape::Poly(segments.clone()),
        ParsedShape::G1(points) => TableShape::G1(
            points
                .iter()
                .take(points.len().saturating_sub(1))
                .map(|&(c_deg, x_mm)| TablePoint {
                    c_deg,
                    d_mm: 0.0,
                    x_mm,
                })
                .collect(),
        ),
    }
}

impl Control {
    /// A control with no tables, nothing coupled, every axis at 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// Runs main program text `main` as the control would; subprogram calls are resolved
    /// with `load(name)` → the text of that program file (name as called, e.g.
    /// `DEMO_CAM_TABLE`). Tables defined stay defined, whatever the outcome.
    pub fn run(
        &mut self,
        main: &str,
        load: &dyn Fn(&str) -> Option<String>,
    ) -> Result<Coupled, ControlError> {
        let mut run = Run {
            control: self,
            load,
            ground: None,
        };
        let mut frame = Frame::new(program_name(main, "MPF").unwrap_or("main"), None);
        let end_line = run.program(main, &mut frame, 0)?;
        run.ground.ok_or(ControlError {
            program: frame.program,
            line: end_line,
            fault: ControlFault::NotGround,
        })
    }

    /// Numbers of the curve tables in memory, ascending.
    pub fn defined_tables(&self) -> Vec<u32> {
        self.tables.keys().copied().collect()
    }
}

/// `NAME` of a first line `%_N_NAME_<kind>`.
fn program_name<'t>(text: &'t str, kind: &str) -> Option<&'t str> {
    text.lines()
        .next()?
        .trim()
        .strip_prefix("%_N_")?
        .strip_suffix(kind)?
        .strip_suffix('_')
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Value {
    Int(i64),
    Real(f64),
}

/// One program level: its variables, declared subprograms and, in a subprogram, its `VAR`
/// parameter (copied in from the caller's variable at the call, back at `RET`).
struct Frame {
    program: String,
    vars: BTreeMap<String, Value>,
    /// Declared subprograms and how many `VAR INT` parameters each takes.
    externs: BTreeMap<String, usize>,
    /// The caller's value for the parameter, until `PROC` names it.
    argument: Option<Value>,
    /// The parameter's name once `PROC` has named it.
    param: Option<String>,
    /// A statement other than a definition has run: definitions must come first.
    executed: bool,
}

impl Frame {
    fn new(program: &str, argument: Option<Value>) -> Self {
        Self {
            program: program.to_owned(),
            vars: BTreeMap::new(),
            externs: BTreeMap::new(),
            argument,
            param: None,
            executed: false,
        }
    }
}

/// How a program level ended.
enum End {
    M30,
    Ret,
}

/// Why a statement stopped the run: a fault at its own line, at another line of the same
/// program (a table block), or an error already located in a called program.
enum Halt {
    Here(ControlFault),
    Line(ControlFault, usize),
    Nested(ControlError),
}

impl From<ControlFault> for Halt {
    fn from(f: ControlFault) -> Self {
        Halt::Here(f)
    }
}

type Step = Result<Option<End>, Halt>;

struct Run<'c> {
    control: &'c mut Control,
    load: &'c dyn Fn(&str) -> Option<String>,
    ground: Option<Coupled>,
}

impl Run<'_> {
    /// Runs `text` in `frame` to its `M30` (depth 0) or `RET`; returns that line.
    fn program(
        &mut self,
        text: &str,
        frame: &mut Frame,
        depth: usize,
    ) -> Result<usize, ControlError> {
        let lines: Vec<&str> = text.lines().collect();
        let fail = |frame: &Frame, line: usize, fault| ControlError {
            program: frame.program.clone(),
            line,
            fault,
        };
        let (mut i, mut open_if) = (0, false);
        while i < lines.len() {
            let line = i + 1;
            let code = lines[i].split(';').next().unwrap_or("").trim();
            i += 1;
            if code.is_empty() || (line == 1 && code.starts_with("%_N_")) {
                continue;
            }
            let step = self.dispatch(code, frame, depth, &lines, &mut i, &mut open_if);
            match (step, depth) {
                (Ok(None), _) => {}
                (Ok(Some(End::M30)), 0) | (Ok(Some(End::Ret)), 1..) if !open_if => return Ok(line),
                (Ok(Some(_)), _) if open_if => {
                    return Err(fail(frame, line, invalid("the program ends inside IF")));
                }
                (Ok(Some(End::M30)), _) => {
                    return Err(fail(frame, line, invalid("M30 in a subprogram")));
                }
                (Ok(Some(End::Ret)), _) => {
                    return Err(fail(frame, line, invalid("RET in the main program")));
                }
                (Err(Halt::Here(f)), _) => return Err(fail(frame, line, f)),
                (Err(Halt::Line(f, at)), _) => return Err(fail(frame, at, f)),
                (Err(Halt::Nested(e)), _) => return Err(e),
            }
        }
        let what = if depth == 0 { "M30" } else { "RET" };
        Err(fail(frame, lines.len(), ControlFault::NoEnd { what }))
    }

    /// One statement; `i` is the next line's index, moved on by `IF` and `CTABDEF`.
    fn dispatch(
        &mut self,
        code: &str,
        frame: &mut Frame,
        depth: usize,
        lines: &[&str],
        i: &mut usize,
        open_if: &mut bool,
    ) -> Step {
        let definition = ["DEF ", "EXTERN ", "PROC "]
            .iter()
            .any(|k| code.starts_with(k));
        if definition && frame.executed {
            return Err(
                invalid("DEF, EXTERN and PROC must come before the first statement").into(),
            );
        }
        frame.executed |= !definition;
        match code {
            "STOPRE" => Ok(None),
            "M30" => Ok(Some(End::M30)),
            "RET" => {
                if let (Some(name), Some(slot)) = (&frame.param, frame.argument.as_mut())
                    && let Some(value) = frame.vars.get(name)
                {
                    *slot = *value;
                }
                Ok(Some(End::Ret))
            }
            "ENDIF" if *open_if => {
                *open_if = false;
                Ok(None)
            }
            "ENDIF" => Err(invalid("ENDIF without IF").into()),
            _ if code.starts_with("IF ") => self.if_block(code, lines, i, open_if),
            _ if code.starts_with("CTABDEF(") => self.table(code, *i, lines, i),
            _ if code.starts_with("DEF ") => define(code, frame),
            _ if code.starts_with("EXTERN ") => declare(code, frame),
            _ if code.starts_with("PROC ") => proc_line(code, frame, depth),
            _ if code.starts_with("LEADON(") => self.leadon(code, frame),
            _ if code.starts_with("LEADOF(") => self.leadof(code),
            _ if code.starts_with("WAITP(") => Ok(args(code, "WAITP").map(|_| None)?),
            _ if code.starts_with("POS[") => self.pos(code),
            _ if code.starts_with('G') && code[1..].starts_with(|c: char| c.is_ascii_digit()) => {
                self.motion(code, frame)
            }
            _ => self.assignment_or_call(code, frame, depth),
        }
    }

    /// `IF $AA_COUP_ACT[X]<>0`: runs on, or skips to the matching `ENDIF`.
    fn if_block(&mut self, code: &str, lines: &[&str], i: &mut usize, open_if: &mut bool) -> Step {
        if *open_if {
            return Err(unsupported(code).into());
        }
        let axis = code
            .strip_prefix("IF $AA_COUP_ACT[")
            .and_then(|r| r.strip_suffix("]<>0"))
            .ok_or_else(|| unsupported(code))?;
        let active = match &self.control.coupling {
            Some(c) if c.following == axis => COUP_ACT_MASTER_VALUE,
            _ => 0,
        };
        if active != 0 {
            *open_if = true;
            return Ok(None);
        }
        while let Some(raw) = lines.get(*i) {
            *i += 1;
            let inner = raw.split(';').next().unwrap_or("").trim();
            if inner == "ENDIF" {
                return Ok(None);
            }
            if inner.starts_with("IF ") {
                return Err(Halt::Line(unsupported(inner), *i));
            }
        }
        Err(invalid("IF without ENDIF").into())
    }

    /// `CTABDEF(…)` … `CTABEND`: reads the blocks and stores the table under its number.
    fn table(&mut self, code: &str, line: usize, lines: &[&str], i: &mut usize) -> Step {
        let def = parse_ctabdef(code, line).map_err(|e| invalid(&e.reason))?;
        if def.periodicity != "1" {
            return Err(unsupported(code).into());
        }
        if self
            .control
            .coupling
            .as_ref()
            .is_some_and(|c| c.table == def.number)
        {
            return Err(ControlFault::TableInUse { number: def.number }.into());
        }
        let mut blocks = TableBlocks::new(def.following.clone(), def.leading.clone());
        while let Some(raw) = lines.get(*i) {
            *i += 1;
            let block = raw.split(';').next().unwrap_or("").trim();
            if block.is_empty() {
                continue;
            }
            if block == "CTABEND" {
                let (following_axis, leading_axis, shape) = blocks.finish();
                check_increasing(def.number, &shape).map_err(|f| Halt::Line(f, *i))?;
                let table = ParsedTable {
                    name: String::new(),
                    table_number: def.number,
                    following_axis,
                    leading_axis,
                    shape,
                };
                // An uncoupled table is replaced without warning [M].
                self.control.tables.insert(def.number, table);
                return Ok(None);
            }
            blocks
                .block(block, *i)
                .map_err(|e| Halt::Line(invalid(&e.reason), e.line))?;
        }
        Err(invalid("CTABDEF without CTABEND").into())
    }

    /// `LEADON(X,C,n)` with `n` a literal or an INT variable.
    fn leadon(&mut self, code: &str, frame: &Frame) -> Step {
        let a = args(code, "LEADON")?;
        let [following, leading, number] = a.as_slice() else {
            return Err(unsupported(code).into());
        };
        let number = table_number(int_arg(number, frame)?)?;
        let table = self
            .control
            .tables
            .get(&number)
            .ok_or(ControlFault::UndefinedTable {
                number: i64::from(number),
            })?;
        if table.following_axis != *following || table.leading_axis != *leading {
            return Err(invalid(&format!(
                "curve table {number} makes {} follow {}, not {following} follow {leading}",
                table.following_axis, table.leading_axis
            ))
            .into());
        }
        if self.control.coupling.is_some() {
            return Err(ControlFault::AlreadyCoupled {
                axis: (*following).to_owned(),
            }
            .into());
        }
        self.control.coupling = Some(Coupling {
            following: (*following).to_owned(),
            leading: (*leading).to_owned(),
            table: number,
        });
        Ok(None)
    }

    /// `LEADOF(X,C)`: ends the coupling of X to C, if any.
    fn leadof(&mut self, code: &str) -> Step {
        let a = args(code, "LEADOF")?;
        let [following, leading] = a.as_slice() else {
            return Err(unsupported(code).into());
        };
        if let Some(c) = &self.control.coupling
            && c.following == *following
            && c.leading == *leading
        {
            self.control.coupling = None;
        }
        Ok(None)
    }

    /// `POS[C]=IC(<deg>) FA[C]=<deg/min>`: turns C; while C leads a coupling, that is the
    /// grinding the run reports.
    fn pos(&mut self, code: &str) -> Step {
        let mut words = code.split_whitespace();
        let (Some(pos), Some(fa), None) = (words.next(), words.next(), words.next()) else {
            return Err(unsupported(code).into());
        };
        let parsed = pos
            .strip_prefix("POS[")
            .and_then(|r| r.split_once("]=IC("))
            .and_then(|(axis, r)| Some((axis, r.strip_suffix(')')?.parse::<f64>().ok()?)));
        let feed = fa
            .strip_prefix("FA[")
            .and_then(|r| r.split_once("]="))
            .and_then(|(axis, v)| Some((axis, v.parse::<f64>().ok()?)));
        let (Some((axis, travel_deg)), Some((fa_axis, feed_deg_min))) = (parsed, feed) else {
            return Err(unsupported(code).into());
        };
        if axis != fa_axis || !(travel_deg.is_finite() && feed_deg_min > 0.0) {
            return Err(unsupported(code).into());
        }
        if let Some(c) = &self.control.coupling
            && c.leading == axis
            && let Some(table) = self.control.tables.get(&c.table)
        {
            self.ground = Some(Coupled {
                table_number: c.table,
                shape: table_shape(&table.shape),
                c_speed_rpm: feed_deg_min / 360.0,
                revolutions: travel_deg / 360.0,
            });
        }
        *self.control.positions.entry(axis.to_owned()).or_default() += travel_deg;
        Ok(None)
    }

    /// `G90 G71` or `G90 G1 X=<var or number> F=<number>`.
    fn motion(&mut self, code: &str, frame: &Frame) -> Step {
        for word in code.split_whitespace() {
            if matches!(word, "G90" | "G71" | "G1") {
                continue;
            }
            let Some((address, value)) = word.split_once('=') else {
                return Err(unsupported(code).into());
            };
            if address == "F" {
                value.parse::<f64>().map_err(|_| unsupported(code))?;
                continue;
            }
            if !is_name(address) {
                return Err(unsupported(code).into());
            }
            if self
                .control
                .coupling
                .as_ref()
                .is_some_and(|c| c.following == address)
            {
                return Err(ControlFault::AxisCoupled {
                    axis: address.to_owned(),
                }
                .into());
            }
            let target = match value.parse::<f64>() {
                Ok(v) => v,
                Err(_) => real_var(value, frame)?,
            };
            self.control.positions.insert(address.to_owned(), target);
        }
        Ok(None)
    }

    /// `NAME=<value>` or a subprogram call `NAME` / `NAME(VAR)`.
    fn assignment_or_call(&mut self, code: &str, frame: &mut Frame, depth: usize) -> Step {
        let Some((target, value)) = code.split_once('=') else {
            return self.call(code, frame, depth);
        };
        let kind = *frame
            .vars
            .get(target)
            .ok_or_else(|| undefined_variable(target))?;
        let new = match kind {
            Value::Int(_) => Value::Int(value.parse().map_err(|_| unsupported(code))?),
            Value::Real(_) => Value::Real(self.real_value(code, value, frame)?),
        };
        frame.vars.insert(target.to_owned(), new);
        Ok(None)
    }

    /// `$AA_IW[<axis>]` or `CTAB(<real var>,<n>,<real var>)` (which also sets the slope).
    fn real_value(&self, code: &str, value: &str, frame: &mut Frame) -> Result<f64, Halt> {
        if let Some(axis) = value
            .strip_prefix("$AA_IW[")
            .and_then(|r| r.strip_suffix(']'))
        {
            return Ok(self.control.positions.get(axis).copied().unwrap_or(0.0));
        }
        let a = args(value, "CTAB").map_err(|_| unsupported(code))?;
        let [leading, number, slope] = a.as_slice() else {
            return Err(unsupported(code).into());
        };
        let c_deg = real_var(leading, frame)?;
        let number = table_number(int_arg(number, frame)?)?;
        let table = self
            .control
            .tables
            .get(&number)
            .ok_or(ControlFault::UndefinedTable {
                number: i64::from(number),
            })?;
        real_var(slope, frame)?;
        let x = |c: f64| table.x_at(c).unwrap_or(f64::NAN);
        // The slope dX/dC, mm per degree, by a central difference.
        let h = 1e-4;
        let gradient = (x(c_deg + h) - x(c_deg - h)) / (2.0 * h);
        frame
            .vars
            .insert((*slope).to_owned(), Value::Real(gradient));
        Ok(x(c_deg))
    }

    /// Calls `NAME` (no parameters) or `NAME(VAR)` (one `VAR INT`, declared by `EXTERN`).
    fn call(&mut self, code: &str, frame: &mut Frame, depth: usize) -> Step {
        let (name, argument) = match code.split_once('(') {
            Some((name, rest)) => {
                let var = rest.strip_suffix(')').ok_or_else(|| unsupported(code))?;
                (name, Some(var))
            }
            None => (code, None),
        };
        if !is_name(name) || argument.is_some_and(|v| !is_name(v)) {
            return Err(unsupported(code).into());
        }
        let declared = frame.externs.get(name).copied().unwrap_or(0);
        if declared != usize::from(argument.is_some()) {
            return Err(invalid(&format!(
                "{name} is called with {} arguments but declared with {declared} by EXTERN",
                usize::from(argument.is_some())
            ))
            .into());
        }
        let value = match argument {
            Some(v) => Some(*frame.vars.get(v).ok_or_else(|| undefined_variable(v))?),
            None => None,
        };
        if depth + 1 > MAX_CALL_DEPTH {
            return Err(invalid("subprograms nested too deep").into());
        }
        let text = (self.load)(name).ok_or_else(|| ControlFault::ProgramNotFound {
            name: name.to_owned(),
        })?;
        if program_name(&text, "SPF") != Some(name) {
            return Err(invalid(&format!(
                "program {name} does not start with %_N_{name}_SPF"
            ))
            .into());
        }
        let mut callee = Frame::new(name, value);
        self.program(&text, &mut callee, depth + 1)
            .map_err(Halt::Nested)?;
        if callee.argument.is_some() && callee.param.is_none() {
            return Err(invalid(&format!("{name} has no parameter for the argument")).into());
        }
        if let (Some(var), Some(returned)) = (argument, callee.argument) {
            frame.vars.insert(var.to_owned(), returned);
        }
        Ok(None)
    }
}

/// `DEF REAL a, b` / `DEF INT a`.
fn define(code: &str, frame: &mut Frame) -> Step {
    let rest = code.strip_prefix("DEF ").unwrap_or(code);
    let (value, names) = if let Some(names) = rest.strip_prefix("REAL ") {
        (Value::Real(0.0), names)
    } else if let Some(names) = rest.strip_prefix("INT ") {
        (Value::Int(0), names)
    } else {
        return Err(unsupported(code).into());
    };
    for name in names.split(',').map(str::trim) {
        if !is_name(name) || frame.vars.insert(name.to_owned(), value).is_some() {
            return Err(invalid(&format!("`{name}` cannot be defined here")).into());
        }
    }
    Ok(None)
}

/// `EXTERN NAME(VAR INT)` or `EXTERN NAME()`.
fn declare(code: &str, frame: &mut Frame) -> Step {
    let rest = code.strip_prefix("EXTERN ").unwrap_or(code);
    let (name, params) = rest
        .strip_suffix(')')
        .and_then(|r| r.split_once('('))
        .ok_or_else(|| unsupported(code))?;
    let count = match params.trim() {
        "" => 0,
        "VAR INT" => 1,
        _ => return Err(unsupported(code).into()),
    };
    if !is_name(name) {
        return Err(unsupported(code).into());
    }
    frame.externs.insert(name.to_owned(), count);
    Ok(None)
}

/// `PROC NAME` or `PROC NAME(VAR INT p)`, optionally ` SAVE`, first in a subprogram.
fn proc_line(code: &str, frame: &mut Frame, depth: usize) -> Step {
    let rest = code.strip_prefix("PROC ").unwrap_or(code);
    let rest = rest.strip_suffix(" SAVE").unwrap_or(rest);
    let (name, param) = match rest.split_once('(') {
        Some((name, p)) => {
            let p = p.strip_suffix(')').ok_or_else(|| unsupported(code))?;
            let p = p
                .strip_prefix("VAR INT ")
                .ok_or_else(|| unsupported(code))?;
            (name, Some(p.trim()))
        }
        None => (rest, None),
    };
    if depth == 0 || name != frame.program || param.is_some_and(|p| !is_name(p)) {
        return Err(unsupported(code).into());
    }
    if let Some(p) = param {
        let value = frame
            .argument
            .ok_or_else(|| invalid(&format!("{name} is called without an argument for {p}")))?;
        if !matches!(value, Value::Int(_)) {
            return Err(invalid(&format!("the argument for {p} is not an INT variable")).into());
        }
        frame.vars.insert(p.to_owned(), value);
        frame.param = Some(p.to_owned());
    }
    Ok(None)
}

/// The arguments of `KEYWORD(a,b,…)`, trimmed; the whole statement must be the call.
fn args<'t>(code: &'t str, keyword: &str) -> Result<Vec<&'t str>, ControlFault> {
    code.strip_prefix(keyword)
        .and_then(|r| r.strip_prefix('('))
        .and_then(|r| r.strip_suffix(')'))
        .map(|inner| inner.split(',').map(str::trim).collect())
        .ok_or_else(|| unsupported(code))
}

/// An integer literal or the value of an INT variable.
fn int_arg(text: &str, frame: &Frame) -> Result<i64, ControlFault> {
    if let Ok(n) = text.parse() {
        return Ok(n);
    }
    match frame.vars.get(text) {
        Some(Value::Int(n)) => Ok(*n),
        Some(Value::Real(_)) => Err(invalid(&format!("{text} is not an INT variable"))),
        None => Err(undefined_variable(text)),
    }
}

/// The value of a REAL variable.
fn real_var(text: &str, frame: &Frame) -> Result<f64, ControlFault> {
    match frame.vars.get(text) {
        Some(Value::Real(v)) => Ok(*v),
        Some(Value::Int(_)) => Err(invalid(&format!("{text} is not a REAL variable"))),
        None => Err(undefined_variable(text)),
    }
}

/// A curve table number: 1 or more.
fn table_number(n: i64) -> Result<u32, ControlFault> {
    u32::try_from(n)
        .ok()
        .filter(|&n| n >= 1)
        .ok_or(ControlFault::UndefinedTable { number: n })
}

/// The leading value must increase in every block (alarm 10949).
fn check_increasing(number: u32, shape: &ParsedShape) -> Result<(), ControlFault> {
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
fn is_name(text: &str) -> bool {
    let mut chars = text.chars();
    chars.next().is_some_and(|c| c.is_ascii_uppercase())
        && chars.all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
}

fn undefined_variable(name: &str) -> ControlFault {
    ControlFault::UndefinedVariable {
        name: name.to_owned(),
    }
}

fn unsupported(code: &str) -> ControlFault {
    ControlFault::Unsupported {
        statement: code.to_owned(),
    }
}

fn invalid(reason: &str) -> ControlFault {
    ControlFault::Invalid {
        reason: reason.to_owned(),
    }
}
