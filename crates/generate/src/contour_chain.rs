//! A whole turned part: lines, arcs, chamfers, radii and curves chained from a start point,
//! checked for continuity, against the axis, and against the tool (the insert's angles and
//! the nose radius), each refusal naming its segment.
//!
//! The chain runs along −z from the part's front (outside turning, tool above the axis).
//! Each curve is placed in chords by tolerance as the single-curve generator does; lines
//! and arcs stay G1 and G2/G3. [`program`] writes the contour subprogram and the main
//! program that roughs (by the control's `CYCLE95` or camloop's own passes) and finishes.

use thiserror::Error;

use crate::chords::round_to;
use crate::contour::place_chords_for;
use crate::curve::Curve;
use crate::setup::{Setup, SetupError};

pub mod program;

/// One element as the contour file gives it; each starts where the one before ends.
#[derive(Debug, Clone)]
pub enum Segment {
    /// A straight line to (z, x); `chamfer_mm` (equal legs) or `round_mm` (a tangent
    /// radius) break its corner with the next line.
    Line {
        z_mm: f64,
        x_mm: f64,
        chamfer_mm: Option<f64>,
        round_mm: Option<f64>,
    },
    /// A circular arc to (z, x) of this radius, the shorter way round; `cw` is G2 seen with
    /// z right and x up.
    Arc {
        z_mm: f64,
        x_mm: f64,
        radius_mm: f64,
        cw: bool,
    },
    /// A curve placed in chords; it must start where the chain is.
    Curve(Curve),
}

/// A segment with the name errors use (`segment 3 (ellipse)` or the file's label).
#[derive(Debug, Clone)]
pub struct Labeled {
    pub label: String,
    pub segment: Segment,
}

/// The insert and its holder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Insert {
    pub nose_radius_mm: f64,
    /// Cutting-edge angle κr of the holder (93° for a common copying holder).
    pub approach_deg: f64,
    /// Included angle ε of the insert (35° V, 55° D, 80° C).
    pub included_deg: f64,
    /// Clearance kept between the insert's edges and the contour, degrees.
    pub min_clearance_deg: f64,
}

impl Insert {
    /// Steepest rise of the contour along the travel the main edge can cut, degrees.
    pub fn max_rise_deg(&self) -> f64 {
        self.approach_deg - self.min_clearance_deg
    }
    /// Steepest descent the trailing edge clears (180° − κr − ε − clearance).
    pub fn max_descent_deg(&self) -> f64 {
        180.0 - self.approach_deg - self.included_deg - self.min_clearance_deg
    }
}

/// How the stock comes off before the finish pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChainRoughing {
    None,
    /// The control's `CYCLE95` from the contour subprogram (SINUMERIK).
    Cycle95 {
        depth_mm: f64,
        allowance_mm: f64,
    },
    /// camloop's passes from a bar of this radius: longitudinal cuts each stopped at the
    /// contour plus the allowance, then one pass along the contour at the allowance.
    Passes {
        blank_radius_mm: f64,
        depth_mm: f64,
        allowance_mm: f64,
    },
}

/// A chained contour job.
#[derive(Debug, Clone)]
pub struct ChainJob {
    pub name: String,
    pub start_z_mm: f64,
    pub start_x_mm: f64,
    pub segments: Vec<Labeled>,
    pub tolerance_mm: f64,
    pub decimals: usize,
    pub insert: Insert,
    pub clearance_mm: f64,
    /// Feeds in the unit of `setup.feed_mode`.
    pub finish_feed: f64,
    pub rough_feed: f64,
    pub roughing: ChainRoughing,
    pub setup: Setup,
}

/// A resolved element of the finish contour, in travel order.
#[derive(Debug, Clone, PartialEq)]
pub enum Prim {
    Line {
        to: (f64, f64),
    },
    /// `centre` absolute (z, x).
    Arc {
        to: (f64, f64),
        centre: (f64, f64),
        cw: bool,
    },
    /// Chord ends after the start, as written.
    Chords {
        points: Vec<(f64, f64)>,
        worst_mm: f64,
    },
}

