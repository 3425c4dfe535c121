//! The statements of the whole grinding cycle (`[cycle] program = "whole"`): the wheel
//! spindle and coolant, the coupling's output offset (SD43106), `FGROUP`, incremental
//! blocks that turn C with X's infeed superimposed on the coupled X (the overlay, which
//! the control allows only with the axis' overlay enabled, DBX26.4), dwells, labels with
//! `IF … GOTOF/GOTOB`, and REAL/INT sums. Each leaves a [`CycleEvent`] in the run.

use super::statements::{Frame, Halt, Run, Step, Value, invalid, is_name, unsupported};
use super::{C_AXIS, ControlFault};
use camloop_core::program::OUTPUT_OFFSET;
use camloop_core::program::syntax::{Cond, Expr, Line, Statement, Word};

/// Most jumps one run may make: a wait that never ends is a fault, not a hang.
const MAX_JUMPS: usize = 100_000;

/// What a cycle run did, in program order.
#[derive(Debug, Clone, PartialEq)]
pub enum CycleEvent {
    /// `M<n>=3 S<n>=…` / `S<n>=…` / `M<n>=5`: a spindle's speed (0: stopped), rpm.
    Spindle { spindle: u32, rpm: f64 },
    /// `M8` / `M9`.
    Coolant(bool),
    /// Another M function for the PLC (the gauge's in and out).
    MFunction(u32),
    /// C turned by `revolutions` with nothing coupled to it (a measurement).
    Turned { revolutions: f64, c_speed_rpm: f64 },
    /// The index into the run's grinds of a grind (C turning with X coupled).
    Ground(usize),
    /// `G4 F=…`, s.
    Dwell(f64),
}

