//! Turn-mill eccentric surfaces (X/Y/C): crank pins, cheek faces and arm contours milled
//! with C held at an angle and the tool on X–Y lines and arcs, at Z stations, in radial
//! depth passes, with the tool radius baked into the path or left to G41/G42.
//!
//! A circle's centre at `(a, b) = e·(cos phase, sin phase)` in the part frame lands, with C
//! at φ, at `X = cos φ·a + sin φ·b`, `Y = −sin φ·a + cos φ·b`. Every pass starts and ends at
//! the park point, on +X outside the part's swing circle, where alone C turns. From there
//! the approach is the turn-mill study's: along Y, then X, then Y at feed, tangentially onto
//! the surface (for a cut starting on the +X side of its centre; otherwise the same three
//! moves along the start's tangent and normal). A concave surface (a bore, an arm fillet)
//! is entered from above, at Z clear, and radially.

pub mod path;

use thiserror::Error;

use super::ir::{Axis, Compensation, Expr, Motion, Plane, Program, Stmt};
use super::setup::{Setup, SetupError};
use camloop_core::program::ProgramNameError;
use path::{OffsetError, P, Seg, Side};

/// One circular surface of the drawing.
#[derive(Debug, Clone, PartialEq)]
pub struct EccentricCircle {
    pub eccentricity_mm: f64,
    pub phase_deg: f64,
    pub radius_mm: f64,
    /// Drawing angles about the circle's own centre, part frame; end > start. A full turn
    /// (end − start = 360) is cut from the point C puts on the +X side of the centre.
    pub start_deg: f64,
    pub end_deg: f64,
    pub safety_deg: f64,
    /// True for a concave surface (bore, arm fillet): the tool runs inside the circle.
    pub concave: bool,
    /// True to cut clockwise (G2); counter-clockwise (G3) otherwise.
    pub clockwise: bool,
    /// C angle while cutting; `None` puts the cut's start on the +X side of the centre.
    pub c_deg: Option<f64>,
}

/// An element of an arm contour, from the end of the one before.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ContourSeg {
    Line { to: P },
    Arc { to: P, centre: P, clockwise: bool },
}

/// An arm contour: lines and arcs in the part frame, cut at one C angle.
#[derive(Debug, Clone, PartialEq)]
pub struct Contour {
    pub start: P,
    pub segments: Vec<ContourSeg>,
    /// Side the tool runs on, looking along the contour; the part is on the other.
    pub tool_side: Side,
    pub c_deg: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    Circle(EccentricCircle),
    Contour(Contour),
}

/// A surface with where and how deep it is cut.
#[derive(Debug, Clone, PartialEq)]
pub struct Feature {
    pub label: String,
    pub shape: Shape,
    /// Z stations, in order: the surface is cut at each.
    pub z_mm: Vec<f64>,
    /// Radial stock on the surface, removed in passes of at most `step_mm`, mm.
    pub stock_mm: f64,
    pub step_mm: f64,
}

/// Tool radius in the path, or G41/G42 with the control's own radius.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RadiusMode {
    Baked,
    Compensated,
}

/// A turn-mill job.
#[derive(Debug, Clone, PartialEq)]
pub struct TurnMillJob {
    pub name: String,
    /// Tool, milling spindle, feed mode (G94) and coolant.
    pub setup: Setup,
    pub tool_radius_mm: f64,
    pub radius_mode: RadiusMode,
    /// Distance off the surface of every approach and retract, mm.
    pub clearance_mm: f64,
    /// Tangential lead-in and lead-out, mm.
    pub lead_mm: f64,
    /// Z above the part: the start, the end and the entry into concave surfaces.
    pub z_clear_mm: f64,
    pub feed_mm_min: f64,
    /// Name of the C axis on the control (SINUMERIK: `C1`, …; ISO: one letter).
    pub c_axis: String,
    pub features: Vec<Feature>,
}

