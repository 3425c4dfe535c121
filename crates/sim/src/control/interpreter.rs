//! The interpreter: runs one program level statement by statement, resolves subprogram
//! calls, and keeps the curve tables and the coupling in the [`super::Control`].

use super::statements::{
    End, Frame, Halt, Run, Step, Value, check_increasing, declare, define, int_arg, invalid,
    is_name, proc_line, real_arg, real_var, table_number, undefined_variable, unsupported,
};
use super::{
    AXIAL_AXIS, C_AXIS, COUP_ACT_MASTER_VALUE, ControlError, ControlFault, Coupled, Coupling,
    MAX_CALL_DEPTH, program_name, r_param, table_shape,
};
use camloop_core::program::syntax::{Cond, CtabDef, Expr, Line, Statement, Word, lines};
use camloop_core::program::{ParsedTable, TableBlocks};

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
        let lines: Vec<Line> = lines(text).collect();
        let fail = |frame: &Frame, line: usize, fault| ControlError {
            program: frame.program.clone(),
            line,
            fault,
        };
        let (mut i, mut open_if) = (0, false);
        while i < lines.len() {
            let current = lines[i];
            let line = current.number;
            i += 1;
            let statement = match current.statement() {
                Ok(Some(Statement::Header { .. })) if line == 1 => continue,
                Ok(Some(statement)) => statement,
                Ok(None) => continue,
                Err(e) => return Err(fail(frame, line, syntax(e))),
            };
            let at = At {
                code: current.code,
                lines: &lines,
            };
            let step = self.dispatch(&statement, at, frame, depth, &mut i, &mut open_if);
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
        statement: &Statement<'_>,
        at: At<'_, '_>,
        frame: &mut Frame,
        depth: usize,
        i: &mut usize,
        open_if: &mut bool,
    ) -> Step {
        let code = at.code;
        let definition = matches!(
            statement,
            Statement::Def { .. } | Statement::Extern { .. } | Statement::Proc { .. }
        );
        if definition && frame.executed {
            return Err(
                invalid("DEF, EXTERN and PROC must come before the first statement").into(),
            );
        }
        frame.executed |= !definition;
        if let Some(step) = self.cycle_statement(statement, code, at.lines, frame, i) {
            return step;
        }
        match statement {
            Statement::Keyword("STOPRE") => Ok(None),
            Statement::Keyword("M30") => Ok(Some(End::M30)),
            Statement::Keyword("RET") => {
                for (name, slot) in frame.params.iter().zip(frame.arguments.iter_mut()) {
                    if let Some(value) = frame.vars.get(name) {
                        *slot = *value;
                    }
                }
                Ok(Some(End::Ret))
            }
            Statement::Keyword("ENDIF") if *open_if => {
                *open_if = false;
                Ok(None)
            }
            Statement::Keyword("ENDIF") => Err(invalid("ENDIF without IF").into()),
            Statement::If { cond, goto: None } => self.if_block(code, cond, frame, at, i, open_if),
            Statement::CtabDef(def) => self.table(code, def, &frame.program, at.lines, i),
            Statement::Def { kind, names } => define(code, kind, names, frame),
            Statement::Extern { name, params } => declare(code, name, params, frame),
            Statement::Proc { name, params, .. } => proc_line(code, name, params, frame, depth),
            Statement::Call {
                name: "LEADON",
                args,
            } => self.leadon(code, args, frame),
            Statement::Call {
                name: "LEADOF",
                args,
            } => self.leadof(code, args),
            Statement::Call { name: "WAITP", .. } => Ok(None),
            Statement::Block(words)
                if matches!(words.first(), Some(Word::Set { index: Some(_), .. })) =>
            {
                self.pos(code, words, frame)
            }
            Statement::Block(words) if words.first().is_some_and(Word::is_g_code) => {
                self.motion(code, words, frame)
            }
            Statement::Assign { target, value } => self.assignment(code, target, value, frame),
            Statement::Call { name, args } => self.call(code, name, args, frame, depth),
            Statement::Keyword(name) => self.call(code, name, &[], frame, depth),
            _ => Err(unsupported(code).into()),
        }
    }

    /// `IF $AA_COUP_ACT[X]<>0` or `IF <INT variable><=<integer>`: runs on, or skips to the
    /// matching `ENDIF`.
    fn if_block(
        &mut self,
        code: &str,
        cond: &Cond<'_>,
        frame: &Frame,
        at: At<'_, '_>,
        i: &mut usize,
        open_if: &mut bool,
    ) -> Step {
        if *open_if {
            return Err(unsupported(code).into());
        }
        let holds = match (&cond.left, cond.op, cond.right.number()) {
            (Expr::Indexed("$AA_COUP_ACT", axis), "<>", Some(0.0)) => {
                self.control.couplings.iter().any(|c| c.following == *axis)
                    && COUP_ACT_MASTER_VALUE != 0
            }
            _ => self.condition(code, cond, frame)?,
        };
        if holds {
            *open_if = true;
            return Ok(None);
        }
        // Skipped lines are not run; only where the block ends matters.
        while let Some(line) = at.lines.get(*i) {
            *i += 1;
            match line.statement() {
                Ok(Some(Statement::Keyword("ENDIF"))) => return Ok(None),
                Ok(Some(Statement::If { .. })) => {
                    return Err(Halt::Line(unsupported(line.code), line.number));
                }
                _ => {}
            }
        }
        Err(invalid("IF without ENDIF").into())
    }

    /// `IF <INT variable or R parameter><op><number>`.
    pub(super) fn condition(
        &self,
        code: &str,
        cond: &Cond<'_>,
        frame: &Frame,
    ) -> Result<bool, Halt> {
        let (Some(left), Some(bound)) = (cond.left.name(), cond.right.number()) else {
            return Err(unsupported(code).into());
        };
        let value = match r_param(left) {
            Some(n) => self.control.r_param(n),
            None => int_arg(&cond.left, frame)? as f64,
        };
        Ok(cond.holds(value, bound))
    }

    /// `CTABDEF(…)` … `CTABEND`: reads the blocks and stores the table under its number.
    fn table(
        &mut self,
        code: &str,
        def: &CtabDef,
        program: &str,
        lines: &[Line<'_>],
        i: &mut usize,
    ) -> Step {
        // 2: periodic in both axes, as the speed plan's C = f(VA) is written.
        if !matches!(def.periodicity.as_str(), "1" | "2") {
            return Err(unsupported(code).into());
        }
        if self.control.couplings.iter().any(|c| c.table == def.number) {
            return Err(ControlFault::TableInUse { number: def.number }.into());
        }
        let mut blocks = TableBlocks::new(def.following.clone(), def.leading.clone());
        while let Some(line) = lines.get(*i) {
            *i += 1;
            let statement = match line.statement() {
                Ok(Some(s)) => s,
                Ok(None) => continue,
                Err(e) => return Err(Halt::Line(syntax(e), line.number)),
            };
            if statement == Statement::Keyword("CTABEND") {
                let (following_axis, leading_axis, shape) = blocks.finish();
                check_increasing(def.number, &shape).map_err(|f| Halt::Line(f, line.number))?;
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
                .block(line, &statement)
                .map_err(|e| Halt::Line(invalid(&e.reason), e.line))?;
        }
        Err(invalid("CTABDEF without CTABEND").into())
    }

    /// `LEADON(X,C,n)` with `n` a literal or an INT variable.
    fn leadon(&mut self, code: &str, args: &[Expr<'_>], frame: &Frame) -> Step {
        let [following, leading, number] = args else {
            return Err(unsupported(code).into());
        };
        let (Some(following), Some(leading)) = (following.name(), leading.name()) else {
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
            .any(|c| c.following == following)
        {
            return Err(ControlFault::AlreadyCoupled {
                axis: following.to_owned(),
            }
            .into());
        }
        self.control.overlay_mm = 0.0;
        self.control.couplings.push(Coupling {
            following: following.to_owned(),
            leading: leading.to_owned(),
            table: number,
        });
        Ok(None)
    }

    /// `LEADOF(X,C)`: ends the coupling of X to C, if any.
    fn leadof(&mut self, code: &str, args: &[Expr<'_>]) -> Step {
        let [Expr::Var(following), Expr::Var(leading)] = args else {
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
    fn pos(&mut self, code: &str, words: &[Word<'_>], frame: &Frame) -> Step {
        let [
            Word::Set {
                address: "POS",
                index: Some(axis),
                value,
            },
            Word::Set {
                address: "FA",
                index: Some(fa_axis),
                value: feed,
            },
        ] = words
        else {
            return Err(unsupported(code).into());
        };
        let feed_deg_min = feed.number().unwrap_or(f64::NAN);
        if axis != fa_axis || feed_deg_min.is_nan() || feed_deg_min <= 0.0 {
            return Err(unsupported(code).into());
        }
        let travel_deg = match value {
            Expr::Call("DC", target) => return self.pos_direct(code, axis, target, frame),
            Expr::Call("IC", travel) => match travel.as_slice() {
                [t] => t.number().filter(|t| t.is_finite()),
                _ => None,
            },
            _ => None,
        }
        .ok_or_else(|| unsupported(code))?;
        if let Some(grind) = self.grind(axis, feed_deg_min, travel_deg) {
            // C follows a virtual axis one revolution per revolution of it.
            if grind.c_law.is_some() {
                *self.control.positions.entry(C_AXIS.to_owned()).or_default() += travel_deg;
            }
            self.ground.push(grind);
        }
        *self
            .control
            .positions
            .entry((*axis).to_owned())
            .or_default() += travel_deg;
        Ok(None)
    }

    /// `POS[<axis>]=DC(…)`: the shortest way to the target, modulo 360°.
    fn pos_direct(&mut self, code: &str, axis: &str, target: &[Expr<'_>], frame: &Frame) -> Step {
        let [target] = target else {
            return Err(unsupported(code).into());
        };
        let target_deg = real_arg(target, frame)?;
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
    pub(super) fn grind(
        &self,
        leading: &str,
        feed_deg_min: f64,
        travel_deg: f64,
    ) -> Option<Coupled> {
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
            x_offset_mm: 0.0,
            x_infeed_mm: 0.0,
        })
    }

    /// `G90 G71`, `G90 G1 X=<var or number> F=<number>` or `G0 <axis>=<number>`.
    fn motion(&mut self, code: &str, words: &[Word<'_>], frame: &Frame) -> Step {
        for word in words {
            let (address, value) = match word {
                Word::Code("G90" | "G71" | "G1" | "G0") => continue,
                Word::Set {
                    address,
                    index: None,
                    value,
                } => (*address, value),
                _ => return Err(unsupported(code).into()),
            };
            if address == "F" {
                value.number().ok_or_else(|| unsupported(code))?;
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
            let target = real_arg(value, frame)?;
            self.control.positions.insert(address.to_owned(), target);
        }
        Ok(None)
    }

    /// `NAME=<value>`: an R parameter, an INT or a REAL variable.
    fn assignment(
        &mut self,
        code: &str,
        target: &str,
        value: &Expr<'_>,
        frame: &mut Frame,
    ) -> Step {
        if let Some(n) = r_param(target) {
            let v = value.number().ok_or_else(|| unsupported(code))?;
            self.control.r_params.insert(n, v);
            return Ok(None);
        }
        let kind = *frame
            .vars
            .get(target)
            .ok_or_else(|| undefined_variable(target))?;
        let new = match kind {
            // A REAL (an R parameter) assigned to an INT is rounded, as the control does.
            Value::Int(_) => Value::Int(match value.name().and_then(r_param) {
                Some(n) => self.control.r_param(n).round() as i64,
                None => value
                    .number()
                    .filter(|v| v.fract() == 0.0 && v.abs() < 1e15)
                    .ok_or_else(|| unsupported(code))? as i64,
            }),
            Value::Real(_) => Value::Real(self.real_value(code, value, frame)?),
        };
        frame.vars.insert(target.to_owned(), new);
        Ok(None)
    }

    /// `$AA_IW[<axis>]` or `CTAB(<real var>,<n>,<real var>)` (which also sets the slope).
    fn real_value(&self, code: &str, value: &Expr<'_>, frame: &mut Frame) -> Result<f64, Halt> {
        let args = match value {
            Expr::Indexed("$AA_IW", axis) => {
                return Ok(self.control.positions.get(*axis).copied().unwrap_or(0.0));
            }
            Expr::Call("CTAB", args) => args,
            _ => return Err(unsupported(code).into()),
        };
        let [leading, number, Expr::Var(slope)] = args.as_slice() else {
            return Err(unsupported(code).into());
        };
        let c_deg = real_arg(leading, frame)?;
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
    fn call(
        &mut self,
        code: &str,
        name: &str,
        args: &[Expr<'_>],
        frame: &mut Frame,
        depth: usize,
    ) -> Step {
        let arguments: Vec<&str> = args.iter().filter_map(Expr::name).collect();
        let all_names = arguments.len() == args.len() && arguments.iter().all(|v| is_name(v));
        if !is_name(name) || KEYWORDS.contains(&name) || !all_names {
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

/// Where a statement stands: its code (for messages) and its program's lines (`IF` and
/// `CTABDEF` read on).
#[derive(Clone, Copy)]
struct At<'a, 't> {
    code: &'t str,
    lines: &'a [Line<'t>],
}

/// A line the reader cannot read, as the run's fault.
fn syntax(e: camloop_core::program::SyntaxError) -> ControlFault {
    ControlFault::Syntax {
        column: e.column,
        reason: e.reason,
    }
}
