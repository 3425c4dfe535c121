//! SINUMERIK 840D sl program text: curve-table subprograms (G1 and POLY form), the
//! main-program fragment that couples X to C, program/axis name rules and table numbering.
//!
//! A table subprogram returns the number it defines through its `VAR INT` parameter, and the
//! main program couples that variable: the numbers alternate between versions (so the table
//! in use is never redefined) while the main program stays the same text.
//!
//! Everything here is pure: values in, `String` or a typed error out. Syntax follows the
//! project's SINUMERIK notes; what is inferred rather than confirmed is marked [?] in the
//! doc comments, never in the generated program.
//!
//! Address form: every axis word is written `<AXIS>=<value>` (`C=12.0000 X=3.1416`). For
//! single-letter axes `C12.0000` would also do, but axis names with several letters or a
//! digit extension (`C1`, `XA`) require the `=`, and `=` is valid for both.

mod cycle_plan;
mod cycle_program;
mod ending;
mod files;
mod main_program;
mod names;
mod parse;
mod provenance;
mod settings;
mod shaft_program;
pub mod syntax;
mod table;

pub use cycle_plan::CyclePlan;
pub use cycle_program::{
    CLEARANCE_MM, CycleMachine, CycleProgramError, CycleStation, OUTPUT_OFFSET, POLL_S,
    READY_PROGRAM, clear_x_mm, render_cycle_program, render_ready_program, wheel_rpm,
};
pub use ending::{EndingError, check_ending};
pub use files::{
    ProgramFilesError, ProgramText, expected_program_files, split_program_files, table_definitions,
};
pub use main_program::{MainProgramSettings, render_main_program};
pub use names::{AxisNameError, ProgramNameError, validate_axis_name, validate_program_name};
pub use parse::{ParsedShape, ParsedTable, TableBlocks, parse_table_program};
pub(crate) use provenance::provenance_lines;
pub use provenance::{RetargetError, retarget_table_program};
pub use settings::{
    CDirection, ProgramSettings, Provenance, SettingError, SettingsErrors, TableMemory,
};
pub(crate) use shaft_program::FROM_VAR;
pub use shaft_program::{
    RESUME_PROGRAM, Station, parse_resume_program, render_resume_program, render_shaft_program,
};
pub use syntax::{CtabDef, SyntaxError, parse_ctabdef};
pub use table::{TableError, fmt_fixed, render_g1_table, render_poly_table};

/// Text made safe for a program comment line: printable ASCII only (the units camloop writes
/// spelled in ASCII, `µm` as `um` and `°` as ` deg`; anything else becomes `?`), at most 200
/// characters.
pub fn comment_text(text: &str) -> String {
    text.replace('µ', "u")
        .replace('°', " deg")
        .chars()
        .map(|c| {
            if c.is_ascii_graphic() || c == ' ' {
                c
            } else {
                '?'
            }
        })
        .take(200)
        .collect()
}

/// The table number for the next table version, so that the table in use is never
/// overwritten (the control redefines a table number without warning).
///
/// Returns `pair.1` when `current == pair.0`, otherwise `pair.0` (including when `current`
/// is neither, e.g. on the first run). `pair` must hold two different numbers, both ≥ 1;
/// check that once with [`check_table_pair`] when loading configuration.
pub fn next_table_number(current: u32, pair: (u32, u32)) -> u32 {
    if current == pair.0 { pair.1 } else { pair.0 }
}

/// Why a pair of alternating table numbers is unusable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TablePairError {
    #[error(
        "table numbers ({0}, {1}) must differ so that a new table never overwrites the one in use"
    )]
    Same(u32, u32),
    #[error("table numbers ({0}, {1}) must both be at least 1")]
    Zero(u32, u32),
}

/// Check a pair of alternating table numbers: both ≥ 1 and different.
pub fn check_table_pair(pair: (u32, u32)) -> Result<(), TablePairError> {
    if pair.0 == 0 || pair.1 == 0 {
        Err(TablePairError::Zero(pair.0, pair.1))
    } else if pair.0 == pair.1 {
        Err(TablePairError::Same(pair.0, pair.1))
    } else {
        Ok(())
    }
}
