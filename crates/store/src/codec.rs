//! Compact encodings of the store: lifts as i32 little-endian in 0.1 µm units, the opaque
//! history cursor, SHA-256 hex, and the input checks shared by the writers.
//!
//! Blob layout: `raw_revolutions` is revolution-major (revolution 0's `points_per_rev`
//! values, then revolution 1's, …); `averaged_profile` is one revolution. Each value is
//! `round(lift_mm · 10⁴)` as i32 LE, so a stored lift is within 0.05 µm of the given one.

use super::error::StoreError;

/// Lift units per mm in blobs: 0.1 µm.
pub(crate) const UNITS_PER_MM: f64 = 10_000.0;

/// `codec` of a row in the version-1 layout (i32 blobs, JSON text), as written before
/// schema version 4 and not yet converted.
pub(crate) const CODEC_PLAIN: i64 = 0;
/// `codec` of a packed row (see [`super::pack`]).
pub(crate) const CODEC_PACKED: i64 = 1;

/// Lifts (mm) as units, with the checks of [`encode_lifts_mm`].
pub(crate) fn encode_units(
    lifts_mm: impl IntoIterator<Item = f64>,
) -> Result<Vec<i32>, StoreError> {
    let mut blob = Vec::new();
    encode_lifts_mm(lifts_mm, &mut blob)?;
    Ok(blob
        .chunks_exact(4)
        .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

/// Units of a version-1 blob; a length not a multiple of 4 is a corrupt row.
pub(crate) fn decode_units(blob: &[u8]) -> Result<Vec<i32>, StoreError> {
    if !blob.len().is_multiple_of(4) {
        return Err(StoreError::invalid(
            "lift blob",
            format!("length {} is not a multiple of 4", blob.len()),
        ));
    }
    Ok(blob
        .chunks_exact(4)
        .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

/// Units as mm, the way a version-1 blob was always read.
pub(crate) fn units_to_mm(units: &[i32]) -> Vec<f64> {
    units.iter().map(|&u| f64::from(u) / UNITS_PER_MM).collect()
}

/// Encodes lifts (mm) for a blob; rejects NaN, infinities and values beyond ±214 m.
pub fn encode_lifts_mm(
    lifts_mm: impl IntoIterator<Item = f64>,
    out: &mut Vec<u8>,
) -> Result<(), StoreError> {
    for (i, lift_mm) in lifts_mm.into_iter().enumerate() {
        let units = (lift_mm * UNITS_PER_MM).round();
        if !units.is_finite() || units < f64::from(i32::MIN) || units > f64::from(i32::MAX) {
            return Err(StoreError::invalid(
                "lift_mm",
                format!("value {lift_mm} at index {i} is not a finite lift within ±214 m"),
            ));
        }
        // In range by the check above, so the cast is exact.
        out.extend_from_slice(&(units as i32).to_le_bytes());
    }
    Ok(())
}

pub use camloop_core::digest::sha256_hex;

/// Cursor text for the position after the row (received_at_ms, id).
pub(crate) fn encode_cursor(received_at_ms: i64, id: i64) -> String {
    format!("{received_at_ms}_{id}")
}

/// Parses a cursor made by [`encode_cursor`].
pub(crate) fn decode_cursor(cursor: &str) -> Result<(i64, i64), StoreError> {
    let bad = || StoreError::invalid("cursor", "not a cursor returned by this store");
    let (at, id) = cursor.split_once('_').ok_or_else(bad)?;
    Ok((
        at.parse().map_err(|_| bad())?,
        id.parse().map_err(|_| bad())?,
    ))
}

/// A name the store keys by: never empty; a machine name follows the one rule of config and
/// API ([`camloop_core::names::check_plain_name`]).
pub(crate) fn check_name(field: &'static str, value: &str) -> Result<(), StoreError> {
    if value.trim().is_empty() {
        return Err(StoreError::invalid(field, "must not be empty"));
    }
    if field == "machine" {
        camloop_core::names::check_plain_name(value)
            .map_err(|e| StoreError::invalid(field, e.to_string()))?;
    }
    Ok(())
}

/// A machine name read back. Every write checks the rule, so a refusal means a row written
/// outside camloop.
pub(crate) fn machine_of(text: String) -> Result<camloop_core::names::MachineName, StoreError> {
    camloop_core::names::MachineName::try_from(text)
        .map_err(|e| StoreError::invalid("machine", e.to_string()))
}

/// A table version read back: the columns hold integers, the records `TableVersion` (never
/// 0); a stored value off that rule is an invalid column, named.
pub(crate) fn version_of(
    column: &'static str,
    n: i64,
) -> Result<camloop_core::ids::TableVersion, StoreError> {
    camloop_core::ids::TableVersion::from_i64(n)
        .map_err(|_| StoreError::invalid(column, format!("stored value {n} is not a version")))
}

/// A lobe or pin name read back, by the same rule as machines: a refusal names the column.
pub(crate) fn feature_of(
    column: &'static str,
    text: String,
) -> Result<camloop_core::names::FeatureName, StoreError> {
    camloop_core::names::FeatureName::try_from(text)
        .map_err(|e| StoreError::invalid(column, e.to_string()))
}

/// A part id read back: every write holds a checked `PartId`, so a refusal names a row
/// written outside camloop.
pub(crate) fn part_of(text: String) -> Result<camloop_core::ids::PartId, StoreError> {
    camloop_core::ids::PartId::try_from(text)
        .map_err(|e| StoreError::invalid("part", e.to_string()))
}

/// A recipe's part name read back, by the names' rule.
pub(crate) fn part_name_of(text: String) -> Result<camloop_core::names::PartName, StoreError> {
    camloop_core::names::PartName::try_from(text)
        .map_err(|e| StoreError::invalid("part", e.to_string()))
}

/// A digest read back (64 lower-case hex digits, as every write stores it).
pub(crate) fn sha256_of(
    column: &'static str,
    text: String,
) -> Result<camloop_core::digest::Sha256, StoreError> {
    text.parse()
        .map_err(|e: camloop_core::digest::Sha256Error| StoreError::invalid(column, e.to_string()))
}

pub(crate) fn check_json(field: &'static str, text: &str) -> Result<(), StoreError> {
    serde_json::from_str::<serde::de::IgnoredAny>(text)
        .map(|_| ())
        .map_err(|e| StoreError::invalid(field, format!("not JSON: {e}")))
}

pub(crate) fn check_finite(field: &'static str, value: f64) -> Result<(), StoreError> {
    if !value.is_finite() {
        return Err(StoreError::invalid(field, format!("{value} is not finite")));
    }
    Ok(())
}

pub(crate) fn check_limit(limit: u32) -> Result<i64, StoreError> {
    if limit == 0 || limit > super::types::MAX_PAGE {
        return Err(StoreError::invalid(
            "limit",
            format!("{limit} is outside 1..={}", super::types::MAX_PAGE),
        ));
    }
    Ok(i64::from(limit))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lifts_round_trip_within_half_a_unit() {
        let lifts = [0.0, 1.234_567_89, -0.000_04, 12.5, 214_748.0];
        let mut blob = Vec::new();
        encode_lifts_mm(lifts, &mut blob).unwrap();
        assert_eq!(blob.len(), 4 * lifts.len());
        let back = units_to_mm(&decode_units(&blob).unwrap());
        for (a, b) in lifts.iter().zip(&back) {
            // Quantisation to 0.1 µm = 1e-4 mm: error at most half a unit.
            assert!((a - b).abs() <= 0.5e-4 + 1e-12, "{a} vs {b}");
        }
        // Little-endian layout of 1.2345679 mm = 12346 units.
        assert_eq!(&blob[4..8], &12_346_i32.to_le_bytes());
    }

    #[test]
    fn bad_lifts_and_blobs_are_refused() {
        let mut blob = Vec::new();
        assert_eq!(
            encode_lifts_mm([f64::NAN], &mut blob).unwrap_err().code(),
            "invalid"
        );
        assert!(encode_lifts_mm([300_000.0], &mut blob).is_err());
        assert!(decode_units(&[1, 2, 3]).is_err());
    }

    #[test]
    fn cursor_round_trips_and_rejects_garbage() {
        assert_eq!(decode_cursor(&encode_cursor(-5, 42)).unwrap(), (-5, 42));
        assert!(decode_cursor("12").is_err());
        assert!(decode_cursor("a_1").is_err());
    }
}
