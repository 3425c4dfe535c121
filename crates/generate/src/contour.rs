//! Non-circular turning contours: the checked geometry, chords placed by tolerance,
//! roughing passes by a programmable X offset, the finish pass with nose-radius compensation,
//! and the program every dialect writes.
//!
//! Roughing is the lathe programmer's pattern repeat: the finish contour shifted outwards by
//! an offset (`CL_OFS`, the job of `TRANS X=` in a hand-written loop), cut again and again
//! with the offset reduced by one depth each time, down to the finish allowance. Then the
//! finish pass runs at offset 0 with compensation on.

use thiserror::Error;

use super::chords::{StepLaw, fixed_step_for, round_to, walk, worst_deviation};
use super::curve::{Curve, Ellipse, Parabola, Sine, Tangent};
use super::ir::{Compensation, Expr, Program, Var};
use super::safety::{self, Rules, Violation};
use super::setup::{Setup, SetupError};
use camloop_core::program::{ProgramNameError, validate_program_name};

pub(crate) mod program;
mod rparam;
use program::{build_program, far_x};
pub use rparam::generate_rparams;

/// Which side of the contour the material is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Outside turning: material at smaller radius, the tool outside.
    Outside,
    /// Boring: material at larger radius, the tool inside.
    Inside,
}

/// Roughing passes down to the finish allowance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Roughing {
    /// Radial stock on the blank over the finished contour, mm.
    pub stock_mm: f64,
    /// Largest radial depth of one pass, mm.
    pub depth_mm: f64,
    /// Radial allowance left for the finish pass, mm.
    pub allowance_mm: f64,
}

/// A contour job.
#[derive(Debug, Clone)]
pub struct ContourJob {
    pub name: String,
    pub curve: Curve,
    /// Largest distance of any chord from the exact curve, mm.
    pub tolerance_mm: f64,
    /// Decimals of written positions; the control's resolution is one unit of the last.
    pub decimals: usize,
    pub side: Side,
    pub nose_radius_mm: f64,
    pub roughing: Option<Roughing>,
    /// Radial clearance of approach and retract moves, mm.
    pub clearance_mm: f64,
    /// Feeds in the unit of `setup.feed_mode` (mm/rev under G95, mm/min under G94).
    pub finish_feed: f64,
    pub rough_feed: f64,
    /// Work offset, X mode, tool, spindle, feed mode and coolant of the safe start.
    pub setup: Setup,
}

/// Why a contour is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ContourError {
    #[error(transparent)]
    Name(#[from] ProgramNameError),
    #[error("{field} is {value}: {rule}")]
    Value {
        field: &'static str,
        value: f64,
        rule: &'static str,
    },
    #[error(
        "tolerance {tolerance_um} um is below what the control can hold: positions are rounded to {resolution_um} um, so the tolerance must be at least {min_um} um"
    )]
    ToleranceBelowResolution {
        tolerance_um: f64,
        resolution_um: f64,
        min_um: f64,
    },
    #[error(
        "the tangent curve reaches its asymptote: at z = {z_mm} mm the argument is {arg_deg} deg (it must stay inside -89 to 89 deg)"
    )]
    TangentAsymptote { z_mm: f64, arg_deg: f64 },
    #[error(
        "the contour turns back along z near z = {z_mm} mm, x = {x_mm} mm: one pass cannot turn it with the tool on one side; split it there"
    )]
    TurnsBack { z_mm: f64, x_mm: f64 },
    #[error("the contour crosses the axis: x = {x_mm} mm at z = {z_mm} mm")]
    CrossesAxis { z_mm: f64, x_mm: f64 },
    #[error(
        "the tool nose radius {nose_radius_mm} mm is larger than the concave radius {radius_mm} mm of the contour at z = {z_mm} mm, x = {x_mm} mm"
    )]
    NoseTooLarge {
        nose_radius_mm: f64,
        radius_mm: f64,
        z_mm: f64,
        x_mm: f64,
    },
    #[error(transparent)]
    Setup(#[from] SetupError),
    #[error("the program fails the safety check: {}", list(.0))]
    Unsafe(Vec<Violation>),
    #[error("boring clearance: the retract radius {x_mm} mm would be below the axis")]
    BoreTooSmall { x_mm: f64 },
    #[error(
        "no chord placement within {tolerance_um} um was found with at most {max_chords} chords"
    )]
    TooManyChords {
        tolerance_um: f64,
        max_chords: usize,
    },
    #[error(
        "the R-parameter form needs a curve the control evaluates (ellipse, parabola, sine or tangent); a {kind} is written as chords: use the loop or expanded form"
    )]
    RParamsNeedFormula { kind: &'static str },
}

