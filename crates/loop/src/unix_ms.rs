//! Instants as integer Unix milliseconds on the wire (`#[serde(with = "crate::unix_ms")]`),
//! the form every file and message camloop writes keeps them in. jiff is used without its
//! `serde` feature, so a `Timestamp` cannot be written in another form by accident.

use jiff::Timestamp;
use serde::{Deserialize, Deserializer, Serializer};

/// Writes an instant as its integer milliseconds since the Unix epoch.
pub fn serialize<S: Serializer>(at: &Timestamp, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_i64(at.as_millisecond())
}

/// Reads integer milliseconds since the Unix epoch; a value outside jiff's years −9999 to
/// 9999 is an error naming it.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Timestamp, D::Error> {
    let unix_ms = i64::deserialize(d)?;
    Timestamp::from_millisecond(unix_ms).map_err(|_| {
        serde::de::Error::custom(format!(
            "{unix_ms} ms is not a time within the years -9999 to 9999"
        ))
    })
}
