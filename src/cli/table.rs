//! `camloop table` and `camloop plot`: a part's wheel-head table as CSV, program and picture.

use super::output::Outputs;
use super::part::{LoadedPart, PartKindArgs, load_part};
use super::program_args::ProgramArgs;
use crate::core::fit::{self, Deviation, Motion, TableForm};
use crate::core::program::{comment_text, render_g1_table, render_main_program, render_poly_table};
use crate::core::setup::setup_view;
use crate::core::svg::render_setup_svg;
use crate::core::table::{PolySegment, TablePoint};
use clap::{Args, ValueEnum};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormArg {
    /// Straight lines between points.
    G1,
    /// Cubic polynomials with continuous velocity and acceleration.
    Poly,
}

#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct TableArgs {
    #[command(subcommand)]
    pub part: PartKindArgs,
    /// Table points per revolution (36 to 36000).
    #[arg(long, global = true, default_value_t = 360)]
    pub points: usize,
    /// How the table runs between points.
    #[arg(long, global = true, value_enum, default_value_t = FormArg::G1)]
    pub form: FormArg,
    /// Write the table as CSV `c_deg,d_mm,x_mm`.
    #[arg(long, global = true, value_name = "OUT")]
    pub csv: Option<PathBuf>,
    /// Draw the setup as SVG.
    #[arg(long, global = true, value_name = "OUT")]
    pub svg: Option<PathBuf>,
    /// C speed for the motion report, rev/min.
    #[arg(long, global = true, value_name = "RPM", default_value_t = 30.0)]
    pub c_speed_rpm: f64,
    /// Largest deviation a POLY table may have from the exact path between points, µm;
    /// segments that exceed it are split.
    #[arg(long, global = true, value_name = "UM", default_value_t = 0.1)]
    pub poly_tolerance_um: f64,
    #[command(flatten)]
    pub program: ProgramArgs,
}

#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct PlotArgs {
    #[command(subcommand)]
    pub part: PartKindArgs,
    /// Where to write the SVG.
    #[arg(long, global = true, value_name = "OUT", default_value = "setup.svg")]
    pub svg: PathBuf,
    /// Table angles (degrees) at which to draw the wheel, comma-separated.
    #[arg(long, global = true, value_delimiter = ',', default_values_t = [0.0, 90.0, 180.0, 270.0])]
    pub angles: Vec<f64>,
}

pub(crate) fn run_table(args: TableArgs) -> anyhow::Result<()> {
    if !(args.c_speed_rpm.is_finite() && args.c_speed_rpm > 0.0) {
        anyhow::bail!(
            "--c-speed-rpm must be a number > 0, got {}",
            args.c_speed_rpm
        );
    }
    if !(args.poly_tolerance_um.is_finite() && args.poly_tolerance_um > 0.0) {
        anyhow::bail!(
            "--poly-tolerance-um must be a number > 0, got {}",
            args.poly_tolerance_um
        );
    }
    let loaded = load_part(&args.part)?;
    let part = &loaded.part;
    let points = part.wheel_table(args.points)?;
    let g1_dev = fit::g1_deviation(part, &points)?;
    let (poly_points, segments, poly_dev) =
        fit::fit_poly_within(part, &points, args.poly_tolerance_um)?;
    let form = match args.form {
        FormArg::G1 => TableForm::G1,
        FormArg::Poly => TableForm::Poly,
    };
    let table_points = match form {
        TableForm::G1 => &points,
        TableForm::Poly => &poly_points,
    };
    let mut outputs = Outputs::default();
    if let Some(path) = &args.csv {
        outputs.add(path, table_csv(table_points));
    }
    if let Some(path) = &args.program.program {
        let deviations = (g1_dev.max_um, poly_dev.max_um);
        let table = (&points[..], &segments[..]);
        add_programs(&mut outputs, &args, path, &loaded, form, table, deviations)?;
    }
    if let Some(path) = &args.svg {
        let view = setup_view(part, &[0.0, 90.0, 180.0, 270.0], &loaded.description)?;
        outputs.add(path, render_setup_svg(&view));
    }
    let mut report = summary(&loaded, &points, form, segments.len());
    let table = (&points[..], &segments[..]);
    motion_report(&mut report, &args, table, (g1_dev, poly_dev))?;
    for path in outputs.commit()? {
        writeln!(report, "wrote {}", path.display())?;
    }
    print!("{report}");
    Ok(())
}

