//! The whole-cycle program's stages on the speed plan: the feature's plan table program
//! (C = f(VA) and X = g(VA), see [`crate::speed_plan::render`]) called for its two numbers,
//! C and X put on their curves at VA = 0 with X the stock and air gap above (the coupling's
//! output offset, as at constant speed), both coupled to the virtual axis with the numbers
//! just returned, and the infeed superimposed on the coupled X while VA turns (`FGROUP(VA)`:
//! one revolution of C per revolution of VA, so the infeed per revolution is the stage's).
//!
//! Stages at a constant C speed keep X coupled to C by the feature's constant-speed table
//! program; the program uncouples (lift-off) and couples again wherever the mode changes, so
//! every coupling still takes the newest table of its kind.
//!
//! [?] on a control, beyond the speed plan's own open points: that X's overlay (DBX26.4)
//! is superimposed on a coupling to a simulated leading axis as on one to C, and that
//! `FGROUP(VA)` spreads it over VA's travel.

use super::settings::Resolved;
use super::table::{NUMBER_VAR, fmt_fixed, line};
use super::{validate_axis_name, validate_program_name};
use crate::speed_plan::render::{C_NUMBER_VAR, VaProgramSettings};

/// A feature's speed plan, for the stages that run on it.
#[derive(Debug, Clone, Copy)]
pub struct CyclePlan<'a> {
    /// The plan's table program: both tables over the virtual axis, their numbers returned
    /// as `CL_TNO` (X) and `CL_TNO_C` (C). Its name must differ from the constant-speed
    /// table program's.
    pub table: &'a VaProgramSettings,
    /// The virtual axis' speed the tables were made for, rev/min (one revolution of C per
    /// revolution of VA).
    pub va_speed_rpm: f64,
}

/// A plan checked against its feature: canonical names.
#[derive(Debug, Clone)]
pub(super) struct PlanResolved {
    pub name: String,
    pub va: String,
    pub va_speed_rpm: f64,
}

/// The plan's names and speed, sound and agreeing with the constant-speed table's axes;
/// else what is wrong, naming the feature.
pub(super) fn resolve_plan(
    label: &str,
    plan: &CyclePlan<'_>,
    r: &Resolved<'_>,
) -> Result<PlanResolved, String> {
    let t = plan.table;
    let name = validate_program_name(&t.name).map_err(|e| format!("feature {label}: {e}"))?;
    let va = validate_axis_name("virtual leading", &t.virtual_axis)
        .map_err(|e| format!("feature {label}: {e}"))?;
    if name == r.name {
        return Err(format!(
            "feature {label}: the plan's table program {name} must differ from the constant-speed one"
        ));
    }
    let same = |a: &str, b: &str| a.eq_ignore_ascii_case(b);
    if !same(&t.x_axis, &r.following) || !same(&t.c_axis, &r.leading) || same(&va, &r.leading) {
        return Err(format!(
            "feature {label}: the plan couples {} and {} to {va}, the cycle grinds {} over {}",
            t.x_axis, t.c_axis, r.following, r.leading
        ));
    }
    if !(plan.va_speed_rpm.is_finite() && plan.va_speed_rpm > 0.0) {
        return Err(format!(
            "feature {label}: virtual axis speed {} rpm must be a number > 0",
            plan.va_speed_rpm
        ));
    }
    Ok(PlanResolved {
        name,
        va,
        va_speed_rpm: plan.va_speed_rpm,
    })
}

/// Releases couplings to the virtual axis an aborted run left active (the opening releases
/// X's coupling to C).
pub(super) fn release(out: &mut String, x: &str, c: &str, va: &str) {
    for axis in [x, c] {
        line(
            out,
            format_args!("IF $AA_COUP_ACT[{axis}]<>0 ; a coupling to {va} left by an aborted run"),
        );
        line(out, format_args!("LEADOF({axis},{va})"));
        out.push_str("ENDIF\n");
    }
}

/// Defines the plan's newest tables, stands C on its curve and X the stock and air gap
/// above its curve at VA = 0, and couples both to VA with the numbers just returned. X goes
/// to `clear` (absolute, above every finished curve plus the lift-off) before C turns to
/// the plan's start: after a lift-off X is only the lift-off above the curve where C
/// stopped, and a lobe's nose turning under it would meet the wheel.
pub(super) fn couple(
    out: &mut String,
    r: &Resolved<'_>,
    p: &PlanResolved,
    (offset_line, clear): (&str, &str),
) {
    let (x, c, va, n, cn) = (&r.following, &r.leading, &p.va, NUMBER_VAR, C_NUMBER_VAR);
    line(
        out,
        format_args!(
            "{}({n},{cn}) ; defines the plan's newest tables, returns their numbers",
            p.name
        ),
    );
    out.push_str(offset_line);
    line(out, format_args!("G90 G0 {va}=0"));
    line(
        out,
        format_args!("CL_C=CTAB(0,{cn},CL_SLOPE) ; {c} on its curve at {va} = 0"),
    );
    line(out, format_args!("CL_X=CTAB(0,{n},CL_SLOPE)"));
    out.push_str("CL_X=CL_X+CL_OFF\n");
    line(
        out,
        format_args!("G90 G0 {x}={clear} ; clear of the part before {c} turns"),
    );
    line(out, format_args!("POS[{c}]=DC(CL_C) FA[{c}]=3600"));
    line(out, format_args!("WAITP({c})"));
    line(out, format_args!("G90 G1 {x}=CL_X F=100.000"));
    line(out, format_args!("LEADON({c},{va},{cn})"));
    line(out, format_args!("LEADON({x},{va},{n})"));
    line(
        out,
        format_args!("FGROUP({va}) ; F is {va}'s speed, {x}'s overlay moves in proportion"),
    );
}

/// The comment of a stage on the plan: VA's speed and the revolution's time.
pub(super) fn speed_note(p: &PlanResolved) -> String {
    format!(
        "on the speed plan ({} at {} rpm, {} s a revolution)",
        p.va,
        fmt_fixed(p.va_speed_rpm, 4),
        fmt_fixed(60.0 / p.va_speed_rpm, 4)
    )
}
