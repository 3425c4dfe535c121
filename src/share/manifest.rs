//! The version manifest: an append-only JSON-lines file of records, folded into the
//! history of every version (status, table number, checksums).
//!
//! Each line is one [`Record`], written in a single `write` and flushed (`fsync`) before the
//! step it announces. History is only ever appended: a status is a new line, and
//! "superseded" is derived (a waiting version is superseded by the next accepted one), so no
//! line is rewritten. A kill can only tear the last line; an unterminated last line is
//! ignored on reading and cut off when the state folder is opened for writing.

use crate::core::digest::Sha256;
use crate::core::ids::TableVersion;
use std::path::Path;

use jiff::Timestamp;
use serde::{Deserialize, Serialize};

use super::error::StateError;

/// One line of the manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "record", rename_all = "snake_case")]
pub enum Record {
    /// A new version (accepted or refused), written after its text is stored.
    Version(VersionRecord),
    /// A push attempt failed; the version waits. Written when the reason changes.
    Waiting {
        version: TableVersion,
        #[serde(rename = "at_unix_ms", with = "crate::clock::unix_ms")]
        at: Timestamp,
        reason: String,
    },
    /// Temporaries are on the share and the renames begin: from here on the control may
    /// see this version's files.
    Delivering {
        version: TableVersion,
        #[serde(rename = "at_unix_ms", with = "crate::clock::unix_ms")]
        at: Timestamp,
    },
    /// All files renamed, the folder flushed, every file read back and verified.
    Pushed {
        version: TableVersion,
        #[serde(rename = "at_unix_ms", with = "crate::clock::unix_ms")]
        at: Timestamp,
    },
    /// The kept text was removed (older than the kept versions); the record stays.
    Pruned {
        version: TableVersion,
        #[serde(rename = "at_unix_ms", with = "crate::clock::unix_ms")]
        at: Timestamp,
    },
    /// The first line of a compacted manifest: the versions held when it was compacted
    /// (see [`super::compact`]); the lines before it went to the archive file.
    Checkpoint(Box<super::compact::Checkpoint>),
}

/// A version as requested: what it contains and why it was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VersionRecord {
    /// 1, 2, 3, … without gaps.
    pub version: TableVersion,
    /// Given by the caller; written as Unix time in milliseconds.
    #[serde(rename = "created_at_unix_ms", with = "crate::clock::unix_ms")]
    pub created_at: Timestamp,
    /// The curve-table number the program defines.
    pub table_number: u32,
    /// The program files, in rename order.
    pub files: Vec<FileRecord>,
    /// Why it was made (e.g. "learned from measurement 42", "rollback to v3").
    pub reason: String,
    /// The measurement the correction was learned from (its SHA-256, the text it always had
    /// in the file), if any.
    pub measurement_id: Option<Sha256>,
    /// Learning parameters, free-form.
    pub learning: serde_json::Value,
    /// The version whose text this one re-pushes.
    pub rollback_of: Option<TableVersion>,
    /// Set when the version was refused; it is then never pushed and has no kept text.
    pub refused: Option<String>,
    /// The fencing epoch of the owner that made it, with several instances (see
    /// [`super::Fence`]); absent for a single instance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epoch: Option<crate::cluster::Epoch>,
}

/// One program file of a version.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileRecord {
    /// Plain file name on the share (no folder).
    pub name: String,
    /// SHA-256 of the file's bytes (lower-case hex in the manifest).
    pub sha256: Sha256,
    /// Length in bytes.
    pub bytes: u64,
}

/// Where a version stands: the one status of a table version, defined in the store (whose
/// status column is written from it) and kept in the manifest as the same tagged JSON.
pub use crate::store::VersionStatus;

/// A version and what happened to it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VersionState {
    pub record: VersionRecord,
    pub status: VersionStatus,
    /// A `Delivering` record exists: the control may have seen this version's files.
    pub reached_share: bool,
    /// The text is in the state folder (accepted and not pruned).
    pub text_kept: bool,
}

impl VersionState {
    /// Still to be delivered (waiting, or renames not confirmed).
    pub(crate) fn is_deliverable(&self) -> bool {
        matches!(
            self.status,
            VersionStatus::Waiting { .. } | VersionStatus::Delivering
        )
    }
}

/// A manifest record that does not follow from the ones before it (the manifest was edited
/// or damaged); the text says which version and what.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct RecordOutOfOrder(pub String);

