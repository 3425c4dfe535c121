//! `camloop planing`: ratio-coupled planing of a cam rotor's end face (A and Z follow X),
//! resumable on the control, from a process card (`--job`) or from options, and the card
//! written back with `--save-job`.

mod card;

use super::output::Outputs;
use crate::core::generate::dialect::{Decimals, Dialect, Form};
use crate::core::generate::planing::coupled::render_sinumerik_table;
use crate::core::generate::planing::{generate, stroke_x_mm};
use anyhow::Context;
use card::Card;
use clap::Args;
use std::path::PathBuf;

/// Every option overrides the card's value; without `--job` the options marked "required
/// without --job" must all be given.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct PlaningArgs {
    /// The process card (TOML) to start from.
    #[arg(long, value_name = "CARD.toml")]
    pub job: Option<PathBuf>,
    /// Write the card of this job (the card read, with the options applied) here.
    #[arg(long, value_name = "CARD.toml")]
    pub save_job: Option<PathBuf>,
    #[arg(long)]
    pub name: Option<String>,
    /// Arcs round the rotor's end face.
    #[arg(long)]
    pub segments: Option<u32>,
    /// Radius of the face's developed section (required without --job).
    #[arg(long)]
    pub pitch_radius_mm: Option<f64>,
    /// Z of the lobe peaks (required without --job).
    #[arg(long)]
    pub z_peak_mm: Option<f64>,
    /// Z of the valleys (required without --job).
    #[arg(long)]
    pub z_valley_mm: Option<f64>,
    /// Degrees of A per mm of X; times the stroke, one arc (required without --job).
    #[arg(long)]
    pub ratio_deg_per_mm: Option<f64>,
    /// Required without --job.
    #[arg(long)]
    pub x_start_mm: Option<f64>,
    /// Required without --job.
    #[arg(long)]
    pub x_end_mm: Option<f64>,
    #[arg(long)]
    pub over_travel_front_mm: Option<f64>,
    #[arg(long)]
    pub over_travel_rear_mm: Option<f64>,
    /// Z of the lifted tool (required without --job).
    #[arg(long)]
    pub z_clear_mm: Option<f64>,
    #[arg(long)]
    pub feed_mm_min: Option<f64>,
    #[arg(long)]
    pub tolerance_um: Option<f64>,
    /// `sinumerik` or `iso`.
    #[arg(long)]
    pub dialect: Option<String>,
    /// `program` (X, A, Z per point) or `table` (SINUMERIK curve tables, A and Z follow X).
    #[arg(long)]
    pub form: Option<String>,
    #[arg(long, value_name = "OUT", default_value = "planing.mpf")]
    pub out: PathBuf,
}

/// The card without `--job`: the defaults of the optional values, the required ones from
/// the options.
fn card_from_options(a: &PlaningArgs) -> anyhow::Result<Card> {
    let need = |v: Option<f64>, flag: &str| {
        v.with_context(|| format!("--{flag} is required without --job"))
    };
    Ok(Card {
        name: "ROTOR_PLANE".to_owned(),
        rotor: card::Rotor {
            segments: 6,
            pitch_radius_mm: need(a.pitch_radius_mm, "pitch-radius-mm")?,
            z_peak_mm: need(a.z_peak_mm, "z-peak-mm")?,
            z_valley_mm: need(a.z_valley_mm, "z-valley-mm")?,
        },
        stroke: card::Stroke {
            ratio_deg_per_mm: need(a.ratio_deg_per_mm, "ratio-deg-per-mm")?,
            x_start_mm: need(a.x_start_mm, "x-start-mm")?,
            x_end_mm: need(a.x_end_mm, "x-end-mm")?,
            over_travel_front_mm: 5.0,
            over_travel_rear_mm: 5.0,
            z_clear_mm: need(a.z_clear_mm, "z-clear-mm")?,
            feed_mm_min: 1000.0,
            tolerance_um: 2.0,
            min_points_per_arc: 24,
        },
        machine: card::Machine {
            work_offset: 1,
            tool: 1,
            tool_offset: 1,
            coolant: false,
            mark_parameter_iso: 5000,
            hydraulics_on_m: None,
            hydraulics_off_m: None,
            a_forward_m: None,
            a_reverse_m: None,
            lift_on_m: None,
            lift_off_m: None,
        },
        output: card::Output {
            dialect: "sinumerik".to_owned(),
            form: "program".to_owned(),
            table_number: 1,
        },
    })
}

