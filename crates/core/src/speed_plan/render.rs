//! The speed plan's table program: both curve tables over the virtual leading axis, each
//! handing its number back to the caller by reference, as the constant-speed table program
//! does with `CL_TNO` (see the controller contract). X = g(VA) is periodic in VA
//! (periodicity 1); C = f(VA) runs C from its start through 360° further over one period of
//! VA, so it is written periodic in both axes (periodicity 2) [?: confirm on a control that
//! a rotary following axis wraps there as the manual's periodicity 2 suggests].
//!
//! The header is the constant-speed table program's: `SAVE`, the provenance block (table
//! version, parent, recipe, feature, correction digest), the caller's comment lines, one
//! `; curve table N:` line per table and the axes line, so a program found on the control
//! is traced the same way. Run by the simulated control, the simulated cell and delivered by
//! the service with `[speed_plan] enabled = true`.

use super::knots::knot_values;
use super::tables::VaTables;
use crate::program::{
    Provenance, fmt_fixed, provenance_lines, validate_axis_name, validate_program_name,
};
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
    /// Added to every C of C's table, degrees (the feature's phase and the learned timing),
    /// as the constant-speed table adds it to C.
    pub c_offset_deg: f64,
    /// Added to every X of X's table, mm.
    pub x_offset_mm: f64,
    /// Comment lines written after the provenance, without `;` (printable ASCII).
    pub comment_lines: Vec<String>,
    /// The provenance block, set by the caller for each version.
    pub provenance: Option<Provenance>,
}