/// The versions the manifest tells of, in order. Folded as read by [`load`], it holds
/// every version; [`History::forget_settled`] drops the versions nothing can need any more,
/// so a long-running service's memory stays bounded while the manifest keeps every record.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct History {
    /// Ascending by version; without gaps until versions are forgotten.
    pub(super) versions: Vec<VersionState>,
    /// Versions told of so far (the highest version number).
    pub(super) told: u64,
    /// The one deliverable version, if any (accepting a version supersedes the previous
    /// deliverable one, so there is never more than one).
    pub(super) deliverable: Option<TableVersion>,
    /// Versions dropped by [`History::forget_settled`].
    pub(super) forgotten: u64,
    /// Versions pushed and verified so far, held or forgotten.
    pub(super) pushed: u64,
}
/// A manifest read from disk.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    pub history: History,
    /// Length of the complete lines; anything after it is a torn last line.
    pub good_len: u64,
    /// Number of complete lines.
    pub lines: usize,
    /// Bytes of a torn (unterminated) last line that were ignored.
    pub torn_bytes: u64,
}

impl History {
    /// The versions held, oldest first: all of them as loaded, the relevant ones after
    /// [`History::forget_settled`].
    pub fn versions(&self) -> &[VersionState] {
        &self.versions
    }

    /// One version, if it is held.
    pub fn get(&self, version: TableVersion) -> Option<&VersionState> {
        let i = self.index(version)?;
        self.versions.get(i)
    }

    fn get_mut(&mut self, version: TableVersion) -> Option<&mut VersionState> {
        let i = self.index(version)?;
        self.versions.get_mut(i)
    }

    fn index(&self, version: TableVersion) -> Option<usize> {
        self.versions
            .binary_search_by_key(&version, |v| v.record.version)
            .ok()
    }

    /// Whether `version` was told of but is no longer held (settled, no kept text).
    pub fn is_forgotten(&self, version: TableVersion) -> bool {
        version.get() <= self.told && self.get(version).is_none()
    }

    /// The number the next version gets.
    pub fn next_version(&self) -> TableVersion {
        TableVersion::new(self.told.saturating_add(1)).unwrap_or(TableVersion::FIRST)
    }

    /// How many versions were pushed and verified so far (forgotten ones included).
    pub fn pushed_count(&self) -> u64 {
        self.pushed
    }

    /// How many versions were dropped from memory so far.
    #[cfg(test)]
    pub(crate) fn forgotten_count(&self) -> u64 {
        self.forgotten
    }

    /// The newest version still to be delivered (at most one: accepting a version supersedes
    /// every older waiting one).
    pub fn waiting(&self) -> Option<&VersionState> {
        self.deliverable.and_then(|v| self.get(v))
    }

    /// Drops the versions nothing can need: no kept text, not deliverable, and neither the
    /// newest version that reached the share nor the newest pushed one (table numbers and
    /// the share's contents are judged by those). Their records stay in the manifest.
    pub(crate) fn forget_settled(&mut self) {
        let newest_reached = self
            .versions
            .iter()
            .rposition(|v| v.reached_share)
            .map(|i| self.versions[i].record.version);
        let newest_pushed = self.last_pushed().map(|v| v.record.version);
        let before = self.versions.len();
        self.versions.retain(|v| {
            v.text_kept
                || v.is_deliverable()
                || Some(v.record.version) == newest_reached
                || Some(v.record.version) == newest_pushed
        });
        self.forgotten += (before - self.versions.len()) as u64;
    }

    /// The newest version whose files may be on the share (and so whose table the control
    /// may be using): the newest that reached the renames, confirmed or not.
    pub fn on_share(&self) -> Option<&VersionState> {
        self.versions.iter().rev().find(|v| v.reached_share)
    }

    /// The newest version that was pushed and verified.
    pub fn last_pushed(&self) -> Option<&VersionState> {
        self.versions
            .iter()
            .rev()
            .find(|v| matches!(v.status, VersionStatus::Pushed { .. }))
    }

    /// Fold one record in, checking that it follows from what came before.
    pub fn apply(&mut self, record: Record) -> Result<(), RecordOutOfOrder> {
        match record {
            Record::Checkpoint(c) => self.restore(*c)?,
            Record::Version(rec) => {
                if rec.version != self.next_version() {
                    return Err(RecordOutOfOrder(format!(
                        "version v{} follows v{}, expected v{}",
                        rec.version,
                        self.told,
                        self.next_version()
                    )));
                }
                let status = match &rec.refused {
                    Some(reason) => VersionStatus::Refused {
                        reason: reason.clone(),
                    },
                    None => {
                        if let Some(older) = self.deliverable.and_then(|v| self.get_mut(v)) {
                            older.status = VersionStatus::Superseded { by: rec.version };
                        }
                        self.deliverable = Some(rec.version);
                        VersionStatus::Waiting { reason: None }
                    }
                };
                let text_kept = rec.refused.is_none();
                self.told = rec.version.get();
                self.versions.push(VersionState {
                    record: rec,
                    status,
                    reached_share: false,
                    text_kept,
                });
            }
            Record::Waiting {
                version, reason, ..
            } => {
                let v = self.deliverable_mut(version, "waiting")?;
                v.status = VersionStatus::Waiting {
                    reason: Some(reason),
                };
            }
            Record::Delivering { version, .. } => {
                let v = self.deliverable_mut(version, "delivering")?;
                v.status = VersionStatus::Delivering;
                v.reached_share = true;
            }
            Record::Pushed { version, at } => {
                let v = self.deliverable_mut(version, "pushed")?;
                if v.status != VersionStatus::Delivering {
                    return Err(RecordOutOfOrder(format!(
                        "v{version} pushed without delivering"
                    )));
                }
                // The status keeps unsigned milliseconds: an instant before 1970 is 1970.
                v.status = VersionStatus::Pushed {
                    at: at.max(Timestamp::UNIX_EPOCH),
                    note: None,
                };
                self.deliverable = None;
                self.pushed += 1;
            }
            Record::Pruned { version, .. } => {
                let v = self.get_mut(version).ok_or_else(|| {
                    RecordOutOfOrder(format!("pruned v{version}, which does not exist"))
                })?;
                if !v.text_kept {
                    return Err(RecordOutOfOrder(format!(
                        "pruned v{version}, which has no kept text"
                    )));
                }
                v.text_kept = false;
            }
        }
        Ok(())
    }

