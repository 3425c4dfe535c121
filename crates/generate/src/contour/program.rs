//! The contour's program: the safe start, the roughing loop over the offset, the finish
//! pass with compensation, lead-in and lead-out.

use super::{ContourJob, DU, OFS, Side, T1, T2, U, du_expr, exprs};
use crate::chords::{StepLaw, round_to};
use crate::ir::{Axis, Compensation, Cond, Expr, Motion, Plane, Program, Stmt, Var};

/// What the step-law loop and the R-parameter form do differently: the declared
/// variables, the offset variable, the constants at the top and the contour itself (a
/// pass at a label and a feed).
pub(crate) struct Shape<'a> {
    pub vars: Vec<Var>,
    pub ofs: Var,
    pub preamble: Vec<Stmt>,
    pub contour: Box<dyn Fn(u16, f64) -> Vec<Stmt> + 'a>,
}

/// The job's program: safe start, roughing passes (a loop over the offset), finish pass.
#[allow(clippy::too_many_arguments)]
pub(super) fn build_program(
    job: &ContourJob,
    name: String,
    law: StepLaw,
    points: &[(f64, f64)],
    comp: Compensation,
    offsets: &[f64],
    span: f64,
) -> Program {
    let sign = side_sign(job);
    let shape = Shape {
        vars: vec![U, DU, T1, T2, OFS],
        ofs: OFS,
        preamble: Vec::new(),
        contour: Box::new(move |label, feed| {
            contour_stmts(job, law, points, span, sign, label, feed)
        }),
    };
    let comments = header_comments(job, law, points, comp, span);
    assemble(job, name, points, comp, offsets, comments, shape)
}

/// +1 for outside turning (offsets grow x), −1 for boring.
pub(crate) fn side_sign(job: &ContourJob) -> f64 {
    match job.side {
        Side::Outside => 1.0,
        Side::Inside => -1.0,
    }
}

/// X shifted by the offset variable `ofs`, outwards from the material.
pub(crate) fn shifted_by(x: Expr, sign: f64, ofs: Var) -> Expr {
    if sign > 0.0 {
        x.add(Expr::var(ofs))
    } else {
        x.sub(Expr::var(ofs))
    }
}

/// The program around the contour: safe start, constants, roughing loop, finish pass with
/// compensation, lead-in and lead-out, safe end.
pub(crate) fn assemble(
    job: &ContourJob,
    name: String,
    points: &[(f64, f64)],
    comp: Compensation,
    offsets: &[f64],
    comments: Vec<String>,
    shape: Shape<'_>,
) -> Program {
    let sign = side_sign(job);
    let ofs = shape.ofs;
    let n = Expr::num;
    let mv = |motion, words: Vec<(Axis, Expr)>, feed| Stmt::Move {
        motion,
        words,
        feed,
    };
    let x_far = far_x(job, points);
    let np = points.len();
    // Lead-in and lead-out at 45° to the contour, on the tool's side: the compensation
    // then turns by 45° at the ends, never back on itself.
    let lead_in = off_axis(
        lead_point(points[1], points[0], comp, job.clearance_mm, true),
        points[1],
        points[0],
        job.clearance_mm,
    );
    let lead_out = off_axis(
        lead_point(
            points[np - 2],
            points[np - 1],
            comp,
            job.clearance_mm,
            false,
        ),
        points[np - 2],
        points[np - 1],
        job.clearance_mm,
    );
    let approach = |feed_label: u16, feed: f64| {
        let mut s = vec![
            mv(Motion::Rapid, vec![(Axis::X, n(x_far))], None),
            mv(Motion::Rapid, vec![(Axis::Z, n(lead_in.0))], None),
            mv(
                Motion::Rapid,
                vec![(Axis::X, shifted_by(n(lead_in.1), sign, ofs))],
                None,
            ),
        ];
        if feed_label == FINISH_LABEL {
            s.push(Stmt::Comp(comp));
        }
        s.extend((shape.contour)(feed_label, feed));
        if feed_label == FINISH_LABEL {
            s.push(Stmt::Comp(Compensation::Off));
        }
        s.push(mv(
            Motion::Linear,
            vec![
                (Axis::X, shifted_by(n(lead_out.1), sign, ofs)),
                (Axis::Z, n(lead_out.0)),
            ],
            None,
        ));
        s.push(mv(Motion::Rapid, vec![(Axis::X, n(x_far))], None));
        s
    };
    let mut body = shape.preamble;
    body.extend(job.setup.start());
    body.extend(roughing_stmts(job, offsets, ofs, &approach));
    body.push(Stmt::Comment("finish pass".to_owned()));
    body.push(Stmt::Assign(ofs, n(0.0)));
    body.extend(approach(FINISH_LABEL, job.finish_feed));
    body.extend(job.setup.end());
    Program {
        name,
        plane: Plane::Zx,
        vars: shape.vars,
        comments,
        body,
    }
}

