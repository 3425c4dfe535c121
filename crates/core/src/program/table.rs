//! Curve-table subprograms (`CTABDEF … CTABEND`) in G1 (point) and POLY (cubic) form.

use std::fmt::Write as _;

use thiserror::Error;

use super::provenance::{TABLE_COMMENT, provenance_lines};
use super::settings::{ProgramSettings, Resolved, SettingsErrors};
use crate::table::{PolySegment, TablePoint};

/// Why a table cannot be rendered. Indices are positions in the caller's slice; angles named
/// `c_deg` are in the part frame, values named `c_prog` / `x_prog` as written in the program.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TableError {
    #[error("program settings: {0}")]
    Settings(#[from] SettingsErrors),
    #[error("the table has {count} points: at least 2 are needed")]
    TooFewPoints { count: usize },
    #[error("the table has no segments")]
    NoSegments,
    #[error("point {index} has a non-finite value (c = {c_deg} deg, x = {x_mm} mm)")]
    NonFinitePoint { index: usize, c_deg: f64, x_mm: f64 },
    #[error("segment {index} has a non-finite value")]
    NonFiniteSegment { index: usize },
    #[error(
        "segment {index} runs from c = {c_start_deg} deg to c = {c_end_deg} deg: the end must be greater than the start"
    )]
    EmptySegment {
        index: usize,
        c_start_deg: f64,
        c_end_deg: f64,
    },
    #[error(
        "{first} (c = {c_first_deg} deg) and {second} (c = {c_second_deg} deg) give C={c_first_prog} and C={c_second_prog} after rounding to the control's resolution: the leading value must increase in every block (alarm 10949)"
    )]
    CNotIncreasing {
        /// "point 3", "segment 3 end", "period end" (first value + 360).
        first: String,
        c_first_deg: f64,
        c_first_prog: String,
        second: String,
        c_second_deg: f64,
        c_second_prog: String,
    },
    #[error(
        "segment {index} ends at C={c_end_prog} but the next segment ({next_index}) starts at C={c_next_prog}: the segments must join over one period of 360 deg"
    )]
    CGap {
        index: usize,
        next_index: usize,
        c_end_prog: f64,
        c_next_prog: f64,
    },
    #[error(
        "segment {index} ends at X={x_end_prog} but the next segment ({next_index}) starts at X={x_next_prog}: the gap exceeds half a unit of the last decimal"
    )]
    XGap {
        index: usize,
        next_index: usize,
        x_end_prog: f64,
        x_next_prog: f64,
    },
}

/// Render a periodic curve table with linear (G1) segments through `points`.
///
/// `points` hold one period in the part frame, in any order, without the closing point at
/// first + 360°. Each point is mapped to program axes (`C = wrap360(offset ± c)`,
/// `X = x + x_offset`, see [`super::ProgramSettings`]), sorted so that C increases from the
/// smallest wrapped value, and written one block per point, `C=<c> X=<x>` with the
/// configured decimals. A last block at first C + 360° repeats the first X and closes the
/// period. `d_mm` is not used.
///
/// Errors: invalid settings (all listed), fewer than 2 points, non-finite values, and two
/// consecutive C values (including the period end) equal after rounding.
pub fn render_g1_table(
    points: &[TablePoint],
    settings: &ProgramSettings,
) -> Result<String, TableError> {
    let r = settings.resolve()?;
    if points.len() < 2 {
        return Err(TableError::TooFewPoints {
            count: points.len(),
        });
    }
    let mut mapped = Vec::with_capacity(points.len());
    for (index, p) in points.iter().enumerate() {
        if !(p.c_deg.is_finite() && p.x_mm.is_finite()) {
            return Err(TableError::NonFinitePoint {
                index,
                c_deg: p.c_deg,
                x_mm: p.x_mm,
            });
        }
        mapped.push((
            index,
            settings.c_prog_deg(p.c_deg),
            settings.x_prog_mm(p.x_mm),
        ));
    }
    mapped.sort_by(|a, b| a.1.total_cmp(&b.1));

    let cd = usize::from(settings.c_decimals);
    let xd = usize::from(settings.x_decimals);
    let knots: Vec<Knot> = mapped
        .iter()
        .map(|&(index, c, _)| Knot {
            label: format!("point {index}"),
            c_deg: points[index].c_deg,
            c_text: fmt_fixed(c, cd),
        })
        .collect();
    let close_text = check_increasing(&knots, points[mapped[0].0].c_deg, settings)?;

    let mut out = header(
        &r,
        &format!("{} points, linear (G1) segments", points.len()),
    );
    let first_x = fmt_fixed(mapped[0].2, xd);
    for (i, (knot, &(_, _, x))) in knots.iter().zip(&mapped).enumerate() {
        let g = if i == 0 { "G1 " } else { "" };
        line(
            &mut out,
            format_args!(
                "{g}{}={} {}={}",
                r.leading,
                knot.c_text,
                r.following,
                fmt_fixed(x, xd)
            ),
        );
    }
    line(
        &mut out,
        format_args!("{}={close_text} {}={first_x}", r.leading, r.following),
    );
    out.push_str(TABLE_END);
    Ok(out)
}

