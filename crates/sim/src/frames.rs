//! The simulated gauge on a CAN bus in memory: a simulated measurement as the frames a
//! real gauge would send, so it can go through the real decoder and assembler.
//!
//! The CAN layout carries numeric ids, so the [`super::PartLabels`] of a measurement meant
//! for CAN must be plain decimal numbers (machine `"1"`, part `"1"`, lobe `"1"`); labels such
//! as `"SIM"` or `"intake-1"` are refused with [`EncodeError::Label`], naming the field.

use camloop_core::measure::RawMeasurement;
use camloop_gauge::{CanId, EncodeError, GaugeDbc, encode_measurement};

/// GaugeStart, every sample in order, GaugeEnd with status 0 (complete), encoded with
/// `dbc`. Lifts are rounded to the DBC resolution (0.1 µm with the shipped DBC).
pub fn measurement_frames(
    dbc: &GaugeDbc,
    m: &RawMeasurement,
) -> Result<Vec<(CanId, Vec<u8>)>, EncodeError> {
    encode_measurement(dbc, m, 0)
}