/// The table subprogram (G1 or POLY) and, when asked for, the main program that calls it.
fn add_programs(
    outputs: &mut Outputs,
    args: &TableArgs,
    path: &std::path::Path,
    loaded: &LoadedPart,
    form: TableForm,
    (points, segments): (&[TablePoint], &[PolySegment]),
    (g1_max_um, poly_max_um): (f64, f64),
) -> anyhow::Result<()> {
    let comments = vec![
        comment_text(&loaded.description),
        format!(
            "{} points, G1 chords stray up to {:.3} um, POLY cubics up to {:.4} um",
            points.len(),
            g1_max_um,
            poly_max_um
        ),
    ];
    let settings = args.program.table_settings(comments);
    let text = match form {
        TableForm::G1 => render_g1_table(points, &settings),
        TableForm::Poly => render_poly_table(segments, &settings),
    }
    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    outputs.add(path, text);
    if let (Some(main_path), Some(main)) = (
        &args.program.main_program,
        args.program.main_settings(args.c_speed_rpm),
    ) {
        let text = render_main_program(&main, &settings)
            .map_err(|e| anyhow::anyhow!("{}: {e}", main_path.display()))?;
        outputs.add(main_path, text);
    }
    Ok(())
}

/// How far each form strays between points, and the X motion each asks at the C speed.
fn motion_report(
    report: &mut String,
    args: &TableArgs,
    (points, segments): (&[TablePoint], &[PolySegment]),
    (g1_dev, poly_dev): (Deviation, Deviation),
) -> std::fmt::Result {
    writeln!(
        report,
        "between points (exact path vs. table, {} samples per gap):",
        fit::DEVIATION_SAMPLES
    )?;
    writeln!(report, "  G1   chords    {}", deviation_text(g1_dev))?;
    writeln!(
        report,
        "  POLY cubics    {} ({} segments)",
        deviation_text(poly_dev),
        segments.len()
    )?;
    writeln!(report, "X motion at C = {} rpm:", args.c_speed_rpm)?;
    writeln!(
        report,
        "  G1   {}",
        motion_text(fit::g1_motion(points, args.c_speed_rpm))
    )?;
    writeln!(
        report,
        "  POLY {}",
        motion_text(fit::poly_motion(segments, args.c_speed_rpm))
    )
}

pub(crate) fn run_plot(args: PlotArgs) -> anyhow::Result<()> {
    if let Some(bad) = args.angles.iter().find(|a| !a.is_finite()) {
        anyhow::bail!("--angles: {bad} is not a finite angle");
    }
    let loaded = load_part(&args.part)?;
    let view = setup_view(&loaded.part, &args.angles, &loaded.description)?;
    let mut outputs = Outputs::default();
    outputs.add(&args.svg, render_setup_svg(&view));
    for path in outputs.commit()? {
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn summary(loaded: &LoadedPart, points: &[TablePoint], form: TableForm, segments: usize) -> String {
    let mut s = format!("{}\n", loaded.description);
    if let Some(sm) = &loaded.smoothed {
        s += &format!(
            "smoothed (Whittaker, λ = {:.3e}): lift changed by at most {:.2} µm (at {:.1}°), lowest lift {:.2} µm\n",
            sm.lambda, sm.max_change_um, sm.at_deg, sm.min_lift_um
        );
    }
    let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        (lo.min(p.x_mm), hi.max(p.x_mm))
    });
    let form_text = match form {
        TableForm::G1 => "G1".to_string(),
        TableForm::Poly => format!("POLY, {segments} segments"),
    };
    s += &format!(
        "table: {} points ({form_text}), X from {lo:.4} to {hi:.4} mm\n",
        points.len()
    );
    s
}

fn deviation_text(d: Deviation) -> String {
    format!("up to {:.4} µm (at C = {:.2}°)", d.max_um, d.at_c_deg)
}

fn motion_text(m: Motion) -> String {
    let mut s = format!("v ≤ {:.2} mm/s", m.velocity_max_mm_s);
    if let Some(step) = m.velocity_step_max_mm_s {
        s += &format!(", velocity steps up to {step:.3} mm/s at points (acceleration unbounded)");
    }
    if let (Some(a), Some(j)) = (m.acceleration_max_mm_s2, m.jerk_max_mm_s3) {
        s += &format!(", a ≤ {a:.1} mm/s², jerk ≤ {j:.0} mm/s³");
    }
    s
}

/// CSV `c_deg,d_mm,x_mm`, 9 decimals (1e-6 µm) so no precision is lost on the way out.
pub(crate) fn table_csv(points: &[TablePoint]) -> String {
    let mut s = String::from("c_deg,d_mm,x_mm\n");
    for p in points {
        let _ = writeln!(s, "{:.9},{:.9},{:.9}", p.c_deg, p.d_mm, p.x_mm);
    }
    s
}
