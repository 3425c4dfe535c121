//! A small evaluator of the SINUMERIK subset our loop programs use: `DEF REAL`, R
//! parameters, assignments, `STOPRE`, arithmetic with `SIN COS TAN SQRT ABS` (degrees), labels,
//! `IF <cond> GOTOB/GOTOF <label>` and motion blocks with `<axis>=<expr>` words.
//!
//! It reads the program *text* with the core's SINUMERIK reader
//! (`camloop::core::program::syntax`), not the generator's structures, so running a loop program
//! through it and comparing the moves with the expanded program checks the rendering.
//!
//! Test support, not product code: the generators' tests evaluate the SINUMERIK loop text
//! with it and require exactly the expanded blocks.

use std::collections::HashMap;

use thiserror::Error;

use camloop::core::generate::ir::{cos_deg, sin_deg, tan_deg};
use camloop::core::program::fmt_fixed as fixed;
use camloop::core::program::syntax::{Cond, Expr, Line, Statement, SyntaxError, Word, lines};

/// Why a program cannot be evaluated; lines are 1-based.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum EvalError {
    #[error(transparent)]
    Read(#[from] SyntaxError),
    #[error("line {line}: {what}")]
    Syntax { line: usize, what: String },
    #[error("line {line}: unknown variable `{name}`")]
    UnknownVar { line: usize, name: String },
    #[error("line {line}: no label `{label}`")]
    NoLabel { line: usize, label: String },
    #[error("more than {0} blocks run: the program does not end")]
    Runaway(usize),
}

/// Blocks run at most.
const MAX_STEPS: usize = 5_000_000;

type Vars = HashMap<String, f64>;

/// Runs `text` and returns every motion block as the expanded form writes it
/// (`G1 X=… Z=…` with `linear`/`angle` decimals), in order, with the R-parameter writes.
pub fn run(text: &str, linear: usize, angle: usize) -> Result<Vec<String>, EvalError> {
    run_with(text, linear, angle, &[])
}

/// [`run`] on a control whose R parameters already hold `preset` (R parameters are kept over
/// power-off: a program resumed from them reads what an earlier run wrote).
pub fn run_with(
    text: &str,
    linear: usize,
    angle: usize,
    preset: &[(&str, f64)],
) -> Result<Vec<String>, EvalError> {
    let lines: Vec<Line> = lines(text).collect();
    let statements = lines
        .iter()
        .map(Line::statement)
        .collect::<Result<Vec<_>, _>>()?;
    let mut labels = HashMap::new();
    for (i, s) in statements.iter().enumerate() {
        if let Some(Statement::Label(name)) = s {
            labels.insert(*name, i);
        }
    }
    let mut vars: Vars = preset.iter().map(|(k, v)| ((*k).to_owned(), *v)).collect();
    let mut out = Vec::new();
    let mut pc = 0;
    let mut steps = 0;
    while pc < lines.len() {
        steps += 1;
        if steps > MAX_STEPS {
            return Err(EvalError::Runaway(MAX_STEPS));
        }
        let (line, n) = (&lines[pc], lines[pc].number);
        pc += 1;
        match &statements[pc - 1] {
            None | Some(Statement::Header { .. } | Statement::Label(_)) => {}
            Some(Statement::Def {
                kind: "REAL",
                names,
            }) => {
                for name in names {
                    vars.insert((*name).to_owned(), 0.0);
                }
            }
            Some(Statement::If {
                cond,
                goto: Some((_, label)),
            }) => {
                if eval_cond(cond, &vars, n)? {
                    pc = *labels.get(label).ok_or_else(|| EvalError::NoLabel {
                        line: n,
                        label: (*label).to_owned(),
                    })?;
                }
            }
            // Only orders preparation against motion; nothing to evaluate.
            Some(Statement::Keyword("STOPRE")) => {}
            Some(Statement::Keyword("M30")) => break,
            // The set-up and its end (radius or diameter X, coolant, spindle off): machine
            // state with no position to evaluate.
            Some(Statement::Keyword(
                "DIAMON" | "DIAMOF" | "M5" | "M7" | "M8" | "M9" | "M3" | "M4",
            )) => {}
            // A machine's own M function (a planer's hydraulics, its tool lifter).
            Some(Statement::Keyword(k))
                if k.len() > 1
                    && k.starts_with('M')
                    && k[1..].chars().all(|c| c.is_ascii_digit()) => {}
            // Tool, spindle, feed-mode and offset blocks (`T1 D1`, `G96 S180 LIMS=3000 M3`).
            Some(Statement::Block(words)) if !is_motion(words) => {}
            Some(Statement::Block(words)) if words.first().is_some_and(Word::is_g_code) => {
                if is_motion(words) {
                    out.push(motion(words, &vars, n, linear, angle)?);
                }
            }
            Some(Statement::Assign { target, value }) => {
                let value = eval(value, &vars, n)?;
                if is_r_parameter(target) {
                    out.push(format!("{target}={value}"));
                } else if !vars.contains_key(*target) {
                    return Err(EvalError::UnknownVar {
                        line: n,
                        name: (*target).to_owned(),
                    });
                }
                vars.insert((*target).to_owned(), value);
            }
            Some(_) => return Err(syntax(n, &format!("cannot read `{}`", line.code))),
        }
    }
    Ok(out)
}

