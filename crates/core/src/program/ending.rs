//! How a main program that grinds leaves the machine: after its last uncoupling, X goes
//! back clear of the part by an absolute rapid move, nothing moves X after it, every spindle
//! and the coolant it switched on are off, and `M30` ends it.
//!
//! It reads the program *text* with the SINUMERIK reader, so it checks what the control
//! will be given, not the generator's intent. The whole-cycle and shaft programs run it on
//! their own text before returning it. The one-feature main program does not: it is the
//! coupling fragment of the table-only contract and hands X back at the curve to the machine
//! builder's cycle, which owns the retract (it knows no clear X).

use super::syntax::{Expr, Statement, SyntaxError, Word, lines};

/// X is written with at least 3 decimals (`x_decimals`, 3 to 9): a retract written at the
/// clear X reads back within half a unit of the third, 0.5 µm, of it.
const WRITTEN_MM: f64 = 5e-4;

/// Why a program's ending is unsafe; lines are 1-based.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EndingError {
    #[error(transparent)]
    Read(#[from] SyntaxError),
    #[error("the program does not end with M30")]
    NoM30,
    #[error("line {line}: {axis} moves incrementally after the last uncoupling (G91)")]
    Incremental { line: usize, axis: String },
    #[error(
        "line {line}: {axis}={x_mm} after the last uncoupling is below the clear X {clear_x_mm} mm"
    )]
    BelowClear {
        line: usize,
        axis: String,
        x_mm: f64,
        clear_x_mm: f64,
    },
    #[error(
        "line {line}: {axis} is moved to a value not written as a number after the last uncoupling"
    )]
    NotANumber { line: usize, axis: String },
    #[error(
        "the program ends with {axis} at the part: no G90 G0 {axis}=<at least {clear_x_mm} mm> after the last uncoupling"
    )]
    NotRetracted { axis: String, clear_x_mm: f64 },
    #[error("the program ends with spindle {0} running")]
    SpindleLeftOn(u32),
    #[error("the program ends with the coolant on")]
    CoolantLeftOn,
}

/// What the check follows through the text, in order.
#[derive(Default)]
struct State {
    incremental: bool,
    /// Past the last `LEADOF`: only then do X moves count as the ending.
    uncoupled: bool,
    retracted: bool,
    spindles_on: Vec<u32>,
    coolant: bool,
}

/// Checks that `text` ends with `following` retracted to at least `clear_x_mm` (absolute,
/// rapid, after the last `LEADOF`, the last X move), spindles and coolant off, and `M30`.
pub fn check_ending(text: &str, following: &str, clear_x_mm: f64) -> Result<(), EndingError> {
    let all: Vec<_> = lines(text).collect();
    let statements = all
        .iter()
        .map(|l| l.statement().map(|s| (l.number, s)))
        .collect::<Result<Vec<_>, _>>()?;
    let statements: Vec<_> = statements
        .into_iter()
        .filter_map(|(n, s)| s.map(|s| (n, s)))
        .collect();
    let last_leadof = statements
        .iter()
        .rposition(|(_, s)| matches!(s, Statement::Call { name: "LEADOF", .. }));
    match statements.last() {
        Some((_, Statement::Keyword("M30"))) => {}
        _ => return Err(EndingError::NoM30),
    }
    let mut st = State {
        uncoupled: last_leadof.is_none(),
        ..State::default()
    };
    for (k, (line, s)) in statements.iter().enumerate() {
        match s {
            Statement::Block(words) => {
                for w in words {
                    modal(&mut st, w);
                }
                let rapid = words.iter().any(|w| matches!(w, Word::Code("G0")));
                for w in words {
                    if let Word::Set {
                        address,
                        index: None,
                        value,
                    } = w
                        && *address == following
                        && st.uncoupled
                    {
                        x_move(&mut st, *line, following, value, rapid, clear_x_mm)?;
                    }
                }
            }
            Statement::Assign { target, value } => m_word(&mut st, target, value),
            Statement::Keyword(k) => keyword(&mut st, k),
            _ => {}
        }
        if Some(k) == last_leadof {
            st.uncoupled = true;
        }
    }
    if let Some(&n) = st.spindles_on.first() {
        return Err(EndingError::SpindleLeftOn(n));
    }
    if st.coolant {
        return Err(EndingError::CoolantLeftOn);
    }
    if !st.retracted {
        return Err(EndingError::NotRetracted {
            axis: following.to_owned(),
            clear_x_mm,
        });
    }
    Ok(())
}

