//! The main program of the whole grinding cycle (`[cycle] program = "whole"`): wheel spindle
//! and coolant on, then per feature the approach, the coupling, the stages with their infeed
//! superimposed on the coupled X, the measurement before the finish with its handshake,
//! spark-out, lift-off and uncoupling; at the end X back clear of the part (an absolute
//! rapid move, checked by [`super::check_ending`]), then coolant and spindle off.
//!
//! With several features the program resumes as the shaft program does: R parameter 90
//! (`resume_r_param`) below 0 starts at the first feature without a gauge record (the
//! resume subprogram camloop rewrites after every gauged feature), k > 0 at feature k, and
//! the run resets it to 0. A feature before the start is jumped over (`IF CL_FROM>k GOTOF
//! CL_SKIPk`) rather than wrapped in `IF … ENDIF`, so no label of its handshake lies inside
//! a control structure.
//!
//! Every coupling is made with the number the table program just returned, as in the
//! table-only program: the finish after a measurement calls the table program again, so it
//! couples the newest table (this part's finish table when camloop delivered it in time, the
//! table in force otherwise). Stages with `speed_plan = true` couple C and X to the virtual
//! axis by the numbers the feature's plan table program returns ([`super::cycle_plan`]).

use super::ProgramSettings;
use super::cycle_plan::{self, CyclePlan, PlanResolved};
use super::ending::{EndingError, check_ending};
use super::main_program::{MainProgramSettings, Opening, define_table, opening};
use super::names::validate_axis_name;
use super::settings::{Resolved, SettingsErrors, check_comments};
use super::shaft_program::{FROM_VAR, RESUME_PROGRAM, resume_point};
use super::table::{NUMBER_VAR, fmt_fixed, line};
use crate::cycle::{CycleSettings, ResolvedStage, StageKind, stage_key};
use crate::speed_plan::render::C_NUMBER_VAR;

/// The handshake subprogram's name (file `CAMLOOP_READY.SPF`): it returns how many same-part
/// finish tables camloop has delivered to this machine.
pub const READY_PROGRAM: &str = "CAMLOOP_READY";
/// The coupling's output offset of the following axis (SD43106), written by the program.
pub const OUTPUT_OFFSET: &str = "$SA_LEAD_OFFSET_OUT_POS";
/// How often the control asks the handshake subprogram while it waits, s.
pub const POLL_S: f64 = 0.1;

/// X clearance above the highest X of the finished curves where X moves freely (Z to a
/// station, the end of a program), mm.
pub const CLEARANCE_MM: f64 = 5.0;

/// The clear X of a main program: the highest X of any feature's finished curve
/// (`top_x_mm`, lift plus `x_offset_mm`) plus the larger of [`CLEARANCE_MM`] and the cycle's
/// lift-off (0 without a cycle), so the retract never moves X towards the part from where
/// the lift-off left it.
pub fn clear_x_mm(top_x_mm: f64, lift_off_mm: f64) -> f64 {
    top_x_mm + CLEARANCE_MM.max(lift_off_mm)
}

/// One feature as the cycle grinds it.
#[derive(Debug, Clone)]
pub struct CycleStation<'a> {
    pub table: &'a ProgramSettings,
    pub label: &'a str,
    pub z_mm: f64,
    /// The feature's speed plan, for stages with `speed_plan = true` (refused without it).
    pub plan: Option<CyclePlan<'a>>,
}

/// The cycle and the machine facts its program needs.
#[derive(Debug, Clone, Copy)]
pub struct CycleMachine<'a> {
    pub cycle: &'a CycleSettings,
    /// The grinding C speed of stages that name none, rpm.
    pub c_speed_rpm: f64,
    /// The wheel's radius, mm: turns the surface speed into spindle rpm.
    pub wheel_radius_mm: f64,
    /// X clear of the part, absolute, mm: where X goes before Z moves (several features)
    /// and at the end of the program, after the last uncoupling. It must lie above every
    /// feature's finished curve plus the lift-off (the service takes the largest X of the
    /// curves plus the larger of 5 mm and `lift_off_mm`).
    pub clear_x_mm: f64,
}

