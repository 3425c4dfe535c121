//! The chained contour's programs: the contour subprogram (the finish contour from its
//! start, what `CYCLE95` reads) and the main program (safe start, roughing, the finish pass
//! with G42 around the call, safe end), checked by the safety check with the call inlined.

use super::{ChainError, ChainJob, ChainRoughing, Prim, Resolved, polyline, resolve, written};
use crate::chords::segment_distance;
use crate::contour::ContourError;
use crate::contour::program::{lead_point, off_axis};
use crate::ir::{Axis, Compensation, Expr, Motion, Plane, Program, Stmt, StockRemoval, inline};
use crate::safety::{self, Rules, SafetyReport};
use camloop_core::program::validate_program_name;

/// The programs of a chained contour and what was proven.
#[derive(Debug, Clone)]
pub struct ChainPrograms {
    pub main: Program,
    /// The contour subprogram (`<NAME>_C`).
    pub contour: Program,
    pub resolved: Resolved,
    /// Worst chord deviation over the curve segments, mm (0 without curves).
    pub worst_deviation_mm: f64,
    /// Radii of camloop's roughing levels, largest first (empty for none or CYCLE95).
    pub levels_mm: Vec<f64>,
    pub safety: SafetyReport,
}

fn mv(motion: Motion, words: &[(Axis, f64)], feed: Option<f64>) -> Stmt {
    Stmt::Move {
        motion,
        words: words
            .iter()
            .map(|&(a, v)| (a, Expr::Num(written(v))))
            .collect(),
        feed,
    }
}

/// The finish contour as moves from its start, X shifted outwards by `shift_mm`.
fn contour_moves(r: &Resolved, shift_mm: f64, first_feed: Option<f64>) -> Vec<Stmt> {
    let mut out = vec![mv(
        Motion::Linear,
        &[(Axis::X, r.start.1 + shift_mm), (Axis::Z, r.start.0)],
        first_feed,
    )];
    let mut at = r.start;
    for (_, p) in &r.prims {
        match p {
            Prim::Line { to } => {
                out.push(mv(
                    Motion::Linear,
                    &[(Axis::X, to.1 + shift_mm), (Axis::Z, to.0)],
                    None,
                ));
                at = *to;
            }
            Prim::Arc { to, centre, cw } => {
                let m = if *cw { Motion::ArcCw } else { Motion::ArcCcw };
                out.push(mv(
                    m,
                    &[
                        (Axis::X, to.1 + shift_mm),
                        (Axis::Z, to.0),
                        (Axis::I, centre.1 - at.1),
                        (Axis::K, centre.0 - at.0),
                    ],
                    None,
                ));
                at = *to;
            }
            Prim::Chords { points, .. } => {
                for q in points {
                    out.push(mv(
                        Motion::Linear,
                        &[(Axis::X, q.1 + shift_mm), (Axis::Z, q.0)],
                        None,
                    ));
                }
                at = *points.last().unwrap_or(&at);
            }
        }
    }
    out
}

