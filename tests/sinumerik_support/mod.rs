//! A small evaluator of the SINUMERIK subset our loop programs use: `DEF REAL`, R
//! parameters, assignments, `STOPRE`, arithmetic with `SIN COS TAN SQRT ABS` (degrees), labels,
//! `IF <cond> GOTOB/GOTOF <label>` and motion blocks with `<axis>=<expr>` words.
//!
//! It reads the program *text*, not the generator's structures, so running a loop program
//! through it and comparing the moves with the expanded program checks the rendering.
//!
//! Test support, not product code: the generators' tests evaluate the SINUMERIK loop text
//! with it and require exactly the expanded blocks.

use std::collections::HashMap;

use thiserror::Error;

use camloop::core::generate::ir::{cos_deg, sin_deg, tan_deg};
use camloop::core::program::fmt_fixed as fixed;

/// Why a program cannot be evaluated; lines are 1-based.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum EvalError {
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

/// Runs `text` and returns every motion block as the expanded form writes it
/// (`G1 X=… Z=…` with `linear`/`angle` decimals), in order, with the R-parameter writes.
pub fn run(text: &str, linear: usize, angle: usize) -> Result<Vec<String>, EvalError> {
    let lines: Vec<&str> = text
        .lines()
        .map(|l| l.split(';').next().unwrap_or("").trim())
        .collect();
    let mut labels = HashMap::new();
    for (i, l) in lines.iter().enumerate() {
        if let Some(name) = l.strip_suffix(':') {
            labels.insert(name.to_owned(), i);
        }
    }
    let mut vars: HashMap<String, f64> = HashMap::new();
    let mut out = Vec::new();
    let mut pc = 0;
    let mut steps = 0;
    while pc < lines.len() {
        steps += 1;
        if steps > MAX_STEPS {
            return Err(EvalError::Runaway(MAX_STEPS));
        }
        let line = lines[pc];
        let n = pc + 1;
        pc += 1;
        if line.is_empty() || line.starts_with('%') || line.ends_with(':') {
            continue;
        }
        if let Some(names) = line.strip_prefix("DEF REAL ") {
            for name in names.split(',') {
                vars.insert(name.trim().to_owned(), 0.0);
            }
        } else if let Some(rest) = line.strip_prefix("IF ") {
            let (cond, jump) = rest
                .split_once(" GOTO")
                .ok_or_else(|| syntax(n, "IF without GOTOB/GOTOF"))?;
            let label = jump[1..].trim();
            if eval_cond(cond, &vars, n)? {
                pc = *labels.get(label).ok_or_else(|| EvalError::NoLabel {
                    line: n,
                    label: label.to_owned(),
                })?;
            }
        } else if line == "STOPRE" {
            // Only orders preparation against motion; nothing to evaluate.
        } else if line == "M30" {
            break;
        } else if line.starts_with('G') {
            if is_motion(line) {
                out.push(motion(line, &vars, n, linear, angle)?);
            }
        } else if let Some((name, e)) = line.split_once('=') {
            let value = Parser::new(e, &vars, n).whole()?;
            if name.starts_with('R') && name[1..].chars().all(|c| c.is_ascii_digit()) {
                out.push(format!("{name}={value}"));
            } else if !vars.contains_key(name) {
                return Err(EvalError::UnknownVar {
                    line: n,
                    name: name.to_owned(),
                });
            }
            vars.insert(name.to_owned(), value);
        } else {
            return Err(syntax(n, &format!("cannot read `{line}`")));
        }
    }
    Ok(out)
}

/// True for a block with a motion word (`G0` to `G3`); mode-only blocks set no position.
pub fn is_motion(line: &str) -> bool {
    line.split_whitespace()
        .any(|w| matches!(w, "G0" | "G1" | "G2" | "G3"))
}

fn syntax(line: usize, what: &str) -> EvalError {
    EvalError::Syntax {
        line,
        what: what.to_owned(),
    }
}