fn x_move(
    st: &mut State,
    line: usize,
    axis: &str,
    value: &Expr<'_>,
    rapid: bool,
    clear_x_mm: f64,
) -> Result<(), EndingError> {
    let axis = axis.to_owned();
    if st.incremental {
        return Err(EndingError::Incremental { line, axis });
    }
    let Some(x_mm) = value.number() else {
        return Err(EndingError::NotANumber { line, axis });
    };
    if x_mm < clear_x_mm - WRITTEN_MM {
        return Err(EndingError::BelowClear {
            line,
            axis,
            x_mm,
            clear_x_mm,
        });
    }
    // A feed move to a clear X is not the rapid retract a machinist expects; it leaves
    // `retracted` as it was, so a program must still retract after it.
    st.retracted = rapid;
    Ok(())
}

fn modal(st: &mut State, w: &Word<'_>) {
    match w {
        Word::Code("G90") => st.incremental = false,
        Word::Code("G91") => st.incremental = true,
        Word::Code(k) => keyword(st, k),
        Word::Set { address, value, .. } => m_word(st, address, value),
    }
}

/// `M3`/`M4`/`M5` (spindle 1), `M7`/`M8`/`M9`.
fn keyword(st: &mut State, k: &str) {
    match k {
        "M3" | "M4" => spindle(st, 1, true),
        "M5" => spindle(st, 1, false),
        "M7" | "M8" => st.coolant = true,
        "M9" => st.coolant = false,
        _ => {}
    }
}

/// `M<n>=3`/`4`/`5`: spindle n on or off.
fn m_word(st: &mut State, target: &str, value: &Expr<'_>) {
    let Some(n) = target.strip_prefix('M').and_then(|d| d.parse::<u32>().ok()) else {
        return;
    };
    match value.number() {
        Some(v) if v == 3.0 || v == 4.0 => spindle(st, n, true),
        Some(5.0) => spindle(st, n, false),
        _ => {}
    }
}

fn spindle(st: &mut State, n: u32, on: bool) {
    st.spindles_on.retain(|&s| s != n);
    if on {
        st.spindles_on.push(n);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "%_N_T_MPF\nG90 G94 G71\nM1=3 S1=1000.0\nM8\nLEADON(X,C,CL_TNO)\n\
        G91 G0 X=2.0000 ; lift off\nG90\nLEADOF(X,C)\nG90 G0 X=13.0000\nM9\nM1=5\nM30\n";

    #[test]
    fn a_retract_after_the_last_uncoupling_passes() {
        check_ending(GOOD, "X", 13.0).unwrap();
    }

    #[test]
    fn ending_at_the_lift_off_is_refused() {
        let text = GOOD.replace("G90 G0 X=13.0000\n", "");
        assert_eq!(
            check_ending(&text, "X", 13.0),
            Err(EndingError::NotRetracted {
                axis: "X".into(),
                clear_x_mm: 13.0
            })
        );
    }

    #[test]
    fn a_retract_below_clear_or_incremental_or_by_feed_is_refused() {
        let low = GOOD.replace("X=13.0000", "X=12.9990");
        assert!(matches!(
            check_ending(&low, "X", 13.0),
            Err(EndingError::BelowClear { line: 9, .. })
        ));
        let rel = GOOD.replace("G90 G0 X=13.0000", "G91 G0 X=13.0000");
        assert!(matches!(
            check_ending(&rel, "X", 13.0),
            Err(EndingError::Incremental { line: 9, .. })
        ));
        let fed = GOOD.replace("G90 G0 X=13.0000", "G90 G1 X=13.0000 F=100");
        assert!(matches!(
            check_ending(&fed, "X", 13.0),
            Err(EndingError::NotRetracted { .. })
        ));
        // A move back towards the part after the retract.
        let back = GOOD.replace("M9\n", "M9\nG0 X=1.0\n");
        assert!(matches!(
            check_ending(&back, "X", 13.0),
            Err(EndingError::BelowClear { line: 11, .. })
        ));
    }

    #[test]
    fn spindle_coolant_and_m30_are_checked() {
        let spinning = GOOD.replace("M1=5\n", "");
        assert_eq!(
            check_ending(&spinning, "X", 13.0),
            Err(EndingError::SpindleLeftOn(1))
        );
        let wet = GOOD.replace("M9\n", "");
        assert_eq!(
            check_ending(&wet, "X", 13.0),
            Err(EndingError::CoolantLeftOn)
        );
        let open = GOOD.replace("M30\n", "");
        assert_eq!(check_ending(&open, "X", 13.0), Err(EndingError::NoM30));
    }
}
