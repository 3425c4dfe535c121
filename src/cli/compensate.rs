//! `camloop compensate`: one turn of the learning loop, offline, for a script to drive.
//!
//! Everything the loop remembers lives in `--state DIR`:
//! - `learning.json`: the learning state, the part's fingerprint, the wheel radius and the
//!   last measurement used (so a measurement is never learned from twice);
//! - `share/`: the program versions and their manifest (see `share`), the program itself
//!   delivered atomically to the folder of `--program`;
//! - `refusals.jsonl`: every table a guard refused, with the measurement and the reason.

use super::analyze::load_dbc;
use super::output::Outputs;
use super::part::{CamArgs, CrankpinArgs, PartKindArgs, load_cam_table};
use super::table::{FormArg, table_csv};
use crate::clock::now;
use crate::core::compensate::{
    self, AxisLimits, Feature, GuardedTable, TableRequest, pin_nominal_lift,
};
use crate::core::digest::Sha256;
use crate::core::fit::TableForm;
use crate::core::geometry::CrankpinGeometry;
use crate::core::learn::{self, LearningParams, LearningState, PreviousPart};
use crate::core::lift::LiftTable;
use crate::core::program::{ProgramSettings, comment_text};
use crate::core::turn::{Decision, measurement_sha256, turn};
use crate::gauge::read_measurement_file;
use crate::recipe::Recipe;
use crate::share::{ProgramFile, PushRequest, RealFs, Share, ShareConfig, sha256_hex};
use anyhow::{Context, bail};
use clap::Args;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct CompensateArgs {
    /// The part by flags (`cam …`), unless --part names a recipe.
    #[command(subcommand)]
    pub part: Option<PartKindArgs>,
    /// Part recipe (TOML) instead of part flags; needs --lobe.
    #[arg(long = "part", global = true, value_name = "RECIPE.toml")]
    pub recipe: Option<PathBuf>,
    /// Lobe of the recipe.
    #[arg(long, global = true, value_name = "NAME", requires = "recipe")]
    pub lobe: Option<String>,
    /// Folder holding the loop's state (created on the first run).
    #[arg(long, global = true, value_name = "DIR")]
    pub state: Option<PathBuf>,
    /// Measurement of the part ground with the current table (`.csv` or candump `.log`).
    /// Without it, the table for the current correction is written (the nominal one on a
    /// new state).
    #[arg(long, global = true, value_name = "FILE")]
    pub measurement: Option<PathBuf>,
    /// DBC of the gauge's CAN frames (default: config/gauge.dbc, else the built-in layout).
    #[arg(long, global = true, value_name = "FILE")]
    pub dbc: Option<PathBuf>,
    /// The curve-table subprogram to write (delivered atomically, versions kept in the state).
    #[arg(long, global = true, value_name = "OUT.SPF")]
    pub program: Option<PathBuf>,
    /// Also write the table as CSV `c_deg,d_mm,x_mm`.
    #[arg(long, global = true, value_name = "OUT")]
    pub csv: Option<PathBuf>,
    /// Table form (default: the recipe's, else g1).
    #[arg(long, global = true, value_enum)]
    pub form: Option<FormArg>,
}

/// One lobe's loop as the command sees it.
use crate::recipe::FeatureSetup as LobeSetup;

#[derive(Debug, Serialize, Deserialize)]
struct SavedState {
    /// SHA-256 over the nominal lift table and the geometry except the wheel radius.
    part_fingerprint: String,
    part_label: String,
    wheel_radius_mm: f64,
    learning: LearningState,
    /// SHA-256 of the last measurement learned from.
    last_measurement_sha256: Option<Sha256>,
    /// What the last measurement measured, learned from or refused.
    #[serde(default)]
    previous: Option<PreviousPart>,
}

const STATE_FILE: &str = "learning.json";
/// Tables refused by a guard, one JSON line each: when, from which measurement, why.
const REFUSALS_FILE: &str = "refusals.jsonl";

