//! The contour file (TOML): a turned part as a start point and `[[segment]]`s chained
//! along −z, with the insert, the roughing and the feeds. Read into a
//! [`crate::contour_chain::ChainJob`]; unknown keys are errors and every error names the
//! segment (`segment 3 (arc)`) or the key.

use serde::Deserialize;
use thiserror::Error;

use crate::contour_chain::{ChainJob, ChainRoughing, Insert, Labeled, Segment};
use crate::curve::{Curve, Ellipse, Parabola, Sine, Tangent};
use crate::param_curve::{ExprError, ParamCurve};
use crate::profile::{ProfileError, parse_profile};
use crate::setup::{FeedMode, Setup};

/// Why a contour file is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ContourFileError {
    #[error("{file}: {message}")]
    Toml { file: String, message: String },
    #[error("{file}: segment {index} ({kind}): {source}")]
    Expr {
        file: String,
        index: usize,
        kind: &'static str,
        source: Box<ExprError>,
    },
    #[error("{file}: segment {index} (spline): {source}")]
    Spline {
        file: String,
        index: usize,
        source: ProfileError,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    name: String,
    #[serde(default = "default_tolerance")]
    tolerance_um: f64,
    #[serde(default = "default_clearance")]
    clearance_mm: f64,
    #[serde(default = "default_finish")]
    finish_feed_mm_rev: f64,
    #[serde(default = "default_rough")]
    rough_feed_mm_rev: f64,
    start: Point,
    insert: InsertFile,
    #[serde(default)]
    roughing: RoughingFile,
    segment: Vec<SegmentFile>,
}

