//! The main-program fragment that defines the table, puts X on the curve, couples X to C
//! with the table just defined, turns C for the grinding revolutions and uncouples.

use serde::Deserialize;

use super::ProgramSettings;
use super::names::validate_program_name;
use super::settings::{Resolved, SettingError, SettingsErrors, check_comments, check_positive};
use super::table::{NUMBER_VAR, fmt_fixed, line};

/// How the main-program fragment is written. `Default`: `CAMLOOP_GRIND`, 3 revolutions at
/// 10 rpm, X onto the curve at 100 mm/min.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MainProgramSettings {
    /// Main program name (file `<NAME>_MPF`), same rules as the table subprogram's, and
    /// different from it.
    pub name: String,
    /// Revolutions of C while X is coupled, > 0 (fractions allowed).
    pub revolutions: f64,
    /// C speed while coupled, rpm, > 0 (written as `FA` in deg/min).
    pub c_speed_rpm: f64,
    /// Feed of the X move onto the curve before coupling, mm/min, > 0.
    pub x_feed_mm_min: f64,
    /// Comment lines written after the `DEF` line, without `;`. Printable ASCII only.
    pub comment_lines: Vec<String>,
    /// The axis along the shaft, moved to each feature's station in a shaft program.
    pub axial_axis: String,
    /// The R parameter through which an operator resumes a shaft program (see
    /// [`super::render_shaft_program`]).
    pub resume_r_param: u32,
}

impl Default for MainProgramSettings {
    fn default() -> Self {
        Self {
            name: "CAMLOOP_GRIND".to_owned(),
            revolutions: 3.0,
            c_speed_rpm: 10.0,
            x_feed_mm_min: 100.0,
            comment_lines: Vec::new(),
            axial_axis: "Z".to_owned(),
            resume_r_param: 90,
        }
    }
}

/// Render the main-program fragment that calls the table subprogram of `table`, couples X
/// to C with the table it just defined, turns C and uncouples.
///
/// ```text
/// %_N_<MAIN>_MPF
/// ;$PATH=/_N_MPF_DIR
/// DEF REAL CL_C, CL_X, CL_SLOPE        ; definitions come first
/// DEF INT CL_TNO
/// EXTERN <TABLE>(VAR INT)
/// ; comment lines
/// IF $AA_COUP_ACT[X]<>0                ; a coupling left active by an aborted run
/// LEADOF(X,C)
/// ENDIF
/// <TABLE>(CL_TNO)                      ; defines the newest table, returns its number
/// STOPRE
/// CL_C=$AA_IW[C]
/// CL_X=CTAB(CL_C,CL_TNO,CL_SLOPE)
/// G90 G1 X=CL_X F=<feed>
/// LEADON(X,C,CL_TNO)
/// POS[C]=IC(<360·revs>) FA[C]=<360·rpm>
/// WAITP(C)
/// LEADOF(X,C)
/// M30
/// ```
///
/// **The table number is not in this program.** The table subprogram alternates its number
/// between versions and returns it in `CL_TNO` (call by reference), and `CTAB` and `LEADON`
/// use that variable: the control always couples the table just defined, never the previous
/// one still in its memory. `table.table_number` is neither read nor checked, so the text
/// depends only on the names, axes and C decimals: deliver it once and rewrite it only when
/// those settings change.
///
/// A coupling left active by an aborted run would make the control refuse to redefine its
/// table; `$AA_COUP_ACT[X]` reports an active coupling (16 for a master-value coupling) [K],
/// so the program releases it first.
///
/// The X offset of the table settings is already inside the table, so the X target is
/// `CTAB(C)` itself; an output offset in SD43106 (or an infeed via `$AA_OFF`) would have to be
/// added to it, otherwise LEADON makes a synchronising move [M-old].
///
/// `$AA_IW[C]` is the **setpoint** of C in workpiece coordinates (without DRF, `$AA_OFF` and
/// external offsets), not a measured actual value [K]; it is read after `STOPRE` so that it
/// is current. camloop applies the part's C offset inside the table (`c_offset_deg`), so a C
/// work offset active on the machine shifts `$AA_IW[C]`, and with it the part, by that
/// amount: leave it at 0 or account for it in `c_offset_deg`. Still open, inferred rather
/// than confirmed on a control:
/// - whether LEADON takes the leading value in machine or in workpiece coordinates, i.e.
///   whether `CTAB` at `$AA_IW[C]` is exactly where the coupling will put X [?];
/// - `FA[C]` is in deg/min for a rotary positioning axis and `POS[C]=IC(…)` turns a modulo
///   axis by more than 360° [?];
/// - the X move onto the curve is a plain G1 at the part: approach and infeed are the
///   machine builder's cycle, this fragment only shows the coupling sequence.
///
/// `CTAB` reduces a leading value outside a periodic table's range into the period [M-old].
/// Variable names contain `_`, which axis names cannot, so they never clash with an axis.
pub fn render_main_program(
    main: &MainProgramSettings,
    table: &ProgramSettings,
) -> Result<String, SettingsErrors> {
    let mut errors = Vec::new();
    let resolved = table
        .resolve_for_main()
        .map_err(|e| errors.extend(e.0))
        .ok();
    let main_name = validate_program_name(&main.name)
        .map_err(|e| errors.push(e.into()))
        .ok();
    if let (Some(m), Some(r)) = (&main_name, &resolved)
        && *m == r.name
    {
        errors.push(SettingError::MainSameAsTable { name: m.clone() });
    }
    check_positive(&mut errors, "revolutions", main.revolutions);
    check_positive(&mut errors, "c_speed_rpm", main.c_speed_rpm);
    check_positive(&mut errors, "x_feed_mm_min", main.x_feed_mm_min);
    check_comments(&mut errors, &main.comment_lines);
    let (Some(main_name), Some(r), true) = (main_name, resolved, errors.is_empty()) else {
        return Err(SettingsErrors(errors));
    };
    Ok(main_text(main, &main_name, &r))
}

