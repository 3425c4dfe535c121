//! The committed files in `tests/fixtures` the gauge tests read, and the lift formula the
//! Python encoders in `tools/` wrote the CAN, serial and CSV fixtures from.

use std::path::PathBuf;

/// The path of fixture `name`.
pub fn fixture_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The text of fixture `name`.
pub fn fixture_text(name: &str) -> String {
    let path = fixture_path(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The formula documented in tools/encode_candump.py, mm: the lift at `angle_index` of
/// `points_per_rev` in revolution `revolution`.
pub fn encoder_lift_mm(revolution: u32, angle_index: u32, points_per_rev: u32) -> f64 {
    let theta = 2.0 * std::f64::consts::PI * f64::from(angle_index) / f64::from(points_per_rev);
    6.2 * ((1.0 - theta.cos()) / 2.0).powi(2) + 0.0015 * (5.0 * theta + f64::from(revolution)).sin()
        - 0.0008
}
