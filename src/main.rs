//! The `camloop` binary: argument parsing and exit codes; the work lives in the library.

// No unwrap() in shipped code: bad input must become an error, not a panic (tests may).
#![warn(clippy::unwrap_used)]

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = camloop::cli::Cli::parse();
    match camloop::cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line on stderr: the whole context chain, joined with ": ".
            eprintln!("camloop: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
