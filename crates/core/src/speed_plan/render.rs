//! The speed plan's table program: both curve tables over the virtual leading axis, each
//! handing its number back to the caller by reference, as the constant-speed table program
//! does with `CL_TNO` (see the controller contract). X = g(VA) is periodic in VA
//! (periodicity 1); C = f(VA) runs C from its start through 360° further over one period of
//! VA, so it is written periodic in both axes (periodicity 2) [?: confirm on a control that
//! a rotary following axis wraps there as the manual's periodicity 2 suggests].
//!
//! Run by the simulated control and the simulated cell; not yet delivered by the service (see
//! the manual's "Speed plan").

use super::tables::VaTables;
use crate::program::{fmt_fixed, validate_axis_name, validate_program_name};
use crate::table::PolySegment;
use std::fmt::Write as _;

/// The variable the table program returns the C table's number in (the X table's is
/// `CL_TNO`, as for a constant-speed table).
pub const C_NUMBER_VAR: &str = "CL_TNO_C";

/// Names, numbers and resolution of the two tables.
#[derive(Debug, Clone, PartialEq)]
pub struct VaProgramSettings {
    /// Table subprogram name.
    pub name: String,
    pub virtual_axis: String,
    pub x_axis: String,
    pub c_axis: String,
    pub x_decimals: usize,
    pub c_decimals: usize,
    /// Curve-table numbers of this version's X and C tables (the caller alternates them
    /// between versions as it does the constant-speed table's).
    pub x_table: u32,
    pub c_table: u32,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VaProgramError {
    #[error("{0}")]
    Name(String),
    #[error("the X and C tables must have different numbers, both are {0}")]
    SameNumber(u32),
}

/// The table program (`.SPF` text) defining both tables.
pub fn render_va_table_program(
    tables: &VaTables,
    s: &VaProgramSettings,
) -> Result<String, VaProgramError> {
    let name = validate_program_name(&s.name).map_err(|e| VaProgramError::Name(e.to_string()))?;
    let axis = |role: &'static str, n: &str| {
        validate_axis_name(role, n).map_err(|e| VaProgramError::Name(e.to_string()))
    };
    let (va, x, c) = (
        axis("virtual leading", &s.virtual_axis)?,
        axis("following", &s.x_axis)?,
        axis("leading", &s.c_axis)?,
    );
    if s.x_table == s.c_table {
        return Err(VaProgramError::SameNumber(s.x_table));
    }
    let mut o = String::new();
    let _ = writeln!(o, "%_N_{name}_SPF\n;$PATH=/_N_SPF_DIR");
    let _ = writeln!(o, "PROC {name}(VAR INT CL_TNO, VAR INT {C_NUMBER_VAR})");
    let _ = writeln!(
        o,
        "; camloop speed plan: {va} at {} rpm, one revolution of {c} per revolution of {va}",
        fmt_fixed(tables.va_speed_rpm, 4)
    );
    o.push_str("G90\n");
    let _ = writeln!(o, "CL_TNO={} ; the X table's number", s.x_table);
    let _ = writeln!(o, "{C_NUMBER_VAR}={} ; the C table's number", s.c_table);
    poly_table(
        &mut o,
        &tables.x_segments,
        (&x, &va),
        s.x_table,
        1,
        s.x_decimals,
        0.0,
    );
    poly_table(
        &mut o,
        &tables.c_segments,
        (&c, &va),
        s.c_table,
        2,
        s.c_decimals,
        360.0,
    );
    o.push_str("RET\n");
    Ok(o)
}