/// Builds, checks and returns the programs.
pub fn generate(job: &ChainJob) -> Result<ChainPrograms, ChainError> {
    let name = validate_program_name(&job.name).map_err(ContourError::from)?;
    let sub_name = validate_program_name(&format!("{name}_C")).map_err(ContourError::from)?;
    job.setup.check()?;
    check_values(job)?;
    let r = resolve(job)?;
    let line = polyline(&r);
    let top = line.iter().map(|p| p.1).fold(0.0, f64::max);
    let blank = match job.roughing {
        ChainRoughing::Passes {
            blank_radius_mm, ..
        } => blank_radius_mm.max(top),
        _ => top,
    };
    let x_far = written(blank + job.clearance_mm);
    let z_front = written(r.start.0 + job.clearance_mm);
    let contour = Program {
        name: sub_name.clone(),
        plane: Plane::Zx,
        vars: Vec::new(),
        comments: vec![format!(
            "contour of {name}: {} segments from z = {}, x = {} (radius)",
            job.segments.len(),
            r.start.0,
            r.start.1
        )],
        body: contour_moves(&r, 0.0, None),
    };
    let mut body = job.setup.start();
    let mut levels_mm = Vec::new();
    match job.roughing {
        ChainRoughing::None => {}
        ChainRoughing::Cycle95 {
            depth_mm,
            allowance_mm,
        } => {
            body.push(Stmt::Comment(
                "roughing by the control's CYCLE95".to_owned(),
            ));
            body.push(mv(Motion::Rapid, &[(Axis::X, x_far)], None));
            body.push(mv(Motion::Rapid, &[(Axis::Z, z_front)], None));
            body.push(Stmt::StockRemoval(StockRemoval {
                contour: sub_name.clone(),
                depth_mm,
                allowance_mm,
                feed: job.rough_feed,
            }));
        }
        ChainRoughing::Passes {
            depth_mm,
            allowance_mm,
            ..
        } => {
            let (stmts, levels) = passes(job, &r, &line, blank, depth_mm, allowance_mm, x_far)?;
            body.extend(stmts);
            levels_mm = levels;
        }
    }
    body.extend(finish(job, &r, &sub_name, x_far));
    body.extend(job.setup.end());
    let main = Program {
        name,
        plane: Plane::Zx,
        vars: Vec::new(),
        comments: vec![
            job.setup.describe(),
            format!(
                "insert: nose {} mm, rises up to {:.1} deg, descends up to {:.1} deg",
                job.insert.nose_radius_mm,
                job.insert.max_rise_deg(),
                job.insert.max_descent_deg()
            ),
        ],
        body,
    };
    let safety = safety::check(
        &inline(&main, std::slice::from_ref(&contour)),
        &Rules::lathe(),
    )
    .map_err(|v| ChainError::Contour(ContourError::Unsafe(v)))?;
    let worst_deviation_mm = r
        .prims
        .iter()
        .map(|(_, p)| match p {
            Prim::Chords { worst_mm, .. } => *worst_mm,
            _ => 0.0,
        })
        .fold(0.0, f64::max);
    Ok(ChainPrograms {
        main,
        contour,
        resolved: r,
        worst_deviation_mm,
        levels_mm,
        safety,
    })
}

fn check_values(job: &ChainJob) -> Result<(), ChainError> {
    let bad = |what: &str, v: f64| ChainError::Value {
        segment: "job".to_owned(),
        what: format!("{what} is {v}: it must be a number > 0"),
    };
    for (what, v) in [
        ("tolerance", job.tolerance_mm),
        ("clearance", job.clearance_mm),
        ("finish feed", job.finish_feed),
        ("rough feed", job.rough_feed),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(bad(what, v));
        }
    }
    if let ChainRoughing::Cycle95 { depth_mm, .. } | ChainRoughing::Passes { depth_mm, .. } =
        job.roughing
        && !(depth_mm.is_finite() && depth_mm > 0.0)
    {
        return Err(bad("roughing depth", depth_mm));
    }
    Ok(())
}