pub(crate) fn run_compensate(args: CompensateArgs) -> anyhow::Result<()> {
    let (Some(state_dir), Some(program)) = (args.state.clone(), args.program.clone()) else {
        bail!("compensate needs --state DIR and --program OUT.SPF");
    };
    let setup = lobe_setup(&args)?;
    let dirs = Dirs {
        state: state_dir,
        program,
    };
    let fingerprint = part_fingerprint(&setup);
    let state_path = dirs.state.join(STATE_FILE);
    let mut saved = load_state(&args, &dirs, &setup, &state_path, fingerprint)?;
    let mut report = Vec::new();
    note_dressing(&mut saved, &setup, &mut report);
    let lobe = setup.lobe_loop();
    let (table, reason, measurement_id) = match &args.measurement {
        None => {
            let table = compensate::current_table(&saved.learning, &lobe)?;
            let reason = if saved.learning.iteration == 0 {
                "nominal table"
            } else {
                "current correction"
            };
            (table, reason.to_string(), None)
        }
        Some(path) => {
            let (table, reason, id) =
                learn_from(&dirs.state, path, args.dbc.as_deref(), &setup, &mut saved)?;
            report.push(reason.clone());
            (table, reason, Some(id))
        }
    };
    let pushed = push(&dirs, &setup, &table, &reason, measurement_id, &saved)?;
    saved.last_measurement_sha256 = measurement_id.or(saved.last_measurement_sha256);
    let mut outputs = Outputs::default();
    outputs.add(&state_path, serde_json::to_string_pretty(&saved)?);
    if let Some(csv) = &args.csv {
        outputs.add(csv, table_csv(&table.points));
    }
    outputs.commit()?;
    for line in report {
        println!("{line}");
    }
    println!(
        "{}: iteration {}, version {} (table {}) written to {}, between points up to {:.4} µm",
        setup.label,
        saved.learning.iteration,
        pushed.0,
        pushed.1,
        dirs.program.display(),
        table.deviation.max_um
    );
    Ok(())
}

/// The saved learning state of this part, or a fresh one at the nominal table when the
/// folder has none yet (which only a run without a measurement may start).
fn load_state(
    args: &CompensateArgs,
    dirs: &Dirs,
    setup: &LobeSetup,
    state_path: &std::path::Path,
    fingerprint: String,
) -> anyhow::Result<SavedState> {
    let saved = match std::fs::read_to_string(state_path) {
        Ok(text) => {
            let saved: SavedState = serde_json::from_str(&text).with_context(|| {
                format!("{}: not a camloop learning state", state_path.display())
            })?;
            if saved.part_fingerprint != fingerprint {
                bail!(
                    "{} belongs to another part ({}); use a new --state folder for {}",
                    dirs.state.display(),
                    saved.part_label,
                    setup.label
                );
            }
            saved
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if args.measurement.is_some() {
                bail!(
                    "{} has no learning state yet: run once without --measurement to write the nominal table",
                    dirs.state.display()
                );
            }
            SavedState {
                part_fingerprint: fingerprint,
                part_label: setup.label.clone(),
                wheel_radius_mm: setup.feature.wheel_radius_mm(),
                learning: LearningState::new(360),
                last_measurement_sha256: None,
                previous: None,
            }
        }
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", state_path.display())),
    };
    Ok(saved)
}

/// A new wheel radius means a dressing: the learned size is reset, the shape kept.
fn note_dressing(saved: &mut SavedState, setup: &LobeSetup, report: &mut Vec<String>) {
    if (saved.wheel_radius_mm - setup.feature.wheel_radius_mm()).abs() > 1e-9 {
        report.push(format!(
            "wheel radius {} → {} mm: dressing, learned size reset, shape kept",
            saved.wheel_radius_mm,
            setup.feature.wheel_radius_mm()
        ));
        let own = learn::size_correction_um(&saved.learning);
        learn::after_dressing(&mut saved.learning, own);
        saved.wheel_radius_mm = setup.feature.wheel_radius_mm();
    }
}

