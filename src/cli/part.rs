//! Part flags shared by every command that works on a part (`table`, `plot`, …) and the
//! loading of lift files behind them.

use crate::core::geometry::{CamGeometry, CrankpinGeometry, Follower, Part};
use crate::core::lift::{LiftCurve, LiftTable};
use crate::core::smooth::{self, Smoothed};
use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use std::path::PathBuf;

#[derive(Debug, Clone, Subcommand)]
pub enum PartKindArgs {
    /// A cam lobe given by its lift table.
    Cam(CamArgs),
    /// A crankpin given by throw and pin radius.
    Crankpin(CrankpinArgs),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FollowerArg {
    Flat,
    Roller,
    Knife,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LiftFormat {
    /// `.csv` files are CSV, anything else is read as OPTICLINE.
    Auto,
    Csv,
    Opticline,
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct CamArgs {
    /// Lift table: CSV `angle_deg,lift_mm` or an OPTICLINE-style nominal file.
    #[arg(long, value_name = "FILE")]
    pub lift: PathBuf,
    #[arg(long, value_enum, default_value_t = LiftFormat::Auto)]
    pub lift_format: LiftFormat,
    /// Follower the lift table was designed for.
    #[arg(long, value_enum)]
    pub follower: FollowerArg,
    /// Base-circle radius Rb, mm.
    #[arg(long, value_name = "MM")]
    pub base_radius: f64,
    /// Roller radius, mm (roller follower only; default: the OPTICLINE probe radius).
    #[arg(long, value_name = "MM")]
    pub roller_radius: Option<f64>,
    /// Grinding-wheel radius R, mm.
    #[arg(long, value_name = "MM")]
    pub wheel_radius: f64,
    /// Smooth a noisy or quantised lift table just enough for the wheel to grind it, and
    /// report the largest change made. Refused if it must move the lift by more than
    /// --smooth-max-um.
    #[arg(long)]
    pub smooth: bool,
    /// Largest lift change smoothing may make, µm.
    #[arg(long, value_name = "UM", default_value_t = 10.0)]
    pub smooth_max_um: f64,
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct CrankpinArgs {
    /// Distance from the main axis to the pin centre b, mm.
    #[arg(long, value_name = "MM")]
    pub throw: f64,
    /// Pin radius r_p, mm.
    #[arg(long, value_name = "MM")]
    pub pin_radius: f64,
    /// Grinding-wheel radius R, mm.
    #[arg(long, value_name = "MM")]
    pub wheel_radius: f64,
}

/// The part flags of a command (`camloop <command> cam …` or `… crankpin …`).
#[derive(Debug, Clone, Args)]
pub struct PartArgs {
    #[command(subcommand)]
    pub part: PartKindArgs,
}

/// A part ready for the core, with what was done to its lift table on the way.
pub(crate) struct LoadedPart {
    pub part: Part,
    pub description: String,
    /// Present when --smooth was given: the smoothed table and the change it made.
    pub smoothed: Option<Smoothed>,
}

pub(crate) fn load_part(args: &PartKindArgs) -> anyhow::Result<LoadedPart> {
    match args {
        PartKindArgs::Crankpin(a) => {
            let part = Part::crankpin(CrankpinGeometry {
                throw_mm: a.throw,
                pin_radius_mm: a.pin_radius,
                wheel_radius_mm: a.wheel_radius,
            })?;
            Ok(LoadedPart {
                part,
                description: format!(
                    "crankpin: throw {} mm, pin radius {} mm, wheel radius {} mm",
                    a.throw, a.pin_radius, a.wheel_radius
                ),
                smoothed: None,
            })
        }
        PartKindArgs::Cam(a) => load_cam_part(a),
    }
}

/// The lift table and geometry given by cam flags (with --smooth applied when asked).
pub(crate) fn load_cam_table(a: &CamArgs) -> anyhow::Result<(LiftTable, CamGeometry)> {
    let loaded = load_cam(a)?;
    Ok((loaded.table, loaded.geometry))
}

struct LoadedCam {
    table: LiftTable,
    geometry: CamGeometry,
    smoothed: Option<Smoothed>,
    part: Part,
}

fn load_cam_part(a: &CamArgs) -> anyhow::Result<LoadedPart> {
    let origin = a.lift.display().to_string();
    let loaded = load_cam(a)?;
    let g = loaded.geometry;
    let description = format!(
        "cam: {origin}, {} follower, base radius {} mm, wheel radius {} mm",
        g.follower.name(),
        g.base_radius_mm,
        g.wheel_radius_mm
    );
    Ok(LoadedPart {
        part: loaded.part,
        description,
        smoothed: loaded.smoothed,
    })
}

fn load_cam(a: &CamArgs) -> anyhow::Result<LoadedCam> {
    let origin = a.lift.display().to_string();
    let text = std::fs::read_to_string(&a.lift)
        .with_context(|| format!("cannot read lift table {origin}"))?;
    let is_csv = match a.lift_format {
        LiftFormat::Csv => true,
        LiftFormat::Opticline => false,
        LiftFormat::Auto => a
            .lift
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv")),
    };
    let table = if is_csv {
        LiftTable::parse_csv(&text, &origin)?
    } else {
        LiftTable::parse_opticline(&text, &origin)?
    };
    let follower = match a.follower {
        FollowerArg::Flat => Follower::Flat,
        FollowerArg::Knife => Follower::Knife,
        FollowerArg::Roller => match a.roller_radius.or(table.probe_radius_mm()) {
            Some(radius_mm) => Follower::Roller { radius_mm },
            None => bail!("--roller-radius is required for a roller follower"),
        },
    };
    if a.roller_radius.is_some() && a.follower != FollowerArg::Roller {
        bail!("--roller-radius is only meaningful with --follower roller");
    }
    let geometry = CamGeometry {
        base_radius_mm: a.base_radius,
        follower,
        wheel_radius_mm: a.wheel_radius,
    };
    if !a.smooth {
        let part = Part::cam(geometry, LiftCurve::new(&table)).map_err(|e| {
            anyhow::anyhow!("{origin}: {e} (see --smooth for quantised or noisy tables)")
        })?;
        return Ok(LoadedCam {
            table,
            geometry,
            smoothed: None,
            part,
        });
    }
    let smoothed = smooth::smooth_until_grindable(&table, a.smooth_max_um / 1000.0, |t| {
        Part::cam(geometry, LiftCurve::new(t)).is_ok()
    })
    .with_context(|| format!("{origin}: cannot smooth"))?;
    let part = Part::cam(geometry, LiftCurve::new(&smoothed.table))?;
    Ok(LoadedCam {
        table: smoothed.table.clone(),
        geometry,
        smoothed: Some(smoothed),
        part,
    })
}
