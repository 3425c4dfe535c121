//! The interpreter: runs one program level statement by statement, resolves subprogram
//! calls, and keeps the curve tables and the coupling in the [`super::Control`].

use super::statements::{
    End, Frame, Halt, Run, Step, Value, args, check_increasing, declare, define, int_arg, invalid,
    is_name, proc_line, real_var, table_number, undefined_variable, unsupported,
};
use super::{
    AXIAL_AXIS, C_AXIS, COUP_ACT_MASTER_VALUE, ControlError, ControlFault, Coupled, Coupling,
    MAX_CALL_DEPTH, program_name, r_param, table_shape,
};
use camloop_core::program::{ParsedTable, TableBlocks, parse_ctabdef};

/// Words that are statements, never subprogram names: out of place, they are refused as
/// statements rather than looked up as programs.
const KEYWORDS: [&str; 8] = [
    "CTABEND", "POLY", "ENDIF", "ELSE", "M17", "M2", "SAVE", "CTABDEL",
];

impl Run<'_> {
    /// Table `number` from the control's memory; coupling or reading an undefined one is
    /// the control's alarm.
    fn defined_table(&self, number: u32) -> Result<&ParsedTable, ControlFault> {
        self.control
            .tables
            .get(&number)
            .ok_or(ControlFault::UndefinedTable {
                number: i64::from(number),
            })
    }

    /// Runs `text` in `frame` to its `M30` (depth 0) or `RET`; returns that line.
    pub(super) fn program(
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
                for (name, slot) in frame.params.iter().zip(frame.arguments.iter_mut()) {
                    if let Some(value) = frame.vars.get(name) {
                        *slot = *value;
                    }
                }
                Ok(Some(End::Ret))
            }
            "ENDIF" if *open_if => {
                *open_if = false;
                Ok(None)
            }
            "ENDIF" => Err(invalid("ENDIF without IF").into()),
            _ if code.starts_with("IF ") => self.if_block(code, frame, lines, i, open_if),
            _ if code.starts_with("CTABDEF(") => self.table(code, &frame.program, lines, i),
            _ if code.starts_with("DEF ") => define(code, frame),
            _ if code.starts_with("EXTERN ") => declare(code, frame),
            _ if code.starts_with("PROC ") => proc_line(code, frame, depth),
            _ if code.starts_with("LEADON(") => self.leadon(code, frame),
            _ if code.starts_with("LEADOF(") => self.leadof(code),
            _ if code.starts_with("WAITP(") => Ok(args(code, "WAITP").map(|_| None)?),
            _ if code.starts_with("POS[") => self.pos(code, frame),
            _ if code.starts_with('G') && code[1..].starts_with(|c: char| c.is_ascii_digit()) => {
                self.motion(code, frame)
            }
            _ => self.assignment_or_call(code, frame, depth),
        }
    }

    /// `IF $AA_COUP_ACT[X]<>0` or `IF <INT variable><=<integer>`: runs on, or skips to the
    /// matching `ENDIF`.
    fn if_block(
        &mut self,
        code: &str,
        frame: &Frame,
        lines: &[&str],
        i: &mut usize,
        open_if: &mut bool,
    ) -> Step {
        if *open_if {
            return Err(unsupported(code).into());
        }
        let holds = if let Some(axis) = code
            .strip_prefix("IF $AA_COUP_ACT[")
            .and_then(|r| r.strip_suffix("]<>0"))
        {
            self.control.couplings.iter().any(|c| c.following == axis) && COUP_ACT_MASTER_VALUE != 0
        } else {
            self.condition(code, frame)?
        };
        if holds {
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

    /// `IF <INT variable or R parameter><op><integer>`, op one of `<=`, `<`, `>`, `==`,
    /// `<>`.
    fn condition(&self, code: &str, frame: &Frame) -> Result<bool, Halt> {
        let rest = code.strip_prefix("IF ").ok_or_else(|| unsupported(code))?;
        let (left, op, right) = ["<=", "<>", "==", "<", ">"]
            .iter()
            .find_map(|op| rest.split_once(op).map(|(l, r)| (l.trim(), *op, r.trim())))
            .ok_or_else(|| unsupported(code))?;
        let bound: f64 = right.parse().map_err(|_| unsupported(code))?;
        let value = match r_param(left) {
            Some(n) => self.control.r_param(n),
            None => int_arg(left, frame)? as f64,
        };
        Ok(match op {
            "<=" => value <= bound,
            "<>" => value != bound,
            "==" => value == bound,
            "<" => value < bound,
            _ => value > bound,
        })
    }

    /// `CTABDEF(…)` … `CTABEND`: reads the blocks and stores the table under its number.
    fn table(&mut self, code: &str, program: &str, lines: &[&str], i: &mut usize) -> Step {
        let def = parse_ctabdef(code, *i).map_err(|e| invalid(&e.reason))?;
        // 2: periodic in both axes, as the speed plan's C = f(VA) is written.
        if !matches!(def.periodicity.as_str(), "1" | "2") {
            return Err(unsupported(code).into());
        }
        if self.control.couplings.iter().any(|c| c.table == def.number) {
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
                    name: program.to_owned(),
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
        let table = self.defined_table(number)?;
        if table.following_axis != *following || table.leading_axis != *leading {
            return Err(invalid(&format!(
                "curve table {number} makes {} follow {}, not {following} follow {leading}",
                table.following_axis, table.leading_axis
            ))
            .into());
        }
        if self
            .control
            .couplings
            .iter()
            .any(|c| c.following == *following)
        {
            return Err(ControlFault::AlreadyCoupled {
                axis: (*following).to_owned(),
            }
            .into());
        }
        self.control.couplings.push(Coupling {
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
        self.control
            .couplings
            .retain(|c| !(c.following == *following && c.leading == *leading));
        Ok(None)
    }

    /// `POS[<axis>]=IC(<deg>) FA[<axis>]=<deg/min>` turns an axis by an increment (while it
    /// leads the coupling of X, that is the grinding the run reports);
    /// `POS[<axis>]=DC(<var or deg>) …` takes an uncoupled rotary axis to a position the
    /// shortest way.
    fn pos(&mut self, code: &str, frame: &Frame) -> Step {
        let mut words = code.split_whitespace();
        let (Some(pos), Some(fa), None) = (words.next(), words.next(), words.next()) else {
            return Err(unsupported(code).into());
        };
        let target = pos.strip_prefix("POS[").and_then(|r| r.split_once("]="));
        let feed = fa
            .strip_prefix("FA[")
            .and_then(|r| r.split_once("]="))
            .and_then(|(axis, v)| Some((axis, v.parse::<f64>().ok()?)));
        let (Some((axis, value)), Some((fa_axis, feed_deg_min))) = (target, feed) else {
            return Err(unsupported(code).into());
        };
        if axis != fa_axis || feed_deg_min.is_nan() || feed_deg_min <= 0.0 {
            return Err(unsupported(code).into());
        }
        if let Some(inner) = value.strip_prefix("DC(").and_then(|r| r.strip_suffix(')')) {
            return self.pos_direct(code, axis, inner, frame);
        }
        let travel_deg = value
            .strip_prefix("IC(")
            .and_then(|r| r.strip_suffix(')')?.parse::<f64>().ok())
            .filter(|t| t.is_finite())
            .ok_or_else(|| unsupported(code))?;
        if let Some(grind) = self.grind(axis, feed_deg_min, travel_deg) {
            // C follows a virtual axis one revolution per revolution of it.
            if grind.c_law.is_some() {
                *self.control.positions.entry(C_AXIS.to_owned()).or_default() += travel_deg;
            }
            self.ground.push(grind);
        }
        *self.control.positions.entry(axis.to_owned()).or_default() += travel_deg;
        Ok(None)
    }

    /// `POS[<axis>]=DC(…)`: the shortest way to the target, modulo 360°.
    fn pos_direct(&mut self, code: &str, axis: &str, target: &str, frame: &Frame) -> Step {
        let target_deg = match target.parse::<f64>() {
            Ok(v) => v,
            Err(_) => real_var(target, frame)?,
        };
        if !target_deg.is_finite() {
            return Err(unsupported(code).into());
        }
        if self.control.couplings.iter().any(|c| c.following == axis) {
            return Err(ControlFault::AxisCoupled {
                axis: axis.to_owned(),
            }
            .into());
        }
        let now = self.control.positions.get(axis).copied().unwrap_or(0.0);
        let mut step = (target_deg - now).rem_euclid(360.0);
        if step > 180.0 {
            step -= 360.0;
        }
        self.control.positions.insert(axis.to_owned(), now + step);
        Ok(None)
    }

    /// What turning `leading` grinds: X coupled to it, and C turning, either as the leading
    /// axis itself or following it by its own table (the speed plan's virtual axis).
    fn grind(&self, leading: &str, feed_deg_min: f64, travel_deg: f64) -> Option<Coupled> {
        let led = |c: &&Coupling| c.leading == leading;
        let c_table = self
            .control
            .couplings
            .iter()
            .filter(led)
            .find(|c| c.following == C_AXIS);
        if leading != C_AXIS && c_table.is_none() {
            return None;
        }
        let x = self
            .control
            .couplings
            .iter()
            .filter(led)
            .find(|c| c.following != C_AXIS)?;
        let table = self.control.tables.get(&x.table)?;
        let c_law = c_table
            .and_then(|c| self.control.tables.get(&c.table))
            .map(|t| table_shape(&t.shape));
        Some(Coupled {
            table_number: x.table,
            defined_by: table.name.clone(),
            z_mm: self
                .control
                .positions
                .get(AXIAL_AXIS)
                .copied()
                .unwrap_or(0.0),
            shape: table_shape(&table.shape),
            c_table_number: c_table.map(|c| c.table),
            c_law,
            c_speed_rpm: feed_deg_min / 360.0,
            revolutions: travel_deg / 360.0,
        })
    }

    /// `G90 G71`, `G90 G1 X=<var or number> F=<number>` or `G0 <axis>=<number>`.
    fn motion(&mut self, code: &str, frame: &Frame) -> Step {
        for word in code.split_whitespace() {
            if matches!(word, "G90" | "G71" | "G1" | "G0") {
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
                .couplings
                .iter()
                .any(|c| c.following == address)
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
        if let Some(n) = r_param(target) {
            let v: f64 = value.trim().parse().map_err(|_| unsupported(code))?;
            self.control.r_params.insert(n, v);
            return Ok(None);
        }
        let kind = *frame
            .vars
            .get(target)
            .ok_or_else(|| undefined_variable(target))?;
        let new = match kind {
            // A REAL (an R parameter) assigned to an INT is rounded, as the control does.
            Value::Int(_) => Value::Int(match r_param(value) {
                Some(n) => self.control.r_param(n).round() as i64,
                None => value.parse().map_err(|_| unsupported(code))?,
            }),
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
        let c_deg = match leading.parse::<f64>() {
            Ok(v) => v,
            Err(_) => real_var(leading, frame)?,
        };
        let number = table_number(int_arg(number, frame)?)?;
        let table = self.defined_table(number)?;
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

    /// Calls `NAME` (no parameters) or `NAME(VAR, …)` (`VAR INT` parameters, declared by
    /// `EXTERN`).
    fn call(&mut self, code: &str, frame: &mut Frame, depth: usize) -> Step {
        let (name, arguments): (&str, Vec<&str>) = match code.split_once('(') {
            Some((name, rest)) => {
                let vars = rest.strip_suffix(')').ok_or_else(|| unsupported(code))?;
                (name, vars.split(',').map(str::trim).collect())
            }
            None => (code, Vec::new()),
        };
        if !is_name(name) || KEYWORDS.contains(&name) || arguments.iter().any(|v| !is_name(v)) {
            return Err(unsupported(code).into());
        }
        let declared = frame.externs.get(name).copied().unwrap_or(0);
        if declared != arguments.len() {
            return Err(invalid(&format!(
                "{name} is called with {} arguments but declared with {declared} by EXTERN",
                arguments.len()
            ))
            .into());
        }
        let values = arguments
            .iter()
            .map(|v| {
                frame
                    .vars
                    .get(*v)
                    .copied()
                    .ok_or_else(|| undefined_variable(v))
            })
            .collect::<Result<Vec<Value>, ControlFault>>()?;
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
        let mut callee = Frame::new(name, values);
        self.program(&text, &mut callee, depth + 1)
            .map_err(Halt::Nested)?;
        if !callee.arguments.is_empty() && callee.params.is_empty() {
            return Err(invalid(&format!("{name} has no parameter for the argument")).into());
        }
        for (var, returned) in arguments.iter().zip(callee.arguments) {
            frame.vars.insert((*var).to_owned(), returned);
        }
        Ok(None)
    }
}
