//! The main program of a whole shaft: every lobe or pin in turn (retract, Z to its station,
//! define its newest table, couple, grind, uncouple), resumable at the first unfinished
//! feature; and the small resume subprogram camloop rewrites after each gauged feature.

use super::ProgramSettings;
use super::ending::check_ending;
use super::main_program::{
    MainProgramSettings, Opening, coupled_revolutions, define_table, opening,
};
use super::names::validate_axis_name;
use super::settings::{Resolved, SettingError, SettingsErrors, check_comments, check_positive};
use super::syntax::{Statement, lines};
use super::table::{fmt_fixed, line};

/// The resume subprogram's name (file `CAMLOOP_RESUME.SPF`).
pub const RESUME_PROGRAM: &str = "CAMLOOP_RESUME";
/// The variable the resume subprogram sets: the first feature (from 1) to grind.
pub(crate) const FROM_VAR: &str = "CL_FROM";

/// One feature of the shaft as the main program grinds it.
#[derive(Debug, Clone)]
pub struct Station<'a> {
    /// The feature's table settings (its subprogram name, axes, decimals).
    pub table: &'a ProgramSettings,
    /// The feature's name, for the comment.
    pub label: &'a str,
    /// Axial position, mm.
    pub z_mm: f64,
}

/// Renders the main program of a shaft. The sequence per feature is the one-feature
/// program's (see [`super::render_main_program`]), wrapped in `IF CL_FROM<=k … ENDIF`, and
/// preceded by a rapid retract of X to `clear_x_mm` and a rapid move of the axial axis to the
/// station: Z never moves with the wheel at the part.
///
/// A run grinds the whole shaft unless the operator asks otherwise through R parameter
/// `resume_r_param` (default R90), which the run resets to 0:
/// - `R90 < 0`: resume at the first feature camloop has no gauge record of for the shaft in
///   the machine (the resume subprogram camloop rewrites after every gauged feature);
/// - `R90 = k > 0`: start at feature k.
///
/// A plain start never resumes: a new shaft loaded after an interrupted one must be ground
/// whole, and only the operator knows which is in the machine.
///
/// ```text
/// DEF REAL CL_C, CL_X, CL_SLOPE
/// DEF INT CL_TNO, CL_FROM
/// EXTERN CAMLOOP_RESUME(VAR INT)
/// EXTERN <TABLE_k>(VAR INT)            ; one per feature
/// IF $AA_COUP_ACT[X]<>0 … LEADOF … ENDIF
/// CL_FROM=1
/// IF R90<0 CAMLOOP_RESUME(CL_FROM) ENDIF
/// IF R90>0 CL_FROM=R90 ENDIF
/// R90=0
/// IF CL_FROM<=k                        ; feature k
/// G0 X=<clear>
/// G0 Z=<station k>
/// <TABLE_k>(CL_TNO)
/// STOPRE … LEADON(X,C,CL_TNO) POS[C]=IC(…) FA[C]=… WAITP(C) LEADOF(X,C)
/// ENDIF
/// G0 X=<clear>
/// M30
/// ```
pub fn render_shaft_program(
    main: &MainProgramSettings,
    stations: &[Station<'_>],
    clear_x_mm: f64,
) -> Result<String, SettingsErrors> {
    let resolved = check_shaft_program(main, stations, clear_x_mm)?;
    let first = &resolved[0];
    let (x, c) = (first.following.as_str(), first.leading.as_str());
    let xd = usize::from(first.settings.x_decimals);
    let z = &main.axial_axis;
    let externs: Vec<&str> = std::iter::once(RESUME_PROGRAM)
        .chain(resolved.iter().map(|r| r.name.as_str()))
        .collect();
    let mut out = String::new();
    opening(
        &mut out,
        &Opening {
            name: &main.name,
            reals: &[],
            ints: &[FROM_VAR],
            externs: &externs,
            pair_externs: &[],
            comments: &main.comment_lines,
            following: x,
            leading: c,
        },
    );
    resume_point(&mut out, main.resume_r_param);
    let clear = fmt_fixed(clear_x_mm, xd);
    for (k, (s, r)) in stations.iter().zip(&resolved).enumerate() {
        line(
            &mut out,
            format_args!("IF {FROM_VAR}<={} ; feature {} {}", k + 1, k + 1, s.label),
        );
        line(&mut out, format_args!("G0 {x}={clear} ; clear of the part"));
        line(
            &mut out,
            format_args!("G0 {z}={} ; station of {}", fmt_fixed(s.z_mm, 3), s.label),
        );
        define_table(&mut out, &r.name);
        coupled_revolutions(&mut out, main, r, false);
        out.push_str("ENDIF\n");
    }
    line(&mut out, format_args!("G0 {x}={clear}"));
    out.push_str("M30\n");
    // The rule every grinding main program meets: X clear of the part at the end.
    check_ending(&out, x, clear_x_mm)
        .map_err(|e| SettingsErrors(vec![SettingError::Unsafe(e.to_string())]))?;
    Ok(out)
}

/// Sets `CL_FROM`, the first feature this run grinds: 1, or where the operator resumes
/// through R parameter `r` (below 0: the resume subprogram's feature; above: that feature),
/// which the run then resets to 0. Shared by the shaft and whole-cycle programs.
pub(crate) fn resume_point(out: &mut String, r: u32) {
    line(
        out,
        format_args!("{FROM_VAR}=1 ; a new shaft: every feature"),
    );
    line(
        out,
        format_args!("IF R{r}<0 ; resume: the first feature without a gauge record"),
    );
    line(out, format_args!("{RESUME_PROGRAM}({FROM_VAR})"));
    out.push_str("ENDIF\n");
    line(
        out,
        format_args!("IF R{r}>0 ; the operator names the feature to start at"),
    );
    line(out, format_args!("{FROM_VAR}=R{r}"));
    out.push_str("ENDIF\n");
    line(out, format_args!("R{r}=0 ; a resume applies to one run"));
}

/// Every problem with the settings at once; the stations' resolved tables when none.
fn check_shaft_program<'a>(
    main: &MainProgramSettings,
    stations: &[Station<'a>],
    clear_x_mm: f64,
) -> Result<Vec<Resolved<'a>>, SettingsErrors> {
    let mut errors = Vec::new();
    if stations.is_empty() {
        errors.push(SettingError::NoFeatures);
    }
    let mut resolved = Vec::new();
    for s in stations {
        match s.table.resolve_for_main() {
            Ok(r) => resolved.push(r),
            Err(e) => errors.extend(e.0),
        }
        if !s.z_mm.is_finite() {
            errors.push(SettingError::NotFinite {
                field: "z_mm",
                value: s.z_mm,
            });
        }
    }
    if !(1..=999).contains(&main.resume_r_param) {
        errors.push(SettingError::NotPositive {
            field: "resume_r_param",
            value: f64::from(main.resume_r_param),
        });
    }
    if let Err(e) = validate_axis_name("axial", &main.axial_axis) {
        errors.push(e.into());
    }
    check_positive(&mut errors, "revolutions", main.revolutions);
    check_positive(&mut errors, "c_speed_rpm", main.c_speed_rpm);
    check_positive(&mut errors, "x_feed_mm_min", main.x_feed_mm_min);
    check_comments(&mut errors, &main.comment_lines);
    if !clear_x_mm.is_finite() {
        errors.push(SettingError::NotFinite {
            field: "clear_x_mm",
            value: clear_x_mm,
        });
    }
    if !errors.is_empty() {
        return Err(SettingsErrors(errors));
    }
    Ok(resolved)
}