fn main_text(main: &MainProgramSettings, main_name: &str, r: &Resolved<'_>) -> String {
    let (x, c, t) = (r.following.as_str(), r.leading.as_str(), r.name.as_str());
    let mut out = String::new();
    opening(
        &mut out,
        &Opening {
            name: main_name,
            reals: &[],
            ints: &[],
            externs: &[t],
            pair_externs: &[],
            comments: &main.comment_lines,
            following: x,
            leading: c,
        },
    );
    define_table(&mut out, t);
    coupled_revolutions(&mut out, main, r, true);
    out.push_str("M30\n");
    out
}

/// The opening every main program shares: header, the coupling's variables (`CL_C, CL_X,
/// CL_SLOPE` and the table number) with the program's own after them, one `EXTERN` per
/// subprogram, the comment lines, and the release of a coupling an aborted run left active
/// (the control would refuse to redefine its table under it).
pub(crate) struct Opening<'a> {
    pub name: &'a str,
    pub reals: &'a [&'a str],
    pub ints: &'a [&'a str],
    pub externs: &'a [&'a str],
    /// Subprograms that return two numbers (a speed plan's table program: `CL_TNO`,
    /// `CL_TNO_C`).
    pub pair_externs: &'a [&'a str],
    pub comments: &'a [String],
    pub following: &'a str,
    pub leading: &'a str,
}

pub(crate) fn opening(out: &mut String, o: &Opening<'_>) {
    let (x, c) = (o.following, o.leading);
    line(out, format_args!("%_N_{}_MPF", o.name));
    out.push_str(";$PATH=/_N_MPF_DIR\n");
    let more = |names: &[&str]| names.iter().map(|n| format!(", {n}")).collect::<String>();
    line(
        out,
        format_args!("DEF REAL CL_C, CL_X, CL_SLOPE{}", more(o.reals)),
    );
    line(out, format_args!("DEF INT {NUMBER_VAR}{}", more(o.ints)));
    for name in o.externs {
        line(out, format_args!("EXTERN {name}(VAR INT)"));
    }
    for name in o.pair_externs {
        line(out, format_args!("EXTERN {name}(VAR INT, VAR INT)"));
    }
    for comment in o.comments {
        line(out, format_args!("; {comment}"));
    }
    line(
        out,
        format_args!("IF $AA_COUP_ACT[{x}]<>0 ; a coupling left active by an aborted run"),
    );
    line(out, format_args!("LEADOF({x},{c})"));
    out.push_str("ENDIF\n");
}

/// The table subprogram's call: it defines the newest table and returns its number.
pub(crate) fn define_table(out: &mut String, table: &str) {
    line(
        out,
        format_args!("{table}({NUMBER_VAR}) ; defines the newest curve table, returns its number"),
    );
}

/// The coupled grind both main programs run once the table program has returned its number
/// in `CL_TNO`: wait for the definition, put X on the curve at the current C, couple, turn C
/// the revolutions at the grinding speed, uncouple. With `explained`, the lines carry the
/// comments a reader of a one-feature program needs (a shaft program repeats the block per
/// feature and leaves them out).
pub(crate) fn coupled_revolutions(
    out: &mut String,
    main: &MainProgramSettings,
    r: &Resolved<'_>,
    explained: bool,
) {
    let (x, c, n) = (&r.following, &r.leading, NUMBER_VAR);
    let cd = usize::from(r.settings.c_decimals);
    let why = |text: &str| {
        if explained {
            format!(" ; {text}")
        } else {
            String::new()
        }
    };
    line(
        out,
        format_args!(
            "STOPRE{}",
            why("read C below only after the table is defined")
        ),
    );
    line(
        out,
        format_args!(
            "CL_C=$AA_IW[{c}]{}",
            why(&format!("setpoint of {c} in workpiece coordinates"))
        ),
    );
    line(
        out,
        format_args!(
            "CL_X=CTAB(CL_C,{n},CL_SLOPE){}",
            why(&format!("{x} on the curve at the current {c}"))
        ),
    );
    line(
        out,
        format_args!("G90 G1 {x}=CL_X F={}", fmt_fixed(main.x_feed_mm_min, 3)),
    );
    line(out, format_args!("LEADON({x},{c},{n})"));
    line(
        out,
        format_args!(
            "POS[{c}]=IC({}) FA[{c}]={} ; {} rev at {} rpm",
            fmt_fixed(360.0 * main.revolutions, cd),
            fmt_fixed(360.0 * main.c_speed_rpm, 3),
            main.revolutions,
            main.c_speed_rpm
        ),
    );
    line(out, format_args!("WAITP({c})"));
    line(out, format_args!("LEADOF({x},{c})"));
}