fn default_tolerance() -> f64 {
    2.0
}
fn default_clearance() -> f64 {
    1.0
}
fn default_finish() -> f64 {
    0.1
}
fn default_rough() -> f64 {
    0.25
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Point {
    z_mm: f64,
    x_mm: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct InsertFile {
    nose_radius_mm: f64,
    approach_deg: f64,
    included_deg: f64,
    #[serde(default = "default_min_clearance")]
    min_clearance_deg: f64,
}

fn default_min_clearance() -> f64 {
    2.0
}

#[derive(Debug, Default, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
enum RoughingFile {
    #[default]
    None,
    Cycle95 {
        depth_mm: f64,
        allowance_mm: f64,
    },
    Passes {
        blank_radius_mm: f64,
        depth_mm: f64,
        allowance_mm: f64,
    },
}

#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
enum SegmentFile {
    Line {
        z_mm: Option<f64>,
        x_mm: Option<f64>,
        chamfer_mm: Option<f64>,
        round_mm: Option<f64>,
    },
    Arc {
        z_mm: f64,
        x_mm: f64,
        radius_mm: f64,
        direction: Direction,
    },
    Ellipse(Ellipse),
    Parabola(Parabola),
    Sine(Sine),
    Tangent(Tangent),
    Spline {
        points: Vec<[f64; 2]>,
    },
    Parametric {
        x: String,
        z: String,
        t_start: f64,
        t_end: f64,
    },
    Graph {
        x: String,
        z_start_mm: f64,
        z_end_mm: f64,
    },
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Direction {
    Cw,
    Ccw,
}

/// The job in `text` (named `file` in errors); `setup` gives spindle, tool and X mode, and
/// gets G95 (the file's feeds are per revolution).
pub fn parse_contour_file(
    text: &str,
    file: &str,
    setup: Setup,
) -> Result<ChainJob, ContourFileError> {
    let f: File = toml::from_str(text).map_err(|e| ContourFileError::Toml {
        file: file.to_owned(),
        message: e.to_string().trim_end().replace('\n', " "),
    })?;
    let mut at = (f.start.z_mm, f.start.x_mm);
    let mut segments = Vec::new();
    for (i, s) in f.segment.into_iter().enumerate() {
        let index = i + 1;
        let kind = kind_of(&s);
        let segment = to_segment(s, at).map_err(|e| match e {
            SegErr::Expr(source) => ContourFileError::Expr {
                file: file.to_owned(),
                index,
                kind,
                source: Box::new(source),
            },
            SegErr::Spline(source) => ContourFileError::Spline {
                file: file.to_owned(),
                index,
                source,
            },
        })?;
        at = end_point(&segment);
        segments.push(Labeled {
            label: format!("segment {index} ({kind})"),
            segment,
        });
    }
    let roughing = match f.roughing {
        RoughingFile::None => ChainRoughing::None,
        RoughingFile::Cycle95 {
            depth_mm,
            allowance_mm,
        } => ChainRoughing::Cycle95 {
            depth_mm,
            allowance_mm,
        },
        RoughingFile::Passes {
            blank_radius_mm,
            depth_mm,
            allowance_mm,
        } => ChainRoughing::Passes {
            blank_radius_mm,
            depth_mm,
            allowance_mm,
        },
    };
    Ok(ChainJob {
        name: f.name,
        start_z_mm: f.start.z_mm,
        start_x_mm: f.start.x_mm,
        segments,
        tolerance_mm: f.tolerance_um * 1e-3,
        decimals: 4,
        insert: Insert {
            nose_radius_mm: f.insert.nose_radius_mm,
            approach_deg: f.insert.approach_deg,
            included_deg: f.insert.included_deg,
            min_clearance_deg: f.insert.min_clearance_deg,
        },
        clearance_mm: f.clearance_mm,
        finish_feed: f.finish_feed_mm_rev,
        rough_feed: f.rough_feed_mm_rev,
        roughing,
        setup: Setup {
            feed_mode: FeedMode::PerRevolution,
            ..setup
        },
    })
}

fn kind_of(s: &SegmentFile) -> &'static str {
    match s {
        SegmentFile::Line { .. } => "line",
        SegmentFile::Arc { .. } => "arc",
        SegmentFile::Ellipse(_) => "ellipse",
        SegmentFile::Parabola(_) => "parabola",
        SegmentFile::Sine(_) => "sine",
        SegmentFile::Tangent(_) => "tangent",
        SegmentFile::Spline { .. } => "spline",
        SegmentFile::Parametric { .. } => "parametric",
        SegmentFile::Graph { .. } => "graph",
    }
}

enum SegErr {
    Expr(ExprError),
    Spline(ProfileError),
}

/// Where a segment ends (a line's missing coordinate stays where the chain is).
fn end_point(s: &Segment) -> (f64, f64) {
    match s {
        Segment::Line { z_mm, x_mm, .. } | Segment::Arc { z_mm, x_mm, .. } => (*z_mm, *x_mm),
        Segment::Curve(c) => {
            let j = c.jet(c.span());
            (j.z, j.x)
        }
    }
}

fn to_segment(s: SegmentFile, at: (f64, f64)) -> Result<Segment, SegErr> {
    Ok(match s {
        SegmentFile::Line {
            z_mm,
            x_mm,
            chamfer_mm,
            round_mm,
        } => Segment::Line {
            z_mm: z_mm.unwrap_or(at.0),
            x_mm: x_mm.unwrap_or(at.1),
            chamfer_mm,
            round_mm,
        },
        SegmentFile::Arc {
            z_mm,
            x_mm,
            radius_mm,
            direction,
        } => Segment::Arc {
            z_mm,
            x_mm,
            radius_mm,
            cw: matches!(direction, Direction::Cw),
        },
        SegmentFile::Ellipse(e) => Segment::Curve(Curve::Ellipse(e)),
        SegmentFile::Parabola(p) => Segment::Curve(Curve::Parabola(p)),
        SegmentFile::Sine(k) => Segment::Curve(Curve::Sine(k)),
        SegmentFile::Tangent(k) => Segment::Curve(Curve::Tangent(k)),
        SegmentFile::Spline { points } => {
            // The profile reader's rules (z monotone, 3 points at least); its "line n" is
            // the n-th point here.
            let text: String = points
                .iter()
                .map(|p| format!("{},{}\n", p[0], p[1]))
                .collect();
            Segment::Curve(parse_profile(&text, "points").map_err(SegErr::Spline)?)
        }
        SegmentFile::Parametric {
            x,
            z,
            t_start,
            t_end,
        } => Segment::Curve(Curve::Param(Box::new(
            ParamCurve::parametric(&x, &z, t_start, t_end).map_err(SegErr::Expr)?,
        ))),
        SegmentFile::Graph {
            x,
            z_start_mm,
            z_end_mm,
        } => Segment::Curve(Curve::Param(Box::new(
            ParamCurve::graph(&x, z_start_mm, z_end_mm).map_err(SegErr::Expr)?,
        ))),
    })
}
