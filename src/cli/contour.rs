//! `camloop contour`: a non-circular turning contour as a SINUMERIK or ISO program, in loop
//! or expanded form, with chords placed by tolerance.

use super::output::Outputs;
use super::program_args::MachineSetupArgs;
use crate::core::generate::contour::{ContourJob, Roughing, Side, generate, generate_rparams};
use crate::core::generate::contour_chain::ChainRoughing;
use crate::core::generate::contour_chain::program::generate as chain_generate;
use crate::core::generate::contour_file::parse_contour_file;
use crate::core::generate::curve::{Curve, Ellipse, Parabola, Sine, Tangent};
use crate::core::generate::dialect::{Decimals, Dialect, Form};
use crate::core::generate::profile::parse_profile;
use crate::core::generate::setup::{FeedMode, Setup, XMode};
use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DialectArg {
    /// SINUMERIK 840D sl (`DEF REAL`, `IF … GOTOB`).
    Sinumerik,
    /// ISO G-code with `#` macro variables and O-word loops (LinuxCNC).
    Iso,
}

impl From<DialectArg> for Dialect {
    fn from(d: DialectArg) -> Self {
        match d {
            DialectArg::Sinumerik => Dialect::Sinumerik,
            DialectArg::Iso => Dialect::Iso,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormArg {
    /// The control evaluates the curve in a loop.
    Loop,
    /// One block per chord.
    Expanded,
    /// The 802D study's editable form: the curve's constants as R parameters at the top, a
    /// loop at a fixed step (no `DEF` variables).
    RParams,
}

#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct ContourArgs {
    #[command(subcommand)]
    pub curve: CurveArgs,
    /// Where to write the program.
    #[arg(long, global = true, value_name = "OUT", default_value = "contour.mpf")]
    pub out: PathBuf,
    /// Program name (SINUMERIK rules).
    #[arg(long, global = true, default_value = "CONTOUR")]
    pub name: String,
    #[arg(long, global = true, value_enum, default_value_t = DialectArg::Sinumerik)]
    pub dialect: DialectArg,
    #[arg(long, global = true, value_enum, default_value_t = FormArg::Loop)]
    pub form: FormArg,
    /// Largest chord error, µm.
    #[arg(long, global = true, default_value_t = 2.0)]
    pub tolerance_um: f64,
    /// Boring (tool inside) instead of outside turning.
    #[arg(long, global = true)]
    pub inside: bool,
    #[arg(long, global = true, default_value_t = 0.8)]
    pub nose_radius_mm: f64,
    /// Radial stock to rough away before the finish pass (0: no roughing).
    #[arg(long, global = true, default_value_t = 0.0)]
    pub stock_mm: f64,
    #[arg(long, global = true, default_value_t = 1.0)]
    pub depth_mm: f64,
    #[arg(long, global = true, default_value_t = 0.2)]
    pub allowance_mm: f64,
    #[arg(long, global = true, default_value_t = 1.0)]
    pub clearance_mm: f64,
    /// Finish feed per revolution (G95, the default).
    #[arg(long, global = true, value_name = "MM", default_value_t = 0.1)]
    pub finish_feed_mm_rev: f64,
    /// Roughing feed per revolution (G95).
    #[arg(long, global = true, value_name = "MM", default_value_t = 0.25)]
    pub rough_feed_mm_rev: f64,
    /// Finish feed per minute: G94 instead of G95 (the rough feed then defaults to 250).
    #[arg(long, global = true, value_name = "MM_MIN")]
    pub finish_feed_mm_min: Option<f64>,
    /// Roughing feed per minute: G94 instead of G95 (the finish feed then defaults to 120).
    #[arg(long, global = true, value_name = "MM_MIN")]
    pub rough_feed_mm_min: Option<f64>,
    /// Program X as a diameter (SINUMERIK DIAMON, ISO G7) instead of a radius.
    #[arg(long, global = true)]
    pub diameter: bool,
    #[command(flatten)]
    pub machine: MachineSetupArgs,
}

#[derive(Debug, Subcommand)]
pub enum CurveArgs {
    /// z = zc + a·cos θ, x = xc + b·sin θ.
    #[command(allow_negative_numbers = true)]
    Ellipse(Ellipse),
    /// (x − x0)² = 2p·(z − z0), run along x.
    #[command(allow_negative_numbers = true)]
    Parabola(Parabola),
    /// x = x0 + A·sin(360·z/λ + φ), run along z.
    #[command(allow_negative_numbers = true)]
    Sine(Sine),
    /// x = x0 + A·tan(ω·(z − zc)), run along z.
    #[command(allow_negative_numbers = true)]
    Tangent(Tangent),
    /// Points `z_mm,x_mm` from a CSV file, interpolated by a natural cubic spline.
    #[command(allow_negative_numbers = true)]
    Profile {
        #[arg(long)]
        csv: PathBuf,
    },
    /// A whole part from a contour file (TOML): lines, arcs, chamfers, radii and curves,
    /// written as a contour subprogram and a main program that roughs and finishes.
    File {
        /// The contour file (see config/contour-802d-aa5.toml).
        #[arg(long)]
        contour: PathBuf,
    },
}

fn curve(args: &CurveArgs) -> anyhow::Result<Curve> {
    Ok(match *args {
        CurveArgs::Ellipse(e) => Curve::Ellipse(e),
        CurveArgs::Parabola(p) => Curve::Parabola(p),
        CurveArgs::Sine(k) => Curve::Sine(k),
        CurveArgs::Tangent(k) => Curve::Tangent(k),
        CurveArgs::File { .. } => anyhow::bail!("a contour file is not one curve"),
        CurveArgs::Profile { ref csv } => {
            let text = std::fs::read_to_string(csv)
                .with_context(|| format!("cannot read {}", csv.display()))?;
            parse_profile(&text, &csv.display().to_string())?
        }
    })
}

pub(crate) fn run_contour(args: ContourArgs) -> anyhow::Result<()> {
    let roughing = (args.stock_mm > 0.0).then_some(Roughing {
        stock_mm: args.stock_mm,
        depth_mm: args.depth_mm,
        allowance_mm: args.allowance_mm,
    });
    let mut setup = args.machine.setup(Setup::turning());
    if args.diameter {
        setup.x_mode = Some(XMode::Diameter);
    }
    if let CurveArgs::File { contour } = &args.curve {
        return run_file(&args, contour, setup);
    }
    let per_min = args.finish_feed_mm_min.is_some() || args.rough_feed_mm_min.is_some();
    let (finish_feed, rough_feed) = if per_min {
        setup.feed_mode = FeedMode::PerMinute;
        (
            args.finish_feed_mm_min.unwrap_or(120.0),
            args.rough_feed_mm_min.unwrap_or(250.0),
        )
    } else {
        (args.finish_feed_mm_rev, args.rough_feed_mm_rev)
    };
    let job = ContourJob {
        name: args.name.clone(),
        curve: curve(&args.curve)?,
        tolerance_mm: args.tolerance_um * 1e-3,
        decimals: Decimals::default().linear,
        side: if args.inside {
            Side::Inside
        } else {
            Side::Outside
        },
        nose_radius_mm: args.nose_radius_mm,
        roughing,
        clearance_mm: args.clearance_mm,
        finish_feed,
        rough_feed,
        setup,
    };
    let c = match args.form {
        FormArg::RParams => generate_rparams(&job),
        FormArg::Loop | FormArg::Expanded => generate(&job),
    }
    .context("contour refused")?;
    let form = match args.form {
        FormArg::Loop | FormArg::RParams => Form::Loop,
        FormArg::Expanded => Form::Expanded,
    };
    let text = Dialect::from(args.dialect).render(&c.program, form, Decimals::default());
    let mut outputs = Outputs::default();
    outputs.add(&args.out, text);
    outputs.commit()?;
    let r = &c.report;
    let fixed = r
        .fixed_step_chords
        .map_or_else(|| "more than 200000".to_owned(), |n| n.to_string());
    let placement = match args.form {
        FormArg::RParams => format!(
            "R-parameter form, {} chords at a fixed step, worst deviation {:.3} um (tolerance {} um)",
            r.chords,
            r.worst_deviation_mm * 1e3,
            args.tolerance_um
        ),
        FormArg::Loop | FormArg::Expanded => format!(
            "{} chords, worst deviation {:.3} um (tolerance {} um); a fixed step needs {fixed} chords for the same worst error",
            r.chords,
            r.worst_deviation_mm * 1e3,
            args.tolerance_um
        ),
    };
    println!(
        "{}: {placement}; {:?} compensation; {} roughing passes",
        args.out.display(),
        r.compensation,
        r.pass_offsets_mm.len()
    );
    Ok(())
}

/// `camloop contour file`: the chained part, main program and contour subprogram.
fn run_file(args: &ContourArgs, path: &Path, setup: Setup) -> anyhow::Result<()> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    if args.form == FormArg::RParams {
        anyhow::bail!(
            "{}: a contour file is written as lines, arcs and chords for the control's own stock removal; the R-parameter form is for a single curve (`camloop contour ellipse|parabola|sine|tangent`)",
            path.display()
        );
    }
    let job = parse_contour_file(&text, &path.display().to_string(), setup)?;
    if args.dialect == DialectArg::Iso && matches!(job.roughing, ChainRoughing::Cycle95 { .. }) {
        anyhow::bail!(
            "{}: roughing by CYCLE95 is SINUMERIK's; for ISO choose kind = \"passes\"",
            path.display()
        );
    }
    let p = chain_generate(&job).context("contour refused")?;
    let diameter = job.setup.x_mode == Some(XMode::Diameter);
    let files = Dialect::from(args.dialect).render_set(
        &p.main,
        std::slice::from_ref(&p.contour),
        Form::Expanded,
        Decimals::default(),
        diameter,
    );
    let dir = args.out.parent().unwrap_or(Path::new(""));
    let mut outputs = Outputs::default();
    let mut written = Vec::new();
    for f in files {
        // The main program goes to --out; a subprogram beside it, named as the control
        // calls it.
        let path = if f.sub {
            dir.join(format!("{}.spf", f.name.to_lowercase()))
        } else {
            args.out.clone()
        };
        written.push(path.display().to_string());
        outputs.add(&path, f.text);
    }
    outputs.commit()?;
    println!(
        "{}: {} elements, worst chord deviation {:.3} um (tolerance {} um); {} roughing levels; safety check: {} moves, {} cutting, lowest x {:.4} mm",
        written.join(", "),
        p.resolved.prims.len(),
        p.worst_deviation_mm * 1e3,
        job.tolerance_mm * 1e3,
        p.levels_mm.len(),
        p.safety.moves,
        p.safety.cutting_moves,
        p.safety.min_x_mm.unwrap_or(f64::NAN)
    );
    Ok(())
}