/// The violations as one line.
fn list(v: &[Violation]) -> String {
    v.iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

/// What the generator proved and how it compares with a fixed step.
#[derive(Debug, Clone, PartialEq)]
pub struct ContourReport {
    pub chords: usize,
    /// Worst distance of a written chord from the exact curve, mm.
    pub worst_deviation_mm: f64,
    /// Chords of equal parameter step needed for a worst deviation no larger.
    pub fixed_step_chords: Option<usize>,
    pub fixed_step_worst_mm: Option<f64>,
    pub law: StepLaw,
    pub compensation: Compensation,
    /// Offsets of the roughing passes, mm, largest first.
    pub pass_offsets_mm: Vec<f64>,
}

/// A generated contour: the program (render it with a dialect) and the report.
#[derive(Debug, Clone)]
pub struct Contour {
    pub program: Program,
    pub report: ContourReport,
    /// Curve parameters and written points (z, x) of the finish chords.
    pub params: Vec<f64>,
    pub points: Vec<(f64, f64)>,
}

pub(super) const U: Var = Var {
    index: 1,
    name: "CL_U",
};
pub(super) const DU: Var = Var {
    index: 2,
    name: "CL_DU",
};
pub(super) const T1: Var = Var {
    index: 4,
    name: "CL_T1",
};
pub(super) const T2: Var = Var {
    index: 5,
    name: "CL_T2",
};
pub(super) const OFS: Var = Var {
    index: 3,
    name: "CL_OFS",
};
/// Chord limit of the search; a job needing more is refused.
pub(crate) const MAX_CHORDS: usize = 200_000;
/// Samples of the geometry checks along the contour.
const SCAN: usize = 4000;

/// Check the job, place the chords and build the program.
pub fn generate(job: &ContourJob) -> Result<Contour, ContourError> {
    let name = validate_program_name(&job.name)?;
    check_values(job)?;
    check_geometry(job)?;
    let span = job.curve.span();
    let (law, us, points) = place_chords(job)?;
    let worst = worst_deviation(&job.curve, &us, &points).1;
    let fixed = fixed_step_for(&job.curve, worst, job.decimals, MAX_CHORDS);
    let compensation = compensation_side(job);
    if job.side == Side::Inside && far_x(job, &points) < 0.0 {
        return Err(ContourError::BoreTooSmall {
            x_mm: far_x(job, &points),
        });
    }
    let pass_offsets_mm = pass_offsets(job.roughing);
    let program = build_program(
        job,
        name,
        law,
        &points,
        compensation,
        &pass_offsets_mm,
        span,
    );
    safety::check(&program, &Rules::lathe()).map_err(ContourError::Unsafe)?;
    Ok(Contour {
        program,
        report: ContourReport {
            chords: us.len() - 1,
            worst_deviation_mm: worst,
            fixed_step_chords: fixed.map(|f| f.0),
            fixed_step_worst_mm: fixed.map(|f| f.1),
            law,
            compensation,
            pass_offsets_mm,
        },
        params: us,
        points,
    })
}

fn check_values(job: &ContourJob) -> Result<(), ContourError> {
    let positive = |field, value: f64| {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(ContourError::Value {
                field,
                value,
                rule: "it must be a number > 0",
            })
        }
    };
    positive("tolerance", job.tolerance_mm)?;
    positive("clearance", job.clearance_mm)?;
    positive("finish feed", job.finish_feed)?;
    positive("rough feed", job.rough_feed)?;
    job.setup.check()?;
    if !(job.nose_radius_mm.is_finite() && job.nose_radius_mm >= 0.0) {
        return Err(ContourError::Value {
            field: "nose radius",
            value: job.nose_radius_mm,
            rule: "it must be a number >= 0",
        });
    }
    if let Some(r) = job.roughing {
        positive("roughing depth", r.depth_mm)?;
        positive("roughing stock", r.stock_mm)?;
        if !(r.allowance_mm.is_finite() && r.allowance_mm >= 0.0 && r.allowance_mm < r.stock_mm) {
            return Err(ContourError::Value {
                field: "finish allowance",
                value: r.allowance_mm,
                rule: "it must be >= 0 and less than the stock",
            });
        }
    }
    // Rounding each end by half a unit moves a chord by up to √2/2 unit: at least half the
    // tolerance must be left for the chord itself.
    let resolution = 10f64.powi(-(job.decimals as i32));
    if job.tolerance_mm < 2.0 * resolution {
        return Err(ContourError::ToleranceBelowResolution {
            tolerance_um: job.tolerance_mm * 1e3,
            resolution_um: resolution * 1e3,
            min_um: 2.0 * resolution * 1e3,
        });
    }
    check_curve(&job.curve)?;
    let span = job.curve.span();
    if !(span.is_finite() && span > 0.0) {
        return Err(ContourError::Value {
            field: "curve span (end - start)",
            value: span,
            rule: "start and end must differ",
        });
    }
    Ok(())
}