/// Why no cycle program was written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CycleProgramError {
    #[error("{0}")]
    Settings(#[from] SettingsErrors),
    #[error("{}", .0.join("; "))]
    Cycle(Vec<String>),
    #[error("the program would be unsafe to load: {0}")]
    Unsafe(#[from] EndingError),
    #[error("{0}: on the speed plan, but feature {1} has no plan tables")]
    PlanStage(String, String),
}

/// Renders the whole-cycle main program for `stations` (one or more features in turn).
pub fn render_cycle_program(
    main: &MainProgramSettings,
    machine: &CycleMachine<'_>,
    stations: &[CycleStation<'_>],
) -> Result<String, CycleProgramError> {
    let (resolved, stages, plans) = check(main, machine, stations)?;
    let first = &resolved[0];
    let (x, c) = (first.following.as_str(), first.leading.as_str());
    let cycle = machine.cycle;
    let spindle = cycle.wheel_spindle;
    // Several features: resumable as the shaft program is.
    let resumable = stations.len() > 1;
    let externs: Vec<&str> = std::iter::once(READY_PROGRAM)
        .chain(resumable.then_some(RESUME_PROGRAM))
        .chain(resolved.iter().map(|r| r.name.as_str()))
        .collect();
    let planned = plans.iter().any(Option::is_some);
    let ints: Vec<&str> = ["CL_SEEN", "CL_READY", "CL_NEW", "CL_WAIT"]
        .into_iter()
        .chain(resumable.then_some(FROM_VAR))
        .chain(planned.then_some(C_NUMBER_VAR))
        .collect();
    let pair_externs: Vec<&str> = plans.iter().flatten().map(|p| p.name.as_str()).collect();
    let mut out = String::new();
    opening(
        &mut out,
        &Opening {
            name: &main.name,
            reals: &["CL_OFF"],
            ints: &ints,
            externs: &externs,
            pair_externs: &pair_externs,
            comments: &main.comment_lines,
            following: x,
            leading: c,
        },
    );
    if let Some(p) = plans.iter().flatten().next() {
        cycle_plan::release(&mut out, x, c, &p.va);
    }
    if resumable {
        resume_point(&mut out, main.resume_r_param);
    }
    output_offset(
        &mut out,
        x,
        "0",
        "no output offset left from an aborted run",
    );
    out.push_str("G90 G94 G71 ; absolute, feed per minute, metric\n");
    let first_speed = stages
        .first()
        .map_or(cycle.wheel_speed_m_s, |s| s.wheel_speed_m_s);
    line(
        &mut out,
        format_args!(
            "M{spindle}=3 S{spindle}={} ; wheel spindle on, {first_speed} m/s",
            fmt_fixed(wheel_rpm(first_speed, machine.wheel_radius_mm), 1)
        ),
    );
    out.push_str("M8 ; coolant on\n");
    let xd = usize::from(first.settings.x_decimals);
    let clear = fmt_fixed(machine.clear_x_mm, xd);
    for (k, ((s, r), plan)) in stations.iter().zip(&resolved).zip(&plans).enumerate() {
        line(&mut out, format_args!("; feature {} {}", k + 1, s.label));
        if resumable {
            line(
                &mut out,
                format_args!(
                    "IF {FROM_VAR}>{} GOTOF CL_SKIP{} ; resumed past it",
                    k + 1,
                    k + 1
                ),
            );
            line(
                &mut out,
                format_args!("G90 G0 {x}={clear} ; clear of the part"),
            );
            line(
                &mut out,
                format_args!(
                    "G0 {}={} ; station of {}",
                    main.axial_axis,
                    fmt_fixed(s.z_mm, 3),
                    s.label
                ),
            );
        }
        feature_cycle(&mut out, machine, &stages, (r, plan.as_ref()), k + 1);
        if resumable {
            line(&mut out, format_args!("CL_SKIP{}:", k + 1));
        }
    }
    output_offset(&mut out, x, "0", "the output offset back to 0");
    line(
        &mut out,
        format_args!("G90 G0 {x}={clear} ; retract clear of the part"),
    );
    out.push_str("M9 ; coolant off\n");
    line(&mut out, format_args!("M{spindle}=5 ; wheel spindle stop"));
    out.push_str("M30\n");
    check_ending(&out, x, machine.clear_x_mm).map_err(CycleProgramError::Unsafe)?;
    Ok(out)
}

/// The handshake subprogram camloop writes after each same-part finish table is durable on
/// the share: `count` such tables so far (the control waits for the count to change).
pub fn render_ready_program(count: u64) -> String {
    let mut out = String::new();
    line(&mut out, format_args!("%_N_{READY_PROGRAM}_SPF"));
    out.push_str(";$PATH=/_N_SPF_DIR\n");
    line(
        &mut out,
        format_args!("PROC {READY_PROGRAM}(VAR INT CL_READY) SAVE"),
    );
    out.push_str("; written by camloop once a same-part finish table is on the share\n");
    line(&mut out, format_args!("CL_READY={count}"));
    out.push_str("RET\n");
    out
}

/// Spindle speed for a surface speed, rpm.
pub fn wheel_rpm(surface_m_s: f64, radius_mm: f64) -> f64 {
    surface_m_s * 60_000.0 / (std::f64::consts::TAU * radius_mm)
}

type Checked<'a> = (
    Vec<Resolved<'a>>,
    Vec<ResolvedStage>,
    Vec<Option<PlanResolved>>,
);

fn check<'a>(
    main: &MainProgramSettings,
    machine: &CycleMachine<'_>,
    stations: &[CycleStation<'a>],
) -> Result<Checked<'a>, CycleProgramError> {
    let mut errors = Vec::new();
    let mut resolved = Vec::new();
    if stations.is_empty() {
        errors.push(super::SettingError::NoFeatures);
    }
    for s in stations {
        match s.table.resolve_for_main() {
            Ok(r) => resolved.push(r),
            Err(e) => errors.extend(e.0),
        }
    }
    if let Err(e) = super::validate_program_name(&main.name) {
        errors.push(e.into());
    }
    if let Err(e) = validate_axis_name("axial", &main.axial_axis) {
        errors.push(e.into());
    }
    check_comments(&mut errors, &main.comment_lines);
    if stations.len() > 1 && !(1..=999).contains(&main.resume_r_param) {
        errors.push(super::SettingError::NotPositive {
            field: "resume_r_param",
            value: f64::from(main.resume_r_param),
        });
    }
    if !errors.is_empty() {
        return Err(SettingsErrors(errors).into());
    }
    let mut problems = machine.cycle.problems(false);
    for (what, v) in [
        ("wheel radius", machine.wheel_radius_mm),
        ("c_speed_rpm", machine.c_speed_rpm),
    ] {
        if !(v.is_finite() && v > 0.0) {
            problems.push(format!("{what} = {v}: must be a number > 0"));
        }
    }
    if !machine.clear_x_mm.is_finite() {
        problems.push(format!("clear X = {}: must be finite", machine.clear_x_mm));
    }
    // A stage on the plan is refused below, by its own error; the rest must be sound.
    problems.retain(|p| !p.contains(".speed_plan: needs [speed_plan]"));
    if !problems.is_empty() {
        return Err(CycleProgramError::Cycle(problems));
    }
    let stages = machine.cycle.resolved(machine.c_speed_rpm);
    let on_plan = stages.iter().position(|s| s.c_speed_rpm.is_none());
    let mut plans = Vec::new();
    for (s, r) in stations.iter().zip(&resolved) {
        match (&s.plan, on_plan) {
            (None, Some(i)) => {
                return Err(CycleProgramError::PlanStage(
                    stage_key(i, stages[i].kind),
                    s.label.to_owned(),
                ));
            }
            // A plan no stage runs on is not called.
            (_, None) => plans.push(None),
            (Some(p), Some(_)) => match cycle_plan::resolve_plan(s.label, p, r) {
                Ok(p) => plans.push(Some(p)),
                Err(e) => problems.push(e),
            },
        }
    }
    if !problems.is_empty() {
        return Err(CycleProgramError::Cycle(problems));
    }
    Ok((resolved, stages, plans))
}

