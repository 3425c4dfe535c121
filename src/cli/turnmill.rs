//! `camloop turnmill`: eccentric circles (crank pins, cheeks, arm contours) from a TOML job
//! file, milled on X/Y with C held, as a SINUMERIK or ISO program.

use super::contour::{DialectArg, FormArg};
use super::output::Outputs;
use crate::core::generate::dialect::{Decimals, Dialect, Form};
use crate::core::generate::turnmill::{EccentricCircle, TurnMillJob, generate};
use anyhow::Context;
use clap::Args;
use serde::Deserialize;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct TurnMillArgs {
    /// The job: `name`, `tool_radius_mm`, `clearance_mm`, `feed_mm_min` and `[[circle]]`
    /// tables (`label`, `eccentricity_mm`, `phase_deg`, `radius_mm`, `start_deg`,
    /// `end_deg`, `safety_deg`, optional `concave` and `c_deg`).
    #[arg(long, value_name = "JOB.toml")]
    pub job: PathBuf,
    #[arg(long, value_name = "OUT", default_value = "turnmill.mpf")]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value_t = DialectArg::Sinumerik)]
    pub dialect: DialectArg,
    /// `loop` keeps the `DEF REAL` centre transform for the control; `expanded` writes
    /// numbers only.
    #[arg(long, value_enum, default_value_t = FormArg::Loop)]
    pub form: FormArg,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct JobFile {
    name: String,
    tool_radius_mm: f64,
    clearance_mm: f64,
    feed_mm_min: f64,
    circle: Vec<CircleFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CircleFile {
    label: String,
    eccentricity_mm: f64,
    phase_deg: f64,
    radius_mm: f64,
    start_deg: f64,
    end_deg: f64,
    safety_deg: f64,
    #[serde(default)]
    concave: bool,
    c_deg: Option<f64>,
}

pub(crate) fn run_turnmill(args: TurnMillArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.job)
        .with_context(|| format!("cannot read {}", args.job.display()))?;
    let file: JobFile = toml::from_str(&text).with_context(|| format!("{}", args.job.display()))?;
    let job = TurnMillJob {
        name: file.name,
        tool_radius_mm: file.tool_radius_mm,
        clearance_mm: file.clearance_mm,
        feed_mm_min: file.feed_mm_min,
        circles: file
            .circle
            .into_iter()
            .map(|c| EccentricCircle {
                label: c.label,
                eccentricity_mm: c.eccentricity_mm,
                phase_deg: c.phase_deg,
                radius_mm: c.radius_mm,
                start_deg: c.start_deg,
                end_deg: c.end_deg,
                safety_deg: c.safety_deg,
                concave: c.concave,
                c_deg: c.c_deg,
            })
            .collect(),
    };
    let program = generate(&job).with_context(|| format!("{}: refused", args.job.display()))?;
    let form = match args.form {
        FormArg::Loop => Form::Loop,
        FormArg::Expanded => Form::Expanded,
    };
    let text = Dialect::from(args.dialect).render(&program, form, Decimals::default());
    let mut outputs = Outputs::default();
    outputs.add(&args.out, text);
    outputs.commit()?;
    println!("{}: {} circles", args.out.display(), job.circles.len());
    Ok(())
}