impl Default for VaProgramSettings {
    /// `CAMLOOP_PLAN`, VA leading X and C, 4 decimals, tables 1 and 2, no offsets.
    fn default() -> Self {
        Self {
            name: "CAMLOOP_PLAN".into(),
            virtual_axis: "VA".into(),
            x_axis: "X".into(),
            c_axis: "C".into(),
            x_decimals: 4,
            c_decimals: 4,
            x_table: 1,
            c_table: 2,
            c_offset_deg: 0.0,
            x_offset_mm: 0.0,
            comment_lines: Vec::new(),
            provenance: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VaProgramError {
    #[error("{0}")]
    Name(String),
    #[error("the X and C tables must have different numbers, both are {0}")]
    SameNumber(u32),
    #[error("the program would be unsafe to load: {0}")]
    Unsafe(#[from] crate::program::EndingError),
}

/// The table program (`.SPF` text) defining both tables.
pub fn render_va_table_program(
    tables: &VaTables,
    s: &VaProgramSettings,
) -> Result<String, VaProgramError> {
    let [name, va, x, c] = checked_va_names(s)?;
    let mut o = String::new();
    let _ = writeln!(o, "%_N_{name}_SPF\n;$PATH=/_N_SPF_DIR");
    let _ = writeln!(
        o,
        "PROC {name}(VAR INT CL_TNO, VAR INT {C_NUMBER_VAR}) SAVE"
    );
    for l in s.provenance.iter().flat_map(provenance_lines) {
        let _ = writeln!(o, "; {l}");
    }
    for l in &s.comment_lines {
        let _ = writeln!(o, "; {l}");
    }
    let _ = writeln!(
        o,
        "; camloop speed plan: {va} at {} rpm, one revolution of {c} per revolution of {va}",
        fmt_fixed(tables.va_speed_rpm, 4)
    );
    let _ = writeln!(
        o,
        "; curve table {}: {x} follows {va}, periodic over 360 deg, {} cubic (POLY) segments",
        s.x_table,
        tables.x_segments.len()
    );
    let _ = writeln!(
        o,
        "; curve table {}: {c} follows {va}, periodic in both, {} cubic (POLY) segments",
        s.c_table,
        tables.c_segments.len()
    );
    let _ = writeln!(
        o,
        "; axes: {c} = {} + c, {x} = x + {} mm (c, x in the part frame)",
        fmt_fixed(s.c_offset_deg, s.c_decimals),
        fmt_fixed(s.x_offset_mm, s.x_decimals)
    );
    o.push_str("G90 G71 ; absolute, metric: the table sets what it relies on, not the caller\n");
    let _ = writeln!(o, "CL_TNO={} ; the X table's number", s.x_table);
    let _ = writeln!(o, "{C_NUMBER_VAR}={} ; the C table's number", s.c_table);
    poly_table(
        &mut o,
        &shifted(&tables.x_segments, s.x_offset_mm),
        (&x, &va),
        s.x_table,
        1,
        s.x_decimals,
        0.0,
    );
    poly_table(
        &mut o,
        &shifted(&tables.c_segments, s.c_offset_deg),
        (&c, &va),
        s.c_table,
        2,
        s.c_decimals,
        360.0,
    );
    o.push_str("RET\n");
    Ok(o)
}

/// The subprogram's name and its virtual, X and C axes, canonical; checked with the table
/// numbers and comments before anything is written.
fn checked_va_names(s: &VaProgramSettings) -> Result<[String; 4], VaProgramError> {
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
    if let Some(bad) = s.comment_lines.iter().find(|l| !printable(l)) {
        return Err(VaProgramError::Name(format!(
            "comment line {bad:?} is not printable ASCII"
        )));
    }
    Ok([name, va, x, c])
}

/// The segments with their value shifted by `by` (the axis offset).
fn shifted(segments: &[PolySegment], by: f64) -> Vec<PolySegment> {
    segments
        .iter()
        .map(|seg| PolySegment {
            x0_mm: seg.x0_mm + by,
            ..*seg
        })
        .collect()
}

fn printable(text: &str) -> bool {
    text.chars().all(|ch| (' '..='~').contains(&ch))
}

/// One periodic POLY table: the first point as `G1`, then each segment's end with its
/// quadratic and cubic coefficients; the last closes at the first VA + 360° with the first
/// value plus `close_gain` (0 for X, 360° for C). The knot values are rounded up or down so
/// that the slope steps the rounding leaves at the joints are smallest ([`knot_values`]).
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
    let starts: Vec<f64> = segments.iter().map(|s| s.x0_mm).collect();
    let lengths: Vec<f64> = segments
        .iter()
        .map(|s| s.c_end_deg - s.c_start_deg)
        .collect();
    let knots = knot_values(&starts, &lengths, decimals);
    let _ = writeln!(o, "CTABDEF({following},{leading},{number},{periodicity})");
    let _ = writeln!(
        o,
        "G1 {leading}={} {following}={}",
        fmt_fixed(first.c_start_deg, 4),
        fmt_fixed(knots[0], decimals)
    );
    o.push_str("POLY\n");
    for (i, seg) in segments.iter().enumerate() {
        let end = knots.get(i + 1).map_or(knots[0] + close_gain, |&next| next);
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
    va_speed_rpm: f64,
    revolutions: f64,
) -> Result<String, VaProgramError> {
    let main = validate_program_name(main_name).map_err(|e| VaProgramError::Name(e.to_string()))?;
    let table = validate_program_name(&s.name).map_err(|e| VaProgramError::Name(e.to_string()))?;
    let mut o = String::new();
    let _ = writeln!(o, "%_N_{main}_MPF\n;$PATH=/_N_MPF_DIR");
    let _ = writeln!(
        o,
        "DEF REAL CL_C, CL_X, CL_SLOPE\nDEF INT CL_TNO, {C_NUMBER_VAR}"
    );
    let _ = writeln!(o, "EXTERN {table}(VAR INT, VAR INT)");
    release_couplings(&mut o, s);
    let _ = writeln!(
        o,
        "{table}(CL_TNO,{C_NUMBER_VAR}) ; defines both tables, returns their numbers"
    );
    grind_block(&mut o, s, va_speed_rpm, revolutions, 100.0);
    o.push_str("M30\n");
    Ok(o)
}

/// Releases couplings of X and C to VA left active by an aborted run.
fn release_couplings(o: &mut String, s: &VaProgramSettings) {
    for axis in [&s.x_axis, &s.c_axis] {
        let _ = writeln!(
            o,
            "IF $AA_COUP_ACT[{axis}]<>0 ; a coupling left active by an aborted run\nLEADOF({axis},{})\nENDIF",
            s.virtual_axis
        );
    }
}

/// Once the table program has returned both numbers: C and X onto their curves at VA = 0,
/// both coupled, VA turned `revolutions` at its speed, both uncoupled.
fn grind_block(
    o: &mut String,
    s: &VaProgramSettings,
    va_speed_rpm: f64,
    revolutions: f64,
    x_feed_mm_min: f64,
) {
    let (va, x, c, cn) = (&s.virtual_axis, &s.x_axis, &s.c_axis, C_NUMBER_VAR);
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
    let _ = writeln!(o, "G1 {x}=CL_X F={}", fmt_fixed(x_feed_mm_min, 3));
    let _ = writeln!(o, "LEADON({c},{va},{cn})\nLEADON({x},{va},CL_TNO)");
    let _ = writeln!(
        o,
        "POS[{va}]=IC({}) FA[{va}]={} ; {revolutions} rev, {} s each",
        fmt_fixed(360.0 * revolutions, 4),
        fmt_fixed(360.0 * va_speed_rpm, 3),
        fmt_fixed(60.0 / va_speed_rpm, 4)
    );
    let _ = writeln!(o, "WAITP({va})\nLEADOF({x},{va})\nLEADOF({c},{va})");
}

/// One feature of a shaft ground with its speed plan.
#[derive(Debug, Clone)]
pub struct VaStation<'a> {
    pub table: &'a VaProgramSettings,
    pub label: &'a str,
    pub z_mm: f64,
    /// The virtual axis' speed of the feature's plan, rev/min (what its tables were made for).
    pub va_speed_rpm: f64,
}

/// The shaft program with speed plans: the constant-speed shaft program's sequence (resume
/// through the R parameter and the resume subprogram, X clear, Z to the station, the table
/// program, the grind, see [`crate::program::render_shaft_program`]) with each feature's
/// grind the plan's: C and X coupled to the virtual axis by the two numbers its table
/// program returns, VA turned at the feature's own speed. The VA speeds are in this text,
/// so it is written again whenever a feature's plan changes (a dressing, new limits).
pub fn render_va_shaft_program(
    main: &crate::program::MainProgramSettings,
    stations: &[VaStation<'_>],
    clear_x_mm: f64,
) -> Result<String, VaProgramError> {
    use crate::program::{FROM_VAR, RESUME_PROGRAM};
    let (main_name, first, z, names) = checked_va_shaft(main, stations, clear_x_mm)?;
    let (x, r) = (&first.table.x_axis, main.resume_r_param);
    let mut o = String::new();
    let _ = writeln!(o, "%_N_{main_name}_MPF\n;$PATH=/_N_MPF_DIR");
    let _ = writeln!(o, "DEF REAL CL_C, CL_X, CL_SLOPE");
    let _ = writeln!(o, "DEF INT CL_TNO, {C_NUMBER_VAR}, {FROM_VAR}");
    let _ = writeln!(o, "EXTERN {RESUME_PROGRAM}(VAR INT)");
    for n in &names {
        let _ = writeln!(o, "EXTERN {n}(VAR INT, VAR INT)");
    }
    for c in &main.comment_lines {
        let _ = writeln!(o, "; {c}");
    }
    release_couplings(&mut o, first.table);
    let _ = writeln!(o, "{FROM_VAR}=1 ; a new shaft: every feature");
    let _ = writeln!(
        o,
        "IF R{r}<0 ; resume: the first feature without a gauge record"
    );
    let _ = writeln!(o, "{RESUME_PROGRAM}({FROM_VAR})\nENDIF");
    let _ = writeln!(o, "IF R{r}>0 ; the operator names the feature to start at");
    let _ = writeln!(
        o,
        "{FROM_VAR}=R{r}\nENDIF\nR{r}=0 ; a resume applies to one run"
    );
    let clear = fmt_fixed(clear_x_mm, first.table.x_decimals);
    for (k, (st, n)) in stations.iter().zip(&names).enumerate() {
        let _ = writeln!(
            o,
            "IF {FROM_VAR}<={} ; feature {} {}",
            k + 1,
            k + 1,
            st.label
        );
        let _ = writeln!(o, "G0 {x}={clear} ; clear of the part");
        let _ = writeln!(
            o,
            "G0 {z}={} ; station of {}",
            fmt_fixed(st.z_mm, 3),
            st.label
        );
        let _ = writeln!(o, "{n}(CL_TNO,{C_NUMBER_VAR}) ; defines both tables");
        grind_block(
            &mut o,
            st.table,
            st.va_speed_rpm,
            main.revolutions,
            main.x_feed_mm_min,
        );
        o.push_str("ENDIF\n");
    }
    let _ = writeln!(o, "G0 {x}={clear}\nM30");
    crate::program::check_ending(&o, x, clear_x_mm)?;
    Ok(o)
}

/// The main program's name, the first station, the axial axis and each feature's
/// subprogram name, once the settings and every station are sound.
fn checked_va_shaft<'a, 's>(
    main: &crate::program::MainProgramSettings,
    stations: &'s [VaStation<'a>],
    clear_x_mm: f64,
) -> Result<(String, &'s VaStation<'a>, String, Vec<String>), VaProgramError> {
    let name_error = |e: &dyn std::fmt::Display| VaProgramError::Name(e.to_string());
    let main_name = validate_program_name(&main.name).map_err(|e| name_error(&e))?;
    let Some(first) = stations.first() else {
        return Err(VaProgramError::Name(
            "a shaft program needs at least one feature".into(),
        ));
    };
    let z = validate_axis_name("axial", &main.axial_axis).map_err(|e| name_error(&e))?;
    let bad = |v: f64| !(v.is_finite() && v > 0.0);
    if let Some(st) = stations
        .iter()
        .find(|st| bad(st.va_speed_rpm) || !st.z_mm.is_finite())
    {
        return Err(VaProgramError::Name(format!(
            "feature {}: virtual axis speed {} rpm and station {} mm must be finite (speed > 0)",
            st.label, st.va_speed_rpm, st.z_mm
        )));
    }
    if bad(main.revolutions) || bad(main.x_feed_mm_min) || !clear_x_mm.is_finite() {
        return Err(VaProgramError::Name(
            "revolutions and x_feed_mm_min must be > 0, the clearance finite".into(),
        ));
    }
    let names = stations
        .iter()
        .map(|st| validate_program_name(&st.table.name).map_err(|e| name_error(&e)))
        .collect::<Result<Vec<_>, _>>()?;
    Ok((main_name, first, z, names))
}
