//! The speed plan's table program: both curve tables over the virtual leading axis, each
//! handing its number back to the caller by reference, as the constant-speed table program
//! does with `CL_TNO` (see the controller contract). X = g(VA) is periodic in VA
//! (periodicity 1); C = f(VA) runs C from its start through 360° further over one period of
//! VA, so it is written periodic in both axes (periodicity 2) [?: confirm on a control that
//! a rotary following axis wraps there as the manual's periodicity 2 suggests].
//!
//! Not yet used by the service or the simulated control; see the manual's "Speed plan".

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
