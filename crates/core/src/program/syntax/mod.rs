//! The one reader of SINUMERIK program text: lines and tokens ([`lex`]), expressions
//! ([`Expr`]) and statements ([`Statement`]) of the subset camloop writes (table and main
//! programs, the shaft and resume programs, and the generators' loop programs). It says
//! what a line is, not what it does: the table reader, the simulated control and the
//! tests' loop evaluator each give the statements their meaning. Errors name the line and
//! the column.

mod expr;
mod lex;

pub use expr::Expr;
pub use lex::{Line, lines};
use lex::{Tok, Token};

use expr::Cursor;

/// Text that is not a statement of the subset, at a 1-based line and column.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}, column {column}: {reason}")]
pub struct SyntaxError {
    pub line: usize,
    pub column: usize,
    pub reason: String,
}

/// A parameter of `PROC` or `EXTERN`: `VAR INT CL_TNO` (`name` is absent in `EXTERN`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Param<'t> {
    pub by_reference: bool,
    pub kind: &'t str,
    pub name: Option<&'t str>,
}

/// `IF <left><op><right>`, op one of `< > <= >= == <>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Cond<'t> {
    pub left: Expr<'t>,
    pub op: &'static str,
    pub right: Expr<'t>,
}

impl Cond<'_> {
    /// The comparison applied to two values.
    pub fn holds(&self, left: f64, right: f64) -> bool {
        match self.op {
            "<" => left < right,
            ">" => left > right,
            "<=" => left <= right,
            ">=" => left >= right,
            "==" => left == right,
            _ => left != right,
        }
    }
}

/// A word of a block: a bare address or G code (`G1`, `DIAMOF`, `F100.0`), or
/// `ADDRESS[INDEX]=<expr>` (`X=CL_X`, `POS[C]=IC(360)`, `PO[X]=(1,2,3)`).
#[derive(Debug, Clone, PartialEq)]
pub enum Word<'t> {
    Code(&'t str),
    Set {
        address: &'t str,
        index: Option<&'t str>,
        value: Expr<'t>,
    },
}

impl Word<'_> {
    /// `G<digits>`: a G code.
    pub fn is_g_code(&self) -> bool {
        matches!(self, Word::Code(c) if c.len() > 1 && c.starts_with('G')
            && c[1..].bytes().all(|b| b.is_ascii_digit()))
    }
}

/// The arguments of `CTABDEF(<following>,<leading>,<n>,<periodicity>[,<memory>])`.
#[derive(Debug, Clone, PartialEq)]
pub struct CtabDef {
    pub following: String,
    pub leading: String,
    pub number: u32,
    /// As written (`1`: periodic in the leading axis, `2`: in both).
    pub periodicity: String,
}