/// Render a periodic curve table of cubic segments in POLY form.
///
/// `segments` cover one period of 360° in the part frame, in any order, each
/// `x(u) = x0 + a1·u + a2·u² + a3·u³` with u from 0 at `c_start_deg` to 1 at `c_end_deg`.
/// After mapping to program axes (reversed C reverses the segment order and re-parameterises
/// each cubic with u' = 1 − u) the program has a start block `G1 C=<c0> X=<x0>`, `POLY`, one
/// block per segment `PO[C]=(<c_end>) PO[X]=(<x_end>,<a2>,<a3>)` ending at C0 + 360° with the
/// first X, and `CTABEND`, which restores the modal state from before `CTABDEF` (so `POLY`
/// does not leak to the caller) [M-old]. The control derives
/// a1 from the end point, so the written cubic passes exactly through the rounded knots.
///
/// a2 and a3 are written with X decimals + 2: with both end points fixed, rounding a2 and a3
/// by at most ½·10^−k changes X inside the segment by at most
/// ½·10^−k·(max|u²−u| + max|u³−u|) = ½·10^−k·(¼ + 2/(3√3)) < 0.32·10^−k, so k = X decimals + 2
/// keeps the coefficient rounding below 0.004 units of the last X decimal, negligible beside
/// the ½-unit rounding of the knots themselves.
///
/// Errors: invalid settings, no segments, non-finite values, a segment whose end is not
/// beyond its start, segments that do not join over exactly one period (C within 1e-6°, X
/// within half a unit of the last decimal), and C values equal after rounding.
pub fn render_poly_table(
    segments: &[PolySegment],
    settings: &ProgramSettings,
) -> Result<String, TableError> {
    let r = settings.resolve()?;
    if segments.is_empty() {
        return Err(TableError::NoSegments);
    }
    let reversed = settings.c_direction == super::CDirection::Reversed;
    let mut mapped = map_segments(segments, settings)?;
    mapped.sort_by(|a, b| a.c_start.total_cmp(&b.c_start));
    check_joins(&mapped, settings.c_decimals, settings.x_decimals)?;

    let cd = usize::from(settings.c_decimals);
    let xd = usize::from(settings.x_decimals);
    let kd = xd + 2;
    // Knot i is the end of segment i; the start of segment 0 comes first.
    let part_c_of_start = |m: &Mapped| {
        let s = &segments[m.index];
        if reversed { s.c_end_deg } else { s.c_start_deg }
    };
    let part_c_of_end = |m: &Mapped| {
        let s = &segments[m.index];
        if reversed { s.c_start_deg } else { s.c_end_deg }
    };
    let mut knots = vec![Knot {
        label: format!("segment {} start", mapped[0].index),
        c_deg: part_c_of_start(&mapped[0]),
        c_text: fmt_fixed(mapped[0].c_start, cd),
    }];
    for w in mapped.windows(2) {
        knots.push(Knot {
            label: format!("segment {} end", w[0].index),
            c_deg: part_c_of_end(&w[0]),
            c_text: fmt_fixed(w[1].c_start, cd),
        });
    }
    let close_text = check_increasing(&knots, knots[0].c_deg, settings)?;

    let mut out = header(&r, &format!("{} cubic (POLY) segments", segments.len()));
    let first_x = fmt_fixed(mapped[0].x0, xd);
    line(
        &mut out,
        format_args!(
            "G1 {}={} {}={first_x}",
            r.leading, knots[0].c_text, r.following
        ),
    );
    out.push_str("POLY\n");
    for (i, m) in mapped.iter().enumerate() {
        let (c_end, x_end) = match (knots.get(i + 1), mapped.get(i + 1)) {
            (Some(k), Some(next)) => (k.c_text.clone(), fmt_fixed(next.x0, xd)),
            _ => (close_text.clone(), first_x.clone()),
        };
        line(
            &mut out,
            format_args!(
                "PO[{}]=({c_end}) PO[{}]=({x_end},{},{})",
                r.leading,
                r.following,
                fmt_fixed(m.a[1], kd),
                fmt_fixed(m.a[2], kd)
            ),
        );
    }
    out.push_str(TABLE_END);
    Ok(out)
}