/// A named value of the job, for error messages.
type Field = (&'static str, f64);

/// The curve's own sizes: finite, and positive where they divide or scale.
fn check_curve(curve: &Curve) -> Result<(), ContourError> {
    let (positive, finite) = curve_fields(curve);
    for (field, value) in finite {
        if !value.is_finite() {
            return Err(ContourError::Value {
                field,
                value,
                rule: "it must be a finite number",
            });
        }
    }
    for (field, value) in positive {
        if !(value.is_finite() && value > 0.0) {
            return Err(ContourError::Value {
                field,
                value,
                rule: "it must be a number > 0 (non-zero for p)",
            });
        }
    }
    Ok(())
}

/// The curve's fields that must be positive, and those that must be finite.
fn curve_fields(curve: &Curve) -> (Vec<Field>, Vec<Field>) {
    match *curve {
        Curve::Ellipse(Ellipse {
            centre_z_mm,
            centre_x_mm,
            a_mm,
            b_mm,
            start_deg,
            end_deg,
        }) => (
            vec![("ellipse a", a_mm), ("ellipse b", b_mm)],
            vec![
                ("centre z", centre_z_mm),
                ("centre x", centre_x_mm),
                ("start", start_deg),
                ("end", end_deg),
            ],
        ),
        Curve::Parabola(Parabola {
            vertex_z_mm,
            vertex_x_mm,
            p_mm,
            x_start_mm,
            x_end_mm,
        }) => (
            vec![("parabola p", p_mm.abs())],
            vec![
                ("vertex z", vertex_z_mm),
                ("vertex x", vertex_x_mm),
                ("x start", x_start_mm),
                ("x end", x_end_mm),
            ],
        ),
        Curve::Sine(Sine {
            mean_x_mm,
            amplitude_mm,
            wavelength_mm,
            phase_deg,
            z_start_mm,
            z_end_mm,
        }) => (
            vec![("wavelength", wavelength_mm)],
            vec![
                ("mean x", mean_x_mm),
                ("amplitude", amplitude_mm),
                ("phase", phase_deg),
                ("z start", z_start_mm),
                ("z end", z_end_mm),
            ],
        ),
        Curve::Tangent(Tangent {
            mean_x_mm,
            amplitude_mm,
            rate_deg_per_mm,
            centre_z_mm,
            z_start_mm,
            z_end_mm,
        }) => (
            vec![],
            vec![
                ("mean x", mean_x_mm),
                ("amplitude", amplitude_mm),
                ("rate", rate_deg_per_mm),
                ("centre z", centre_z_mm),
                ("z start", z_start_mm),
                ("z end", z_end_mm),
            ],
        ),
        Curve::Profile { .. } | Curve::Param(_) => (vec![], vec![]),
    }
}

/// Asymptotes, travel that turns back in z, the axis, and concave radii tighter than the
/// nose, on a dense scan.
fn check_geometry(job: &ContourJob) -> Result<(), ContourError> {
    check_asymptote(&job.curve)?;
    let span = job.curve.span();
    let mut direction = 0.0;
    let mut tightest = None;
    let tool_left = compensation_side(job) == Compensation::Left;
    for i in 0..=SCAN {
        let j = job.curve.jet(span * i as f64 / SCAN as f64);
        if !(j.z.is_finite() && j.x.is_finite()) || j.x < 0.0 {
            return Err(ContourError::CrossesAxis {
                z_mm: j.z,
                x_mm: j.x,
            });
        }
        // The ends may be vertical (an ellipse quadrant); inside, z must keep one sense.
        let speed = j.dz.hypot(j.dx);
        if j.dz.abs() > 1e-9 * speed {
            if direction == 0.0 {
                direction = j.dz.signum();
            } else if j.dz.signum() != direction {
                return Err(ContourError::TurnsBack {
                    z_mm: j.z,
                    x_mm: j.x,
                });
            }
        }
        let k = j.curvature();
        let towards_tool = if tool_left { k } else { -k };
        if towards_tool > 0.0
            && job.nose_radius_mm * towards_tool >= 1.0
            && tightest.is_none_or(|t: (f64, f64, f64)| towards_tool > t.0)
        {
            tightest = Some((towards_tool, j.z, j.x));
        }
    }
    if let Some((k, z_mm, x_mm)) = tightest {
        // The tightest concave radius, not the first one too tight, so the user sees the
        // real limit.
        return Err(ContourError::NoseTooLarge {
            nose_radius_mm: job.nose_radius_mm,
            radius_mm: 1.0 / k,
            z_mm,
            x_mm,
        });
    }
    Ok(())
}

/// A tangent curve must stay off its asymptotes.
fn check_asymptote(curve: &Curve) -> Result<(), ContourError> {
    if let Curve::Tangent(Tangent {
        rate_deg_per_mm,
        centre_z_mm,
        z_start_mm,
        z_end_mm,
        ..
    }) = *curve
    {
        for z in [z_start_mm, z_end_mm] {
            let arg_deg = (z - centre_z_mm) * rate_deg_per_mm;
            if arg_deg.is_nan() || arg_deg.abs() >= 89.0 {
                return Err(ContourError::TangentAsymptote { z_mm: z, arg_deg });
            }
        }
    }
    Ok(())
}

/// G41 or G42 in the Z–X plane seen with z to the right and x up: the tool is left of the
/// travel when it runs +z outside the material or −z inside it.
pub(crate) fn compensation_side(job: &ContourJob) -> Compensation {
    let span = job.curve.span();
    // The mid-point is inside the contour, where z has its one sense (checked above).
    let dz = job.curve.jet(span / 2.0).dz;
    match (job.side, dz > 0.0) {
        (Side::Outside, true) | (Side::Inside, false) => Compensation::Left,
        _ => Compensation::Right,
    }
}

/// Offsets of the roughing passes: equal depths no larger than the given one, from the
/// stock down to the allowance.
fn pass_offsets(r: Option<Roughing>) -> Vec<f64> {
    let Some(r) = r else { return Vec::new() };
    let n = ((r.stock_mm - r.allowance_mm) / r.depth_mm).ceil().max(1.0) as usize;
    let dd = (r.stock_mm - r.allowance_mm) / n as f64;
    (0..n)
        .map(|i| r.allowance_mm + (n - 1 - i) as f64 * dd)
        .collect()
}

/// A constant as the program will carry it: 10 significant digits, read back.
fn snap(v: f64) -> f64 {
    format!("{v:.9e}").parse().unwrap_or(v)
}

/// The curve as the loop evaluates it, on the loop's variables.
pub(super) fn exprs(curve: &Curve) -> Option<super::curve::CurveExprs> {
    curve.exprs(U, T1, T2)
}

/// The step law's Δu as an expression.
pub(super) fn du_expr(curve: &Curve, law: StepLaw) -> Option<Expr> {
    let e = exprs(curve)?;
    Some(Expr::num(law.kf).div(e.weight.add(Expr::num(law.c0)).sqrt()))
}

/// Search the law's factors until every chord is within the tolerance; returns the law,
/// the parameters and the written points.
#[allow(clippy::type_complexity)]
fn place_chords(job: &ContourJob) -> Result<(StepLaw, Vec<f64>, Vec<(f64, f64)>), ContourError> {
    place_chords_for(&job.curve, job.tolerance_mm, job.decimals)
}

/// The same for any curve: its own sizes checked first (a chained contour's curve).
#[allow(clippy::type_complexity)]
pub(crate) fn place_chords_for(
    curve: &Curve,
    tolerance_mm: f64,
    decimals: usize,
) -> Result<(StepLaw, Vec<f64>, Vec<(f64, f64)>), ContourError> {
    check_curve(curve)?;
    check_asymptote(curve)?;
    let span = curve.span();
    let exprs = exprs(curve);
    let (mut k, mut cap) = (1.0, span / 2.0);
    for _ in 0..200 {
        let kf = snap(k * (8.0 * tolerance_mm).sqrt());
        let law = StepLaw {
            kf,
            c0: snap((kf / cap).powi(2)),
        };
        let du: Box<dyn Fn(f64) -> f64> = match (du_expr(curve, law), exprs.as_ref()) {
            (Some(e), Some(c)) => Box::new(move |u| e.eval(&c.vars_at(U, u))),
            _ => Box::new(move |u| law.kf / (curve.jet(u).weight() + law.c0).sqrt()),
        };
        let Some(us) = walk(span, &du, MAX_CHORDS) else {
            break;
        };
        let points: Vec<(f64, f64)> = us
            .iter()
            .map(|&u| written_point(curve, exprs.as_ref(), u, decimals))
            .collect();
        let (i, dev) = worst_deviation(curve, &us, &points);
        if dev <= tolerance_mm {
            return Ok((law, us, points));
        }
        // A failing chord at the cap is bent by more than curvature (an inflection):
        // lower the cap; otherwise shorten every step.
        if curve.jet(us[i]).weight() < law.c0 {
            cap *= 0.7;
        } else {
            k *= 0.92;
        }
    }
    Err(ContourError::TooManyChords {
        tolerance_um: tolerance_mm * 1e3,
        max_chords: MAX_CHORDS,
    })
}

/// The point at u as the program writes it: through the same expressions the control
/// evaluates (for analytic curves), rounded to the written decimals.
fn written_point(
    curve: &Curve,
    exprs: Option<&super::curve::CurveExprs>,
    u: f64,
    decimals: usize,
) -> (f64, f64) {
    let (z, x) = match exprs {
        Some(e) => {
            let vars = e.vars_at(U, u);
            (e.z.eval(&vars), e.x.eval(&vars) + 0.0)
        }
        None => {
            let j = curve.jet(u);
            (j.z, j.x)
        }
    };
    (round_to(z, decimals), round_to(x, decimals))
}