    fn deliverable_mut(
        &mut self,
        version: TableVersion,
        what: &str,
    ) -> Result<&mut VersionState, RecordOutOfOrder> {
        let v = self.get_mut(version).ok_or_else(|| {
            RecordOutOfOrder(format!("{what} for v{version}, which does not exist"))
        })?;
        if !v.is_deliverable() {
            return Err(RecordOutOfOrder(format!(
                "{what} for v{version}, which is {:?}",
                v.status
            )));
        }
        Ok(v)
    }
}

/// Read and fold a manifest without changing it, holding every version. A missing file is
/// an empty history.
pub fn load(path: &Path) -> Result<Loaded, StateError> {
    fold_file(path, false)
}

/// [`load`], forgetting settled versions as it goes ([`History::forget_settled`]), so a
/// long manifest never sits whole in memory.
pub(crate) fn load_settled(path: &Path) -> Result<Loaded, StateError> {
    fold_file(path, true)
}

fn fold_file(path: &Path, forget: bool) -> Result<Loaded, StateError> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(StateError::io("read manifest", path)(e)),
    };
    let good_len = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    let mut history = History::default();
    let lines = bytes[..good_len].iter().filter(|&&b| b == b'\n').count();
    for (index, line) in bytes[..good_len].split(|&b| b == b'\n').enumerate() {
        if line.is_empty() {
            continue;
        }
        let corrupt = |reason: String| StateError::CorruptManifest {
            path: path.to_path_buf(),
            line: index + 1,
            reason,
        };
        let record: Record = serde_json::from_slice(line).map_err(|e| corrupt(e.to_string()))?;
        let is_version = matches!(record, Record::Version(_));
        history.apply(record).map_err(|e| corrupt(e.0))?;
        if forget && is_version {
            history.forget_settled();
        }
    }
    Ok(Loaded {
        history,
        good_len: good_len as u64,
        lines,
        torn_bytes: (bytes.len() - good_len) as u64,
    })
}

