//! The wall clock, read only at the edges (the core takes time as an argument).

/// Milliseconds since the Unix epoch (0 if the clock is before it).
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX))
        .unwrap_or(0)
}

/// [`now_ms`] as the unsigned value the share manifest uses.
pub(crate) fn now_ms_u64() -> u64 {
    u64::try_from(now_ms()).unwrap_or(0)
}

/// Unix milliseconds as `YYYY-MM-DDTHH:MM:SSZ` (UTC), for provenance written into programs.
pub(crate) fn utc_text(unix_ms: u64) -> String {
    utc_format(
        i64::try_from(unix_ms).unwrap_or(i64::MAX),
        "%Y-%m-%dT%H:%M:%SZ",
    )
}

/// Unix milliseconds in UTC, written by a `strftime` pattern (jiff's). Times outside jiff's
/// range (years −9999 to 9999) are clamped to its ends.
pub(crate) fn utc_format(unix_ms: i64, pattern: &str) -> String {
    let ts = jiff::Timestamp::from_millisecond(unix_ms).unwrap_or(if unix_ms < 0 {
        jiff::Timestamp::MIN
    } else {
        jiff::Timestamp::MAX
    });
    ts.strftime(pattern).to_string()
}

/// A UTC date or time as unix milliseconds: `2026-11-21` (midnight),
/// `2026-11-21T10:00:00` or an RFC 3339 time with its offset (`…Z`, `…+01:00`).
pub(crate) fn parse_utc(text: &str) -> Option<i64> {
    use jiff::civil::{Date, DateTime};
    use jiff::tz::TimeZone;
    if let Ok(ts) = text.parse::<jiff::Timestamp>() {
        return Some(ts.as_millisecond());
    }
    let civil = match text.parse::<DateTime>() {
        Ok(dt) => dt,
        Err(_) => text
            .parse::<Date>()
            .ok()?
            .to_datetime(jiff::civil::Time::midnight()),
    };
    Some(TimeZone::UTC.to_timestamp(civil).ok()?.as_millisecond())
}

#[cfg(test)]
mod tests {
    /// Checked against dates whose Unix time is known independently (`date -u -d @…`).
    #[test]
    fn utc_text_matches_known_dates() {
        assert_eq!(super::utc_text(0), "1970-01-01T00:00:00Z");
        assert_eq!(super::utc_text(951_782_400_000), "2000-02-29T00:00:00Z");
        assert_eq!(super::utc_text(1_795_443_845_123), "2026-11-23T14:24:05Z");
    }

    /// The same known dates read back, in each accepted form; nonsense is refused.
    #[test]
    fn parse_utc_reads_dates_and_times() {
        use super::parse_utc;
        assert_eq!(parse_utc("2000-02-29"), Some(951_782_400_000));
        assert_eq!(parse_utc("2026-11-23T14:24:05Z"), Some(1_795_443_845_000));
        assert_eq!(parse_utc("2026-11-23T14:24:05"), Some(1_795_443_845_000));
        assert_eq!(
            parse_utc("2026-11-23T15:24:05+01:00"),
            Some(1_795_443_845_000)
        );
        for bad in ["2026-13-01", "2026-02-30", "yesterday", ""] {
            assert_eq!(parse_utc(bad), None, "{bad}");
        }
    }
}
