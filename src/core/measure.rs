//! Gauge measurements as they arrive: raw samples of several revolutions, before checks.

/// Who and what a measurement belongs to, as announced by the gauge at the start.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MeasurementHeader {
    pub machine: String,
    pub part: String,
    pub lobe: String,
    /// Revolutions the gauge announced it would measure.
    pub revolutions: u32,
    /// Readings per revolution, equally spaced, index 0 at 0° of the part frame.
    pub points_per_rev: u32,
}

/// One gauge reading: revolution number (0-based), angle index within the revolution
/// (0-based, angle = index · 360° / points_per_rev) and the lift in mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawSample {
    pub revolution: u32,
    pub angle_index: u32,
    pub lift_mm: f64,
}

/// A measurement as received, in arrival order, not yet checked for completeness.
#[derive(Debug, Clone, PartialEq)]
pub struct RawMeasurement {
    pub header: MeasurementHeader,
    pub samples: Vec<RawSample>,
    /// Where it came from, for error messages and traceability ("can0", a file path, …).
    pub origin: String,
}