/// One record as a manifest line, ending in `\n`.
pub(crate) fn line(record: &Record) -> String {
    // A Record holds only strings, numbers and a JSON value: serializing cannot fail.
    let mut line = serde_json::to_string(record).expect("a manifest record serializes to JSON");
    line.push('\n');
    line
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::share::test_version as v;

    fn ms(unix_ms: u64) -> jiff::Timestamp {
        jiff::Timestamp::from_millisecond(unix_ms as i64).unwrap()
    }

    fn version(n: u64, refused: Option<&str>) -> Record {
        Record::Version(VersionRecord {
            version: v(n),
            created_at: ms(1000 * n),
            table_number: 1,
            files: vec![FileRecord {
                name: "CAM_T1.SPF".into(),
                sha256: "00".repeat(32).parse().unwrap(),
                bytes: 5,
            }],
            reason: "test".into(),
            measurement_id: None,
            learning: serde_json::json!({"gain": 0.5}),
            rollback_of: None,
            refused: refused.map(str::to_owned),
            epoch: None,
        })
    }

    fn fold(records: Vec<Record>) -> Result<History, RecordOutOfOrder> {
        let mut h = History::default();
        for r in records {
            h.apply(r)?;
        }
        Ok(h)
    }

    /// While the share is down, the last pushed version is what the control runs: it stays
    /// held (table numbers are judged by it) though its text was pruned; the superseded
    /// versions after it are forgotten. Once a newer one is pushed, the old one goes too.
    #[test]
    fn settled_versions_are_forgotten_but_not_the_one_on_the_share() {
        let at = |n| Record::Pruned {
            version: v(n),
            at: ms(0),
        };
        let mut h = fold(vec![
            version(1, None),
            Record::Delivering {
                version: v(1),
                at: ms(1),
            },
            Record::Pushed {
                version: v(1),
                at: ms(2),
            },
            version(2, None),
            version(3, Some("guard")),
            version(4, None),
            version(5, None),
            at(1),
            at(2),
            at(4),
        ])
        .unwrap();
        h.forget_settled();
        let held = |h: &History| {
            h.versions()
                .iter()
                .map(|v| v.record.version.get())
                .collect::<Vec<_>>()
        };
        assert_eq!(held(&h), [1, 5]);
        assert_eq!(h.forgotten_count(), 3);
        assert!(h.is_forgotten(v(2)) && h.is_forgotten(v(3)) && h.is_forgotten(v(4)));
        assert!(!h.is_forgotten(v(1)) && !h.is_forgotten(v(6)));
        assert_eq!(h.on_share().map(|v| v.record.version), Some(v(1)));
        assert_eq!(h.waiting().map(|v| v.record.version), Some(v(5)));
        assert_eq!(h.next_version(), v(6));
        for r in [
            Record::Delivering {
                version: v(5),
                at: ms(3),
            },
            Record::Pushed {
                version: v(5),
                at: ms(4),
            },
        ] {
            h.apply(r).unwrap();
        }
        h.forget_settled();
        assert_eq!(held(&h), [5]);
        assert_eq!(h.last_pushed().map(|v| v.record.version), Some(v(5)));
    }

    #[test]
    fn a_record_round_trips_through_one_json_line() {
        let r = version(1, None);
        let text = line(&r);
        assert!(text.ends_with('\n') && text.matches('\n').count() == 1);
        assert!(
            text.starts_with(r#"{"record":"version","version":1,"#),
            "{text}"
        );
        assert_eq!(serde_json::from_str::<Record>(&text).unwrap(), r);
        let w = Record::Waiting {
            version: v(1),
            at: ms(7),
            reason: "share /x is missing".into(),
        };
        assert_eq!(
            line(&w),
            "{\"record\":\"waiting\",\"version\":1,\"at_unix_ms\":7,\"reason\":\"share /x is missing\"}\n"
        );
    }

    #[test]
    fn a_newer_accepted_version_supersedes_older_waiting_ones_but_not_refused_or_pushed() {
        let h = fold(vec![
            version(1, None),
            Record::Delivering {
                version: v(1),
                at: ms(1),
            },
            Record::Pushed {
                version: v(1),
                at: ms(2),
            },
            version(2, None),
            version(3, Some("table 1 is in use")),
            version(4, None),
        ])
        .unwrap();
        let status = |n| h.get(v(n)).unwrap().status.clone();
        assert_eq!(
            status(1),
            VersionStatus::Pushed {
                at: ms(2),
                note: None
            }
        );
        assert_eq!(status(2), VersionStatus::Superseded { by: v(4) });
        assert!(matches!(status(3), VersionStatus::Refused { .. }));
        assert_eq!(status(4), VersionStatus::Waiting { reason: None });
        assert_eq!(h.waiting().unwrap().record.version, v(4));
        assert_eq!(h.on_share().unwrap().record.version, v(1));
        assert!(!h.get(v(3)).unwrap().text_kept);
    }

    #[test]
    fn records_that_do_not_follow_are_refused() {
        assert!(
            fold(vec![version(2, None)])
                .unwrap_err()
                .0
                .contains("expected v1")
        );
        let pushed = Record::Pushed {
            version: v(1),
            at: ms(0),
        };
        assert!(
            fold(vec![version(1, None), pushed.clone()])
                .unwrap_err()
                .0
                .contains("without delivering")
        );
        let delivering = Record::Delivering {
            version: v(1),
            at: ms(0),
        };
        assert!(
            fold(vec![version(1, Some("no")), delivering])
                .unwrap_err()
                .0
                .contains("Refused")
        );
        let pruned = Record::Pruned {
            version: v(1),
            at: ms(0),
        };
        assert!(
            fold(vec![version(1, None), pruned.clone(), pruned])
                .unwrap_err()
                .0
                .contains("no kept text")
        );
    }

    #[test]
    fn a_torn_last_line_is_ignored_and_a_corrupt_middle_line_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("manifest.jsonl");
        let first = line(&version(1, None));
        std::fs::write(&path, format!("{first}{{\"record\":\"vers")).unwrap();
        let loaded = load(&path).unwrap();
        assert_eq!(loaded.history.versions().len(), 1);
        assert_eq!(loaded.good_len, first.len() as u64);
        assert_eq!(loaded.lines, 1);
        assert_eq!(loaded.torn_bytes, 15);

        std::fs::write(&path, format!("{first}garbage\n{first}")).unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("manifest.jsonl:2: expected value"), "{err}");
    }
}
