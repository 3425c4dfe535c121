//! Keeps the manifest bounded: once it has [`COMPACT_AFTER_LINES`] lines, it is replaced by
//! one [`Checkpoint`] line holding the versions still held in memory (the kept texts, the
//! deliverable one, the newest that reached the share and the newest pushed: see
//! [`History::forget_settled`]), and the lines it replaces become the archive
//! `manifest.1.jsonl` (replacing the previous archive). So start-up reads at most
//! [`COMPACT_AFTER_LINES`] lines plus a checkpoint of a few versions, and the state folder
//! holds at most two manifests' worth, however long the service runs. Every version's
//! history stays in the database's table versions.
//!
//! Crash safety: the checkpoint is written to a temporary and flushed; the current manifest
//! is linked (or copied) to a temporary and renamed over the archive; then the temporary
//! checkpoint is renamed over the manifest and the folder flushed. At every step the
//! manifest is either the old one, whole, or the new one; temporaries left by a kill are
//! removed at the next start with the versions folder's.

use crate::core::ids::TableVersion;
use std::fs;
use std::path::Path;

use jiff::Timestamp;
use serde::{Deserialize, Serialize};

use super::error::StateError;
use super::fs::{create_temp, sync_dir, write_synced};
use super::manifest::{self, History, Record, RecordOutOfOrder, VersionState};

/// Lines after which the manifest is compacted (about 128 versions, 250 KiB of records).
pub const COMPACT_AFTER_LINES: usize = 512;

/// The previous manifest's lines, kept once.
pub const ARCHIVE_FILE: &str = "manifest.1.jsonl";

/// The versions held when the manifest was compacted, and the counters that go with them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The highest version number told of so far.
    pub told: u64,
    /// Versions dropped from memory before the checkpoint.
    pub forgotten: u64,
    /// The version still to be delivered, if any.
    pub deliverable: Option<TableVersion>,
    /// Versions pushed so far.
    pub pushed: u64,
    /// The versions held, ascending.
    pub versions: Vec<VersionState>,
    #[serde(rename = "at_unix_ms", with = "crate::clock::unix_ms")]
    pub at: Timestamp,
    /// Lines the manifest had when it was compacted (now in the archive).
    pub archived_lines: usize,
}

impl Checkpoint {
    /// The history the checkpoint describes, checked for consistency.
    pub(super) fn into_history(self) -> Result<History, RecordOutOfOrder> {
        let ascending = self
            .versions
            .windows(2)
            .all(|w| w[0].record.version < w[1].record.version);
        let newest = self.versions.last().map_or(0, |v| v.record.version.get());
        if !ascending || newest > self.told {
            return Err(RecordOutOfOrder(format!(
                "checkpoint holds versions out of order or above v{}",
                self.told
            )));
        }
        if let Some(d) = self.deliverable
            && !self
                .versions
                .iter()
                .any(|v| v.record.version == d && v.is_deliverable())
        {
            return Err(RecordOutOfOrder(format!(
                "checkpoint's deliverable v{d} is not held as deliverable"
            )));
        }
        Ok(History {
            versions: self.versions,
            told: self.told,
            deliverable: self.deliverable,
            forgotten: self.forgotten,
            pushed: self.pushed,
        })
    }
}

impl History {
    /// Takes the checkpoint's history; only a first line may be a checkpoint.
    pub(super) fn restore(&mut self, c: Checkpoint) -> Result<(), RecordOutOfOrder> {
        if self.told != 0 {
            return Err(RecordOutOfOrder(format!(
                "checkpoint after v{}: only a first line may be one",
                self.told
            )));
        }
        *self = c.into_history()?;
        Ok(())
    }

    fn checkpoint(&self, at: Timestamp, archived_lines: usize) -> Checkpoint {
        Checkpoint {
            told: self.told,
            forgotten: self.forgotten,
            deliverable: self.deliverable,
            pushed: self.pushed,
            versions: self.versions.clone(),
            at,
            archived_lines,
        }
    }
}