/// The resume subprogram: hands the main program the first feature to grind (from 1).
/// camloop rewrites it after every gauged feature; an operator may write it by hand.
pub fn render_resume_program(first_feature: usize) -> String {
    let mut out = String::new();
    line(&mut out, format_args!("%_N_{RESUME_PROGRAM}_SPF"));
    out.push_str(";$PATH=/_N_SPF_DIR\n");
    line(
        &mut out,
        format_args!("PROC {RESUME_PROGRAM}(VAR INT {FROM_VAR}) SAVE"),
    );
    out.push_str(
        "; written by camloop after each gauged feature: the first feature of the shaft\n",
    );
    out.push_str("; in the machine not yet ground and gauged (1: a new shaft)\n");
    line(&mut out, format_args!("{FROM_VAR}={first_feature}"));
    out.push_str("RET\n");
    out
}

/// The first feature a resume subprogram names, if `text` is one.
pub fn parse_resume_program(text: &str) -> Option<usize> {
    lines(text).find_map(|l| match l.statement() {
        Ok(Some(Statement::Assign { target, value })) if target == FROM_VAR => value
            .number()
            .filter(|n| n.fract() == 0.0 && *n >= 0.0 && *n <= usize::MAX as f64)
            .map(|n| n as usize),
        _ => None,
    })
}