/// Why a chain is refused; `segment` is the label.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ChainError {
    #[error("{segment}: {what}")]
    Value { segment: String, what: String },
    #[error(
        "{segment} starts at z = {z_mm} mm, x = {x_mm} mm, {gap_um:.1} um from where the chain is (z = {at_z_mm} mm, x = {at_x_mm} mm)"
    )]
    Gap {
        segment: String,
        z_mm: f64,
        x_mm: f64,
        at_z_mm: f64,
        at_x_mm: f64,
        gap_um: f64,
    },
    #[error("{segment}: x = {x_mm} mm at z = {z_mm} mm is behind the axis")]
    BehindAxis {
        segment: String,
        z_mm: f64,
        x_mm: f64,
    },
    #[error(
        "{segment}: the contour {what} at {angle_deg:.1} deg near z = {z_mm:.3} mm, x = {x_mm:.3} mm; the insert follows at most {limit_deg:.1} deg"
    )]
    Insert {
        segment: String,
        what: &'static str,
        angle_deg: f64,
        limit_deg: f64,
        z_mm: f64,
        x_mm: f64,
    },
    #[error(
        "{segment}: the concave radius {radius_mm:.3} mm near z = {z_mm:.3} mm is smaller than the nose radius {nose_radius_mm} mm"
    )]
    NoseTooLarge {
        segment: String,
        radius_mm: f64,
        nose_radius_mm: f64,
        z_mm: f64,
    },
    #[error(
        "{segment}: the recess behind the crown is {depth_mm:.3} mm deep, more than one cut of {cut_mm} mm: camloop's passes cannot reach it; use CYCLE95"
    )]
    Recess {
        segment: String,
        depth_mm: f64,
        cut_mm: f64,
    },
    #[error(transparent)]
    Setup(#[from] SetupError),
    #[error(transparent)]
    Contour(#[from] crate::contour::ContourError),
    #[error("the chain has no segments")]
    Empty,
}

/// The finish contour: the start and its elements, each with its segment's label.
#[derive(Debug, Clone)]
pub struct Resolved {
    pub start: (f64, f64),
    pub prims: Vec<(String, Prim)>,
}

/// Gap allowed between a curve's start and the chain, mm (the written resolution).
const GAP_MM: f64 = 1e-3;

/// Resolve corners, place chords, and run the geometry and tool checks.
pub fn resolve(job: &ChainJob) -> Result<Resolved, ChainError> {
    if job.segments.is_empty() {
        return Err(ChainError::Empty);
    }
    let mut at = (job.start_z_mm, job.start_x_mm);
    let mut prims = Vec::new();
    // A corner break shortens the start of the next line: carried here.
    let mut segs = job.segments.iter().peekable();
    while let Some(l) = segs.next() {
        let bad = |what: String| ChainError::Value {
            segment: l.label.clone(),
            what,
        };
        match &l.segment {
            Segment::Line {
                z_mm,
                x_mm,
                chamfer_mm,
                round_mm,
            } => {
                let corner = (*z_mm, *x_mm);
                let brk = chamfer_mm
                    .map(|c| (c, false))
                    .or(round_mm.map(|r| (r, true)));
                let next = segs.peek().and_then(|n| match n.segment {
                    Segment::Line { z_mm, x_mm, .. } => Some((z_mm, x_mm)),
                    _ => None,
                });
                match (brk, next) {
                    (None, _) => prims.push((l.label.clone(), Prim::Line { to: corner })),
                    (Some(_), None) => {
                        return Err(bad("a chamfer or radius needs a line after it".to_owned()));
                    }
                    (Some((size, round)), Some(after)) => {
                        for p in break_corner(at, corner, after, size, round).map_err(bad)? {
                            prims.push((l.label.clone(), p));
                        }
                    }
                }
                at = end_of(&prims, at);
            }
            Segment::Arc {
                z_mm,
                x_mm,
                radius_mm,
                cw,
            } => {
                let to = (*z_mm, *x_mm);
                let centre = arc_centre(at, to, *radius_mm, *cw).map_err(bad)?;
                prims.push((
                    l.label.clone(),
                    Prim::Arc {
                        to,
                        centre,
                        cw: *cw,
                    },
                ));
                at = to;
            }
            Segment::Curve(curve) => {
                let j = curve.jet(0.0);
                let gap = (j.z - at.0).hypot(j.x - at.1);
                if gap.is_nan() || gap > GAP_MM {
                    return Err(ChainError::Gap {
                        segment: l.label.clone(),
                        z_mm: j.z,
                        x_mm: j.x,
                        at_z_mm: at.0,
                        at_x_mm: at.1,
                        gap_um: gap * 1e3,
                    });
                }
                let (_, us, mut points) = place_chords_for(curve, job.tolerance_mm, job.decimals)?;
                let worst_mm = crate::chords::worst_deviation(curve, &us, &points).1;
                points.remove(0);
                at = *points.last().unwrap_or(&at);
                prims.push((l.label.clone(), Prim::Chords { points, worst_mm }));
            }
        }
    }
    let r = Resolved {
        start: (job.start_z_mm, job.start_x_mm),
        prims,
    };
    check_tool(&r, &job.insert)?;
    Ok(r)
}

fn end_of(prims: &[(String, Prim)], at: (f64, f64)) -> (f64, f64) {
    match prims.last().map(|p| &p.1) {
        Some(Prim::Line { to } | Prim::Arc { to, .. }) => *to,
        Some(Prim::Chords { points, .. }) => *points.last().unwrap_or(&at),
        None => at,
    }
}

/// The line `from` → `corner` with its corner towards `after` broken: a chamfer of equal
/// legs `size`, or a tangent radius `size`.
fn break_corner(
    from: (f64, f64),
    corner: (f64, f64),
    after: (f64, f64),
    size: f64,
    round: bool,
) -> Result<Vec<Prim>, String> {
    let unit = |a: (f64, f64), b: (f64, f64)| {
        let l = (b.0 - a.0).hypot(b.1 - a.1);
        ((b.0 - a.0) / l, (b.1 - a.1) / l, l)
    };
    let (u1z, u1x, l1) = unit(from, corner);
    let (u2z, u2x, l2) = unit(corner, after);
    let turn = (u1z * u2x - u1x * u2z).atan2(u1z * u2z + u1x * u2x);
    if !(size.is_finite() && size > 0.0) || turn.abs() < 1e-9 {
        return Err(format!(
            "the corner break {size} mm needs a size > 0 and a corner to break"
        ));
    }
    let leg = if round {
        size * (turn.abs() / 2.0).tan()
    } else {
        size
    };
    if leg >= l1 || leg >= l2 {
        return Err(format!(
            "the corner break {size} mm is longer than the lines it joins"
        ));
    }
    let t1 = (corner.0 - leg * u1z, corner.1 - leg * u1x);
    let t2 = (corner.0 + leg * u2z, corner.1 + leg * u2x);
    let second = if round {
        // Centre to the side the path turns to; a left turn (turn > 0) runs counter-clockwise.
        let s = turn.signum();
        Prim::Arc {
            to: t2,
            centre: (t1.0 - s * size * u1x, t1.1 + s * size * u1z),
            cw: turn < 0.0,
        }
    } else {
        Prim::Line { to: t2 }
    };
    Ok(vec![Prim::Line { to: t1 }, second])
}

/// Centre of the shorter arc from `a` to `b` with radius `r`, clockwise or not.
fn arc_centre(a: (f64, f64), b: (f64, f64), r: f64, cw: bool) -> Result<(f64, f64), String> {
    let (dz, dx) = (b.0 - a.0, b.1 - a.1);
    let half = dz.hypot(dx) / 2.0;
    if !(r.is_finite() && r >= half && half > 0.0) {
        return Err(format!(
            "radius {r} mm cannot join points {:.4} mm apart",
            2.0 * half
        ));
    }
    let s = (r * r - half * half).sqrt() / (2.0 * half);
    // Right of the chord for a clockwise arc, left for counter-clockwise.
    let (nz, nx) = if cw { (dx, -dz) } else { (-dx, dz) };
    Ok((a.0 + dz / 2.0 + s * nz, a.1 + dx / 2.0 + s * nx))
}

/// Travel directions and radii of the finish contour, sampled, against the insert; and
/// the axis.
fn check_tool(r: &Resolved, insert: &Insert) -> Result<(), ChainError> {
    let mut at = r.start;
    for (label, p) in &r.prims {
        for (a, b, radius) in samples(at, p) {
            let seg = || label.clone();
            if a.1 < -1e-9 || b.1 < -1e-9 {
                let q = if a.1 < b.1 { a } else { b };
                return Err(ChainError::BehindAxis {
                    segment: seg(),
                    z_mm: q.0,
                    x_mm: q.1,
                });
            }
            let (dz, dx) = (b.0 - a.0, b.1 - a.1);
            if dz.hypot(dx) < 1e-12 {
                continue;
            }
            // 0° along −z, +90° straight up a face, −90° straight down.
            let angle_deg = dx.atan2(-dz).to_degrees();
            let (what, limit_deg, over) = if angle_deg >= 0.0 {
                ("rises", insert.max_rise_deg(), angle_deg)
            } else {
                ("descends", insert.max_descent_deg(), -angle_deg)
            };
            if over > limit_deg + 1e-9 {
                return Err(ChainError::Insert {
                    segment: seg(),
                    what,
                    angle_deg: over,
                    limit_deg,
                    z_mm: a.0,
                    x_mm: a.1,
                });
            }
            if let Some(rad) = radius
                && rad < insert.nose_radius_mm
            {
                return Err(ChainError::NoseTooLarge {
                    segment: seg(),
                    radius_mm: rad,
                    nose_radius_mm: insert.nose_radius_mm,
                    z_mm: a.0,
                });
            }
        }
        at = end_of(std::slice::from_ref(&(label.clone(), p.clone())), at);
    }
    Ok(())
}

/// A piece of the contour: from, to, and the concave radius it bends by, if any.
type Piece = ((f64, f64), (f64, f64), Option<f64>);

/// Short pieces of an element: (from, to, concave radius seen from the tool if any).
/// Arcs are cut in 64; chords are their own pieces, their radius from three points.
fn samples(at: (f64, f64), p: &Prim) -> Vec<Piece> {
    match p {
        Prim::Line { to } => vec![(at, *to, None)],
        Prim::Arc { to, centre, cw } => {
            let r = (at.0 - centre.0).hypot(at.1 - centre.1);
            let a0 = (at.1 - centre.1).atan2(at.0 - centre.0);
            let a1 = (to.1 - centre.1).atan2(to.0 - centre.0);
            let tau = std::f64::consts::TAU;
            let sweep = if *cw {
                -(a0 - a1).rem_euclid(tau)
            } else {
                (a1 - a0).rem_euclid(tau)
            };
            let pt = |k: usize| {
                let a = a0 + sweep * k as f64 / 64.0;
                (centre.0 + r * a.cos(), centre.1 + r * a.sin())
            };
            // Travelling −z with the tool above, a clockwise arc bends towards the tool.
            let concave = cw.then_some(r);
            (0..64).map(|k| (pt(k), pt(k + 1), concave)).collect()
        }
        Prim::Chords { points, .. } => {
            let mut all = vec![at];
            all.extend(points);
            (1..all.len())
                .map(|i| {
                    let rad = all
                        .get(i + 1)
                        .and_then(|&c| concave_radius(all[i - 1], all[i], c));
                    (all[i - 1], all[i], rad)
                })
                .collect()
        }
    }
}

/// Radius of the circle through three points when it bends to the tool's side (right of
/// the travel), else `None`.
fn concave_radius(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> Option<f64> {
    let cross = (b.0 - a.0) * (c.1 - b.1) - (b.1 - a.1) * (c.0 - b.0);
    if cross >= 0.0 {
        return None;
    }
    let (ab, bc, ca) = (
        (b.0 - a.0).hypot(b.1 - a.1),
        (c.0 - b.0).hypot(c.1 - b.1),
        (a.0 - c.0).hypot(a.1 - c.1),
    );
    Some(ab * bc * ca / (2.0 * cross.abs()))
}

/// Points along the finish contour (arcs in 64 pieces), for roughing and reports.
pub fn polyline(r: &Resolved) -> Vec<(f64, f64)> {
    let mut out = vec![r.start];
    let mut at = r.start;
    for (_, p) in &r.prims {
        for (_, b, _) in samples(at, p) {
            out.push(b);
        }
        at = *out.last().unwrap_or(&at);
    }
    out
}

/// `v` rounded to the written decimals.
pub(crate) fn written(v: f64) -> f64 {
    round_to(v, 4)
}
