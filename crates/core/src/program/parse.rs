//! Reading back the curve-table programs camloop writes: what the control will run, for
//! verification, diffs between versions and the simulator. It reads our own output form
//! (`AXIS=value` words, `POLY` with `PO[…]=(…)`), not arbitrary part programs.

use super::super::table::PolySegment;
use super::syntax::{Expr, Line, Statement, SyntaxError, Word, lines};

/// A curve table as written in a program, in machine axis values.
#[derive(Debug, Clone, PartialEq)]
pub struct ParsedTable {
    pub name: String,
    pub table_number: u32,
    pub following_axis: String,
    pub leading_axis: String,
    pub shape: ParsedShape,
}

#[derive(Debug, Clone, PartialEq)]
pub enum ParsedShape {
    /// (C, X) of every G1 block, the closing block at first C + 360 included.
    G1(Vec<(f64, f64)>),
    /// The cubic segments, a1 derived from each end point as the control does.
    Poly(Vec<PolySegment>),
}

impl ParsedTable {
    /// The C values of the table's points (the closing point at first C + 360° excluded).
    pub fn c_knots_deg(&self) -> Vec<f64> {
        match &self.shape {
            ParsedShape::G1(points) => points
                .iter()
                .take(points.len().saturating_sub(1))
                .map(|p| p.0)
                .collect(),
            ParsedShape::Poly(segments) => segments.iter().map(|s| s.c_start_deg).collect(),
        }
    }

    /// X as the control interpolates it at leading value `c_deg` (reduced into the table's
    /// period); `None` for an empty table.
    pub fn x_at(&self, c_deg: f64) -> Option<f64> {
        let start = self.c_knots_deg().first().copied()?;
        let c = start + (c_deg - start).rem_euclid(360.0);
        match &self.shape {
            ParsedShape::G1(points) => {
                points
                    .windows(2)
                    .find(|w| c >= w[0].0 && c <= w[1].0)
                    .map(|w| {
                        let u = (c - w[0].0) / (w[1].0 - w[0].0);
                        w[0].1 + u * (w[1].1 - w[0].1)
                    })
            }
            ParsedShape::Poly(segments) => segments
                .iter()
                .find(|s| c >= s.c_start_deg && c <= s.c_end_deg)
                .map(|s| {
                    let u = (c - s.c_start_deg) / (s.c_end_deg - s.c_start_deg);
                    s.x0_mm + u * (s.a1_mm + u * (s.a2_mm + u * s.a3_mm))
                }),
        }
    }
}

/// Parses a curve-table subprogram written by `render_g1_table` or `render_poly_table`.
/// Lines outside `CTABDEF … CTABEND` other than `PROC` are not read.
pub fn parse_table_program(text: &str) -> Result<ParsedTable, SyntaxError> {
    let err = |line: usize, reason: &str| SyntaxError {
        line,
        column: 1,
        reason: reason.to_owned(),
    };
    let mut name = None;
    let mut table: Option<(u32, TableBlocks)> = None;
    let mut done: Option<(u32, String, String, ParsedShape)> = None;
    for line in lines(text) {
        // Outside a table only PROC, CTABDEF and CTABEND matter: other lines are not read.
        let wanted = table.is_some()
            || ["PROC", "CTABDEF", "CTABEND"]
                .iter()
                .any(|k| line.code.starts_with(k));
        if !wanted {
            continue;
        }
        match line.statement()? {
            None => {}
            // `PROC NAME(VAR INT CL_TNO) SAVE`, or `PROC NAME` in programs written before
            // the table number was returned to the caller.
            Some(Statement::Proc { name: n, .. }) => name = Some(n.to_owned()),
            Some(Statement::CtabDef(def)) => {
                table = Some((def.number, TableBlocks::new(def.following, def.leading)));
            }
            Some(Statement::Keyword("CTABEND")) => {
                let Some((number, blocks)) = table.take() else {
                    return Err(err(line.number, "CTABEND without CTABDEF"));
                };
                let (following, leading, shape) = blocks.finish();
                done = Some((number, following, leading, shape));
            }
            Some(statement) => {
                if let Some((_, blocks)) = table.as_mut() {
                    blocks.block(&line, &statement)?;
                }
            }
        }
    }
    let Some((table_number, following_axis, leading_axis, shape)) = done else {
        return Err(match table {
            Some(_) => err(
                text.lines().count(),
                "CTABEND missing: the program is incomplete",
            ),
            None => err(1, "no CTABDEF in the program"),
        });
    };
    Ok(ParsedTable {
        name: name.unwrap_or_default(),
        table_number,
        following_axis,
        leading_axis,
        shape,
    })
}