/// The roughing passes, when the job has them: one pass (`approach`) in a loop that steps
/// the offset down to the finishing allowance.
fn roughing_stmts(
    job: &ContourJob,
    offsets: &[f64],
    ofs: Var,
    approach: &dyn Fn(u16, f64) -> Vec<Stmt>,
) -> Vec<Stmt> {
    let n = Expr::num;
    let mut body = Vec::new();
    if let (Some(r), Some(&first)) = (job.roughing, offsets.first()) {
        let dd = (r.stock_mm - r.allowance_mm) / offsets.len() as f64;
        body.push(Stmt::Comment(format!(
            "roughing: {} passes of {:.4} mm down to the allowance of {:.4} mm",
            offsets.len(),
            dd,
            r.allowance_mm
        )));
        body.push(Stmt::Assign(ofs, n(first)));
        let mut pass = approach(ROUGH_LABEL, job.rough_feed);
        pass.push(Stmt::Assign(ofs, Expr::var(ofs).sub(n(dd))));
        body.push(Stmt::DoWhile {
            label: PASS_LABEL,
            body: pass,
            cond: Cond {
                left: Expr::var(ofs),
                less: false,
                right: n(r.allowance_mm - dd / 2.0),
            },
        });
    }
    body
}

/// The program's header: the chords' tolerance, the step law and the tool's side.
fn header_comments(
    job: &ContourJob,
    law: StepLaw,
    points: &[(f64, f64)],
    comp: Compensation,
    span: f64,
) -> Vec<String> {
    vec![
        job.setup.describe(),
        format!(
            "contour: {} chords within {:.2} um of the exact curve",
            points.len() - 1,
            job.tolerance_mm * 1e3
        ),
        format!(
            "step law: du = {} / sqrt(w(u) + {}), u from 0 to {}",
            law.kf, law.c0, span
        ),
        nose_comment(job, comp),
    ]
}

/// The nose radius and the side of the compensation, for a program's header.
pub(crate) fn nose_comment(job: &ContourJob, comp: Compensation) -> String {
    let side = match comp {
        Compensation::Left => "G41 (tool left of the travel)",
        _ => "G42 (tool right of the travel)",
    };
    format!(
        "nose radius {:.3} mm, {side} in the Z-X plane seen with Z right and X up",
        job.nose_radius_mm
    )
}

const ROUGH_LABEL: u16 = 1;
const PASS_LABEL: u16 = 3;
const FINISH_LABEL: u16 = 4;