/// camloop's roughing: longitudinal cuts at levels from the blank down, each to where the
/// contour plus the allowance reaches the level, pulled off at 45°; then one pass along
/// the contour at the allowance.
#[allow(clippy::too_many_arguments)]
fn passes(
    job: &ChainJob,
    r: &Resolved,
    line: &[(f64, f64)],
    blank: f64,
    depth_mm: f64,
    allowance_mm: f64,
    x_far: f64,
) -> Result<(Vec<Stmt>, Vec<f64>), ChainError> {
    let bottom = line[0].1 + allowance_mm;
    let z_end = line.last().map_or(r.start.0, |p| p.0);
    let z_front = r.start.0 + job.clearance_mm;
    let crowns = crowns(r, line, depth_mm)?;
    let n = ((blank - bottom) / depth_mm).ceil().max(0.0) as usize;
    // Equal steps from the blank down, plus a level at each crown (plus the allowance), so
    // the cut there passes over the crown and clears the recess behind it down to the
    // crown's height; the pass along the contour then takes what is left in the recess.
    let mut levels: Vec<f64> = (1..=n)
        .map(|k| blank - (blank - bottom) * k as f64 / n as f64)
        .chain(crowns.iter().map(|x| x + allowance_mm))
        .filter(|x| *x < blank)
        .collect();
    levels.sort_by(|a, b| b.total_cmp(a));
    levels.dedup_by(|a, b| (*a - *b).abs() < 1e-3);
    let c = job.clearance_mm;
    let mut s = vec![Stmt::Comment(format!(
        "roughing: {} cuts from the blank radius {blank} mm down to the allowance of {allowance_mm} mm",
        levels.len()
    ))];
    for &x in &levels {
        // Where the contour plus allowance first rises above x.
        let z_stop = line
            .windows(2)
            .find(|w| w[1].1 + allowance_mm > x + 1e-6)
            .map_or(z_end, |w| {
                let (a, b) = (w[0], w[1]);
                if b.1 - a.1 <= 1e-12 {
                    b.0
                } else {
                    a.0 + (b.0 - a.0) * ((x - allowance_mm - a.1) / (b.1 - a.1)).clamp(0.0, 1.0)
                }
            });
        // The allowance in z too, so a face keeps its finishing stock.
        let z_stop = z_stop + allowance_mm;
        s.push(mv(Motion::Rapid, &[(Axis::Z, z_front)], None));
        s.push(mv(Motion::Rapid, &[(Axis::X, x)], None));
        s.push(mv(
            Motion::Linear,
            &[(Axis::Z, z_stop)],
            Some(job.rough_feed),
        ));
        s.push(mv(
            Motion::Linear,
            &[(Axis::X, x + c), (Axis::Z, z_stop + c)],
            None,
        ));
        s.push(mv(Motion::Rapid, &[(Axis::X, x_far)], None));
    }
    s.push(Stmt::Comment(format!(
        "along the contour at the allowance of {allowance_mm} mm"
    )));
    // Offset along the normal, not shifted in x: on a face or the ellipse's tip a shift
    // in x would run on the contour itself.
    let off = offset_polyline(line, allowance_mm);
    s.push(mv(
        Motion::Rapid,
        &[(Axis::Z, z_front.max(off[0].0 + c))],
        None,
    ));
    s.push(mv(Motion::Rapid, &[(Axis::X, off[0].1)], None));
    for (k, q) in off.iter().enumerate() {
        let feed = (k == 0).then_some(job.rough_feed);
        s.push(mv(Motion::Linear, &[(Axis::X, q.1), (Axis::Z, q.0)], feed));
    }
    let last = off.last().copied().unwrap_or(r.start);
    s.push(mv(Motion::Linear, &[(Axis::X, last.1 + c)], None));
    s.push(mv(Motion::Rapid, &[(Axis::X, x_far)], None));
    Ok((s, levels))
}

/// The polyline offset by `d` to the tool's side (right of the travel, outwards), with
/// mitred corners (a miter at most 4·d long); the first point stays, so the pass starts
/// in front of the contour.
fn offset_polyline(line: &[(f64, f64)], d: f64) -> Vec<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> = Vec::new();
    for &p in line {
        if pts
            .last()
            .is_none_or(|q| (q.0 - p.0).hypot(q.1 - p.1) > 1e-9)
        {
            pts.push(p);
        }
    }
    let normal = |a: (f64, f64), b: (f64, f64)| {
        let l = (b.0 - a.0).hypot(b.1 - a.1);
        ((b.1 - a.1) / l, -(b.0 - a.0) / l)
    };
    let n = pts.len();
    (0..n)
        .map(|i| {
            let np = (i > 0).then(|| normal(pts[i - 1], pts[i]));
            let nn = (i + 1 < n).then(|| normal(pts[i], pts[i + 1]));
            let (a, b) = match (np, nn) {
                (Some(a), Some(b)) => (a, b),
                (Some(a), None) | (None, Some(a)) => (a, a),
                (None, None) => ((0.0, 1.0), (0.0, 1.0)),
            };
            let (mz, mx) = (a.0 + b.0, a.1 + b.1);
            let ml = mz.hypot(mx).max(1e-12);
            let (mz, mx) = (mz / ml, mx / ml);
            let scale = (d / (mz * a.0 + mx * a.1).max(0.25)).min(4.0 * d);
            (pts[i].0 + mz * scale, pts[i].1 + mx * scale)
        })
        // In a concave corner the offsets of short pieces swing past the corner and come
        // closer than `d` to the other side: such points are left out.
        .filter(|&q| {
            pts.windows(2)
                .all(|w| segment_distance(q, w[0], w[1]) >= d * (1.0 - 1e-6))
        })
        .collect()
}

