//! `camloop history` and `camloop export`: the measurement history from the same store the
//! service writes, as a table, CSV or JSON.

use super::output::Outputs;
use crate::clock::now;
use crate::config::{Config, ENV_DATABASE_URL};
use crate::names::{FeatureName, MachineName};
use crate::store::{
    HistoryFilter, MAX_PAGE, MasterRuns, MeasurementStage, MeasurementSummary, Store,
};
use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    Table,
    Csv,
    Json,
    /// Q-DAS AQDEF (`export` only).
    Dfq,
}

/// Where the store is: --database, else CAMLOOP_DATABASE_URL, else the service config's URL.
#[derive(Debug, Args)]
pub struct StoreArgs {
    /// Database URL (sqlite://… or postgres://…).
    #[arg(long, value_name = "URL")]
    pub database: Option<String>,
    /// Service configuration whose database to read.
    #[arg(long, value_name = "FILE", default_value = "config/camloop.toml")]
    pub config: PathBuf,
}

#[derive(Debug, Args)]
pub struct HistoryArgs {
    #[arg(long)]
    pub machine: MachineName,
    #[arg(long)]
    pub lobe: Option<FeatureName>,
    /// From this time: `2026-11-21`, `2026-11-21T10:00:00Z`, Unix ms, or an age like `24h`, `7d`.
    #[arg(long, value_name = "TIME")]
    pub since: Option<String>,
    /// The newest N measurements (any number: the store is read page by page).
    #[arg(long, value_name = "N", default_value_t = 20)]
    pub last: u32,
    #[arg(long, value_enum, default_value_t = Format::Table)]
    pub format: Format,
    /// List the master runs (part ids MASTER…) of gauge studies instead of production parts.
    #[arg(long)]
    pub masters: bool,
    /// Only this stage: `final` (the finished part) or `in_process` (before the finish,
    /// stock on); default both.
    #[arg(long, value_name = "STAGE")]
    pub stage: Option<MeasurementStage>,
    #[command(flatten)]
    pub store: StoreArgs,
}

#[derive(Debug, Args)]
pub struct ExportArgs {
    #[arg(long, value_enum, default_value_t = Format::Csv)]
    pub format: Format,
    /// From this time (see `history --since`); default: everything.
    #[arg(long, value_name = "TIME")]
    pub since: Option<String>,
    /// Up to this time (exclusive); default: now.
    #[arg(long, value_name = "TIME")]
    pub until: Option<String>,
    /// With `--format dfq`: the part (recipe name) to export; a .dfq file holds one part.
    #[arg(long)]
    pub part: Option<String>,
    /// Write here instead of stdout.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub store: StoreArgs,
}

pub(crate) fn run_history(args: HistoryArgs) -> anyhow::Result<()> {
    let now = now();
    let since = args
        .since
        .as_deref()
        .map(|t| crate::clock::parse_time(t, now))
        .transpose()?;
    let runtime = runtime()?;
    let rows = runtime.block_on(async {
        let store = connect(&args.store).await?;
        let filter = HistoryFilter {
            lobe: args.lobe.clone(),
            since,
            masters: if args.masters {
                MasterRuns::Only
            } else {
                MasterRuns::Excluded
            },
            stage: args.stage,
            ..HistoryFilter::new(args.machine.clone(), 0)
        };
        let rows = newest(&store, filter, args.last, MAX_PAGE).await;
        store.close().await;
        anyhow::Ok(rows?)
    })?;
    print!("{}", render(&rows, args.format)?);
    Ok(())
}

/// The newest `last` measurements matching `filter` (newest first), read `page` rows at a
/// time (the store serves at most [`MAX_PAGE`] per query), so `--last` is never capped.
pub async fn newest(
    store: &Store,
    mut filter: HistoryFilter,
    last: u32,
    page: u32,
) -> anyhow::Result<Vec<MeasurementSummary>> {
    let page = page.clamp(1, MAX_PAGE);
    let mut rows = Vec::new();
    filter.cursor = None;
    while let Some(wanted) = last.checked_sub(rows.len() as u32).filter(|&n| n > 0) {
        filter.limit = wanted.min(page);
        let batch = store.measurement_history(&filter).await?;
        rows.extend(batch.items);
        match batch.next_cursor {
            Some(cursor) => filter.cursor = Some(cursor),
            None => break,
        }
    }
    Ok(rows)
}

