//! Instants as integer Unix milliseconds, the form every column, journal line, message and
//! reply of camloop keeps them in: serde for the wire (`#[serde(with = "unix_ms")]`, and
//! [`option`] for an `Option`), and the checked conversion of a stored column.
//!
//! jiff's own serde would write RFC 3339 text; camloop's formats are integers, so jiff is
//! used without its `serde` feature and a `Timestamp` cannot be serialized by accident in
//! another form.

use jiff::Timestamp;
use serde::{Deserialize, Deserializer, Serializer};

use super::error::StoreError;

/// Writes an instant as its integer milliseconds since the Unix epoch.
pub fn serialize<S: Serializer>(at: &Timestamp, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_i64(at.as_millisecond())
}

/// Reads integer milliseconds since the Unix epoch; a value outside jiff's years −9999 to
/// 9999 is an error naming it.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Timestamp, D::Error> {
    let unix_ms = i64::deserialize(d)?;
    from_ms(unix_ms).map_err(serde::de::Error::custom)
}

/// The same for an `Option<Timestamp>` (`null` when `None`).
pub mod option {
    use jiff::Timestamp;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(at: &Option<Timestamp>, s: S) -> Result<S::Ok, S::Error> {
        match at {
            Some(at) => s.serialize_some(&at.as_millisecond()),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Timestamp>, D::Error> {
        Option::<i64>::deserialize(d)?
            .map(|unix_ms| super::from_ms(unix_ms).map_err(serde::de::Error::custom))
            .transpose()
    }
}

/// The same as unsigned milliseconds, the share manifest's form of a pushed version's time:
/// an instant before 1970 is written as 0, as the manifest always wrote it.
pub mod unsigned {
    use jiff::Timestamp;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(at: &Timestamp, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(u64::try_from(at.as_millisecond()).unwrap_or(0))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Timestamp, D::Error> {
        let unix_ms = u64::deserialize(d)?;
        i64::try_from(unix_ms)
            .map_err(|_| format!("{unix_ms} ms is not a time within the years -9999 to 9999"))
            .and_then(super::from_ms)
            .map_err(serde::de::Error::custom)
    }
}

/// Integer milliseconds as an instant, or why not.
pub(crate) fn from_ms(unix_ms: i64) -> Result<Timestamp, String> {
    Timestamp::from_millisecond(unix_ms)
        .map_err(|_| format!("{unix_ms} ms is not a time within the years -9999 to 9999"))
}

/// An instant from an integer-millisecond column. A stored value outside jiff's range (only
/// another program could have written it) is refused, naming the column, never clamped.
pub(crate) fn instant(unix_ms: i64, column: &'static str) -> Result<Timestamp, StoreError> {
    from_ms(unix_ms).map_err(|why| StoreError::invalid(column, format!("stored value {why}")))
}

/// [`instant`] of a column that may be NULL.
pub(crate) fn instant_opt(
    unix_ms: Option<i64>,
    column: &'static str,
) -> Result<Option<Timestamp>, StoreError> {
    unix_ms.map(|ms| instant(ms, column)).transpose()
}

#[cfg(test)]
mod tests {
    use jiff::Timestamp;

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Record {
        #[serde(rename = "at_ms", with = "super")]
        at: Timestamp,
        #[serde(rename = "until_ms", with = "super::option")]
        until: Option<Timestamp>,
    }

    /// The JSON text is the integer the records always had, byte for byte, and reads back
    /// to the same instant (2026-11-23T14:24:05.123Z, checked with `date -u -d @1795443845`).
    #[test]
    fn an_instant_round_trips_as_the_same_integer_text() {
        let text = r#"{"at_ms":1795443845123,"until_ms":null}"#;
        let r: Record = serde_json::from_str(text).unwrap();
        assert_eq!(r.at.to_string(), "2026-11-23T14:24:05.123Z");
        assert_eq!(serde_json::to_string(&r).unwrap(), text);
        let before_1970 = r#"{"at_ms":-1,"until_ms":0}"#;
        let r: Record = serde_json::from_str(before_1970).unwrap();
        assert_eq!(serde_json::to_string(&r).unwrap(), before_1970);
    }

    /// A value no instant has is an error that says so, on the wire and from a column.
    #[test]
    fn an_out_of_range_integer_is_an_error_not_a_panic() {
        let err =
            serde_json::from_str::<Record>(r#"{"at_ms":9223372036854775807,"until_ms":null}"#)
                .unwrap_err()
                .to_string();
        assert!(
            err.contains("9223372036854775807 ms is not a time"),
            "{err}"
        );
        let err = super::instant(i64::MIN, "received_at_ms").unwrap_err();
        assert_eq!(err.code(), "invalid");
        assert!(err.to_string().contains("received_at_ms"), "{err}");
        assert!(super::instant_opt(Some(253_402_300_800_000), "x").is_err());
        assert_eq!(super::instant_opt(None, "x").unwrap(), None);
    }
}