fn apply_options(a: &PlaningArgs, c: &mut Card) {
    let set = |slot: &mut f64, v: Option<f64>| {
        if let Some(v) = v {
            *slot = v;
        }
    };
    if let Some(n) = &a.name {
        c.name.clone_from(n);
    }
    if let Some(s) = a.segments {
        c.rotor.segments = s;
    }
    set(&mut c.rotor.pitch_radius_mm, a.pitch_radius_mm);
    set(&mut c.rotor.z_peak_mm, a.z_peak_mm);
    set(&mut c.rotor.z_valley_mm, a.z_valley_mm);
    let s = &mut c.stroke;
    set(&mut s.ratio_deg_per_mm, a.ratio_deg_per_mm);
    set(&mut s.x_start_mm, a.x_start_mm);
    set(&mut s.x_end_mm, a.x_end_mm);
    set(&mut s.over_travel_front_mm, a.over_travel_front_mm);
    set(&mut s.over_travel_rear_mm, a.over_travel_rear_mm);
    set(&mut s.z_clear_mm, a.z_clear_mm);
    set(&mut s.feed_mm_min, a.feed_mm_min);
    set(&mut s.tolerance_um, a.tolerance_um);
    if let Some(d) = &a.dialect {
        c.output.dialect.clone_from(d);
    }
    if let Some(f) = &a.form {
        c.output.form.clone_from(f);
    }
}

/// The program text the card asks for.
fn render(card: &Card) -> anyhow::Result<String> {
    let job = card.job()?;
    if card.output.dialect == "sinumerik" && job.m_codes.any_p() {
        anyhow::bail!("a P word on an M code is LinuxCNC's: a SINUMERIK M function has none");
    }
    let refused = "planing refused";
    match (card.output.dialect.as_str(), card.output.form.as_str()) {
        ("sinumerik", "table") => {
            render_sinumerik_table(&job, card.output.table_number).context(refused)
        }
        (d @ ("sinumerik" | "iso"), "program") => {
            let dialect = if d == "iso" {
                Dialect::Iso
            } else {
                Dialect::Sinumerik
            };
            let p = generate(&job).context(refused)?;
            // The loop form keeps the guards that skip the arcs done.
            Ok(dialect.render(&p, Form::Loop, Decimals::default()))
        }
        ("iso", "table") => {
            anyhow::bail!(
                "form \"table\" is SINUMERIK's curve tables: use form \"program\" for iso"
            )
        }
        (d, f) => anyhow::bail!(
            "dialect {d:?} and form {f:?}: dialect is \"sinumerik\" or \"iso\", form \"program\" or \"table\""
        ),
    }
}

pub(crate) fn run_planing(args: PlaningArgs) -> anyhow::Result<()> {
    let mut card = match &args.job {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            toml::from_str::<Card>(&text).with_context(|| format!("{}", path.display()))?
        }
        None => card_from_options(&args)?,
    };
    apply_options(&args, &mut card);
    let text = render(&card)?;
    let points = stroke_x_mm(&card.job()?).context("planing refused")?.len();
    let mut outputs = Outputs::default();
    outputs.add(&args.out, text);
    if let Some(path) = &args.save_job {
        outputs.add(path, card.to_toml());
    }
    outputs.commit()?;
    println!(
        "{}: {} arcs, {points} points per stroke",
        args.out.display(),
        card.rotor.segments
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped example card reads, and writing it gives the same text: every key is
    /// there, under its comment, and the writer and the reader agree.
    #[test]
    fn shipped_card_round_trips_through_the_writer() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/planing-card.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let card: Card = toml::from_str(&text).unwrap();
        assert_eq!(card.to_toml(), text);
        let again: Card = toml::from_str(&card.to_toml()).unwrap();
        assert_eq!(again, card);
        let keys = text
            .lines()
            .filter(|l| l.contains(" = ") && !l.starts_with('#'))
            .count();
        assert_eq!(keys, 28, "every key of the card is in the example");
        render(&card).unwrap();
    }
}
