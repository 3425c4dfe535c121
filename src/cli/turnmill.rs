//! `camloop turnmill`: crank pins, cheeks and arm contours from a TOML job file, milled on
//! X/Y with C held, at Z stations and in radial passes, as a SINUMERIK or ISO program.

use super::contour::{DialectArg, FormArg};
use super::output::Outputs;
use crate::core::generate::dialect::{Dialect, Form};
use crate::core::generate::setup::{Coolant, Setup, SpindleSpeed};
use crate::core::generate::turnmill::path::Side;
use crate::core::generate::turnmill::{
    Contour, ContourSeg, EccentricCircle, Feature, RadiusMode, Shape, TurnMillJob, generate, render,
};
use anyhow::Context;
use clap::Args;
use serde::Deserialize;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct TurnMillArgs {
    /// The job (TOML): tool, spindle, radius mode, approach and `[[feature]]` tables, each a
    /// `circle` or a `contour` of lines and arcs; `config/turnmill-crank.toml` names every
    /// key.
    #[arg(long, value_name = "JOB.toml")]
    pub job: PathBuf,
    #[arg(long, value_name = "OUT", default_value = "turnmill.mpf")]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value_t = DialectArg::Sinumerik)]
    pub dialect: DialectArg,
    /// Both forms write numbers only (the path is computed here); kept for symmetry with
    /// `camloop contour`.
    #[arg(long, value_enum, default_value_t = FormArg::Loop)]
    pub form: FormArg,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct JobFile {
    name: String,
    tool_radius_mm: f64,
    /// `baked` or `compensated`.
    radius_mode: String,
    clearance_mm: f64,
    lead_mm: f64,
    z_clear_mm: f64,
    feed_mm_min: f64,
    #[serde(default = "c_axis")]
    c_axis: String,
    #[serde(default)]
    setup: SetupFile,
    feature: Vec<FeatureFile>,
}

fn c_axis() -> String {
    "C".to_owned()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct SetupFile {
    work_offset: u8,
    tool: u32,
    tool_offset: u32,
    spindle_rpm: f64,
    /// `flood`, `mist` or `off`.
    coolant: String,
}

impl Default for SetupFile {
    fn default() -> Self {
        SetupFile {
            work_offset: 1,
            tool: 1,
            tool_offset: 1,
            spindle_rpm: 3000.0,
            coolant: "flood".to_owned(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FeatureFile {
    label: String,
    z_mm: Vec<f64>,
    #[serde(default)]
    stock_mm: f64,
    #[serde(default = "one")]
    step_mm: f64,
    circle: Option<CircleFile>,
    contour: Option<ContourFile>,
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CircleFile {
    eccentricity_mm: f64,
    phase_deg: f64,
    radius_mm: f64,
    start_deg: f64,
    end_deg: f64,
    safety_deg: f64,
    #[serde(default)]
    concave: bool,
    #[serde(default)]
    clockwise: bool,
    c_deg: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ContourFile {
    c_deg: f64,
    /// `left` or `right`, looking along the contour.
    tool_side: String,
    start: [f64; 2],
    segment: Vec<SegmentFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentFile {
    line_to: Option<[f64; 2]>,
    arc_to: Option<[f64; 2]>,
    centre: Option<[f64; 2]>,
    #[serde(default)]
    clockwise: bool,
}

fn setup(s: &SetupFile) -> anyhow::Result<Setup> {
    let mut setup = Setup::milling();
    setup.work_offset = s.work_offset;
    setup.tool.number = s.tool;
    setup.tool.offset = s.tool_offset;
    setup.spindle.speed = SpindleSpeed::Rpm(s.spindle_rpm);
    setup.coolant = match s.coolant.as_str() {
        "flood" => Coolant::Flood,
        "mist" => Coolant::Mist,
        "off" => Coolant::Off,
        other => anyhow::bail!("setup.coolant is {other:?}: \"flood\", \"mist\" or \"off\""),
    };
    Ok(setup)
}

fn feature(f: FeatureFile) -> anyhow::Result<Feature> {
    let shape = match (f.circle, f.contour) {
        (Some(c), None) => Shape::Circle(EccentricCircle {
            eccentricity_mm: c.eccentricity_mm,
            phase_deg: c.phase_deg,
            radius_mm: c.radius_mm,
            start_deg: c.start_deg,
            end_deg: c.end_deg,
            safety_deg: c.safety_deg,
            concave: c.concave,
            clockwise: c.clockwise,
            c_deg: c.c_deg,
        }),
        (None, Some(k)) => Shape::Contour(contour(&f.label, k)?),
        _ => anyhow::bail!(
            "feature {:?}: give exactly one of [feature.circle] and [feature.contour]",
            f.label
        ),
    };
    Ok(Feature {
        label: f.label,
        shape,
        z_mm: f.z_mm,
        stock_mm: f.stock_mm,
        step_mm: f.step_mm,
    })
}

fn contour(label: &str, k: ContourFile) -> anyhow::Result<Contour> {
    let tool_side = match k.tool_side.as_str() {
        "left" => Side::Left,
        "right" => Side::Right,
        other => anyhow::bail!("feature {label:?}: tool_side is {other:?}: \"left\" or \"right\""),
    };
    let mut segments = Vec::new();
    for (i, s) in k.segment.into_iter().enumerate() {
        segments.push(match (s.line_to, s.arc_to, s.centre) {
            (Some(to), None, None) => ContourSeg::Line { to: (to[0], to[1]) },
            (None, Some(to), Some(c)) => ContourSeg::Arc {
                to: (to[0], to[1]),
                centre: (c[0], c[1]),
                clockwise: s.clockwise,
            },
            _ => anyhow::bail!(
                "feature {label:?}, segment {}: a segment is `line_to`, or `arc_to` with `centre`",
                i + 1
            ),
        });
    }
    Ok(Contour {
        start: (k.start[0], k.start[1]),
        segments,
        tool_side,
        c_deg: k.c_deg,
    })
}

fn job(file: JobFile) -> anyhow::Result<TurnMillJob> {
    let radius_mode = match file.radius_mode.as_str() {
        "baked" => RadiusMode::Baked,
        "compensated" => RadiusMode::Compensated,
        other => anyhow::bail!("radius_mode is {other:?}: \"baked\" or \"compensated\""),
    };
    Ok(TurnMillJob {
        name: file.name,
        setup: setup(&file.setup)?,
        tool_radius_mm: file.tool_radius_mm,
        radius_mode,
        clearance_mm: file.clearance_mm,
        lead_mm: file.lead_mm,
        z_clear_mm: file.z_clear_mm,
        feed_mm_min: file.feed_mm_min,
        c_axis: file.c_axis,
        features: file
            .feature
            .into_iter()
            .map(feature)
            .collect::<anyhow::Result<_>>()?,
    })
}

pub(crate) fn run_turnmill(args: TurnMillArgs) -> anyhow::Result<()> {
    let path = args.job.display().to_string();
    let text = std::fs::read_to_string(&args.job).with_context(|| format!("cannot read {path}"))?;
    let file: JobFile = toml::from_str(&text).with_context(|| path.clone())?;
    let job = job(file).with_context(|| path.clone())?;
    let refused = || format!("{path}: refused");
    let program = generate(&job).with_context(refused)?;
    let form = match args.form {
        FormArg::Loop => Form::Loop,
        FormArg::Expanded => Form::Expanded,
        FormArg::RParams => anyhow::bail!(
            "{path}: --form r-params is the single turning curves' form; a turn-mill program is written with numbers only"
        ),
    };
    let text = render(&job, &program, Dialect::from(args.dialect), form).with_context(refused)?;
    let mut outputs = Outputs::default();
    outputs.add(&args.out, text);
    outputs.commit()?;
    println!("{}: {} features", args.out.display(), job.features.len());
    Ok(())
}