/// `STOPRE` then the output offset: setting data are written as the block is prepared, so
/// the motion before it must be finished first.
fn output_offset(out: &mut String, x: &str, value: &str, why: &str) {
    out.push_str("STOPRE\n");
    line(out, format_args!("{OUTPUT_OFFSET}[{x}]={value} ; {why}"));
}

/// How X is coupled: to C by the constant-speed table, or with C to the virtual axis by the
/// plan's tables.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Constant,
    Plan,
}

/// The axis whose travel a coupled block programs, its speed (rpm) and the stage comment's
/// note on it.
fn lead<'r>(
    mode: Mode,
    s: &ResolvedStage,
    r: &'r Resolved<'_>,
    plan: Option<&'r PlanResolved>,
) -> (&'r str, f64, String) {
    match (mode, plan, s.c_speed_rpm) {
        (Mode::Plan, Some(p), _) => (&p.va, p.va_speed_rpm, cycle_plan::speed_note(p)),
        (_, _, rpm) => {
            let rpm = rpm.unwrap_or(0.0);
            (&r.leading, rpm, format!("at {rpm} rpm"))
        }
    }
}

type Feature<'f, 'a> = (&'f Resolved<'a>, Option<&'f PlanResolved>);

/// One feature's cycle: coupled segments split at the measurement and wherever a stage's
/// mode (constant C speed or the plan) differs from the one before.
fn feature_cycle(
    out: &mut String,
    machine: &CycleMachine<'_>,
    stages: &[ResolvedStage],
    (r, plan): Feature<'_, '_>,
    k: usize,
) {
    let cycle = machine.cycle;
    let clear = fmt_fixed(machine.clear_x_mm, usize::from(r.settings.x_decimals));
    let mut stock_left = cycle.stock_mm;
    let mut coupled: Option<Mode> = None;
    for s in stages {
        if s.kind == StageKind::Measure {
            if let Some(mode) = coupled.take() {
                uncouple(out, (r, plan), mode, (cycle.lift_off_mm, &clear));
            }
            measure(out, machine, s, r, k, stock_left);
            continue;
        }
        let mode = if s.c_speed_rpm.is_some() {
            Mode::Constant
        } else {
            Mode::Plan
        };
        if let Some(was) = coupled.filter(|m| *m != mode) {
            uncouple(out, (r, plan), was, (cycle.lift_off_mm, &clear));
            coupled = None;
        }
        if coupled.is_none() {
            couple(out, machine, (r, plan), mode, stock_left, s);
            coupled = Some(mode);
        }
        stage(out, machine, s, r, lead(mode, s, r, plan));
        stock_left -= s.infeed_mm;
    }
    if let Some(mode) = coupled {
        uncouple(out, (r, plan), mode, (cycle.lift_off_mm, &clear));
    }
}

/// Defines the newest table(s), stands X the stock and the air gap above its curve (the
/// coupling's output offset), couples, and takes the air gap at the approach feed.
fn couple(
    out: &mut String,
    machine: &CycleMachine<'_>,
    (r, plan): Feature<'_, '_>,
    mode: Mode,
    stock_left: f64,
    next: &ResolvedStage,
) {
    let (x, c, t, n) = (&r.following, &r.leading, &r.name, NUMBER_VAR);
    let cd = usize::from(r.settings.c_decimals);
    let xd = usize::from(r.settings.x_decimals);
    let cycle = machine.cycle;
    let mut offset = String::new();
    line(
        &mut offset,
        format_args!(
            "CL_OFF={} ; stock {} mm and air gap {} mm above the curve",
            fmt_fixed(stock_left + cycle.approach_mm, xd),
            fmt_fixed(stock_left, xd),
            fmt_fixed(cycle.approach_mm, xd)
        ),
    );
    output_offset(
        &mut offset,
        x,
        "CL_OFF",
        "SD43106: X couples this far above the curve",
    );
    match (mode, plan) {
        (Mode::Plan, Some(p)) => {
            let clear = fmt_fixed(machine.clear_x_mm, xd);
            cycle_plan::couple(out, r, p, (&offset, &clear));
        }
        _ => {
            define_table(out, t);
            out.push_str(&offset);
            line(out, format_args!("CL_C=$AA_IW[{c}]"));
            line(out, format_args!("CL_X=CTAB(CL_C,{n},CL_SLOPE)"));
            out.push_str("CL_X=CL_X+CL_OFF\n");
            line(out, format_args!("G90 G1 {x}=CL_X F=100.000"));
            line(out, format_args!("LEADON({x},{c},{n})"));
            line(
                out,
                format_args!("FGROUP({c}) ; F is {c}'s speed, {x}'s overlay moves in proportion"),
            );
        }
    }
    let (axis, rpm, _) = lead(mode, next, r, plan);
    let revs = cycle.approach_mm / cycle.approach_feed_mm_per_rev;
    line(
        out,
        format_args!(
            "G91 G1 {axis}={} {x}=-{} F={} ; approach: the air gap",
            fmt_fixed(360.0 * revs, cd),
            fmt_fixed(cycle.approach_mm, xd),
            fmt_fixed(360.0 * rpm, 3)
        ),
    );
    out.push_str("G90\n");
}

/// A coupled stage: the leading axis (C, or VA on the plan) turns the stage's revolutions
/// with its infeed superimposed on X.
fn stage(
    out: &mut String,
    machine: &CycleMachine<'_>,
    s: &ResolvedStage,
    r: &Resolved<'_>,
    (axis, rpm, note): (&str, f64, String),
) {
    let x = &r.following;
    let cd = usize::from(r.settings.c_decimals);
    let xd = usize::from(r.settings.x_decimals);
    let spindle = machine.cycle.wheel_spindle;
    line(
        out,
        format_args!(
            "; {}: {} mm in {} rev {note}, wheel {} m/s",
            s.kind.name(),
            fmt_fixed(s.infeed_mm, xd),
            s.revolutions,
            s.wheel_speed_m_s
        ),
    );
    line(
        out,
        format_args!(
            "S{spindle}={}",
            fmt_fixed(wheel_rpm(s.wheel_speed_m_s, machine.wheel_radius_mm), 1)
        ),
    );
    let infeed = if s.infeed_mm > 0.0 {
        format!(" {x}=-{}", fmt_fixed(s.infeed_mm, xd))
    } else {
        String::new()
    };
    line(
        out,
        format_args!(
            "G91 G1 {axis}={}{infeed} F={}",
            fmt_fixed(360.0 * s.revolutions, cd),
            fmt_fixed(360.0 * rpm, 3)
        ),
    );
    out.push_str("G90\n");
    if s.dwell_s > 0.0 {
        line(out, format_args!("G4 F={}", fmt_fixed(s.dwell_s, 3)));
    }
}

/// Lift-off on the overlay while still coupled, then uncouple (X, and on the plan C, from
/// the axis they follow), then X to `clear` (absolute): C turns uncoupled next (the
/// measurement's revolutions, the plan's start), and the lift-off alone leaves the wheel
/// above the curve only where C stopped, below a lobe's nose turning under it.
fn uncouple(
    out: &mut String,
    (r, plan): Feature<'_, '_>,
    mode: Mode,
    (lift_off_mm, clear): (f64, &str),
) {
    let (x, c) = (&r.following, &r.leading);
    let xd = usize::from(r.settings.x_decimals);
    line(
        out,
        format_args!("G91 G0 {x}={} ; lift off", fmt_fixed(lift_off_mm, xd)),
    );
    out.push_str("G90\n");
    out.push_str("FGROUP() ; the feed back to the path axes\n");
    match (mode, plan) {
        (Mode::Plan, Some(p)) => {
            line(out, format_args!("LEADOF({x},{})", p.va));
            line(out, format_args!("LEADOF({c},{})", p.va));
        }
        _ => line(out, format_args!("LEADOF({x},{c})")),
    }
    line(
        out,
        format_args!("G90 G0 {x}={clear} ; clear of the part before {c} turns"),
    );
}

/// The in-process measurement with stock on, then the wait for this part's finish table.
fn measure(
    out: &mut String,
    machine: &CycleMachine<'_>,
    s: &ResolvedStage,
    r: &Resolved<'_>,
    k: usize,
    stock_left: f64,
) {
    let c = &r.leading;
    let cd = usize::from(r.settings.c_decimals);
    let cycle = machine.cycle;
    let rpm = s.c_speed_rpm.unwrap_or(machine.c_speed_rpm);
    let (gauge_in, gauge_out) = cycle.gauge_m_codes;
    line(
        out,
        format_args!(
            "; measure: {} rev at {rpm} rpm, {} mm stock on",
            s.revolutions,
            fmt_fixed(stock_left, 4)
        ),
    );
    line(
        out,
        format_args!("{READY_PROGRAM}(CL_SEEN) ; same-part tables delivered before this one"),
    );
    line(out, format_args!("M{gauge_in} ; gauge in"));
    line(
        out,
        format_args!(
            "POS[{c}]=IC({}) FA[{c}]={}",
            fmt_fixed(360.0 * s.revolutions, cd),
            fmt_fixed(360.0 * rpm, 3)
        ),
    );
    line(out, format_args!("WAITP({c})"));
    line(out, format_args!("M{gauge_out} ; gauge out"));
    let polls = (cycle.handshake_timeout_s / POLL_S).ceil().max(1.0) as u64;
    line(
        out,
        format_args!(
            "; wait for this part's finish table, at most {} s, then grind with the table in force",
            cycle.handshake_timeout_s
        ),
    );
    out.push_str("CL_WAIT=0\n");
    line(out, format_args!("CL_HS{k}:"));
    line(out, format_args!("{READY_PROGRAM}(CL_READY)"));
    out.push_str("CL_NEW=CL_READY-CL_SEEN\n");
    line(out, format_args!("IF CL_NEW<>0 GOTOF CL_GO{k}"));
    line(out, format_args!("G4 F={}", fmt_fixed(POLL_S, 3)));
    out.push_str("CL_WAIT=CL_WAIT+1\n");
    line(out, format_args!("IF CL_WAIT<{polls} GOTOB CL_HS{k}"));
    line(out, format_args!("CL_GO{k}:"));
}
