//! The 802D study's editable R-parameter form: the curve's constants as R parameters at the
//! top of the program, and a loop at a fixed step of the curve's own parameter that reads
//! them, so a machinist can change a semi-axis or the end angle at the control.
//!
//! The 802D's manuals describe R parameters (`R0`–`R249`) and not `DEF` variables, so this
//! form declares nothing: every variable is an R parameter. The step is fixed (the count of
//! chords is a constant too), as the study's loops step, and is the smallest count whose
//! worst chord deviation, as written, stays within the tolerance. What was proven (chord deviation,
//! lead-in, lead-out, retract, the safety check) holds for the values as written; the
//! program's header says so.

use super::program::{Shape, assemble, nose_comment, shifted_by, side_sign};
use super::{Contour, ContourError, ContourJob, ContourReport, MAX_CHORDS, generate};
use crate::chords::{fixed_step_for, round_to};
use crate::curve::{Curve, Ellipse, Parabola, Sine, Tangent};
use crate::ir::{Axis, Cond, Expr, Motion, Program, Stmt, Var};
use crate::safety::{self, Rules};

/// An R parameter: its number is its ISO `#` index too (rendered `#(100 + n)`).
const fn r(index: u16, name: &'static str) -> Var {
    Var { index, name }
}

/// The chord counter, the curve's parameter at the chord's end, the roughing offset.
const I: Var = r(1, "R1");
const T: Var = r(2, "R2");
const OFS: Var = r(3, "R3");
/// The parameter's start, its end and the count of chords; the curve's own constants
/// follow from R13.
const START: Var = r(10, "R10");
const END: Var = r(11, "R11");
const CHORDS: Var = r(12, "R12");
const CONSTS: [Var; 4] = [r(13, "R13"), r(14, "R14"), r(15, "R15"), r(16, "R16")];