/// Each segment checked (finite, end beyond start) and mapped to program axes, u running
/// with increasing C, in the caller's order.
fn map_segments(
    segments: &[PolySegment],
    settings: &ProgramSettings,
) -> Result<Vec<Mapped>, TableError> {
    let reversed = settings.c_direction == super::CDirection::Reversed;
    let mut mapped = Vec::with_capacity(segments.len());
    for (index, s) in segments.iter().enumerate() {
        if !s.is_finite() {
            return Err(TableError::NonFiniteSegment { index });
        }
        if s.c_end_deg <= s.c_start_deg {
            return Err(TableError::EmptySegment {
                index,
                c_start_deg: s.c_start_deg,
                c_end_deg: s.c_end_deg,
            });
        }
        let (c_first_deg, cubic) = if reversed {
            (
                s.c_end_deg,
                reverse_cubic([s.x0_mm, s.a1_mm, s.a2_mm, s.a3_mm]),
            )
        } else {
            (s.c_start_deg, [s.x0_mm, s.a1_mm, s.a2_mm, s.a3_mm])
        };
        mapped.push(Mapped {
            index,
            c_start: settings.c_prog_deg(c_first_deg),
            len_deg: s.c_end_deg - s.c_start_deg,
            x0: settings.x_prog_mm(cubic[0]),
            a: [cubic[1], cubic[2], cubic[3]],
        });
    }
    Ok(mapped)
}

/// Coefficients `[x0, a1, a2, a3]` of the same cubic with the parameter reversed,
/// `u' = 1 − u`: x0' = x0 + a1 + a2 + a3, a1' = −a1 − 2a2 − 3a3, a2' = a2 + 3a3, a3' = −a3.
pub(crate) fn reverse_cubic([x0, a1, a2, a3]: [f64; 4]) -> [f64; 4] {
    [
        x0 + a1 + a2 + a3,
        -a1 - 2.0 * a2 - 3.0 * a3,
        a2 + 3.0 * a3,
        -a3,
    ]
}

/// One segment in program axes, u running with increasing C.
struct Mapped {
    index: usize,
    c_start: f64,
    len_deg: f64,
    x0: f64,
    /// a1, a2, a3, mm.
    a: [f64; 3],
}

impl Mapped {
    fn x_end(&self) -> f64 {
        self.x0 + self.a[0] + self.a[1] + self.a[2]
    }
}

/// A leading value as it will be written, with where it came from for error messages.
struct Knot {
    label: String,
    c_deg: f64,
    c_text: String,
}