/// The blocks between `CTABDEF` and `CTABEND`, read one at a time: `G1 C=… X=…` points, or
/// a start point, `POLY` and `PO[C]=(…) PO[X]=(…)` segments. Shared by the reader and the
/// simulated control, so both see the same table.
#[derive(Debug, Clone)]
pub struct TableBlocks {
    following: String,
    leading: String,
    poly: bool,
    points: Vec<(f64, f64)>,
    segments: Vec<PolySegment>,
}

impl TableBlocks {
    pub fn new(following: String, leading: String) -> Self {
        Self {
            following,
            leading,
            poly: false,
            points: Vec::new(),
            segments: Vec::new(),
        }
    }

    /// One block, `statement` read from `line`.
    pub fn block(&mut self, line: &Line<'_>, statement: &Statement<'_>) -> Result<(), SyntaxError> {
        let err = |reason: &str| line.error_at(0, reason);
        let words = match statement {
            Statement::Keyword("POLY") => {
                self.poly = true;
                return Ok(());
            }
            Statement::Block(words) => words.as_slice(),
            _ => return Err(err("expected a table block")),
        };
        let (following, leading) = (self.following.as_str(), self.leading.as_str());
        if !self.poly {
            let c = value(words, leading, None, line)?;
            let x = value(words, following, None, line)?;
            self.points.push((c, x));
            return Ok(());
        }
        let c_end = value_list(words, "PO", leading, line)?;
        let x = value_list(words, "PO", following, line)?;
        let (&[c1], &[x_end, a2, a3]) = (c_end.as_slice(), x.as_slice()) else {
            return Err(err("expected PO[C]=(c_end) PO[X]=(x_end,a2,a3)"));
        };
        let (c0, x0) = match (self.segments.last(), self.points.last()) {
            (Some(s), _) => (s.c_end_deg, s.x_end_mm()),
            (None, Some(&p)) => p,
            (None, None) => return Err(err("POLY block before the start point")),
        };
        self.segments.push(PolySegment {
            c_start_deg: c0,
            c_end_deg: c1,
            x0_mm: x0,
            a1_mm: x_end - x0 - a2 - a3,
            a2_mm: a2,
            a3_mm: a3,
        });
        Ok(())
    }

    /// Following axis, leading axis and the shape read.
    pub fn finish(self) -> (String, String, ParsedShape) {
        let shape = if self.poly {
            ParsedShape::Poly(self.segments)
        } else {
            ParsedShape::G1(self.points)
        };
        (self.following, self.leading, shape)
    }
}

/// The expression of word `address[index]=…` in a block.
fn find<'w, 't>(
    words: &'w [Word<'t>],
    address: &str,
    index: Option<&str>,
    line: &Line<'_>,
) -> Result<&'w Expr<'t>, SyntaxError> {
    words
        .iter()
        .find_map(|w| match w {
            Word::Set {
                address: a,
                index: i,
                value,
            } if *a == address && *i == index => Some(value),
            _ => None,
        })
        .ok_or_else(|| {
            let word = index.map_or(address.to_owned(), |i| format!("{address}[{i}]"));
            line.error_at(0, format!("no {word}= word"))
        })
}

