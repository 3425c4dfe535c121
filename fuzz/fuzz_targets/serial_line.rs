//! Fuzz target: the serial line protocol (line parser and decoder state machine).
#![no_main]

use camloop::gauge::serial::parse_serial_line;
use camloop::gauge::{SerialEvent, decode_serial_text};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: &[u8]| {
    let text = String::from_utf8_lossy(input);
    for line in text.lines() {
        let _ = parse_serial_line(line);
    }
    for event in decode_serial_text(&text, "fuzz") {
        if let SerialEvent::Measurement(m) = event {
            assert!(m.samples.iter().all(|s| s.revolution < m.header.revolutions
                && s.angle_index < m.header.points_per_rev
                && s.lift_mm.is_finite()));
        }
    }
});