/// True for a block with a motion word (`G0` to `G3`); mode-only blocks set no position.
fn is_motion(words: &[Word]) -> bool {
    words
        .iter()
        .any(|w| matches!(w, Word::Code("G0" | "G1" | "G2" | "G3")))
}

/// `R` and digits: an R parameter.
fn is_r_parameter(name: &str) -> bool {
    name.len() > 1 && name.starts_with('R') && name[1..].chars().all(|c| c.is_ascii_digit())
}

fn syntax(line: usize, what: &str) -> EvalError {
    EvalError::Syntax {
        line,
        what: what.to_owned(),
    }
}

/// A motion block with its words evaluated and written with fixed decimals.
fn motion(
    words: &[Word],
    vars: &Vars,
    n: usize,
    linear: usize,
    angle: usize,
) -> Result<String, EvalError> {
    let mut out = Vec::new();
    for w in words {
        match w {
            Word::Set {
                address,
                index: None,
                value,
            } => {
                let v = eval(value, vars, n)?;
                let d = if matches!(*address, "A" | "C") {
                    angle
                } else {
                    linear
                };
                out.push(format!("{address}={}", fixed(v, d)));
            }
            Word::Code(code) => out.push((*code).to_owned()),
            Word::Set { address, .. } => {
                return Err(syntax(n, &format!("indexed `{address}` in a motion block")));
            }
        }
    }
    Ok(out.join(" "))
}

fn eval_cond(cond: &Cond, vars: &Vars, n: usize) -> Result<bool, EvalError> {
    Ok(cond.holds(eval(&cond.left, vars, n)?, eval(&cond.right, vars, n)?))
}

/// The value of an expression: numbers, variables, `+ - * /`, unary minus and `SIN COS TAN
/// SQRT ABS` (degrees).
fn eval(e: &Expr, vars: &Vars, n: usize) -> Result<f64, EvalError> {
    Ok(match e {
        Expr::Num(v) => *v,
        // R parameters always exist on the control (0 until written); other names must be
        // declared.
        Expr::Var(name) if is_r_parameter(name) => vars.get(*name).copied().unwrap_or(0.0),
        Expr::Var(name) => *vars.get(*name).ok_or_else(|| EvalError::UnknownVar {
            line: n,
            name: (*name).to_owned(),
        })?,
        Expr::Neg(a) => -eval(a, vars, n)?,
        Expr::Binary(op, a, b) => {
            let (a, b) = (eval(a, vars, n)?, eval(b, vars, n)?);
            match op {
                '+' => a + b,
                '-' => a - b,
                '*' => a * b,
                _ => a / b,
            }
        }
        Expr::Call(name, args) => {
            let f: fn(f64) -> f64 = match *name {
                "SIN" => sin_deg,
                "COS" => cos_deg,
                "TAN" => tan_deg,
                "SQRT" => f64::sqrt,
                "ABS" => f64::abs,
                _ => return Err(syntax(n, &format!("unknown function `{name}`"))),
            };
            let [arg] = args.as_slice() else {
                return Err(syntax(n, &format!("{name} takes one argument")));
            };
            f(eval(arg, vars, n)?)
        }
        other => return Err(syntax(n, &format!("cannot evaluate {other:?}"))),
    })
}

/// `main` with every line that calls `sub_name` (the name alone, a comment after it)
/// replaced by the subprogram's blocks, as the control runs them: the subprogram's
/// transfer header and its `RET` are left out.
pub fn inline_sub(main: &str, sub_name: &str, sub: &str) -> String {
    let body: String = sub
        .lines()
        .filter(|l| !l.starts_with('%') && !l.starts_with(";$PATH") && l.trim() != "RET")
        .map(|l| format!("{l}\n"))
        .collect();
    main.lines()
        .map(|l| {
            let code = l.split(';').next().unwrap_or("").trim();
            if code == sub_name {
                body.clone()
            } else {
                format!("{l}\n")
            }
        })
        .collect()
}
