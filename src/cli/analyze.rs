//! `camloop analyze`: a measurement against the nominal part, as a cam or crankpin gauge
//! reports it, with the full report as JSON.

use super::output::Outputs;
use super::part::{CamArgs, PartKindArgs, load_cam_table};
use crate::core::analysis::{
    LobeOptions, LobeReport, PinNominal, PinReport, analyse_lobe, analyse_pin,
};
use crate::core::lift::LiftCurve;
use crate::core::measure::{AssemblyLimits, AveragedMeasurement, check_and_average};
use crate::gauge::{GaugeDbc, GaugeSignalNames, read_measurement_file};
use anyhow::Context;
use clap::Args;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Where the gauge DBC is looked for when --dbc is not given.
pub(crate) const DEFAULT_DBC: &str = "config/gauge.dbc";

#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct AnalyzeArgs {
    #[command(subcommand)]
    pub part: PartKindArgs,
    /// The measurement: `.csv` (`rev,angle_deg,lift_mm`) or a candump `.log`.
    #[arg(long, global = true, value_name = "FILE")]
    pub measurement: Option<PathBuf>,
    /// DBC of the gauge's CAN frames (default: config/gauge.dbc, else the built-in layout).
    #[arg(long, global = true, value_name = "FILE")]
    pub dbc: Option<PathBuf>,
    /// Write the full report as JSON.
    #[arg(long, global = true, value_name = "OUT")]
    pub json: Option<PathBuf>,
    /// Tolerance band half-width on the profile error, µm (cams).
    #[arg(long, global = true, value_name = "UM", default_value_t = 5.0)]
    pub band_um: f64,
    /// A revolution differing from the per-angle median by more than this is dropped, µm.
    #[arg(long, global = true, value_name = "UM", default_value_t = 5.0)]
    pub revolution_limit_um: f64,
    /// Fewest revolutions a measurement must keep.
    #[arg(long, global = true, value_name = "N", default_value_t = 3)]
    pub min_revolutions: u32,
}

/// The gauge layout: the named DBC, else `config/gauge.dbc` if present, else the built-in one.
pub(crate) fn load_dbc(explicit: Option<&Path>) -> anyhow::Result<GaugeDbc> {
    let path = match explicit {
        Some(p) => p,
        None if Path::new(DEFAULT_DBC).exists() => Path::new(DEFAULT_DBC),
        None => return Ok(GaugeDbc::builtin()),
    };
    GaugeDbc::load(path, &GaugeSignalNames::default())
        .with_context(|| format!("cannot load DBC {}", path.display()))
}

/// Reads, checks and averages a measurement file.
pub(crate) fn averaged_measurement(
    path: &Path,
    dbc: &GaugeDbc,
    limits: &AssemblyLimits,
) -> anyhow::Result<AveragedMeasurement> {
    let raw = read_measurement_file(path, dbc)?;
    check_and_average(&raw, limits)
        .with_context(|| format!("measurement {} rejected", path.display()))
}

pub(crate) fn run_analyze(args: AnalyzeArgs) -> anyhow::Result<()> {
    let path = args
        .measurement
        .as_deref()
        .context("--measurement is required")?;
    let dbc = load_dbc(args.dbc.as_deref())?;
    let limits = AssemblyLimits {
        min_revolutions: args.min_revolutions,
        revolution_limit_um: args.revolution_limit_um,
    };
    let avg = averaged_measurement(path, &dbc, &limits)?;
    let (summary, json) = match &args.part {
        PartKindArgs::Cam(cam) => {
            let report = analyse_cam(cam, &avg, args.band_um)?;
            (
                lobe_summary(&report),
                serde_json::to_string_pretty(&report)?,
            )
        }
        PartKindArgs::Crankpin(pin) => {
            let nominal = PinNominal {
                throw_mm: pin.throw,
                pin_radius_mm: pin.pin_radius,
                index_deg: 0.0,
            };
            let report = analyse_pin(&avg, &nominal, 50)?;
            (pin_summary(&report), serde_json::to_string_pretty(&report)?)
        }
    };
    let mut outputs = Outputs::default();
    if let Some(out) = &args.json {
        outputs.add(out, json + "\n");
    }
    let written = outputs.commit()?;
    print!("{summary}");
    for p in written {
        println!("wrote {}", p.display());
    }
    Ok(())
}

fn analyse_cam(
    cam: &CamArgs,
    avg: &AveragedMeasurement,
    band_um: f64,
) -> anyhow::Result<LobeReport> {
    let (table, _) = load_cam_table(cam)?;
    let curve = LiftCurve::new(&table);
    // The analysis takes the slope per degree; the curve gives it per radian.
    let nominal = |psi_deg: f64| {
        let s = curve.eval(psi_deg.to_radians());
        (s.h_mm, s.dh_mm.to_radians())
    };
    let options = LobeOptions {
        default_band_um: band_um,
        ..LobeOptions::default()
    };
    Ok(analyse_lobe(avg, &nominal, &options)?)
}

fn lobe_summary(r: &LobeReport) -> String {
    let mut s = String::new();
    let verdict = if r.verdict.pass { "PASS" } else { "FAIL" };
    let _ = writeln!(
        s,
        "{}: {verdict} (margin {:.2} µm)",
        r.origin, r.verdict.margin_um
    );
    if let Some(v) = &r.verdict.worst_violation {
        let _ = writeln!(
            s,
            "  worst violation: {:.2} µm at {:.1}°",
            v.value_um, v.angle_deg
        );
    }
    let _ = writeln!(
        s,
        "  profile error: max {:.2} µm, min {:.2} µm, peak-to-valley {:.2} µm, RMS {:.2} µm",
        r.profile_error_max_um,
        r.profile_error_min_um,
        r.profile_error_peak_to_valley_um,
        r.profile_error_rms_um
    );
    let _ = writeln!(
        s,
        "  datum: phase error {:.4}° (positive: lags), base-circle radius error {:.2} µm (positive: oversize)",
        r.phase_error_deg, r.base_radius_error_um
    );
    if let Some(runout) = r.runout_um {
        let _ = writeln!(s, "  base-circle runout {runout:.2} µm");
    }
    let _ = writeln!(
        s,
        "  repeatability: max 1σ {:.2} µm over revolutions {:?}, dropped {}",
        r.repeatability_max_um,
        r.revolutions_used,
        r.dropped_revolutions.len()
    );
    for d in &r.dropped_revolutions {
        let _ = writeln!(s, "    dropped revolution {}: {}", d.revolution, d.reason);
    }
    let mut top = r.harmonics.clone();
    top.sort_by(|a, b| b.amplitude_um.total_cmp(&a.amplitude_um));
    let list: Vec<String> = top
        .iter()
        .take(5)
        .map(|h| format!("{}: {:.2} µm", h.order, h.amplitude_um))
        .collect();
    let _ = writeln!(s, "  largest harmonics: {}", list.join(", "));
    s
}

fn pin_summary(r: &PinReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{}: crankpin", r.origin);
    let _ = writeln!(
        s,
        "  diameter error {:.2} µm, throw error {:.2} µm, index {:.4}° (error {:.4}°), roundness {:.2} µm",
        r.diameter_error_um, r.throw_error_um, r.index_angle_deg, r.index_error_deg, r.roundness_um
    );
    let _ = writeln!(
        s,
        "  revolutions used {:?}, dropped {}",
        r.revolutions_used,
        r.dropped_revolutions.len()
    );
    s
}
