//! `camloop speed-plan`: the C speed plan of a part's finish revolution against the fastest
//! constant C speed under the same limits, with the limits that bind and an SVG chart.

use super::output::Outputs;
use super::part::{PartKindArgs, load_part};
use crate::core::speed_plan::render::{
    VaProgramSettings, render_va_main_program, render_va_table_program,
};
use crate::core::speed_plan::{self, Constraint, SpeedLimits, SpeedPlan, plot};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

/// The defaults are the demo camshaft's (`config/parts/demo-camshaft.toml`).
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct SpeedPlanArgs {
    #[command(subcommand)]
    pub part: PartKindArgs,
    /// X velocity limit, mm/s.
    #[arg(long, global = true, value_name = "MM_S", default_value_t = 200.0)]
    pub x_velocity: f64,
    /// X acceleration limit, mm/s².
    #[arg(long, global = true, value_name = "MM_S2", default_value_t = 10_000.0)]
    pub x_acceleration: f64,
    /// X jerk limit, mm/s³.
    #[arg(
        long,
        global = true,
        value_name = "MM_S3",
        default_value_t = 10_000_000.0
    )]
    pub x_jerk: f64,
    /// C speed limit, rev/min.
    #[arg(long, global = true, value_name = "RPM", default_value_t = 120.0)]
    pub c_max_speed_rpm: f64,
    /// C acceleration limit, degrees/s².
    #[arg(long, global = true, value_name = "DEG_S2", default_value_t = 3600.0)]
    pub c_max_accel: f64,
    /// Largest specific removal rate Q'w, mm³/(mm·s).
    #[arg(long, global = true, value_name = "MM3_MM_S", default_value_t = 2.36)]
    pub q_w_max: f64,
    /// Stock the finish revolution removes, mm (normal to the profile).
    #[arg(long, global = true, value_name = "MM", default_value_t = 0.02)]
    pub stock: f64,
    /// Write the chart (C speed and each limit's usage against C) as SVG.
    #[arg(long, global = true, value_name = "OUT")]
    pub svg: Option<PathBuf>,
    /// Write the table program with both curve tables over the virtual leading axis
    /// (X = g(VA) as table 1, C = f(VA) as table 2).
    #[arg(long, global = true, value_name = "OUT")]
    pub program: Option<PathBuf>,
    /// Write the main program that couples both tables to the virtual axis and grinds one
    /// revolution (needs --program).
    #[arg(long, global = true, value_name = "OUT", requires = "program")]
    pub main_program: Option<PathBuf>,
    /// The table program's name.
    #[arg(
        long,
        global = true,
        value_name = "NAME",
        default_value = "CAMLOOP_PLAN"
    )]
    pub program_name: String,
}

pub(crate) fn run_speed_plan(args: SpeedPlanArgs) -> anyhow::Result<()> {
    let limits = SpeedLimits {
        x_velocity_mm_s: args.x_velocity,
        x_acceleration_mm_s2: args.x_acceleration,
        x_jerk_mm_s3: args.x_jerk,
        c_max_speed_rpm: args.c_max_speed_rpm,
        c_max_accel_deg_s2: args.c_max_accel,
        q_w_max_mm3_mm_s: args.q_w_max,
        stock_mm: args.stock,
    };
    let loaded = load_part(&args.part)?;
    let plan = speed_plan::plan(&loaded.part, &limits)?;
    let mut outputs = Outputs::default();
    if let Some(path) = &args.svg {
        outputs.add(path, plot::render_plan_svg(&plan, &loaded.description));
    }
    let mut report = format!("{}\n", loaded.description);
    report += &summary(&plan)?;
    if !plan.is_constant {
        let tables = speed_plan::tables::va_tables(&loaded.part, &plan.law, 0.1)?;
        if let Some(path) = &args.program {
            let settings = VaProgramSettings {
                name: args.program_name.clone(),
                virtual_axis: "VA".into(),
                x_axis: "X".into(),
                c_axis: "C".into(),
                x_decimals: 4,
                c_decimals: 4,
                x_table: 1,
                c_table: 2,
                ..VaProgramSettings::default()
            };
            let text = render_va_table_program(&tables, &settings)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            outputs.add(path, text);
            if let Some(main_path) = &args.main_program {
                let text =
                    render_va_main_program("CAMLOOP_GRIND", &settings, tables.va_speed_rpm, 1.0)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", main_path.display()))?;
                outputs.add(main_path, text);
            }
        }
        writeln!(
            report,
            "for the control: VA at {:.3} rpm leads C = f(VA) ({} POLY segments, the plan's own cubics) and X = g(VA) ({} POLY segments, within {:.4} µm of the exact X)",
            tables.va_speed_rpm,
            tables.c_segments.len(),
            tables.x_segments.len(),
            tables.x_deviation_um
        )?;
    }
    for path in outputs.commit()? {
        writeln!(report, "wrote {}", path.display())?;
    }
    print!("{report}");
    Ok(())
}

/// The figures of a plan, one per line.
pub fn summary(plan: &SpeedPlan) -> Result<String, std::fmt::Error> {
    let mut s = String::new();
    let constant = &plan.constant;
    let q_constant = constant
        .points
        .iter()
        .map(|p| p.q_w_mm3_mm_s)
        .fold(0.0, f64::max);
    let q_plan = plan
        .points
        .iter()
        .map(|p| p.q_w_mm3_mm_s)
        .fold(0.0, f64::max);
    writeln!(
        s,
        "fastest constant C speed: {:.2} rpm, {:.3} s per revolution ({} binds at C = {:.1}°), max Q'w {:.3} mm³/(mm·s)",
        constant.speed_rpm,
        constant.revolution_s,
        constant.binding.name(),
        constant.at_c_deg,
        q_constant
    )?;
    if plan.is_constant {
        writeln!(s, "planned: no varying speed is faster under these limits")?;
        return Ok(s);
    }
    let (lo, hi) = plan.points.iter().fold((f64::MAX, 0.0f64), |(lo, hi), p| {
        (lo.min(p.speed_rpm), hi.max(p.speed_rpm))
    });
    writeln!(
        s,
        "planned: {:.3} s per revolution ({:.1} % shorter), C from {lo:.2} to {hi:.2} rpm, max Q'w {q_plan:.3} mm³/(mm·s)",
        plan.revolution_s(),
        100.0 * plan.time_saved()
    )?;
    let usage: Vec<String> = Constraint::ALL
        .iter()
        .map(|&c| format!("{} {:.1} %", c.name(), 100.0 * plan.max_usage(c)))
        .collect();
    writeln!(
        s,
        "largest usage along the plan (0.1° grid): {}",
        usage.join(", ")
    )?;
    writeln!(s, "binding (a limit used above 97 %):")?;
    for b in plan.binding_stretches(0.97) {
        if b.to_deg - b.from_deg >= 360.0 - 1e-9 {
            writeln!(s, "  all round          {}", b.constraint.name())?;
            continue;
        }
        writeln!(
            s,
            "  {:>6.1}° to {:>6.1}°  {}",
            b.from_deg.rem_euclid(360.0),
            b.to_deg.rem_euclid(360.0),
            b.constraint.name()
        )?;
    }
    Ok(s)
}