/// The number of `AXIS=value` in a block.
fn value(
    words: &[Word<'_>],
    axis: &str,
    index: Option<&str>,
    line: &Line<'_>,
) -> Result<f64, SyntaxError> {
    find(words, axis, index, line)?
        .number()
        .ok_or_else(|| line.error_at(0, format!("{axis} value is not a number")))
}

/// The numbers of `KEY[AXIS]=(a,b,…)` in a block.
fn value_list(
    words: &[Word<'_>],
    key: &str,
    axis: &str,
    line: &Line<'_>,
) -> Result<Vec<f64>, SyntaxError> {
    find(words, key, Some(axis), line)?
        .numbers()
        .ok_or_else(|| line.error_at(0, format!("{key}[{axis}]: the values are not numbers")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::{ProgramSettings, render_g1_table, render_poly_table};
    use crate::table::TablePoint;

    fn points() -> Vec<TablePoint> {
        (0..36)
            .map(|k| {
                let c_deg = k as f64 * 10.0;
                let x_mm = 2.0 + (c_deg.to_radians()).cos();
                TablePoint {
                    c_deg,
                    d_mm: x_mm + 270.0,
                    x_mm,
                }
            })
            .collect()
    }

    #[test]
    fn reads_back_a_g1_table_within_the_written_resolution() {
        let text = render_g1_table(&points(), &ProgramSettings::default()).unwrap();
        let parsed = parse_table_program(&text).unwrap();
        assert_eq!(parsed.table_number, 1);
        // `PROC CAMLOOP_TABLE(VAR INT CL_TNO) SAVE`: the name alone.
        assert_eq!(parsed.name, "CAMLOOP_TABLE");
        assert_eq!(
            parse_table_program(&text.replace("(VAR INT CL_TNO) SAVE", ""))
                .unwrap()
                .name,
            "CAMLOOP_TABLE"
        );
        let ParsedShape::G1(read) = parsed.shape else {
            panic!("G1 expected")
        };
        assert_eq!(read.len(), 37, "36 points and the closing block");
        for (p, (c, x)) in points().iter().zip(&read) {
            assert!((p.c_deg - c).abs() < 5e-5 && (p.x_mm - x).abs() < 5e-5);
        }
        assert!((read[36].0 - 360.0).abs() < 1e-9);
    }

    #[test]
    fn reads_back_poly_segments_as_the_control_does() {
        let segments = crate::fit::fit_poly(&points());
        let text = render_poly_table(&segments, &ProgramSettings::default()).unwrap();
        let ParsedShape::Poly(read) = parse_table_program(&text).unwrap().shape else {
            panic!("POLY expected")
        };
        assert_eq!(read.len(), 36);
        for (a, b) in segments.iter().zip(&read) {
            for u in [0.25, 0.5, 0.75] {
                let xa = a.x0_mm + u * (a.a1_mm + u * (a.a2_mm + u * a.a3_mm));
                let xb = b.x0_mm + u * (b.a1_mm + u * (b.a2_mm + u * b.a3_mm));
                // X end points are written with 4 decimals (±5e-5 mm), a2/a3 with 6.
                assert!((xa - xb).abs() < 1e-4, "{xa} vs {xb}");
            }
        }
    }

    #[test]
    fn x_is_interpolated_as_the_control_does_between_points() {
        let text = render_g1_table(&points(), &ProgramSettings::default()).unwrap();
        let parsed = parse_table_program(&text).unwrap();
        assert_eq!(parsed.c_knots_deg().len(), 36);
        // Halfway between 10° and 20° on a chord; and one turn later the same.
        let (x10, x20) = (
            2.0 + 10f64.to_radians().cos(),
            2.0 + 20f64.to_radians().cos(),
        );
        for c in [15.0, 375.0, -345.0] {
            let x = parsed.x_at(c).unwrap();
            assert!((x - 0.5 * (x10 + x20)).abs() < 1e-4, "{c}: {x}");
        }
    }

    #[test]
    fn a_block_that_cannot_be_read_is_refused_naming_line_and_column() {
        let text = render_g1_table(&points(), &ProgramSettings::default()).unwrap();
        let at = text.lines().position(|l| l.starts_with("G1 C=")).unwrap();
        let bad: String = text
            .lines()
            .enumerate()
            .map(|(i, l)| {
                if i == at {
                    "G1 C=(10 X=2\n".to_owned()
                } else {
                    format!("{l}\n")
                }
            })
            .collect();
        let e = parse_table_program(&bad).unwrap_err();
        assert_eq!((e.line, e.column), (at + 1, 10), "{e}");
        assert_eq!(e.reason, "expected `,` or `)`");
    }

    #[test]
    fn a_truncated_program_is_refused() {
        let text = render_g1_table(&points(), &ProgramSettings::default()).unwrap();
        let cut = &text[..text.len() / 2];
        let e = parse_table_program(cut).unwrap_err();
        assert!(e.reason.contains("CTABEND missing"), "{e}");
    }
}
