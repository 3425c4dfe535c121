//! `camloop planing`: ratio-coupled planing of a twisted-lobe rotor (A follows X), from the
//! first unfinished segment: SINUMERIK curve table with `LEADON`, or ISO G-code with
//! synchronised X–A moves.

use super::contour::DialectArg;
use super::output::Outputs;
use crate::core::generate::dialect::{Decimals, Dialect, Form};
use crate::core::generate::planing::{JobState, PlaningJob, generate, render_sinumerik_table};
use anyhow::Context;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct PlaningArgs {
    #[arg(long, default_value = "ROTOR_PLANE")]
    pub name: String,
    /// Identical segments of the rotor end face.
    #[arg(long, default_value_t = 6)]
    pub segments: u32,
    /// Degrees of A per mm of X over the stroke.
    #[arg(long)]
    pub ratio_deg_per_mm: f64,
    #[arg(long)]
    pub x_start_mm: f64,
    #[arg(long)]
    pub x_end_mm: f64,
    #[arg(long, default_value_t = 5.0)]
    pub lead_in_mm: f64,
    #[arg(long)]
    pub z_cut_mm: f64,
    #[arg(long)]
    pub z_lift_mm: f64,
    #[arg(long, default_value_t = 1000.0)]
    pub feed_mm_min: f64,
    /// Segments already finished, as the control's job mark (R50 / #50) reads after an
    /// interruption; the program starts at the next one.
    #[arg(long, default_value_t = 0)]
    pub done: u32,
    /// Curve table number (SINUMERIK).
    #[arg(long, default_value_t = 1)]
    pub table_number: u32,
    #[arg(long, value_enum, default_value_t = DialectArg::Sinumerik)]
    pub dialect: DialectArg,
    #[arg(long, value_name = "OUT", default_value = "planing.mpf")]
    pub out: PathBuf,
}

pub(crate) fn run_planing(args: PlaningArgs) -> anyhow::Result<()> {
    let job = PlaningJob {
        name: args.name.clone(),
        segments: args.segments,
        ratio_deg_per_mm: args.ratio_deg_per_mm,
        x_start_mm: args.x_start_mm,
        x_end_mm: args.x_end_mm,
        lead_in_mm: args.lead_in_mm,
        z_cut_mm: args.z_cut_mm,
        z_lift_mm: args.z_lift_mm,
        feed_mm_min: args.feed_mm_min,
    };
    if args.done > args.segments {
        anyhow::bail!(
            "--done is {}: the job has only {} segments",
            args.done,
            args.segments
        );
    }
    let state = JobState::from_mark(args.segments, args.done);
    let text = match args.dialect {
        DialectArg::Sinumerik => render_sinumerik_table(&job, &state, args.table_number),
        DialectArg::Iso => generate(&job, &state)
            .map(|p| Dialect::Iso.render(&p, Form::Expanded, Decimals::default())),
    }
    .context("planing refused")?;
    let mut outputs = Outputs::default();
    outputs.add(&args.out, text);
    outputs.commit()?;
    println!(
        "{}: segments {} to {} of {}",
        args.out.display(),
        args.done + 1,
        args.segments,
        args.segments
    );
    Ok(())
}