impl Run<'_> {
    /// The cycle's statements; `None` for a statement the table-only subset handles.
    pub(super) fn cycle_statement(
        &mut self,
        statement: &Statement<'_>,
        code: &str,
        lines: &[Line<'_>],
        frame: &mut Frame,
        i: &mut usize,
    ) -> Option<Step> {
        Some(match statement {
            Statement::Label(_) => Ok(None),
            Statement::If {
                cond,
                goto: Some((direction, label)),
            } => self.goto(code, cond, direction, label, lines, frame, i),
            Statement::Keyword("M8") => self.event(CycleEvent::Coolant(true)),
            Statement::Keyword("M9") => self.event(CycleEvent::Coolant(false)),
            Statement::Keyword(m) if m_number(m).is_some() => {
                self.event(CycleEvent::MFunction(m_number(m)?))
            }
            Statement::Call {
                name: "FGROUP",
                args,
            } => match args.as_slice() {
                [Expr::Var(C_AXIS)] | [] => Ok(None),
                // The virtual axis that leads X on the speed plan.
                [Expr::Var(axis)] if self.control.couplings.iter().any(|c| c.leading == *axis) => {
                    Ok(None)
                }
                _ => Err(unsupported(code).into()),
            },
            Statement::Assign { target, value } if spindle_number(target, 'S').is_some() => {
                let rpm = value.number().ok_or_else(|| unsupported(code));
                rpm.map_err(Halt::from).and_then(|rpm| {
                    self.event(CycleEvent::Spindle {
                        spindle: spindle_number(target, 'S').unwrap_or(0),
                        rpm,
                    })
                })
            }
            // `M<n>=5` alone: the spindle stops.
            Statement::Assign { target, value } if spindle_number(target, 'M').is_some() => {
                match value.number() {
                    Some(5.0) => self.event(CycleEvent::Spindle {
                        spindle: spindle_number(target, 'M').unwrap_or(0),
                        rpm: 0.0,
                    }),
                    _ => Err(unsupported(code).into()),
                }
            }
            Statement::Assign { target, value } if needs_sum(value, frame, target) => {
                self.sum(code, target, value, frame)
            }
            Statement::Block(words) => return self.cycle_block(code, words, frame),
            _ => return None,
        })
    }

    fn event(&mut self, event: CycleEvent) -> Step {
        self.events.push(event);
        Ok(None)
    }

    /// `IF <cond> GOTOF|GOTOB <label>`: on to the line after the label when it holds.
    #[allow(clippy::too_many_arguments)]
    fn goto(
        &mut self,
        code: &str,
        cond: &Cond<'_>,
        direction: &str,
        label: &str,
        lines: &[Line<'_>],
        frame: &Frame,
        i: &mut usize,
    ) -> Step {
        if !self.condition(code, cond, frame)? {
            return Ok(None);
        }
        self.jumps += 1;
        if self.jumps > MAX_JUMPS {
            return Err(invalid(&format!(
                "more than {MAX_JUMPS} jumps: the program does not end"
            ))
            .into());
        }
        let is_label =
            |l: &Line<'_>| matches!(l.statement(), Ok(Some(Statement::Label(n))) if n == label);
        let found = match direction {
            "GOTOF" => lines[*i..].iter().position(is_label).map(|k| *i + k),
            "GOTOB" => lines[..*i].iter().rposition(is_label),
            _ => return Err(unsupported(code).into()),
        };
        match found {
            Some(k) => {
                *i = k + 1;
                Ok(None)
            }
            None => Err(invalid(&format!("label {label} not found ({direction})")).into()),
        }
    }

    /// `NAME=a+b` / `NAME=a-b` of variables and numbers, or a number into a REAL.
    fn sum(&mut self, code: &str, target: &str, value: &Expr<'_>, frame: &mut Frame) -> Step {
        let v = eval(value, frame).ok_or_else(|| unsupported(code))?;
        let new = match frame.vars.get(target) {
            Some(Value::Real(_)) => Value::Real(v),
            Some(Value::Int(_)) if v.fract() == 0.0 && v.abs() < 1e15 => Value::Int(v as i64),
            Some(Value::Int(_)) => {
                return Err(invalid(&format!("{target} is an INT, {v} is not whole")).into());
            }
            None => return Err(super::statements::undefined_variable(target).into()),
        };
        frame.vars.insert(target.to_owned(), new);
        Ok(None)
    }

    /// Blocks of the cycle; `None` for the table-only subset's (`G90 G1 X=…`, `POS[C]=…`).
    fn cycle_block(&mut self, code: &str, words: &[Word<'_>], frame: &Frame) -> Option<Step> {
        let codes: Vec<&str> = words
            .iter()
            .filter_map(|w| match w {
                Word::Code(c) => Some(*c),
                Word::Set { .. } => None,
            })
            .collect();
        let sets: Vec<(&str, Option<&str>, &Expr<'_>)> = words
            .iter()
            .filter_map(|w| match w {
                Word::Set {
                    address,
                    index,
                    value,
                } => Some((*address, *index, value)),
                Word::Code(_) => None,
            })
            .collect();
        if sets.is_empty() && codes.iter().all(|c| ["G90", "G94", "G71"].contains(c)) {
            return Some(Ok(None));
        }
        if let [(OUTPUT_OFFSET, Some(axis), value)] = sets.as_slice() {
            return Some(self.output_offset(code, axis, value, frame));
        }
        if let Some((m, _, _)) = sets.first()
            && spindle_number(m, 'M').is_some()
        {
            return Some(self.spindle(code, &sets));
        }
        if codes.first() == Some(&"G4") {
            return Some(match sets.as_slice() {
                [("F", None, v)] => match v.number().filter(|s| *s >= 0.0) {
                    Some(s) => self.event(CycleEvent::Dwell(s)),
                    None => Err(unsupported(code).into()),
                },
                _ => Err(unsupported(code).into()),
            });
        }
        if codes.first() == Some(&"G91") {
            return Some(self.incremental(code, &codes[1..], &sets));
        }
        if let Some(("POS", Some(axis), Expr::Call("IC", travel))) = sets.first().copied()
            && !self.control.couplings.iter().any(|c| c.leading == axis)
        {
            // Turning C with nothing coupled: a measurement. The subset's POS runs it.
            let feed = sets.get(1).and_then(|s| s.2.number()).unwrap_or(0.0);
            let travel = travel.first().and_then(Expr::number).unwrap_or(0.0);
            self.events.push(CycleEvent::Turned {
                revolutions: travel / 360.0,
                c_speed_rpm: feed / 360.0,
            });
        }
        None
    }

    /// `$SA_LEAD_OFFSET_OUT_POS[X]=<REAL var or number>`: X couples this far off its curve.
    fn output_offset(&mut self, code: &str, axis: &str, value: &Expr<'_>, frame: &Frame) -> Step {
        let v = eval(value, frame).ok_or_else(|| unsupported(code))?;
        if self.control.couplings.iter().any(|c| c.following == axis) {
            // Not modelled: a change of the offset while coupled; camloop never writes one.
            return Err(invalid("the output offset changes only while uncoupled").into());
        }
        self.control.output_offset_mm.insert(axis.to_owned(), v);
        Ok(None)
    }

    /// `M<n>=3 S<n>=<rpm>` or `M<n>=5`.
    fn spindle(&mut self, code: &str, sets: &[(&str, Option<&str>, &Expr<'_>)]) -> Step {
        let n = spindle_number(sets[0].0, 'M').unwrap_or(0);
        let s_name = format!("S{n}");
        let rpm = match (sets[0].2.number(), sets.get(1)) {
            (Some(3.0), Some((s, None, v))) if *s == s_name && sets.len() == 2 => {
                v.number().filter(|r| *r > 0.0)
            }
            (Some(5.0), None) => Some(0.0),
            _ => None,
        }
        .ok_or_else(|| unsupported(code))?;
        self.event(CycleEvent::Spindle { spindle: n, rpm })
    }

    /// `G91 G1 C=<deg> [X=<mm>] F=<deg/min>` (a grind with X's infeed on the overlay; on the
    /// speed plan the axis X follows, the virtual one, in C's place) or `G91 G0 X=<mm>` (the
    /// lift-off, on the overlay while coupled).
    fn incremental(
        &mut self,
        code: &str,
        codes: &[&str],
        sets: &[(&str, Option<&str>, &Expr<'_>)],
    ) -> Step {
        let number = |name: &str| {
            sets.iter()
                .find(|s| s.0 == name && s.1.is_none())
                .and_then(|s| s.2.number())
        };
        let x_mm = number("X").unwrap_or(0.0);
        let coupled = self
            .control
            .couplings
            .iter()
            .find(|c| c.following == "X")
            .cloned();
        // The axis that leads X (C, or a virtual axis on the plan); C when X is free.
        let lead = coupled
            .as_ref()
            .map_or(C_AXIS.to_owned(), |c| c.leading.clone());
        let known = sets
            .iter()
            .all(|s| [lead.as_str(), "X", "F"].contains(&s.0) && s.1.is_none());
        if !known || !matches!(codes, ["G1"] | ["G0"]) {
            return Err(unsupported(code).into());
        }
        if let Some(c) = &coupled
            && number("X").is_some()
            && !self.control.overlay_enabled
        {
            return Err(ControlFault::AxisCoupled {
                axis: c.following.clone(),
            }
            .into());
        }
        let start_off = self
            .control
            .output_offset_mm
            .get("X")
            .copied()
            .unwrap_or(0.0)
            + self.control.overlay_mm;
        match (codes, number(&lead), number("F")) {
            (["G1"], Some(travel), Some(feed)) if travel > 0.0 && feed > 0.0 => {
                if let Some(mut grind) = self.grind(&lead, feed, travel) {
                    grind.x_offset_mm = start_off;
                    grind.x_infeed_mm = x_mm;
                    // C follows a virtual axis one revolution per revolution of it.
                    if grind.c_law.is_some() {
                        *self.control.positions.entry(C_AXIS.to_owned()).or_default() += travel;
                    }
                    self.ground.push(grind);
                    self.events.push(CycleEvent::Ground(self.ground.len() - 1));
                } else if x_mm != 0.0 {
                    return Err(invalid("an X infeed with C turning needs X coupled to C").into());
                }
                *self.control.positions.entry(lead.clone()).or_default() += travel;
            }
            (["G0"], None, None) => {}
            _ => return Err(unsupported(code).into()),
        }
        if coupled.is_some() {
            self.control.overlay_mm += x_mm;
        } else {
            *self.control.positions.entry("X".to_owned()).or_default() += x_mm;
        }
        Ok(None)
    }
}

/// `n` of `M<n>` (not the program ends `M30`, `M17`, `M2`).
fn m_number(text: &str) -> Option<u32> {
    let n: u32 = text.strip_prefix('M')?.parse().ok()?;
    (![2, 17, 30].contains(&n)).then_some(n)
}

/// `n` of a spindle word `M<n>` / `S<n>`.
fn spindle_number(text: &str, letter: char) -> Option<u32> {
    let digits = text.strip_prefix(letter)?;
    (!digits.is_empty() && digits.chars().all(|c| c.is_ascii_digit()))
        .then(|| digits.parse().ok())
        .flatten()
}

/// An assignment the table-only subset does not read: a sum, or a number into a REAL.
fn needs_sum(value: &Expr<'_>, frame: &Frame, target: &str) -> bool {
    matches!(value, Expr::Binary(..))
        || (value.number().is_some() && matches!(frame.vars.get(target), Some(Value::Real(_))))
}

/// A number, a variable, or a sum or difference of them.
fn eval(e: &Expr<'_>, frame: &Frame) -> Option<f64> {
    match e {
        Expr::Num(v) => Some(*v),
        Expr::Neg(inner) => eval(inner, frame).map(|v| -v),
        Expr::Var(name) if is_name(name) => match frame.vars.get(*name)? {
            Value::Int(n) => Some(*n as f64),
            Value::Real(v) => Some(*v),
        },
        Expr::Binary(op, a, b) => {
            let (a, b) = (eval(a, frame)?, eval(b, frame)?);
            match op {
                '+' => Some(a + b),
                '-' => Some(a - b),
                _ => None,
            }
        }
        _ => None,
    }
}
