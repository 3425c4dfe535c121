//! A table version's status as the store keeps it: [`VersionStatus`] (the share's type, the
//! one status of a version) spelled as the `status` and `why` columns, for the database and
//! for journal lines written before the journal carried the type.

use super::{StoreError, VersionStatus};

/// The store's spelling of a [`VersionStatus`]: the `status` and `why` columns of
/// `table_version_status`, whose time column (`at_ms`) is a pushed version's time.
///
/// The store holds `waiting`, `pushed` and `refused` only (its migrations check that, and
/// no other value was ever written). `Delivering` and `Superseded` are the share's own
/// states, never written to the store: the machine loop records only what the share
/// confirmed (pushed) or refused, and a version it has not seen confirmed stays `waiting`
/// (a store rebuilt from the share's manifest records both share states as waiting). So the
/// store refuses to write them rather than fold them into a status it would read back as
/// another.
impl VersionStatus {
    /// Pushed at `at`, learned as `note` says; an instant before 1970 is taken as 1970, as in
    /// the share's manifest (its times are unsigned milliseconds).
    pub fn pushed_at(at: jiff::Timestamp, note: impl Into<String>) -> Self {
        VersionStatus::Pushed {
            at: at.max(jiff::Timestamp::UNIX_EPOCH),
            note: Some(note.into()),
        }
    }

    /// The `status` column's text.
    pub fn name(&self) -> &'static str {
        match self {
            VersionStatus::Waiting { .. } => "waiting",
            VersionStatus::Delivering => "delivering",
            VersionStatus::Pushed { .. } => "pushed",
            VersionStatus::Refused { .. } => "refused",
            VersionStatus::Superseded { .. } => "superseded",
        }
    }

    /// Why it has this status, as the `why` column keeps it (empty when none was given).
    pub fn why(&self) -> &str {
        match self {
            VersionStatus::Waiting { reason } | VersionStatus::Pushed { note: reason, .. } => {
                reason.as_deref().unwrap_or("")
            }
            VersionStatus::Refused { reason } => reason,
            VersionStatus::Delivering | VersionStatus::Superseded { .. } => "",
        }
    }

    /// The `status` and `why` columns to write; a share-only state is refused (see above).
    pub fn column(&self) -> Result<(&'static str, &str), StoreError> {
        match self {
            VersionStatus::Delivering | VersionStatus::Superseded { .. } => {
                Err(StoreError::invalid(
                    "table status",
                    format!(
                        "`{}` is the share's own state; the store keeps waiting, pushed or refused",
                        self.name()
                    ),
                ))
            }
            _ => Ok((self.name(), self.why())),
        }
    }

    /// The status stored as `status` and `why` at `at_ms` (a pushed version's time).
    pub fn from_column(status: &str, why: String, at_ms: i64) -> Result<Self, StoreError> {
        let text = (!why.is_empty()).then_some(why);
        match status {
            "waiting" => Ok(VersionStatus::Waiting { reason: text }),
            "pushed" if at_ms < 0 => Err(StoreError::invalid(
                "table status",
                format!("pushed at {at_ms} ms, before 1970"),
            )),
            "pushed" => Ok(VersionStatus::Pushed {
                at: crate::unix_ms::instant(at_ms, "table status")?,
                note: text,
            }),
            "refused" => Ok(VersionStatus::Refused {
                reason: text.unwrap_or_default(),
            }),
            other => Err(StoreError::invalid(
                "table status",
                format!("unknown value `{other}` (known: waiting, pushed, refused)"),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every status text the store ever wrote (its migrations allow these three and no
    /// other) reads back, and writes the same columns again.
    #[test]
    fn every_stored_status_reads_and_writes_back_the_same_columns() {
        let why = |text: &str| text.to_string();
        let cases = [
            (
                "waiting",
                "submitted to the share",
                VersionStatus::Waiting {
                    reason: Some(why("submitted to the share")),
                },
            ),
            ("waiting", "", VersionStatus::Waiting { reason: None }),
            (
                "pushed",
                "pushed to the share on retry",
                VersionStatus::Pushed {
                    at: jiff::Timestamp::from_millisecond(6_000).expect("a time"),
                    note: Some(why("pushed to the share on retry")),
                },
            ),
            (
                "pushed",
                "",
                VersionStatus::Pushed {
                    at: jiff::Timestamp::from_millisecond(6_000).expect("a time"),
                    note: None,
                },
            ),
            (
                "refused",
                "step too large",
                VersionStatus::Refused {
                    reason: why("step too large"),
                },
            ),
            ("refused", "", VersionStatus::Refused { reason: why("") }),
        ];
        for (status, text, expected) in cases {
            let read = VersionStatus::from_column(status, why(text), 6_000).unwrap();
            assert_eq!(read, expected, "{status} / {text:?}");
            assert_eq!(read.column().unwrap(), (status, text));
        }
    }

    #[test]
    fn an_unknown_status_or_a_push_before_1970_is_an_error_naming_it() {
        for status in ["delivered", "Pushed", "", "delivering", "superseded"] {
            let e = VersionStatus::from_column(status, "x".into(), 1).unwrap_err();
            let text = e.to_string();
            assert!(
                text.contains(&format!("unknown value `{status}`")),
                "{text}"
            );
            assert!(text.contains("table status"), "{text}");
        }
        let e = VersionStatus::from_column("pushed", "x".into(), -1).unwrap_err();
        assert!(e.to_string().contains("-1 ms"), "{e}");
    }

    /// The share's own states have no column: the store refuses them, naming the state.
    #[test]
    fn the_shares_own_states_have_no_column() {
        for status in [
            VersionStatus::Delivering,
            VersionStatus::Superseded {
                by: camloop_core::ids::TableVersion::new(4).unwrap(),
            },
        ] {
            let e = status.column().unwrap_err().to_string();
            assert!(e.contains(&format!("`{}`", status.name())), "{e}");
        }
    }

    /// A pushed version's time is a `Timestamp` in the code and the manifest's unsigned
    /// milliseconds on disk, as every build wrote it: an old manifest's status reads, and
    /// writes back byte for byte.
    #[test]
    fn a_pushed_status_keeps_the_manifests_unsigned_milliseconds() {
        let old = r#"{"status":"pushed","at_unix_ms":1795443845123}"#;
        let read: VersionStatus = serde_json::from_str(old).expect("an old status reads");
        let at = jiff::Timestamp::from_millisecond(1_795_443_845_123).expect("a time");
        assert_eq!(read, VersionStatus::Pushed { at, note: None });
        assert_eq!(serde_json::to_string(&read).expect("writes"), old);
        let noted = r#"{"status":"pushed","at_unix_ms":50,"note":"pushed to the share on retry"}"#;
        let read: VersionStatus = serde_json::from_str(noted).expect("a noted status reads");
        assert_eq!(serde_json::to_string(&read).expect("writes"), noted);
        // An instant before 1970 was written as 0, and still is.
        let before = jiff::Timestamp::from_millisecond(-5).expect("a time");
        let status = VersionStatus::pushed_at(before, "x");
        let json = serde_json::to_value(&status).expect("writes");
        assert_eq!(json["at_unix_ms"], 0);
        // A number no time can be is an error naming it, never a clamped time.
        let huge = r#"{"status":"pushed","at_unix_ms":18446744073709551615}"#;
        let e = serde_json::from_str::<VersionStatus>(huge).unwrap_err();
        assert!(e.to_string().contains("18446744073709551615 ms"), "{e}");
    }
}