/// Reads the measurement and runs one loop turn on it; returns the next table, the reason
/// to record and the measurement's id.
fn learn_from(
    state_dir: &Path,
    path: &Path,
    dbc_path: Option<&Path>,
    setup: &LobeSetup,
    saved: &mut SavedState,
) -> anyhow::Result<(GuardedTable, String, Sha256)> {
    let dbc = load_dbc(dbc_path)?;
    let raw = read_measurement_file(path, &dbc)?;
    let id = measurement_sha256(&raw);
    if saved.last_measurement_sha256 == Some(id) {
        bail!(
            "{}: this measurement was already learned from (iteration {})",
            path.display(),
            saved.learning.iteration
        );
    }
    let done = turn(
        &setup.turn_setup(),
        &saved.learning,
        &raw,
        None,
        saved.previous,
    )
    .with_context(|| format!("measurement {}", path.display()))?;
    saved.previous = Some(done.measured.as_previous());
    let (outcome, next, table) = match done.decision {
        Decision::Table {
            outcome,
            next,
            table,
            ..
        } => (outcome, next, table),
        Decision::Refused(refused) => {
            // Nothing is delivered; the refusal is kept with the measurement it came from.
            let record = Refusal {
                at: now(),
                measurement: path.display().to_string(),
                measurement_sha256: id,
                iteration: saved.learning.iteration,
                reason: refused.to_string(),
            };
            append_line(
                &state_dir.join(REFUSALS_FILE),
                &serde_json::to_string(&record)?,
            )?;
            // The refused part still confirms (or not) the next one's error: keep it.
            let mut outputs = Outputs::default();
            outputs.add(
                &state_dir.join(STATE_FILE),
                serde_json::to_string_pretty(&*saved)?,
            );
            outputs.commit()?;
            return Err(anyhow::Error::new(refused))
                .with_context(|| format!("{}: the previous table stays in force", path.display()));
        }
        Decision::Held(reason) => bail!("{}: not learned: {reason}", path.display()),
    };
    saved.learning = *next;
    let reason = format!("{}: {outcome}", path.display());
    Ok((*table, reason, id))
}

/// A refused table as kept in `refusals.jsonl`.
#[derive(Debug, Serialize)]
struct Refusal {
    #[serde(rename = "at_unix_ms", with = "crate::clock::unix_ms")]
    at: jiff::Timestamp,
    measurement: String,
    measurement_sha256: Sha256,
    iteration: u32,
    reason: String,
}

/// Renders the program with the next table number and delivers it through the share.
/// Where the state lives and where the program goes.
struct Dirs {
    state: PathBuf,
    program: PathBuf,
}

fn push(
    args: &Dirs,
    setup: &LobeSetup,
    table: &GuardedTable,
    reason: &str,
    measurement_id: Option<Sha256>,
    saved: &SavedState,
) -> anyhow::Result<(u64, u32)> {
    let file_name = args
        .program
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .with_context(|| format!("--program {} has no file name", args.program.display()))?;
    let share_dir = match args.program.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&share_dir)
        .with_context(|| format!("cannot create {}", share_dir.display()))?;
    let config = ShareConfig {
        share_dir,
        state_dir: args.state.join("share"),
        table_pair: setup.table_pair,
        keep_versions: 50,
    };
    let (mut share, _report) = Share::open(config, Box::new(RealFs), Box::new(now))
        .context("cannot open the program share")?;
    let mut settings = setup.program.clone();
    settings.table_number = share.next_table_number();
    settings.comment_lines = vec![
        comment_text(&setup.label),
        comment_text(reason),
        format!("learning iteration {}", saved.learning.iteration),
    ];
    let text = table
        .render(&settings)
        .with_context(|| format!("{}: cannot render", args.program.display()))?;
    let request = PushRequest {
        files: vec![ProgramFile {
            name: file_name,
            text,
        }],
        table_number: settings.table_number,
        reason: reason.to_string(),
        measurement_id,
        learning: serde_json::json!({
            "iteration": saved.learning.iteration,
            "params": setup.params,
            "max_correction_um": saved.learning.correction_um.iter().fold(0.0f64, |m, u| m.max(u.abs())),
        }),
        rollback_of: None,
        created_at: now(),
    };
    let pushed = share
        .push_once(request)
        .context("cannot deliver the program")?;
    Ok((pushed.version.get(), pushed.table_number))
}