/// One statement of the subset.
#[derive(Debug, Clone, PartialEq)]
pub enum Statement<'t> {
    /// `%_N_<NAME>_<MPF|SPF>`, the transfer header.
    Header {
        name: &'t str,
        kind: &'t str,
    },
    /// `PROC NAME[(params)] [SAVE]`.
    Proc {
        name: &'t str,
        params: Vec<Param<'t>>,
        save: bool,
    },
    /// `DEF <kind> a, b`.
    Def {
        kind: &'t str,
        names: Vec<&'t str>,
    },
    /// `EXTERN NAME(params)`.
    Extern {
        name: &'t str,
        params: Vec<Param<'t>>,
    },
    /// `NAME:`.
    Label(&'t str),
    /// `IF <cond>` (a block up to `ENDIF`) or `IF <cond> GOTOB|GOTOF <label>`.
    If {
        cond: Cond<'t>,
        goto: Option<(&'t str, &'t str)>,
    },
    CtabDef(CtabDef),
    /// A keyword alone: `ENDIF`, `STOPRE`, `M30`, `RET`, `POLY`, `CTABEND`, or a
    /// subprogram called without arguments.
    Keyword(&'t str),
    /// `NAME(<expr>, …)`: `LEADON`, `LEADOF`, `WAITP` or a subprogram call.
    Call {
        name: &'t str,
        args: Vec<Expr<'t>>,
    },
    /// One `NAME=<expr>` word that is not a G-code block.
    Assign {
        target: &'t str,
        value: Expr<'t>,
    },
    /// Words: a motion block (`G90 G1 X=CL_X F=100`), `POS[C]=IC(…) FA[C]=…`, a table's
    /// `PO[C]=(…) PO[X]=(…)`.
    Block(Vec<Word<'t>>),
}

impl<'t> Line<'t> {
    /// The statement on this line; `None` for a line without code.
    pub fn statement(&self) -> Result<Option<Statement<'t>>, SyntaxError> {
        if self.code.is_empty() {
            return Ok(None);
        }
        if let Some(rest) = self.code.strip_prefix("%_N_") {
            let (name, kind) = rest
                .rsplit_once('_')
                .ok_or_else(|| self.error_at(0, "a header is %_N_<NAME>_MPF or _SPF"))?;
            return Ok(Some(Statement::Header { name, kind }));
        }
        let tokens = self.tokens()?;
        let mut c = Cursor {
            line: self,
            tokens: &tokens,
            at: 0,
        };
        let statement = statement(&mut c)?;
        c.end()?;
        Ok(Some(statement))
    }
}

fn statement<'t>(c: &mut Cursor<'_, 't>) -> Result<Statement<'t>, SyntaxError> {
    let first = c.name()?;
    match first {
        "PROC" => return proc_statement(c),
        "EXTERN" => {
            let name = c.name()?;
            c.expect("(")?;
            return Ok(Statement::Extern {
                name,
                params: params(c)?,
            });
        }
        "DEF" => {
            let kind = c.name()?;
            let mut names = vec![c.name()?];
            while c.eat(",") {
                names.push(c.name()?);
            }
            return Ok(Statement::Def { kind, names });
        }
        "IF" => return if_statement(c),
        "CTABDEF" => return Ok(Statement::CtabDef(ctabdef(c)?)),
        _ => {}
    }
    if c.done() {
        let code = Word::Code(first);
        return Ok(if code.is_g_code() {
            Statement::Block(vec![code])
        } else {
            Statement::Keyword(first)
        });
    }
    if c.eat(":") {
        return Ok(Statement::Label(first));
    }
    if c.eat("(") {
        return Ok(Statement::Call {
            name: first,
            args: c.list(")")?,
        });
    }
    c.at -= 1;
    let words = words(c)?;
    match words.as_slice() {
        [
            Word::Set {
                address,
                index: None,
                value,
            },
        ] => Ok(Statement::Assign {
            target: address,
            value: value.clone(),
        }),
        _ => Ok(Statement::Block(words)),
    }
}

fn proc_statement<'t>(c: &mut Cursor<'_, 't>) -> Result<Statement<'t>, SyntaxError> {
    let name = c.name()?;
    let params = if c.eat("(") { params(c)? } else { Vec::new() };
    let save = match c.peek() {
        Some(Tok::Name("SAVE")) => {
            c.at += 1;
            true
        }
        _ => false,
    };
    Ok(Statement::Proc { name, params, save })
}

/// `[VAR] <kind> [name], …)` after the opening bracket.
fn params<'t>(c: &mut Cursor<'_, 't>) -> Result<Vec<Param<'t>>, SyntaxError> {
    let mut out = Vec::new();
    if c.eat(")") {
        return Ok(out);
    }
    loop {
        let mut kind = c.name()?;
        let by_reference = kind == "VAR";
        if by_reference {
            kind = c.name()?;
        }
        let name = match c.peek() {
            Some(Tok::Name(n)) => {
                c.at += 1;
                Some(n)
            }
            _ => None,
        };
        out.push(Param {
            by_reference,
            kind,
            name,
        });
        if c.eat(")") {
            return Ok(out);
        }
        c.expect(",")?;
    }
}

fn if_statement<'t>(c: &mut Cursor<'_, 't>) -> Result<Statement<'t>, SyntaxError> {
    let left = c.expr()?;
    let op = match c.peek() {
        Some(Tok::Symbol(s @ ("<" | ">" | "<=" | ">=" | "==" | "<>"))) => {
            c.at += 1;
            s
        }
        _ => return Err(c.error("expected a comparison")),
    };
    let right = c.expr()?;
    let goto = match c.peek() {
        Some(Tok::Name(jump @ ("GOTOB" | "GOTOF"))) => {
            c.at += 1;
            Some((jump, c.name()?))
        }
        _ => None,
    };
    Ok(Statement::If {
        cond: Cond { left, op, right },
        goto,
    })
}

/// `CTABDEF(` onwards: two axis names, a whole table number, the periodicity and an
/// optional memory.
fn ctabdef(c: &mut Cursor<'_, '_>) -> Result<CtabDef, SyntaxError> {
    c.expect("(")?;
    let following = c.name()?.to_owned();
    c.expect(",")?;
    let leading = c.name()?.to_owned();
    c.expect(",")?;
    let number = match c.peek() {
        Some(Tok::Number(v)) if v.fract() == 0.0 && v <= f64::from(u32::MAX) => v as u32,
        _ => return Err(c.error("the table number is not a whole number")),
    };
    c.at += 1;
    c.expect(",")?;
    let periodicity = match c.tokens.get(c.at) {
        Some(
            t @ Token {
                tok: Tok::Number(_),
                ..
            },
        ) => &c.line.code[t.start..t.end],
        _ => return Err(c.error("the periodicity is not a number")),
    };
    c.at += 1;
    if c.eat(",") {
        c.expr()?;
    }
    c.expect(")")?;
    Ok(CtabDef {
        following,
        leading,
        number,
        periodicity: periodicity.to_owned(),
    })
}

/// The words of a block up to the end of the code.
fn words<'t>(c: &mut Cursor<'_, 't>) -> Result<Vec<Word<'t>>, SyntaxError> {
    let mut out = Vec::new();
    while !c.done() {
        let token = c.tokens[c.at];
        let address = c.name()?;
        let index = if c.eat("[") {
            let index = c.name()?;
            c.expect("]")?;
            Some(index)
        } else {
            None
        };
        if c.eat("=") {
            out.push(Word::Set {
                address,
                index,
                value: c.expr()?,
            });
            continue;
        }
        if index.is_some() {
            return Err(c.error("expected `=`"));
        }
        // `F100.0`: an address with its number written without `=` is one word.
        let mut end = token.end;
        if let Some(next) = c.tokens.get(c.at)
            && matches!(next.tok, Tok::Number(_))
            && next.start == end
        {
            end = next.end;
            c.at += 1;
        }
        out.push(Word::Code(&c.line.code[token.start..end]));
    }
    Ok(out)
}

/// Reads a `CTABDEF(…)` statement (`code`, a comment allowed) on line `line`.
pub fn parse_ctabdef(code: &str, line: usize) -> Result<CtabDef, SyntaxError> {
    let l = Line::new(line, code);
    match l.statement()? {
        Some(Statement::CtabDef(def)) => Ok(def),
        _ => Err(l.error_at(0, format!("`{}` is not CTABDEF(…)", l.code))),
    }
}

#[cfg(test)]
mod tests;