pub(crate) fn run_export(args: ExportArgs) -> anyhow::Result<()> {
    let now = now();
    let since = args
        .since
        .as_deref()
        .map(|t| crate::clock::parse_time(t, now))
        .transpose()?
        .unwrap_or(jiff::Timestamp::UNIX_EPOCH);
    let until = args
        .until
        .as_deref()
        .map(|t| crate::clock::parse_time(t, now))
        .transpose()?
        .unwrap_or(now + jiff::SignedDuration::from_millis(1));
    if since >= until {
        bail!("--since must be before --until");
    }
    let runtime = runtime()?;
    let rows = runtime.block_on(async {
        let store = connect(&args.store).await?;
        let mut rows = Vec::new();
        let mut after = None;
        loop {
            let batch = store.export(since, until, after, 1000).await?;
            let Some(last) = batch.last() else { break };
            after = Some(last.summary.id);
            rows.extend(batch);
        }
        let recipes = super::export_dfq::recipe_parts(&store, &rows).await;
        store.close().await;
        anyhow::Ok((rows, recipes?))
    })?;
    let (mut rows, recipes) = rows;
    if args.format == Format::Dfq {
        // Q-DAS judges finished parts: an in-process measurement (stock on) is not one.
        rows.retain(|d| d.summary.stage == MeasurementStage::Final);
    }
    let count = rows.len();
    let text = if args.format == Format::Dfq {
        let export = super::export_dfq::DfqExport {
            recipes: &recipes,
            part: args.part.as_deref(),
            config: &args.store.config,
        };
        export.text(&rows)?
    } else {
        let rows: Vec<MeasurementSummary> = rows.into_iter().map(|d| d.summary).collect();
        render(&rows, args.format)?
    };
    match &args.out {
        Some(path) => {
            let mut outputs = Outputs::default();
            outputs.add(path, text);
            outputs.commit()?;
            println!("exported {count} measurements to {}", path.display());
        }
        None => print!("{text}"),
    }
    Ok(())
}

pub(crate) fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

pub(crate) async fn connect(args: &StoreArgs) -> anyhow::Result<Store> {
    let url = match (&args.database, std::env::var(ENV_DATABASE_URL).ok()) {
        (Some(url), _) => url.clone(),
        (None, Some(url)) => url,
        (None, None) => {
            let text = std::fs::read_to_string(&args.config).with_context(|| {
                format!(
                    "cannot read configuration {} (or give --database)",
                    args.config.display()
                )
            })?;
            Config::parse(&text, &args.config, |_| None)?.database_url()
        }
    };
    Ok(Store::connect(&url).await?)
}

fn render(rows: &[MeasurementSummary], format: Format) -> anyhow::Result<String> {
    let mut s = String::new();
    match format {
        Format::Dfq => bail!("--format dfq is for `camloop export`"),
        Format::Table => {
            let _ = writeln!(
                s,
                "{:>8}  {:<13}  {:<8} {:<8} {:<6} {:<10} {:>10} {:>10} {:>9}",
                "id",
                "received (UTC)",
                "machine",
                "lobe",
                "verdict",
                "stage",
                "profile µm",
                "size µm",
                "phase °"
            );
            for m in rows {
                let _ = writeln!(
                    s,
                    "{:>8}  {:<13}  {:<8} {:<8} {:<6} {:<10} {:>10.2} {:>10.2} {:>9.4}",
                    m.id.0,
                    format_time(m.received_at),
                    m.machine,
                    m.lobe,
                    m.verdict.as_str(),
                    m.stage.as_str(),
                    m.max_profile_error_um,
                    m.base_radius_error_um,
                    m.phase_error_deg
                );
            }
        }
        Format::Csv => {
            s.push_str("id,received_at_ms,machine,part,lobe,verdict,max_profile_error_um,base_radius_error_um,phase_error_deg,revolutions_used,points_per_rev,origin,sha256,stage\n");
            for m in rows {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                    m.id.0,
                    m.received_at.as_millisecond(),
                    csv_field(&m.machine),
                    csv_field(&m.part),
                    csv_field(&m.lobe),
                    m.verdict.as_str(),
                    m.max_profile_error_um,
                    m.base_radius_error_um,
                    m.phase_error_deg,
                    m.revolutions_used,
                    m.points_per_rev,
                    csv_field(&m.origin),
                    m.sha256,
                    m.stage.as_str()
                );
            }
        }
        Format::Json => {
            let items: Vec<serde_json::Value> = rows
                .iter()
                .map(|m| {
                    serde_json::json!({
                        "id": m.id.0, "received_at_ms": m.received_at.as_millisecond(), "machine": m.machine, "part": m.part,
                        "lobe": m.lobe, "verdict": m.verdict.as_str(), "max_profile_error_um": m.max_profile_error_um,
                        "base_radius_error_um": m.base_radius_error_um, "phase_error_deg": m.phase_error_deg,
                        "revolutions_used": m.revolutions_used, "points_per_rev": m.points_per_rev,
                        "origin": m.origin, "sha256": m.sha256, "stage": m.stage.as_str(),
                    })
                })
                .collect();
            s = serde_json::to_string_pretty(&items)? + "\n";
        }
    }
    Ok(s)
}

fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// `MM-DD HH:MM:SS` in UTC, enough to tell parts apart in a terminal.
fn format_time(at: jiff::Timestamp) -> String {
    crate::clock::utc_format(at, "%m-%d %H:%M:%S")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(unix_ms: i64) -> jiff::Timestamp {
        jiff::Timestamp::from_millisecond(unix_ms).unwrap()
    }

    #[test]
    fn times_format_for_a_terminal() {
        assert_eq!(
            format_time(ms(1_795_219_200_000 + 37_800_000)),
            "11-21 10:30:00"
        );
    }
}