/// Check that the written C values increase strictly at the control's resolution (each
/// rounded to `c_increments_per_deg`, as the control rounds them), up to and including the
/// period end (first + 360°), and return the period end as written. Decimals finer than the
/// resolution are refused by the settings, so today two different written values never
/// round to the same increment; the check is made at the resolution all the same, because
/// that is what the control compares.
fn check_increasing(
    knots: &[Knot],
    first_c_deg: f64,
    settings: &ProgramSettings,
) -> Result<String, TableError> {
    let cd = usize::from(settings.c_decimals);
    let first_back = parse_back(&knots[0].c_text);
    let close = Knot {
        label: "period end (first value + 360 deg)".to_owned(),
        c_deg: first_c_deg,
        c_text: fmt_fixed(first_back + 360.0, cd),
    };
    let at_resolution = |text: &str| settings.c_increments(parse_back(text));
    let mut prev = &knots[0];
    for k in knots[1..].iter().chain(std::iter::once(&close)) {
        if at_resolution(&k.c_text) <= at_resolution(&prev.c_text) {
            return Err(TableError::CNotIncreasing {
                first: prev.label.clone(),
                c_first_deg: prev.c_deg,
                c_first_prog: prev.c_text.clone(),
                second: k.label.clone(),
                c_second_deg: k.c_deg,
                c_second_prog: k.c_text.clone(),
            });
        }
        prev = k;
    }
    Ok(close.c_text)
}

/// Consecutive segments (cyclically, the last joining the first + 360°) must meet, so the
/// written table is the fitted one. X may differ by half a unit of the last decimal: the
/// written knot is then within half a unit of both. C must agree to 1e-6° (or half a unit,
/// if smaller): a C gap would stretch a cubic over a different range, moving X by
/// slope × gap everywhere in the segment.
fn check_joins(mapped: &[Mapped], c_decimals: u8, x_decimals: u8) -> Result<(), TableError> {
    let c_tol = (0.5 * 10f64.powi(-i32::from(c_decimals))).min(1e-6);
    let x_tol = 0.5 * 10f64.powi(-i32::from(x_decimals));
    for (i, m) in mapped.iter().enumerate() {
        let (next, period) = match mapped.get(i + 1) {
            Some(next) => (next, 0.0),
            None => (&mapped[0], 360.0),
        };
        let c_end = m.c_start + m.len_deg;
        let c_next = next.c_start + period;
        if (c_end - c_next).abs() > c_tol {
            return Err(TableError::CGap {
                index: m.index,
                next_index: next.index,
                c_end_prog: c_end,
                c_next_prog: c_next,
            });
        }
        if (m.x_end() - next.x0).abs() > x_tol {
            return Err(TableError::XGap {
                index: m.index,
                next_index: next.index,
                x_end_prog: m.x_end(),
                x_next_prog: next.x0,
            });
        }
    }
    Ok(())
}

/// The variable through which a table program returns the number it defines (its `VAR INT`
/// parameter); the main program couples that variable, never a literal.
pub(crate) const NUMBER_VAR: &str = "CL_TNO";

/// The last lines of every table program.
const TABLE_END: &str = "CTABEND ; the control restores the modal state from before CTABDEF\nRET\n";

/// Transfer header, `PROC`, provenance, comments, the number assignment and `CTABDEF` of a
/// table subprogram.
///
/// `PROC <NAME>(VAR INT CL_TNO) SAVE`: the caller passes a variable by reference (`VAR`,
/// declared in the caller with `EXTERN <NAME>(VAR INT)`) and reads the defined number from
/// it, so `CTAB` and `LEADON` use the table just defined. Points not in the project's notes:
/// - `VAR` passes by reference, and a subprogram with parameters needs `EXTERN` in the
///   caller [?];
/// - `SAVE` restores the caller's modal G functions at `RET` [?]; Siemens' frames function
///   manual (K2) describes `SAVE` restoring frames at the end of a subprogram [M-old], the
///   same for G functions is our reading.
///
/// `G90 G71` are set inside because the table cannot rely on what the caller left active
/// (the notes' "modal state" finding).
fn header(r: &Resolved<'_>, what: &str) -> String {
    let s = r.settings;
    let cd = usize::from(s.c_decimals);
    let xd = usize::from(s.x_decimals);
    let mut out = String::new();
    line(&mut out, format_args!("%_N_{}_SPF", r.name));
    out.push_str(";$PATH=/_N_SPF_DIR\n");
    line(
        &mut out,
        format_args!("PROC {}(VAR INT {NUMBER_VAR}) SAVE", r.name),
    );
    if let Some(p) = &s.provenance {
        for l in provenance_lines(p) {
            line(&mut out, format_args!("; {l}"));
        }
    }
    for c in &s.comment_lines {
        line(&mut out, format_args!("; {c}"));
    }
    line(
        &mut out,
        format_args!(
            "{TABLE_COMMENT}{}: {} follows {}, periodic over 360 deg, {what}",
            s.table_number, r.following, r.leading
        ),
    );
    let sign = match s.c_direction {
        super::CDirection::Same => '+',
        super::CDirection::Reversed => '-',
    };
    line(
        &mut out,
        format_args!(
            "; axes: {} = {} {sign} c (mod 360 deg), {} = x + {} mm (c, x in the part frame)",
            r.leading,
            fmt_fixed(s.c_offset_deg, cd),
            r.following,
            fmt_fixed(s.x_offset_mm, xd)
        ),
    );
    out.push_str("G90 G71 ; absolute, metric: the table sets what it relies on, not the caller\n");
    line(
        &mut out,
        format_args!(
            "{NUMBER_VAR}={} ; the number this program defines, read by the caller for CTAB and LEADON",
            s.table_number
        ),
    );
    let memory = s
        .memory
        .map(|m| format!(",\"{}\"", m.keyword()))
        .unwrap_or_default();
    line(
        &mut out,
        format_args!(
            "CTABDEF({},{},{},1{memory})",
            r.following, r.leading, s.table_number
        ),
    );
    out
}