fn lobe_setup(args: &CompensateArgs) -> anyhow::Result<LobeSetup> {
    let form_override = args.form.map(|f| match f {
        FormArg::G1 => TableForm::G1,
        FormArg::Poly => TableForm::Poly,
    });
    match (&args.recipe, &args.part) {
        (Some(_), Some(_)) => {
            bail!("give the part either by --part RECIPE.toml or by flags, not both")
        }
        (None, None) => bail!("give the part: `cam …` flags or --part RECIPE.toml --lobe NAME"),
        (None, Some(PartKindArgs::Crankpin(pin))) => Ok(from_pin_flags(pin, form_override)),
        (None, Some(PartKindArgs::Cam(cam))) => from_flags(cam, form_override),
        (Some(path), None) => from_recipe(path, args.lobe.as_deref(), form_override),
    }
}

fn from_flags(cam: &CamArgs, form: Option<TableForm>) -> anyhow::Result<LobeSetup> {
    let (nominal, geometry) = load_cam_table(cam)?;
    Ok(flag_setup(
        format!("lobe {}", cam.lift.display()),
        nominal,
        Feature::Cam(geometry),
        form,
    ))
}

fn from_pin_flags(pin: &CrankpinArgs, form: Option<TableForm>) -> LobeSetup {
    let geometry = CrankpinGeometry {
        throw_mm: pin.throw,
        pin_radius_mm: pin.pin_radius,
        wheel_radius_mm: pin.wheel_radius,
    };
    let label = format!(
        "crankpin throw {} mm, pin radius {} mm",
        pin.throw, pin.pin_radius
    );
    flag_setup(
        label,
        pin_nominal_lift(&geometry),
        Feature::Pin(geometry),
        form,
    )
}

/// A setup from part flags: the defaults of the recipe's sections.
fn flag_setup(
    label: String,
    nominal: LiftTable,
    feature: Feature,
    form: Option<TableForm>,
) -> LobeSetup {
    let program = ProgramSettings {
        name: "CAMLOOP_TABLE".to_string(),
        ..ProgramSettings::default()
    };
    LobeSetup {
        part: crate::names::PartName::new("PART").expect("a plain name"),
        name: crate::names::FeatureName::new("LOBE").expect("a plain name"),
        label,
        nominal,
        feature,
        program,
        params: LearningParams::default(),
        limits: AxisLimits::default(),
        speed_plan: Default::default(),
        cycle: None,
        request: TableRequest {
            points: 360,
            form: form.unwrap_or(TableForm::G1),
            poly_tolerance_um: 0.1,
        },
        table_pair: (1, 2),
        c_table_pair: None,
        plan_x_table_pair: None,
        bands: Vec::new(),
        index: 1,
        phase_deg: 0.0,
        z_mm: 0.0,
        tolerances: crate::recipe::FeatureTolerances::Lobe {
            timing_deg: 0.05,
            size_um: None,
            max_error_um: None,
        },
    }
}

fn from_recipe(
    path: &Path,
    lobe_name: Option<&str>,
    form: Option<TableForm>,
) -> anyhow::Result<LobeSetup> {
    let recipe = Recipe::load(path)?;
    let Some(name) = lobe_name else {
        bail!(
            "--lobe is required with --part (has: {})",
            recipe.feature_names().join(", ")
        );
    };
    let mut setup = recipe.feature_setup(path, name)?;
    if let Some(form) = form {
        setup.request.form = form;
    }
    Ok(setup)
}

fn part_fingerprint(setup: &LobeSetup) -> String {
    // The wheel radius changes with every dressing; everything else names the part.
    let mut text = format!("{:?} ", setup.feature.with_wheel_radius(0.0));
    for (a, l) in setup
        .nominal
        .angles_deg()
        .iter()
        .zip(setup.nominal.lifts_mm())
    {
        text.push_str(&format!("{a:.9},{l:.9};"));
    }
    sha256_hex(text.as_bytes())
}

/// Appends one line and flushes it to disk before returning.
fn append_line(path: &Path, line: &str) -> anyhow::Result<()> {
    use std::io::Write;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("cannot open {}", path.display()))?;
    file.write_all(format!("{line}\n").as_bytes())
        .and_then(|()| file.sync_all())
        .with_context(|| format!("cannot write {}", path.display()))
}
