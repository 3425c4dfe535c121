//! `camloop run`: loads the configuration, sets up logging and starts the service.

use crate::config::LogFormat;
use crate::service::{self, RunOptions};
use anyhow::Context;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct RunArgs {
    /// Service configuration.
    #[arg(long, value_name = "FILE", default_value = "config/camloop.toml")]
    pub config: PathBuf,
    /// Stop after this many parts per simulated machine in this run (demos, tests).
    #[arg(long, value_name = "N")]
    pub parts: Option<u64>,
    /// Continue on a database that is not the one camloop last wrote (it was replaced,
    /// emptied or restored from an older backup). Without it such a start is refused, naming
    /// both databases. Versions then continue from the shares' manifests; the learning state
    /// from the newest one kept in each machine's journal.
    #[arg(long)]
    pub accept_new_database: bool,
}

pub fn run_service(args: RunArgs) -> anyhow::Result<()> {
    // Everything the service makes (var/, its journals, the share's versions) is its
    // account's only.
    crate::private_fs::owner_only_umask();
    let text = std::fs::read_to_string(&args.config)
        .with_context(|| format!("cannot read configuration {}", args.config.display()))?;
    // Everything is checked, recipes, DBC files, folders and the listener included, before
    // the database or a share is touched; every problem is reported in one error.
    let checked = crate::config::load(&text, &args.config, |k| std::env::var(k).ok())?;
    init_logging(checked.config.service.log_format);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    runtime.block_on(service::run(
        checked,
        RunOptions {
            parts: args.parts,
            accept_new_database: args.accept_new_database,
        },
    ))
}

/// Plain lines for a terminal, JSON lines for collectors; RUST_LOG filters (default info).
fn init_logging(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,sqlx=warn"));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stdout());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_target(false)
        .with_ansi(ansi);
    let _ = match format {
        LogFormat::Plain => builder.try_init(),
        LogFormat::Json => builder.json().try_init(),
    };
}
