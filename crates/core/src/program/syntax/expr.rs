//! Expressions as written in a statement: numbers, variables, indexed system variables
//! (`$AA_IW[C]`), function calls (`CTAB(…)`, `SIN(…)`, `IC(…)`), bracketed lists
//! (`PO[X]=(…)`) and `+ - * /` with the usual precedence.

use super::SyntaxError;
use super::lex::{Line, Tok, Token};

/// An expression, not evaluated: what it means depends on the reader (the simulated
/// control, the table reader, the loop evaluator).
#[derive(Debug, Clone, PartialEq)]
pub enum Expr<'t> {
    Num(f64),
    Text(&'t str),
    Var(&'t str),
    /// `NAME[INDEX]`, e.g. `$AA_IW[C]`.
    Indexed(&'t str, &'t str),
    Call(&'t str, Vec<Expr<'t>>),
    /// `(a, b, …)` with two or more members.
    List(Vec<Expr<'t>>),
    Neg(Box<Expr<'t>>),
    Binary(char, Box<Expr<'t>>, Box<Expr<'t>>),
}

impl<'t> Expr<'t> {
    /// The value of a number, signed or not.
    pub fn number(&self) -> Option<f64> {
        match self {
            Expr::Num(v) => Some(*v),
            Expr::Neg(e) => e.number().map(|v| -v),
            _ => None,
        }
    }

    /// The numbers of a list, or of a single number as a list of one.
    pub(crate) fn numbers(&self) -> Option<Vec<f64>> {
        match self {
            Expr::List(items) => items.iter().map(Expr::number).collect(),
            other => other.number().map(|v| vec![v]),
        }
    }

    /// The name of a plain variable.
    pub fn name(&self) -> Option<&'t str> {
        match self {
            Expr::Var(name) => Some(name),
            _ => None,
        }
    }
}

/// Reads tokens of one line, left to right.
pub(super) struct Cursor<'l, 't> {
    pub(super) line: &'l Line<'t>,
    pub(super) tokens: &'l [Token<'t>],
    pub(super) at: usize,
}

impl<'l, 't> Cursor<'l, 't> {
    pub(super) fn peek(&self) -> Option<Tok<'t>> {
        self.tokens.get(self.at).map(|t| t.tok)
    }

    pub(super) fn peek_symbol(&self, s: &str) -> bool {
        matches!(self.peek(), Some(Tok::Symbol(x)) if x == s)
    }

    /// Moves past symbol `s` when it is next.
    pub(super) fn eat(&mut self, s: &str) -> bool {
        let here = self.peek_symbol(s);
        self.at += usize::from(here);
        here
    }

    pub(super) fn done(&self) -> bool {
        self.at >= self.tokens.len()
    }

    /// An error at the next token (or at the end of the code).
    pub(super) fn error(&self, reason: impl Into<String>) -> SyntaxError {
        let at = self
            .tokens
            .get(self.at)
            .map_or(self.line.code.len(), |t| t.start);
        self.line.error_at(at, reason)
    }

    pub(super) fn expect(&mut self, s: &str) -> Result<(), SyntaxError> {
        if self.eat(s) {
            Ok(())
        } else {
            Err(self.error(format!("expected `{s}`")))
        }
    }

    pub(super) fn name(&mut self) -> Result<&'t str, SyntaxError> {
        match self.peek() {
            Some(Tok::Name(n)) => {
                self.at += 1;
                Ok(n)
            }
            _ => Err(self.error("expected a name")),
        }
    }

    /// Requires the end of the code.
    pub(super) fn end(&self) -> Result<(), SyntaxError> {
        if self.done() {
            Ok(())
        } else {
            Err(self.error("unexpected text"))
        }
    }

    /// `+ -` over `* /` over unary minus and the primaries.
    pub(super) fn expr(&mut self) -> Result<Expr<'t>, SyntaxError> {
        let mut e = self.product()?;
        loop {
            let op = if self.eat("+") {
                '+'
            } else if self.eat("-") {
                '-'
            } else {
                return Ok(e);
            };
            e = Expr::Binary(op, Box::new(e), Box::new(self.product()?));
        }
    }

    fn product(&mut self) -> Result<Expr<'t>, SyntaxError> {
        let mut e = self.unary()?;
        loop {
            let op = if self.eat("*") {
                '*'
            } else if self.eat("/") {
                '/'
            } else {
                return Ok(e);
            };
            e = Expr::Binary(op, Box::new(e), Box::new(self.unary()?));
        }
    }

    fn unary(&mut self) -> Result<Expr<'t>, SyntaxError> {
        if self.eat("-") {
            return Ok(Expr::Neg(Box::new(self.unary()?)));
        }
        match self.peek() {
            Some(Tok::Number(v)) => {
                self.at += 1;
                Ok(Expr::Num(v))
            }
            Some(Tok::Text(t)) => {
                self.at += 1;
                Ok(Expr::Text(t))
            }
            Some(Tok::Symbol("(")) => {
                self.at += 1;
                let mut items = self.list(")")?;
                Ok(match items.len() {
                    1 => items.remove(0),
                    _ => Expr::List(items),
                })
            }
            Some(Tok::Name(name)) => {
                self.at += 1;
                if self.eat("[") {
                    let index = self.name()?;
                    self.expect("]")?;
                    Ok(Expr::Indexed(name, index))
                } else if self.eat("(") {
                    Ok(Expr::Call(name, self.list(")")?))
                } else {
                    Ok(Expr::Var(name))
                }
            }
            _ => Err(self.error("expected a value")),
        }
    }

    /// Comma-separated expressions up to `close` (already past the opening bracket); `()`
    /// is an empty list.
    pub(super) fn list(&mut self, close: &str) -> Result<Vec<Expr<'t>>, SyntaxError> {
        let mut items = Vec::new();
        if self.eat(close) {
            return Ok(items);
        }
        loop {
            items.push(self.expr()?);
            if self.eat(close) {
                return Ok(items);
            }
            if !self.eat(",") {
                return Err(self.error(format!("expected `,` or `{close}`")));
            }
        }
    }
}