/// A curve family in R parameters: what its parameter is, its constants with what they
/// mean, and the point `(z, x)` in the parameter `T` and the constants.
struct Family {
    parameter: &'static str,
    start: f64,
    end: f64,
    consts: Vec<(f64, &'static str)>,
    point: fn(&[Expr]) -> (Expr, Expr),
}

fn family(curve: &Curve) -> Result<Family, ContourError> {
    Ok(match *curve {
        Curve::Ellipse(Ellipse {
            centre_z_mm,
            centre_x_mm,
            a_mm,
            b_mm,
            start_deg,
            end_deg,
        }) => Family {
            parameter: "the ellipse's angle, deg",
            start: start_deg,
            end: end_deg,
            consts: vec![
                (centre_z_mm, "centre z, mm"),
                (centre_x_mm, "centre x, mm"),
                (a_mm, "semi-axis a along z, mm"),
                (b_mm, "semi-axis b along x, mm"),
            ],
            // z = zc + a·cos t, x = xc + b·sin t.
            point: |k| {
                let t = Expr::var(T);
                (
                    k[0].clone().add(k[2].clone().mul(t.clone().cos())),
                    k[1].clone().add(k[3].clone().mul(t.sin())),
                )
            },
        },
        Curve::Parabola(Parabola {
            vertex_z_mm,
            vertex_x_mm,
            p_mm,
            x_start_mm,
            x_end_mm,
        }) => Family {
            parameter: "x, mm",
            start: x_start_mm,
            end: x_end_mm,
            consts: vec![
                (vertex_z_mm, "vertex z, mm"),
                (vertex_x_mm, "vertex x, mm"),
                (p_mm, "parameter p, mm"),
            ],
            // z = z0 + (x − x0)²/(2p), x = t.
            point: |k| {
                let w = || Expr::var(T).sub(k[1].clone());
                (
                    k[0].clone()
                        .add(w().mul(w()).div(Expr::num(2.0).mul(k[2].clone()))),
                    Expr::var(T),
                )
            },
        },
        Curve::Sine(Sine {
            mean_x_mm,
            amplitude_mm,
            wavelength_mm,
            phase_deg,
            z_start_mm,
            z_end_mm,
        }) => Family {
            parameter: "z, mm",
            start: z_start_mm,
            end: z_end_mm,
            consts: vec![
                (mean_x_mm, "mean x, mm"),
                (amplitude_mm, "amplitude, mm"),
                (wavelength_mm, "wavelength, mm"),
                (phase_deg, "phase, deg"),
            ],
            // x = mean + amplitude·sin(360·z/wavelength + phase), z = t.
            point: |k| {
                let arg = Expr::num(360.0)
                    .mul(Expr::var(T))
                    .div(k[2].clone())
                    .add(k[3].clone());
                (Expr::var(T), k[0].clone().add(k[1].clone().mul(arg.sin())))
            },
        },
        Curve::Tangent(Tangent {
            mean_x_mm,
            amplitude_mm,
            rate_deg_per_mm,
            centre_z_mm,
            z_start_mm,
            z_end_mm,
        }) => Family {
            parameter: "z, mm",
            start: z_start_mm,
            end: z_end_mm,
            consts: vec![
                (mean_x_mm, "mean x, mm"),
                (amplitude_mm, "amplitude, mm"),
                (rate_deg_per_mm, "rate, deg per mm"),
                (centre_z_mm, "centre z, mm"),
            ],
            // x = mean + amplitude·tan(rate·(z − centre)), z = t.
            point: |k| {
                let arg = k[2].clone().mul(Expr::var(T).sub(k[3].clone()));
                (Expr::var(T), k[0].clone().add(k[1].clone().mul(arg.tan())))
            },
        },
        Curve::Profile { .. } => return Err(ContourError::RParamsNeedFormula { kind: "profile" }),
        Curve::Param(_) => {
            return Err(ContourError::RParamsNeedFormula {
                kind: "parametric curve",
            });
        }
    })
}

/// The job in the R-parameter form: the same checks as [`generate`], a fixed step within the
/// tolerance, the constants at the top.
pub fn generate_rparams(job: &ContourJob) -> Result<Contour, ContourError> {
    // The step-law program's checks (values, geometry, tool, axis, safety) after the
    // form's own: the form changes how the loop steps, not what is cut.
    let fam = family(&job.curve)?;
    let proven = generate(job)?;
    let (chords, worst_mm) = fixed_step_for(&job.curve, job.tolerance_mm, job.decimals, MAX_CHORDS)
        .ok_or(ContourError::TooManyChords {
            tolerance_um: job.tolerance_mm * 1e3,
            max_chords: MAX_CHORDS,
        })?;
    let span = job.curve.span();
    let params: Vec<f64> = (0..=chords)
        .map(|i| span * i as f64 / chords as f64)
        .collect();
    let points: Vec<(f64, f64)> = params
        .iter()
        .map(|&u| {
            let j = job.curve.jet(u);
            (round_to(j.z, job.decimals), round_to(j.x, job.decimals))
        })
        .collect();
    let program = build(job, &fam, chords, worst_mm, &points, &proven);
    safety::check(&program, &Rules::lathe()).map_err(ContourError::Unsafe)?;
    Ok(Contour {
        program,
        report: ContourReport {
            chords,
            worst_deviation_mm: worst_mm,
            fixed_step_chords: Some(chords),
            fixed_step_worst_mm: Some(worst_mm),
            ..proven.report
        },
        params,
        points,
    })
}

fn build(
    job: &ContourJob,
    fam: &Family,
    chords: usize,
    worst_mm: f64,
    points: &[(f64, f64)],
    proven: &Contour,
) -> Program {
    let consts: Vec<Expr> = CONSTS[..fam.consts.len()]
        .iter()
        .map(|&v| Expr::var(v))
        .collect();
    let (z, x) = (fam.point)(&consts);
    let sign = side_sign(job);
    let named = [
        (START, fam.start, "start of the parameter"),
        (END, fam.end, "end of the parameter"),
        (CHORDS, chords as f64, "chords, at a fixed step"),
    ]
    .into_iter()
    .chain(
        CONSTS
            .iter()
            .zip(&fam.consts)
            .map(|(&v, &(value, what))| (v, value, what)),
    );
    let mut preamble = vec![Stmt::Comment(format!(
        "the curve: edit here (parameter: {})",
        fam.parameter
    ))];
    for (var, value, what) in named {
        preamble.push(Stmt::Comment(format!("{}: {what}", var.name)));
        preamble.push(Stmt::Assign(var, Expr::num(value)));
    }
    let contour = move |label: u16, feed: f64| contour_stmts(&z, &x, sign, label, feed);
    let comments = vec![
        job.setup.describe(),
        format!(
            "R-parameter form: {chords} chords at a fixed step, worst chord deviation {:.3} um (tolerance {:.2} um)",
            worst_mm * 1e3,
            job.tolerance_mm * 1e3
        ),
        "the chord deviation, lead-in, lead-out, retract and safety check hold for the values written in R10 to R16: regenerate after changing them".to_owned(),
        "working R parameters: R1 chord, R2 parameter, R3 roughing offset".to_owned(),
        nose_comment(job, proven.report.compensation),
    ];
    let shape = Shape {
        vars: Vec::new(),
        ofs: OFS,
        preamble,
        contour: Box::new(contour),
    };
    let name = proven.program.name.clone();
    let offsets = &proven.report.pass_offsets_mm;
    assemble(
        job,
        name,
        points,
        proven.report.compensation,
        offsets,
        comments,
        shape,
    )
}

/// One pass over the curve: the first point at feed, then a loop over the chords, each end
/// at `R10 + (R11 − R10)·R1/R12`.
fn contour_stmts(z: &Expr, x: &Expr, sign: f64, label: u16, feed: f64) -> Vec<Stmt> {
    let point = || Stmt::Move {
        motion: Motion::Linear,
        words: vec![
            (Axis::X, shifted_by(x.clone(), sign, OFS)),
            (Axis::Z, z.clone()),
        ],
        feed: None,
    };
    let at = Expr::var(START).add(
        Expr::var(END)
            .sub(Expr::var(START))
            .mul(Expr::var(I))
            .div(Expr::var(CHORDS)),
    );
    let mut first = point();
    if let Stmt::Move { feed: f, .. } = &mut first {
        *f = Some(feed);
    }
    vec![
        Stmt::Assign(I, Expr::num(0.0)),
        Stmt::Assign(T, Expr::var(START)),
        first,
        Stmt::DoWhile {
            label,
            body: vec![
                Stmt::Assign(I, Expr::var(I).add(Expr::num(1.0))),
                Stmt::Assign(T, at),
                point(),
            ],
            // Half a chord short of the count, so that an R12 edited to a non-integer
            // still ends on a whole chord rather than one past the end.
            cond: Cond {
                left: Expr::var(I),
                less: true,
                right: Expr::var(CHORDS).sub(Expr::num(0.5)),
            },
        },
    ]
}
