//! The wall clock, read only at the edges (the core takes time as an argument).

use jiff::Timestamp;

/// Serde of an instant as integer milliseconds since the Unix epoch, the form every file and
/// message camloop writes uses (`#[serde(with = "crate::clock::unix_ms")]`).
pub use crate::store::unix_ms;

/// The current instant.
pub fn now() -> Timestamp {
    Timestamp::now()
}

/// An instant as `YYYY-MM-DDTHH:MM:SSZ` (UTC), for provenance written into programs.
pub(crate) fn utc_text(at: Timestamp) -> String {
    utc_format(at, "%Y-%m-%dT%H:%M:%SZ")
}

/// An instant in UTC, written by a `strftime` pattern (jiff's).
pub(crate) fn utc_format(at: Timestamp, pattern: &str) -> String {
    at.strftime(pattern).to_string()
}

/// A UTC date or time: `2026-11-21` (midnight), `2026-11-21T10:00:00` or an RFC 3339 time
/// with its offset (`…Z`, `…+01:00`).
pub(crate) fn parse_utc(text: &str) -> Option<Timestamp> {
    use jiff::civil::{Date, DateTime};
    use jiff::tz::TimeZone;
    if let Ok(ts) = text.parse::<Timestamp>() {
        return Some(ts);
    }
    let civil = match text.parse::<DateTime>() {
        Ok(dt) => dt,
        Err(_) => text
            .parse::<Date>()
            .ok()?
            .to_datetime(jiff::civil::Time::midnight()),
    };
    TimeZone::UTC.to_timestamp(civil).ok()
}

#[cfg(test)]
mod tests {
    fn ms(unix_ms: i64) -> jiff::Timestamp {
        jiff::Timestamp::from_millisecond(unix_ms).unwrap()
    }

    /// Checked against dates whose Unix time is known independently (`date -u -d @…`).
    #[test]
    fn utc_text_matches_known_dates() {
        assert_eq!(super::utc_text(ms(0)), "1970-01-01T00:00:00Z");
        assert_eq!(super::utc_text(ms(951_782_400_000)), "2000-02-29T00:00:00Z");
        assert_eq!(
            super::utc_text(ms(1_795_443_845_123)),
            "2026-11-23T14:24:05Z"
        );
    }

    /// The same known dates read back, in each accepted form; nonsense is refused.
    #[test]
    fn parse_utc_reads_dates_and_times() {
        use super::parse_utc;
        assert_eq!(parse_utc("2000-02-29"), Some(ms(951_782_400_000)));
        assert_eq!(
            parse_utc("2026-11-23T14:24:05Z"),
            Some(ms(1_795_443_845_000))
        );
        assert_eq!(
            parse_utc("2026-11-23T14:24:05"),
            Some(ms(1_795_443_845_000))
        );
        assert_eq!(
            parse_utc("2026-11-23T15:24:05+01:00"),
            Some(ms(1_795_443_845_000))
        );
        for bad in ["2026-13-01", "2026-02-30", "yesterday", ""] {
            assert_eq!(parse_utc(bad), None, "{bad}");
        }
    }
}
