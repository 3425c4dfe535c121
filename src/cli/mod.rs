//! Command-line front end: argument types and the commands behind them. This is an edge:
//! it reads files, calls the pure core and writes outputs atomically.

mod access;
mod analyze;
mod compensate;
mod contour;
mod export_dfq;
pub mod history;
mod output;
mod part;
mod planing;
mod program_args;
mod quality;
mod run;
mod speed_plan;
mod table;
mod tls;
mod turnmill;

use clap::{Parser, Subcommand};

pub use part::{PartArgs, PartKindArgs};

/// camloop: closed-loop compensation for X–C following grinding of cams and crankpins.
#[derive(Debug, Parser)]
#[command(name = "camloop", version, about, propagate_version = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Compute the wheel-head X(C) table of a part and write it as CSV and/or a program.
    Table(table::TableArgs),
    /// Draw the grinding setup (outline, wheel, wheel-centre path) as SVG.
    Plot(table::PlotArgs),
    /// Check and analyse a gauge measurement against the nominal part.
    Analyze(analyze::AnalyzeArgs),
    /// One turn of the learning loop: learn from a measurement, write the next table.
    Compensate(compensate::CompensateArgs),
    /// The service: gauges in, learning, tables to the controller share, history, HTTP API.
    Run(run::RunArgs),
    /// Measurement history of a machine from the store.
    History(history::HistoryArgs),
    /// Export the measurement history of a time range as CSV, JSON or Q-DAS AQDEF (dfq).
    Export(history::ExportArgs),
    /// Process capability of a machine's features: Cp/Cpk, Pp/Ppk with 95 % bounds, per
    /// characteristic, over a window of parts.
    Capability(quality::CapabilityArgs),
    /// The type-1 gauge study (Cg, Cgk, bias) of a feature from its master runs.
    GaugeStudy(quality::GaugeStudyArgs),
    /// A non-circular turning contour (ellipse, parabola, sine, tangent, CSV profile) as a
    /// program with chords placed by tolerance.
    Contour(contour::ContourArgs),
    /// Eccentric circles on a turn-mill centre (X/Y with C held) from a TOML job file.
    Turnmill(turnmill::TurnMillArgs),
    /// Ratio-coupled planing of a twisted-lobe rotor (A follows X), resumable by segment.
    Planing(planing::PlaningArgs),
    /// Plan C speed along the profile for the shortest finish revolution within the X, C and
    /// removal-rate limits, against the fastest constant C speed; optionally as SVG.
    SpeedPlan(speed_plan::SpeedPlanArgs),
    /// Users of the service and dashboard: add, passwd, disable, list.
    User(access::UserArgs),
    /// Per-user API tokens: create (shown once), revoke, list.
    Token(access::TokenArgs),
    /// The audit trail: who did what (`--since`), and `verify` its chain.
    Audit(access::AuditArgs),
    /// TLS for the API: `camloop tls self-signed` makes a development certificate and key.
    Tls(tls::TlsArgs),
}

/// Runs a parsed command; the error chain is printed by `main` on one line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Table(args) => table::run_table(args),
        Command::Plot(args) => table::run_plot(args),
        Command::Analyze(args) => analyze::run_analyze(args),
        Command::Compensate(args) => compensate::run_compensate(args),
        Command::Run(args) => run::run_service(args),
        Command::History(args) => history::run_history(args),
        Command::Export(args) => history::run_export(args),
        Command::Capability(args) => quality::run_capability(args),
        Command::GaugeStudy(args) => quality::run_gauge_study(args),
        Command::Contour(args) => contour::run_contour(args),
        Command::Turnmill(args) => turnmill::run_turnmill(args),
        Command::Planing(args) => planing::run_planing(args),
        Command::SpeedPlan(args) => speed_plan::run_speed_plan(args),
        Command::User(args) => access::run_user(args),
        Command::Token(args) => access::run_token(args),
        Command::Audit(args) => access::run_audit(args),
        Command::Tls(args) => tls::run_tls(args),
    }
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// clap checks the argument definitions only when a command is built: do it for all.
    #[test]
    fn argument_definitions_are_consistent() {
        Cli::command().debug_assert();
    }
}