/// Heights of the crowns (x where the contour, followed along the travel, falls again),
/// each with the recess behind it no deeper than one cut: a deeper recess is refused,
/// naming the segment of its bottom.
fn crowns(r: &Resolved, line: &[(f64, f64)], depth_mm: f64) -> Result<Vec<f64>, ChainError> {
    let mut out = Vec::new();
    let mut i = 1;
    while i + 1 < line.len() {
        let x = line[i].1;
        if !(x >= line[i - 1].1 && line[i + 1].1 < x - 1e-9) {
            i += 1;
            continue;
        }
        // The recess: until the contour is back above the crown (or ends).
        let mut j = i + 1;
        let mut low = (line[j].1, j);
        while j < line.len() && line[j].1 < x {
            if line[j].1 < low.0 {
                low = (line[j].1, j);
            }
            j += 1;
        }
        if x - low.0 > depth_mm + 1e-9 {
            return Err(ChainError::Recess {
                segment: segment_at(r, low.1),
                depth_mm: x - low.0,
                cut_mm: depth_mm,
            });
        }
        out.push(x);
        i = j;
    }
    Ok(out)
}

/// The label of the element holding polyline point `k`.
fn segment_at(r: &Resolved, k: usize) -> String {
    let mut at = r.start;
    let mut count = 0;
    for (label, p) in &r.prims {
        let pts = polyline(&Resolved {
            start: at,
            prims: vec![(label.clone(), p.clone())],
        });
        count += pts.len() - 1;
        if k <= count {
            return label.clone();
        }
        at = *pts.last().unwrap_or(&at);
    }
    r.prims.last().map_or_else(String::new, |p| p.0.clone())
}

/// The finish pass: to the lead-in, G42 on the move onto the contour's start, the contour
/// subprogram, G40 on the lead-out, retract.
fn finish(job: &ChainJob, r: &Resolved, sub: &str, x_far: f64) -> Vec<Stmt> {
    let c = job.clearance_mm;
    let line = polyline(r);
    let (p0, p1) = (line[0], line[1]);
    let n = line.len();
    let lead_in = off_axis(lead_point(p1, p0, Compensation::Right, c, true), p1, p0, c);
    let lead_out = off_axis(
        lead_point(line[n - 2], line[n - 1], Compensation::Right, c, false),
        line[n - 2],
        line[n - 1],
        c,
    );
    vec![
        Stmt::Comment("finish pass".to_owned()),
        mv(Motion::Rapid, &[(Axis::X, x_far)], None),
        mv(Motion::Rapid, &[(Axis::Z, lead_in.0 + c)], None),
        mv(Motion::Rapid, &[(Axis::X, lead_in.1 + c)], None),
        // G42 on the move to the lead-in point: the subprogram's first block then runs
        // onto the contour with the compensation already active.
        Stmt::Comp(Compensation::Right),
        mv(
            Motion::Linear,
            &[(Axis::X, lead_in.1), (Axis::Z, lead_in.0)],
            Some(job.finish_feed),
        ),
        Stmt::Call(sub.to_owned()),
        Stmt::Comp(Compensation::Off),
        mv(
            Motion::Linear,
            &[(Axis::X, lead_out.1), (Axis::Z, lead_out.0)],
            None,
        ),
        mv(Motion::Rapid, &[(Axis::X, x_far)], None),
    ]
}
