//! `camloop capability` and `camloop gauge-study`: the quality engineer's numbers from the
//! same store the service writes, with the limits from the service configuration's recipes.

use super::history::{StoreArgs, connect, runtime};
use crate::clock::now;
use crate::clock::parse_time;
use crate::config::Config;
use crate::names::{FeatureName, MachineName};
use crate::quality::{self, FeatureLimits, Window, render, study::gauge_studies};
use crate::recipe::Recipe;
use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use std::path::Path;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum QualityFormat {
    Table,
    Json,
    Csv,
}

#[derive(Debug, Args)]
pub struct CapabilityArgs {
    #[arg(long)]
    pub machine: MachineName,
    /// One lobe or pin; default: every feature of the machine.
    #[arg(long)]
    pub lobe: Option<FeatureName>,
    /// The newest N production parts (master runs never count).
    #[arg(long, value_name = "N", default_value_t = 125)]
    pub last: u32,
    /// From this time (see `history --since`).
    #[arg(long, value_name = "TIME")]
    pub since: Option<String>,
    /// Up to this time (exclusive).
    #[arg(long, value_name = "TIME")]
    pub until: Option<String>,
    /// Only parts after the machine's last wheel dressing.
    #[arg(long)]
    pub since_dressing: bool,
    /// Only parts after the feature's recipe (its lift table or settings) last changed.
    #[arg(long)]
    pub since_recipe_change: bool,
    #[arg(long, value_enum, default_value_t = QualityFormat::Table)]
    pub format: QualityFormat,
    #[command(flatten)]
    pub store: StoreArgs,
}

#[derive(Debug, Args)]
pub struct GaugeStudyArgs {
    #[arg(long)]
    pub machine: MachineName,
    #[arg(long)]
    pub lobe: FeatureName,
    /// The newest N master runs.
    #[arg(long, value_name = "N", default_value_t = 50)]
    pub last: u32,
    #[arg(long, value_enum, default_value_t = QualityFormat::Table)]
    pub format: QualityFormat,
    #[command(flatten)]
    pub store: StoreArgs,
}

pub(crate) fn run_capability(args: CapabilityArgs) -> anyhow::Result<()> {
    let now = now();
    let time = |t: &Option<String>| t.as_deref().map(|t| parse_time(t, now)).transpose();
    let window = Window {
        last: args.last,
        since: time(&args.since)?,
        until: time(&args.until)?,
        since_dressing: args.since_dressing,
        since_recipe_change: args.since_recipe_change,
    };
    let limits = feature_limits(&args.store.config, &args.machine, args.lobe.as_deref())?;
    let results = runtime()?.block_on(async {
        let store = connect(&args.store).await?;
        let mut out = Vec::new();
        for (lobe, l) in &limits {
            let (rows, since, masters) =
                quality::window_rows(&store, &args.machine, lobe, &window, false).await?;
            out.push((
                lobe.clone(),
                rows.len(),
                since,
                masters,
                quality::study(&rows, l, false),
            ));
        }
        store.close().await;
        anyhow::Ok(out)
    })?;
    let mut text = String::new();
    for (lobe, parts, since, masters, items) in &results {
        match args.format {
            QualityFormat::Table => {
                let from = since.map_or(String::new(), |at| {
                    format!(" from {}", crate::clock::utc_text(at))
                });
                let title = format!(
                    "{} {lobe}: {parts} parts{from} ({masters} master runs left out)",
                    args.machine
                );
                text.push_str(&render::capability_table(&title, items));
                text.push('\n');
            }
            QualityFormat::Csv => {
                let csv = render::capability_csv(&args.machine, lobe, items);
                // One header for all features.
                let skip = if text.is_empty() { 0 } else { 1 };
                for line in csv.lines().skip(skip) {
                    text.push_str(line);
                    text.push('\n');
                }
            }
            QualityFormat::Json => {}
        }
    }
    if args.format == QualityFormat::Json {
        let items: Vec<serde_json::Value> = results
            .iter()
            .map(|(lobe, parts, since, masters, items)| {
                serde_json::json!({"machine": args.machine, "feature": lobe, "parts": parts,
                    "since_ms": since.map(|at| at.as_millisecond()),
                    "master_runs_left_out": masters,
                    "indicative": items.iter().any(|c| c.indicative),
                    "min_values": quality::MIN_CAPABILITY_VALUES, "characteristics": items})
            })
            .collect();
        text = serde_json::to_string_pretty(&items)? + "\n";
    }
    print!("{text}");
    Ok(())
}

pub(crate) fn run_gauge_study(args: GaugeStudyArgs) -> anyhow::Result<()> {
    let limits = feature_limits(&args.store.config, &args.machine, Some(args.lobe.as_str()))?;
    let l = &limits[0].1;
    let window = Window {
        last: args.last,
        ..Window::default()
    };
    let rows = runtime()?.block_on(async {
        let store = connect(&args.store).await?;
        let rows = quality::window_rows(&store, &args.machine, &args.lobe, &window, true).await;
        store.close().await;
        anyhow::Ok(rows?.0)
    })?;
    if rows.is_empty() {
        bail!(
            "{} {}: no master runs in the store (parts named MASTER…; the simulated gauge makes them with master_runs)",
            args.machine,
            args.lobe
        );
    }
    let items = gauge_studies(&rows, l);
    let text = match args.format {
        QualityFormat::Json => {
            serde_json::to_string_pretty(&serde_json::json!({
                "machine": args.machine, "feature": args.lobe, "runs": rows.len(),
                "first_ms": rows.first().map(|r| r.received_at.as_millisecond()),
                "last_ms": rows.last().map(|r| r.received_at.as_millisecond()), "characteristics": items,
            }))? + "\n"
        }
        QualityFormat::Table | QualityFormat::Csv => render::gauge_table(
            &format!(
                "{} {}: type-1 study of {} master runs",
                args.machine,
                args.lobe,
                rows.len()
            ),
            &items,
        ),
    };
    print!("{text}");
    Ok(())
}

/// Each asked feature's limits from the configuration's recipe for `machine`, in recipe
/// order.
fn feature_limits(
    config: &Path,
    machine: &str,
    lobe: Option<&str>,
) -> anyhow::Result<Vec<(FeatureName, FeatureLimits)>> {
    let text = std::fs::read_to_string(config).with_context(|| {
        format!("the limits come from the recipes of the service configuration: cannot read {} (give --config)", config.display())
    })?;
    let config_parsed = Config::parse(&text, config, |_| None)?;
    let Some(m) = config_parsed.machines.iter().find(|m| m.name == machine) else {
        bail!("{}: no machine {machine}", config.display());
    };
    let path = config_parsed.resolve(&m.recipe);
    let recipe = Recipe::load(&path)?;
    let features = crate::config::machine_features(&recipe, m)
        .map_err(|e| anyhow::anyhow!("{}: machine {machine}: {e}", config.display()))?;
    let chosen: Vec<FeatureName> = match lobe {
        Some(l) if features.iter().any(|f| f == l) => {
            features.into_iter().filter(|f| f == l).collect()
        }
        Some(l) => bail!("machine {machine} grinds {}, not {l}", features.join(", ")),
        None => features,
    };
    chosen
        .into_iter()
        .map(|f| {
            let setup = recipe.feature_setup(&path, &f)?;
            Ok((setup.name.clone(), FeatureLimits::from_setup(&setup)))
        })
        .collect()
}
