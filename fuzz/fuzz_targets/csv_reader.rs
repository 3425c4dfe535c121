//! Fuzz target: the drop-folder CSV reader. The first line of the input is the file name.
#![no_main]

use camloop::gauge::parse_measurement_csv;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: &[u8]| {
    let Ok(text) = std::str::from_utf8(input) else {
        return;
    };
    let (name, body) = text.split_once('\n').unwrap_or(("M1_P1_L1.csv", text));
    if let Ok(m) = parse_measurement_csv(body, name, "fuzz") {
        assert!(!m.samples.is_empty());
        assert!(m.samples.iter().all(|s| s.revolution < m.header.revolutions
            && s.angle_index < m.header.points_per_rev
            && s.lift_mm.is_finite()));
    }
});