/// Replaces the manifest `state_dir/manifest_name` by a checkpoint of `history` (settled
/// versions already forgotten), archiving its `lines` lines. Temporaries go in `temp_dir`
/// (on the same file system, cleaned at start).
pub(crate) fn compact(
    state_dir: &Path,
    manifest_name: &str,
    temp_dir: &Path,
    history: &History,
    lines: usize,
    at: Timestamp,
) -> Result<(), StateError> {
    let manifest = state_dir.join(manifest_name);
    let checkpoint = Record::Checkpoint(Box::new(history.checkpoint(at, lines)));
    let text = manifest::line(&checkpoint);
    let (file, fresh) = create_temp(temp_dir, |p| fs::File::create_new(p))
        .map_err(StateError::io("create a temporary in", temp_dir))?;
    write_synced(&file, text.as_bytes()).map_err(StateError::io("write", &fresh))?;
    let archived = create_temp(temp_dir, |p| fs::hard_link(&manifest, p))
        .or_else(|_| {
            create_temp(temp_dir, |p| {
                fs::copy(&manifest, p)?;
                fs::File::open(p)?.sync_all()
            })
        })
        .map_err(StateError::io("copy", &manifest))?
        .1;
    let archive = state_dir.join(ARCHIVE_FILE);
    fs::rename(&archived, &archive).map_err(StateError::io("rename", &archived))?;
    fs::rename(&fresh, &manifest).map_err(StateError::io("rename", &fresh))?;
    sync_dir(state_dir).map_err(StateError::io("flush", state_dir))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::share::test_version as v;

    fn ms(unix_ms: u64) -> jiff::Timestamp {
        jiff::Timestamp::from_millisecond(unix_ms as i64).unwrap()
    }
    use crate::share::manifest::{FileRecord, VersionRecord, VersionStatus};

    fn version(n: u64) -> Record {
        Record::Version(VersionRecord {
            version: v(n),
            created_at: ms(n),
            table_number: 1 + (n as u32 % 2),
            files: vec![FileRecord {
                name: "CAM.SPF".into(),
                sha256: "00".repeat(32).parse().unwrap(),
                bytes: 5,
            }],
            reason: "test".into(),
            measurement_id: None,
            learning: serde_json::json!({"gain": 0.5}),
            rollback_of: None,
            refused: None,
            epoch: None,
        })
    }

    /// A compacted manifest folds to the same held history as the long one, and records
    /// appended after the checkpoint apply as before.
    #[test]
    fn a_checkpoint_folds_to_the_same_history_and_takes_new_records() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("manifest.jsonl");
        let mut text = String::new();
        for n in 1..=50 {
            text.push_str(&manifest::line(&version(n)));
            for r in [
                Record::Delivering {
                    version: v(n),
                    at: ms(n),
                },
                Record::Pushed {
                    version: v(n),
                    at: ms(n),
                },
            ] {
                text.push_str(&manifest::line(&r));
            }
            if n > 3 {
                text.push_str(&manifest::line(&Record::Pruned {
                    version: v(n - 3),
                    at: ms(n),
                }));
            }
        }
        text.push_str(&manifest::line(&version(51)));
        std::fs::write(&path, &text).unwrap();
        let long = manifest::load_settled(&path).unwrap();
        let mut held = long.history.clone();
        held.forget_settled();
        compact(
            dir.path(),
            "manifest.jsonl",
            dir.path(),
            &held,
            long.lines,
            ms(9),
        )
        .unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.path().join(ARCHIVE_FILE)).unwrap(),
            text
        );
        let short = manifest::load(&path).unwrap();
        assert_eq!(short.lines, 1);
        assert_eq!(short.history, held);
        assert_eq!(short.history.next_version(), v(52));
        assert_eq!(short.history.waiting().unwrap().record.version, v(51));
        assert_eq!(
            short.history.last_pushed().unwrap().status,
            VersionStatus::Pushed {
                at: ms(50),
                note: None
            }
        );
        assert!(short.history.is_forgotten(v(10)));
        let mut h = short.history;
        h.apply(Record::Delivering {
            version: v(51),
            at: ms(60),
        })
        .unwrap();
        h.apply(version(52)).unwrap();
        // Only a first line may be a checkpoint.
        let again = Record::Checkpoint(Box::new(h.checkpoint(ms(0), 0)));
        assert!(h.apply(again).unwrap_err().0.contains("only a first line"));
    }

    /// A checkpoint line as camloop wrote it before the version status moved to the store
    /// crate (one definition for share and store): it loads unchanged, each status the
    /// same tagged JSON.
    #[test]
    fn a_checkpoint_written_before_the_status_moved_loads() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("manifest.jsonl");
        let file = r#"{"name":"CAM.SPF","sha256":"0000000000000000000000000000000000000000000000000000000000000000","bytes":5}"#;
        let record = |n: u32| {
            format!(
                r#"{{"version":{n},"created_at_unix_ms":{n},"table_number":1,"files":[{file}],"reason":"test","measurement_id":null,"learning":{{"gain":0.5}},"rollback_of":null,"refused":null}}"#
            )
        };
        let states = [
            (1, r#"{"status":"pushed","at_unix_ms":50}"#, true),
            (2, r#"{"status":"superseded","by":4}"#, false),
            (
                3,
                r#"{"status":"refused","reason":"step too large"}"#,
                false,
            ),
            (
                4,
                r#"{"status":"waiting","reason":"share unreachable"}"#,
                false,
            ),
        ];
        let versions: Vec<String> = states
            .iter()
            .map(|(n, status, reached)| {
                format!(
                    r#"{{"record":{},"status":{status},"reached_share":{reached},"text_kept":true}}"#,
                    record(*n)
                )
            })
            .collect();
        let line = format!(
            r#"{{"record":"checkpoint","told":4,"forgotten":0,"deliverable":4,"pushed":1,"versions":[{}],"at_unix_ms":60,"archived_lines":9}}"#,
            versions.join(",")
        );
        std::fs::write(&path, format!("{line}\n")).unwrap();
        let loaded = manifest::load(&path).unwrap();
        let status = |n: u64| loaded.history.get(v(n)).unwrap().status.clone();
        assert_eq!(
            status(1),
            VersionStatus::Pushed {
                at: ms(50),
                note: None
            }
        );
        assert_eq!(status(2), VersionStatus::Superseded { by: v(4) });
        assert_eq!(
            status(3),
            VersionStatus::Refused {
                reason: "step too large".into()
            }
        );
        assert_eq!(
            status(4),
            VersionStatus::Waiting {
                reason: Some("share unreachable".into())
            }
        );
    }

    #[test]
    fn an_inconsistent_checkpoint_is_refused() {
        let mut h = History::default();
        h.apply(version(1)).unwrap();
        let mut c = h.checkpoint(ms(0), 1);
        c.told = 0;
        assert!(c.clone().into_history().is_err());
        c.told = 1;
        c.deliverable = Some(v(7));
        assert!(c.into_history().is_err());
    }
}