/// Why a turn-mill job is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TurnMillError {
    #[error(transparent)]
    Name(#[from] ProgramNameError),
    #[error(transparent)]
    Setup(#[from] SetupError),
    #[error("{label}: {field} is {value}: {rule}")]
    Value {
        label: String,
        field: &'static str,
        value: f64,
        rule: &'static str,
    },
    #[error("{label}: the path radius {radius_mm} mm leaves no room for the tool")]
    ToolTooLarge { label: String, radius_mm: f64 },
    #[error("{label}: segment {segment}: {what}")]
    Segment {
        label: String,
        segment: usize,
        what: &'static str,
    },
    #[error("{label}: {what}")]
    Approach { label: String, what: &'static str },
    #[error("the C axis name {0:?}: {1}")]
    AxisName(String, &'static str),
    #[error("the job has no features")]
    Empty,
}

mod build;

pub use build::{cut_span_deg, generate, park_x_mm, passes, render, safety_rules};

/// The tool side of a circle: looking along travel, the part is inside a convex circle.
fn circle_side(c: &EccentricCircle) -> Side {
    match (c.concave, c.clockwise) {
        (false, false) | (true, true) => Side::Right,
        (false, true) | (true, false) => Side::Left,
    }
}

/// C while cutting a circle.
pub fn circle_c_deg(c: &EccentricCircle) -> f64 {
    c.c_deg.unwrap_or(if c.end_deg - c.start_deg >= 360.0 {
        c.phase_deg
    } else if c.clockwise {
        c.end_deg + c.safety_deg
    } else {
        c.start_deg - c.safety_deg
    })
}

/// The feature's path in the part frame, before any offset.
fn part_path(f: &Feature) -> Result<Vec<Seg>, TurnMillError> {
    match &f.shape {
        Shape::Circle(c) => {
            let centre = path::polar_deg(c.eccentricity_mm, c.phase_deg);
            let (from, to) = cut_span_deg(c);
            let (start, sweep) = if c.clockwise {
                (to, from - to)
            } else {
                (from, to - from)
            };
            Ok(vec![Seg::Arc {
                centre,
                radius: c.radius_mm,
                start_deg: start,
                sweep_deg: sweep,
            }])
        }
        Shape::Contour(k) => contour_path(&f.label, k),
    }
}

fn contour_path(label: &str, k: &Contour) -> Result<Vec<Seg>, TurnMillError> {
    let mut at = k.start;
    let mut out = Vec::new();
    for (i, s) in k.segments.iter().enumerate() {
        let bad = |what| TurnMillError::Segment {
            label: label.to_owned(),
            segment: i + 1,
            what,
        };
        let seg = match *s {
            ContourSeg::Line { to } => {
                if (to.0 - at.0).hypot(to.1 - at.1) < 1e-6 {
                    return Err(bad("the line has no length"));
                }
                Seg::Line { from: at, to }
            }
            ContourSeg::Arc {
                to,
                centre,
                clockwise,
            } => {
                let r0 = (at.0 - centre.0).hypot(at.1 - centre.1);
                let r1 = (to.0 - centre.0).hypot(to.1 - centre.1);
                // 1 µm: the drawing's own precision.
                if (r0 - r1).abs() > 1e-3 || r0 < 1e-6 {
                    return Err(bad(
                        "the arc's start and end are not on one circle about its centre",
                    ));
                }
                Seg::Arc {
                    centre,
                    radius: r0,
                    start_deg: (at.1 - centre.1).atan2(at.0 - centre.0).to_degrees(),
                    sweep_deg: path::sweep_between(centre, at, to, !clockwise),
                }
            }
        };
        at = seg.end();
        out.push(seg);
    }
    if out.is_empty() {
        return Err(TurnMillError::Segment {
            label: label.to_owned(),
            segment: 0,
            what: "the contour has no segments",
        });
    }
    Ok(out)
}

fn offset_error(label: &str, e: OffsetError) -> TurnMillError {
    match e {
        OffsetError::ArcTooSmall { segment } => TurnMillError::Segment {
            label: label.to_owned(),
            segment,
            what: "the arc is smaller than the tool's offset from it",
        },
        OffsetError::InsideCorner { segment } => TurnMillError::Segment {
            label: label.to_owned(),
            segment,
            what: "the corner after it is inside the tool's side: round it with an arc at least the offset's radius",
        },
    }
}

fn move_xy(motion: Motion, p: P, feed: Option<f64>) -> Stmt {
    Stmt::Move {
        motion,
        words: vec![(Axis::X, Expr::num(p.0)), (Axis::Y, Expr::num(p.1))],
        feed,
    }
}

fn move_1(motion: Motion, axis: Axis, v: f64) -> Stmt {
    Stmt::Move {
        motion,
        words: vec![(axis, Expr::num(v))],
        feed: None,
    }
}

/// Program header facts: plane and comments.
fn program(name: String, comments: Vec<String>, body: Vec<Stmt>) -> Program {
    Program {
        name,
        plane: Plane::Xy,
        vars: Vec::new(),
        comments,
        body,
    }
}

fn comp_for(side: Side) -> Compensation {
    match side {
        Side::Left => Compensation::Left,
        Side::Right => Compensation::Right,
    }
}