/// Append one line.
pub(crate) fn line(out: &mut String, args: std::fmt::Arguments<'_>) {
    // Writing into a String cannot fail.
    let _ = out.write_fmt(args);
    out.push('\n');
}

/// `v` with exactly `decimals` decimals, rounded as `format!` does (to the nearest decimal
/// of the exact binary value), never `-0.000`.
pub fn fmt_fixed(v: f64, decimals: usize) -> String {
    let text = format!("{v:.decimals$}");
    match text.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_owned(),
        _ => text,
    }
}

/// The value a written number stands for.
fn parse_back(text: &str) -> f64 {
    // fmt_fixed only produces `-?digits.digits`, which always parses.
    text.parse().unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval([x0, a1, a2, a3]: [f64; 4], u: f64) -> f64 {
        x0 + u * (a1 + u * (a2 + u * a3))
    }

    #[test]
    fn reversed_cubic_is_the_same_curve_run_backwards() {
        let c = [1.25, -0.7, 3.1, -2.4];
        let r = reverse_cubic(c);
        for i in 0..=20 {
            let u = f64::from(i) / 20.0;
            // Values are O(10), so 1e-12 is a few ulps of the arithmetic.
            assert!((eval(c, u) - eval(r, 1.0 - u)).abs() < 1e-12, "u = {u}");
        }
        // Reversing twice gives the original back.
        let rr = reverse_cubic(r);
        for (a, b) in c.iter().zip(rr) {
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn c_is_compared_at_the_control_resolution_not_at_the_written_decimals() {
        let knot = |c_text: &str| Knot {
            label: format!("at {c_text}"),
            c_deg: 0.0,
            c_text: c_text.to_owned(),
        };
        let knots = [knot("10.0000"), knot("10.0004"), knot("20.0000")];
        // Settings refuse 4 decimals at 1000 increments/deg; the check itself must still
        // compare what the control keeps: 10.0000 and 10.0004 are both 10000 increments.
        let coarse = ProgramSettings {
            c_increments_per_deg: 1000,
            ..ProgramSettings::default()
        };
        match check_increasing(&knots, 10.0, &coarse) {
            Err(TableError::CNotIncreasing { first, second, .. }) => {
                assert_eq!(
                    (first.as_str(), second.as_str()),
                    ("at 10.0000", "at 10.0004")
                );
            }
            other => panic!("unexpected {other:?}"),
        }
        let fine = ProgramSettings::default();
        assert_eq!(
            check_increasing(&knots, 10.0, &fine).unwrap(),
            "370.0000",
            "the period end, as written"
        );
    }

    #[test]
    fn fixed_format_has_no_negative_zero() {
        assert_eq!(fmt_fixed(-0.00001, 4), "0.0000");
        assert_eq!(fmt_fixed(-0.0, 2), "0.00");
        assert_eq!(fmt_fixed(-0.00006, 4), "-0.0001");
        assert_eq!(fmt_fixed(12.4, 0), "12");
        assert_eq!(fmt_fixed(-3.0, 0), "-3");
    }
}
