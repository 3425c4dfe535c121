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

/// A time given on the command line or in a query that is none of the accepted forms.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("time `{0}`: use 2026-11-21, 2026-11-21T10:00:00Z, Unix ms, or an age like 24h or 7d")]
pub struct BadTime(pub String);

/// `2026-11-21`, `2026-11-21T10:00:00Z`, Unix ms, or an age (`90s`, `30m`, `24h`, `7d`).
pub(crate) fn parse_time(text: &str, now: Timestamp) -> Result<Timestamp, BadTime> {
    let t = text.trim();
    let bad = || BadTime(text.to_string());
    if let Some((digits, unit)) = t.char_indices().last().map(|(i, c)| (&t[..i], c))
        && let Some(unit_s) = match unit {
            's' => Some(1),
            'm' => Some(60),
            'h' => Some(3_600),
            'd' => Some(86_400),
            _ => None,
        }
        && let Ok(n) = digits.parse::<i64>()
    {
        // An age too large for jiff's years −9999 to 9999 is refused, not wrapped.
        return n
            .checked_mul(unit_s)
            .and_then(|s| now.checked_sub(jiff::SignedDuration::from_secs(s)).ok())
            .ok_or_else(bad);
    }
    if t.chars().all(|c| c.is_ascii_digit()) && t.len() > 8 {
        return t
            .parse()
            .ok()
            .and_then(|ms| Timestamp::from_millisecond(ms).ok())
            .ok_or_else(bad);
    }
    parse_utc(t).ok_or_else(bad)
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

    #[test]
    fn times_parse_in_every_documented_form() {
        // 2026-11-21T00:00:00Z is 1795219200 s after the epoch (20778 days).
        assert_eq!(
            super::parse_time("2026-11-21", ms(0)).unwrap(),
            ms(1_795_219_200_000)
        );
        assert_eq!(
            super::parse_time("2026-11-21T10:30:00Z", ms(0)).unwrap(),
            ms(1_795_219_200_000 + 37_800_000)
        );
        assert_eq!(
            super::parse_time("1795219200123", ms(0)).unwrap(),
            ms(1_795_219_200_123)
        );
        assert_eq!(
            super::parse_time("24h", ms(100_000_000)).unwrap(),
            ms(100_000_000 - 86_400_000)
        );
        assert_eq!(super::parse_time("7d", ms(0)).unwrap(), ms(-7 * 86_400_000));
        assert!(
            super::parse_time("yesterday", ms(0))
                .unwrap_err()
                .to_string()
                .contains("time `yesterday`")
        );
        assert!(super::parse_time("2026-13-01", ms(0)).is_err());
        // Beyond the years jiff holds: refused, not wrapped around.
        assert!(super::parse_time("9999999999d", ms(0)).is_err());
    }
}