/// One periodic POLY table: the first point as `G1`, then each segment's end with its
/// quadratic and cubic coefficients; the last closes at the first VA + 360° with the first
/// value plus `close_gain` (0 for X, 360° for C).
fn poly_table(
    o: &mut String,
    segments: &[PolySegment],
    (following, leading): (&str, &str),
    number: u32,
    periodicity: u8,
    decimals: usize,
    close_gain: f64,
) {
    let Some(first) = segments.first() else {
        return;
    };
    let _ = writeln!(o, "CTABDEF({following},{leading},{number},{periodicity})");
    let _ = writeln!(
        o,
        "G1 {leading}={} {following}={}",
        fmt_fixed(first.c_start_deg, 4),
        fmt_fixed(first.x0_mm, decimals)
    );
    o.push_str("POLY\n");
    for (i, seg) in segments.iter().enumerate() {
        let end = segments
            .get(i + 1)
            .map_or(first.x0_mm + close_gain, |next| next.x0_mm);
        let _ = writeln!(
            o,
            "PO[{leading}]=({}) PO[{following}]=({},{},{})",
            fmt_fixed(seg.c_end_deg, 4),
            fmt_fixed(end, decimals),
            fmt_fixed(seg.a2_mm, decimals + 2),
            fmt_fixed(seg.a3_mm, decimals + 2)
        );
    }
    o.push_str("CTABEND\n");
}

/// The main program that grinds `revolutions` finish revolutions with the plan: it calls the
/// table program, puts C and X on their curves at VA = 0, couples C and then X to VA with the
/// numbers the table program returned (never literals, as for the constant-speed main
/// program), turns VA at its constant speed and uncouples.
///
/// [?] on a control: VA must be an axis the control can move without a drive (a simulated
/// axis in machine data); whether two `LEADON` to one leading axis start in step when
/// programmed in consecutive blocks; whether C, a rotary axis that may be a spindle, can
/// follow in a curve-table coupling in its axis mode.
pub fn render_va_main_program(
    main_name: &str,
    s: &VaProgramSettings,
    tables: &VaTables,
    revolutions: f64,
) -> Result<String, VaProgramError> {
    let main = validate_program_name(main_name).map_err(|e| VaProgramError::Name(e.to_string()))?;
    let table = validate_program_name(&s.name).map_err(|e| VaProgramError::Name(e.to_string()))?;
    let (va, x, c, cn) = (&s.virtual_axis, &s.x_axis, &s.c_axis, C_NUMBER_VAR);
    let mut o = String::new();
    let _ = writeln!(o, "%_N_{main}_MPF\n;$PATH=/_N_MPF_DIR");
    let _ = writeln!(o, "DEF REAL CL_C, CL_X, CL_SLOPE\nDEF INT CL_TNO, {cn}");
    let _ = writeln!(o, "EXTERN {table}(VAR INT, VAR INT)");
    for axis in [x, c] {
        let _ = writeln!(
            o,
            "IF $AA_COUP_ACT[{axis}]<>0 ; a coupling left active by an aborted run\nLEADOF({axis},{va})\nENDIF"
        );
    }
    let _ = writeln!(
        o,
        "{table}(CL_TNO,{cn}) ; defines both tables, returns their numbers"
    );
    o.push_str("STOPRE ; use the numbers only after the tables are defined\n");
    let _ = writeln!(o, "G90 G0 {va}=0");
    let _ = writeln!(
        o,
        "CL_C=CTAB(0,{cn},CL_SLOPE) ; {c} on its curve at {va} = 0"
    );
    let _ = writeln!(
        o,
        "CL_X=CTAB(0,CL_TNO,CL_SLOPE) ; {x} on its curve at {va} = 0"
    );
    let _ = writeln!(o, "POS[{c}]=DC(CL_C) FA[{c}]=3600\nWAITP({c})");
    let _ = writeln!(o, "G1 {x}=CL_X F=100.000");
    let _ = writeln!(o, "LEADON({c},{va},{cn})\nLEADON({x},{va},CL_TNO)");
    let _ = writeln!(
        o,
        "POS[{va}]=IC({}) FA[{va}]={} ; {revolutions} rev, {} s each",
        fmt_fixed(360.0 * revolutions, 4),
        fmt_fixed(360.0 * tables.va_speed_rpm, 3),
        fmt_fixed(60.0 / tables.va_speed_rpm, 4)
    );
    let _ = writeln!(o, "WAITP({va})\nLEADOF({x},{va})\nLEADOF({c},{va})\nM30");
    Ok(o)
}
