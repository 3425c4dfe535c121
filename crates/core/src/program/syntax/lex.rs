//! Lines and tokens of SINUMERIK program text: the comment split off, the code cut into
//! names, numbers, quoted text and symbols, each with the column it starts at.

use super::SyntaxError;

/// One program line: its 1-based number, the code before any `;` comment (trimmed) and
/// the comment (without the `;`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Line<'t> {
    pub number: usize,
    pub code: &'t str,
    pub comment: Option<&'t str>,
    /// 1-based column of `code`'s first character in the line.
    code_column: usize,
}

/// The lines of `text`, numbered from 1.
pub fn lines(text: &str) -> impl Iterator<Item = Line<'_>> {
    text.lines()
        .enumerate()
        .map(|(index, raw)| Line::new(index + 1, raw))
}

impl<'t> Line<'t> {
    /// Line `number` with text `raw` (the comment is split off here).
    pub fn new(number: usize, raw: &'t str) -> Self {
        let (code, comment) = split_comment(raw);
        let leading = code.len() - code.trim_start().len();
        Line {
            number,
            code: code.trim(),
            comment,
            code_column: raw[..leading].chars().count() + 1,
        }
    }
}

/// `;` starts a comment unless it is inside quoted text.
fn split_comment(raw: &str) -> (&str, Option<&str>) {
    let mut quoted = false;
    for (at, c) in raw.char_indices() {
        match c {
            '"' => quoted = !quoted,
            ';' if !quoted => return (&raw[..at], Some(&raw[at + 1..])),
            _ => {}
        }
    }
    (raw, None)
}

/// What a token is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Tok<'t> {
    /// A name, address or keyword: a letter, `_` or `$`, then letters, digits and `_`.
    Name(&'t str),
    /// An unsigned number (`12`, `1.5`, `.5`); a sign is an operator.
    Number(f64),
    /// Text in double quotes, without them.
    Text(&'t str),
    /// One of [`SYMBOLS`].
    Symbol(&'static str),
}

/// Symbols, two-character ones first so that `<=` is not read as `<`, `=`.
pub(crate) const SYMBOLS: [&str; 17] = [
    "<=", ">=", "==", "<>", "(", ")", "[", "]", ",", "=", "+", "-", "*", "/", "<", ">", ":",
];

/// A token, where it stands in its line's code (byte offsets) and its 1-based column.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Token<'t> {
    pub tok: Tok<'t>,
    pub start: usize,
    pub end: usize,
    pub column: usize,
}

impl<'t> Line<'t> {
    /// 1-based column in the line of byte offset `at` of the code.
    fn column_of(&self, at: usize) -> usize {
        self.code_column + self.code[..at.min(self.code.len())].chars().count()
    }

    /// An error at byte offset `at` of the code.
    pub(crate) fn error_at(&self, at: usize, reason: impl Into<String>) -> SyntaxError {
        SyntaxError {
            line: self.number,
            column: self.column_of(at),
            reason: reason.into(),
        }
    }

    /// The code cut into tokens.
    pub(crate) fn tokens(&self) -> Result<Vec<Token<'t>>, SyntaxError> {
        let code = self.code;
        let bytes = code.as_bytes();
        let mut out = Vec::new();
        let mut at = 0;
        while at < bytes.len() {
            let c = bytes[at];
            let start = at;
            let tok = if c.is_ascii_whitespace() {
                at += 1;
                continue;
            } else if c.is_ascii_alphabetic() || c == b'_' || c == b'$' {
                at += 1;
                while at < bytes.len() && (bytes[at].is_ascii_alphanumeric() || bytes[at] == b'_') {
                    at += 1;
                }
                Tok::Name(&code[start..at])
            } else if c.is_ascii_digit() || c == b'.' {
                at = number_end(bytes, at);
                let text = &code[start..at];
                Tok::Number(
                    text.parse()
                        .map_err(|_| self.error_at(start, format!("`{text}` is not a number")))?,
                )
            } else if c == b'"' {
                let close = code[at + 1..]
                    .find('"')
                    .ok_or_else(|| self.error_at(start, "quoted text without its closing `\"`"))?;
                at += close + 2;
                Tok::Text(&code[start + 1..at - 1])
            } else if let Some(s) = SYMBOLS.iter().find(|s| code[at..].starts_with(**s)) {
                at += s.len();
                Tok::Symbol(s)
            } else {
                let ch = code[at..].chars().next().unwrap_or('?');
                return Err(self.error_at(start, format!("`{ch}` is not read here")));
            };
            out.push(Token {
                tok,
                start,
                end: at,
                column: self.column_of(start),
            });
        }
        Ok(out)
    }
}

/// The end of the digits and one decimal point starting at `at`.
fn number_end(bytes: &[u8], mut at: usize) -> usize {
    let mut point = false;
    while at < bytes.len() {
        match bytes[at] {
            b'0'..=b'9' => {}
            b'.' if !point => point = true,
            _ => break,
        }
        at += 1;
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toks(code: &str) -> Vec<Tok<'_>> {
        let line = lines(code).next().unwrap();
        line.tokens().unwrap().into_iter().map(|t| t.tok).collect()
    }

    #[test]
    fn comments_are_split_off_outside_quotes() {
        let l: Vec<Line> = lines("  G1 X=1 ; a comment\nCTABDEF(X,C,1,1,\"A;B\")\n").collect();
        assert_eq!(
            (l[0].number, l[0].code, l[0].comment),
            (1, "G1 X=1", Some(" a comment"))
        );
        assert_eq!(
            (l[1].code, l[1].comment),
            ("CTABDEF(X,C,1,1,\"A;B\")", None)
        );
    }

    #[test]
    fn tokens_carry_their_columns() {
        use Tok::*;
        assert_eq!(
            toks("IF $AA_COUP_ACT[X]<>0"),
            [
                Name("IF"),
                Name("$AA_COUP_ACT"),
                Symbol("["),
                Name("X"),
                Symbol("]"),
                Symbol("<>"),
                Number(0.0)
            ]
        );
        assert_eq!(
            toks("X=-.5"),
            [Name("X"), Symbol("="), Symbol("-"), Number(0.5)]
        );
        let line = lines("  PO[X]=(1,2)").next().unwrap();
        let columns: Vec<usize> = line.tokens().unwrap().iter().map(|t| t.column).collect();
        assert_eq!(columns, [3, 5, 6, 7, 8, 9, 10, 11, 12, 13]);
    }

    #[test]
    fn what_cannot_be_read_is_named_with_its_column() {
        let line = lines("G1 X=1 # 2").next().unwrap();
        let e = line.tokens().unwrap_err();
        assert_eq!(e.to_string(), "line 1, column 8: `#` is not read here");
        let e = lines("\n A=\"open").nth(1).unwrap().tokens().unwrap_err();
        assert_eq!((e.line, e.column), (2, 4));
    }
}
