//! Fuzz target: candump log lines through the parser, decoder and assembler.
#![no_main]

use camloop::gauge::{GaugeDbc, read_candump_measurements};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: &[u8]| {
    let text = String::from_utf8_lossy(input);
    let report = read_candump_measurements(&text, &GaugeDbc::builtin(), "fuzz");
    assert!(report.measurements.len() <= text.lines().count());
});