/// The point `clearance` back along the chord from `end` (`before`) or on beyond it, and
/// `clearance` off it on the tool's side, rounded as written. Chords run `from` → `end`
/// in travel order for the lead-out, `end` ← `from` for the lead-in.
pub(crate) fn lead_point(
    from: (f64, f64),
    end: (f64, f64),
    comp: Compensation,
    clearance: f64,
    before: bool,
) -> (f64, f64) {
    let (dz, dx) = (end.0 - from.0, end.1 - from.1);
    let len = dz.hypot(dx);
    // Travel direction: for the lead-in the chord runs end → from.
    let (tz, tx) = if before {
        (-dz / len, -dx / len)
    } else {
        (dz / len, dx / len)
    };
    // Tool side: left of the travel is (−tx, tz) in (z, x).
    let (nz, nx) = match comp {
        Compensation::Left => (-tx, tz),
        _ => (tx, -tz),
    };
    let along = if before { -clearance } else { clearance };
    (
        round_to(end.0 + along * tz + clearance * nz, 4),
        round_to(end.1 + along * tx + clearance * nx, 4),
    )
}

/// `lead`, or, where it would be behind the axis (a contour that starts or ends on it, as
/// the 802D study's ellipse from its tip does), the point `along` mm off `end` in z, away
/// from the chord `from`–`end`, at `end`'s own x: the move then runs parallel to the axis
/// and never crosses it.
pub(crate) fn off_axis(
    lead: (f64, f64),
    from: (f64, f64),
    end: (f64, f64),
    along: f64,
) -> (f64, f64) {
    if lead.1 >= 0.0 {
        return lead;
    }
    // The travel's sense in z at this end (the lead-in runs end ← from).
    let sense = (from.0 - end.0).signum();
    (round_to(end.0 - sense * along, 4), end.1)
}

/// Retract radius: clear of the blank everywhere.
pub(super) fn far_x(job: &ContourJob, points: &[(f64, f64)]) -> f64 {
    let stock = job.roughing.map_or(0.0, |r| r.stock_mm);
    let xs = points.iter().map(|p| p.1);
    match job.side {
        Side::Outside => round_to(xs.fold(f64::MIN, f64::max) + stock + job.clearance_mm, 3),
        Side::Inside => round_to(xs.fold(f64::MAX, f64::min) - stock - job.clearance_mm, 3),
    }
}

/// The contour from its first point: the loop the control runs (analytic curves) or the
/// placed points (profiles); X shifted by the offset.
fn contour_stmts(
    job: &ContourJob,
    law: StepLaw,
    points: &[(f64, f64)],
    span: f64,
    sign: f64,
    label: u16,
    feed: f64,
) -> Vec<Stmt> {
    let n = Expr::num;
    let mv = |words: Vec<(Axis, Expr)>, feed| Stmt::Move {
        motion: Motion::Linear,
        words,
        feed,
    };
    let (Some(e), Some(du)) = (exprs(&job.curve), du_expr(&job.curve, law)) else {
        return points
            .iter()
            .enumerate()
            .map(|(i, &(z, x))| {
                mv(
                    vec![(Axis::X, shifted_by(n(x), sign, OFS)), (Axis::Z, n(z))],
                    (i == 0).then_some(feed),
                )
            })
            .collect();
    };
    let point = || {
        vec![
            (Axis::X, shifted_by(e.x.clone(), sign, OFS)),
            (Axis::Z, e.z.clone()),
        ]
    };
    let pre = || e.pre.iter().map(|(t, x)| Stmt::Assign(*t, x.clone()));
    let mut body = vec![
        Stmt::Assign(DU, du),
        Stmt::Assign(U, Expr::var(U).add(Expr::var(DU))),
        Stmt::If {
            label: label + 1,
            cond: Cond {
                left: Expr::var(U),
                less: false,
                right: n(span),
            },
            body: vec![Stmt::Assign(U, n(span))],
        },
    ];
    body.extend(pre());
    body.push(mv(point(), None));
    let mut out = vec![Stmt::Assign(U, n(0.0))];
    out.extend(pre());
    out.push(mv(point(), Some(feed)));
    out.push(Stmt::DoWhile {
        label,
        body,
        cond: Cond {
            left: Expr::var(U),
            less: true,
            right: n(span),
        },
    });
    out
}