/// A motion block with its words evaluated and written with fixed decimals.
fn motion(
    line: &str,
    vars: &HashMap<String, f64>,
    n: usize,
    linear: usize,
    angle: usize,
) -> Result<String, EvalError> {
    let mut words = Vec::new();
    for w in line.split_whitespace() {
        if let Some((axis, e)) = w.split_once('=') {
            let v = Parser::new(e, vars, n).whole()?;
            let d = if matches!(axis, "A" | "C") {
                angle
            } else {
                linear
            };
            words.push(format!("{axis}={}", fixed(v, d)));
        } else {
            words.push(w.to_owned());
        }
    }
    Ok(words.join(" "))
}

fn eval_cond(text: &str, vars: &HashMap<String, f64>, n: usize) -> Result<bool, EvalError> {
    for op in ["<=", ">=", "==", "<>", "<", ">"] {
        if let Some((l, r)) = text.split_once(op) {
            let a = Parser::new(l, vars, n).whole()?;
            let b = Parser::new(r, vars, n).whole()?;
            return Ok(match op {
                "<=" => a <= b,
                ">=" => a >= b,
                "==" => a == b,
                "<>" => a != b,
                "<" => a < b,
                _ => a > b,
            });
        }
    }
    Err(syntax(n, &format!("no comparison in `{text}`")))
}

/// Recursive-descent arithmetic: `+ -` over `* /` over unary minus, numbers, variables,
/// functions and brackets.
struct Parser<'a> {
    s: &'a [u8],
    i: usize,
    vars: &'a HashMap<String, f64>,
    line: usize,
}

impl<'a> Parser<'a> {
    fn new(s: &'a str, vars: &'a HashMap<String, f64>, line: usize) -> Self {
        Parser {
            s: s.trim().as_bytes(),
            i: 0,
            vars,
            line,
        }
    }

    fn whole(mut self) -> Result<f64, EvalError> {
        let v = self.sum()?;
        if self.i != self.s.len() {
            return Err(syntax(self.line, "trailing text in an expression"));
        }
        Ok(v)
    }

    fn peek(&self) -> Option<u8> {
        self.s.get(self.i).copied()
    }

    fn sum(&mut self) -> Result<f64, EvalError> {
        let mut v = self.product()?;
        while let Some(op @ (b'+' | b'-')) = self.peek() {
            self.i += 1;
            let r = self.product()?;
            v = if op == b'+' { v + r } else { v - r };
        }
        Ok(v)
    }

    fn product(&mut self) -> Result<f64, EvalError> {
        let mut v = self.unary()?;
        while let Some(op @ (b'*' | b'/')) = self.peek() {
            self.i += 1;
            let r = self.unary()?;
            v = if op == b'*' { v * r } else { v / r };
        }
        Ok(v)
    }

    fn unary(&mut self) -> Result<f64, EvalError> {
        if self.peek() == Some(b'-') {
            self.i += 1;
            return Ok(-self.unary()?);
        }
        if self.peek() == Some(b'(') {
            self.i += 1;
            let v = self.sum()?;
            self.expect(b')')?;
            return Ok(v);
        }
        let start = self.i;
        while let Some(c) = self.peek() {
            if c.is_ascii_alphanumeric() || c == b'_' || c == b'.' {
                self.i += 1;
            } else {
                break;
            }
        }
        let word = std::str::from_utf8(&self.s[start..self.i]).unwrap_or("");
        if word.is_empty() {
            return Err(syntax(self.line, "expected a value"));
        }
        if word.as_bytes()[0].is_ascii_digit() || word.starts_with('.') {
            return word
                .parse()
                .map_err(|_| syntax(self.line, &format!("bad number `{word}`")));
        }
        let f: Option<fn(f64) -> f64> = match word {
            "SIN" => Some(sin_deg),
            "COS" => Some(cos_deg),
            "TAN" => Some(tan_deg),
            "SQRT" => Some(f64::sqrt),
            "ABS" => Some(f64::abs),
            _ => None,
        };
        if let Some(f) = f {
            self.expect(b'(')?;
            let v = self.sum()?;
            self.expect(b')')?;
            return Ok(f(v));
        }
        self.vars
            .get(word)
            .copied()
            .ok_or_else(|| EvalError::UnknownVar {
                line: self.line,
                name: word.to_owned(),
            })
    }

    fn expect(&mut self, c: u8) -> Result<(), EvalError> {
        if self.peek() == Some(c) {
            self.i += 1;
            Ok(())
        } else {
            Err(syntax(self.line, &format!("expected `{}`", c as char)))
        }
    }
}
