//! The local journal every record passes through on its way to the database: appended and
//! flushed to disk first (from then on it is acknowledged and cannot be lost), written to the
//! store when it can be, and kept while the database is down.

use crate::store::{
    EventLevel, NewEvent, NewMeasurement, NewTableVersion, Store, StoreError, TableStatus, Verdict,
};
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// One record waiting for the database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "record", rename_all = "snake_case")]
pub enum Pending {
    Measurement {
        machine: String,
        part: String,
        lobe: String,
        received_at_ms: i64,
        pass: bool,
        max_profile_error_um: f64,
        base_radius_error_um: f64,
        phase_error_deg: f64,
        revolutions_used: u32,
        points_per_rev: u32,
        origin: String,
        sha256: String,
        raw_lift_mm: Vec<Vec<f64>>,
        averaged_lift_mm: Vec<f64>,
        analysis_json: String,
    },
    Table {
        machine: String,
        lobe: String,
        table_number: u32,
        program_text: String,
        learning_params_json: String,
        reason: String,
        /// "pushed", "waiting" or "refused".
        status: String,
        status_why: String,
        created_at_ms: i64,
    },
    Event {
        machine: String,
        at_ms: i64,
        /// "info", "warn" or "error".
        level: String,
        kind: String,
        message: String,
    },
    Learning {
        machine: String,
        lobe: String,
        state_json: String,
        saved_at_ms: i64,
    },
}

/// The journal of one machine: `<dir>/journal.jsonl`, mirrored in memory so a part's flush
/// does not read and parse the file again. The file is the truth after a crash; the mirror is
/// loaded from it at open and changed only together with it.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    pending: Vec<Pending>,
}

impl Journal {
    /// Opens the journal in `dir`, cutting off a torn last line left by a crash mid-append
    /// (otherwise the next record would be glued onto it and lost), and loads what waits.
    pub fn open(dir: &Path) -> anyhow::Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let path = dir.join("journal.jsonl");
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
            Err(e) => {
                return Err(e).with_context(|| format!("cannot read journal {}", path.display()));
            }
        };
        let keep = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        if keep < bytes.len() {
            let file = std::fs::OpenOptions::new().write(true).open(&path)?;
            file.set_len(keep as u64)?;
            file.sync_all()?;
        }
        let pending = String::from_utf8_lossy(&bytes[..keep])
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect();
        Ok(Self { path, pending })
    }

    /// Appends the records and flushes them to disk before returning.
    pub fn append(&mut self, records: &[Pending]) -> anyhow::Result<()> {
        let mut text = String::new();
        for r in records {
            text.push_str(&serde_json::to_string(r)?);
            text.push('\n');
        }
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.path)
            .with_context(|| format!("cannot open journal {}", self.path.display()))?;
        file.write_all(text.as_bytes())
            .and_then(|()| file.sync_data())
            .with_context(|| format!("cannot write journal {}", self.path.display()))?;
        self.pending.extend_from_slice(records);
        Ok(())
    }

    /// Records not yet in the database, oldest first.
    pub fn pending(&self) -> &[Pending] {
        &self.pending
    }

    /// Writes pending records to the store in order. Returns how many went; those that went
    /// leave the journal, the rest stay for the next attempt (e.g. the database is down).
    pub async fn flush(&mut self, store: &Store) -> anyhow::Result<usize> {
        let mut done = 0;
        let mut failure = None;
        for record in &self.pending {
            match apply(store, record).await {
                Ok(()) => done += 1,
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
        if done > 0 {
            self.forget(done)?;
        }
        match failure {
            Some(e) if done == 0 => {
                Err(anyhow::Error::new(e)
                    .context("database write failed, records kept in the journal"))
            }
            _ => Ok(done),
        }
    }

    /// Drops the first `done` records from the file and the mirror. All of them (the usual
    /// case, one part's records): the file is cut to nothing. Some: the rest replaces the
    /// file atomically (temporary file, rename), so a crash leaves the old or the new list.
    fn forget(&mut self, done: usize) -> anyhow::Result<()> {
        let rest = &self.pending[done..];
        if rest.is_empty() {
            let file = std::fs::OpenOptions::new()
                .write(true)
                .open(&self.path)
                .and_then(|f| f.set_len(0).and_then(|()| f.sync_data()));
            file.with_context(|| format!("cannot empty journal {}", self.path.display()))?;
        } else {
            let dir = self.path.parent().unwrap_or(Path::new("."));
            let mut tmp = tempfile::Builder::new()
                .prefix(".journal-")
                .tempfile_in(dir)?;
            for r in rest {
                writeln!(tmp, "{}", serde_json::to_string(r)?)?;
            }
            tmp.as_file().sync_all()?;
            tmp.persist(&self.path)
                .with_context(|| format!("cannot replace journal {}", self.path.display()))?;
        }
        self.pending.drain(..done);
        Ok(())
    }
}

async fn apply(store: &Store, record: &Pending) -> Result<(), StoreError> {
    match record.clone() {
        Pending::Measurement {
            machine,
            part,
            lobe,
            received_at_ms,
            pass,
            max_profile_error_um,
            base_radius_error_um,
            phase_error_deg,
            revolutions_used,
            points_per_rev,
            origin,
            sha256,
            raw_lift_mm,
            averaged_lift_mm,
            analysis_json,
        } => {
            let m = NewMeasurement {
                machine,
                part,
                lobe,
                received_at_ms,
                verdict: if pass { Verdict::Pass } else { Verdict::Fail },
                max_profile_error_um,
                base_radius_error_um,
                phase_error_deg,
                revolutions_used,
                points_per_rev,
                origin,
                sha256,
                recipe_snapshot: None,
                raw_lift_mm,
                averaged_lift_mm,
                analysis_json,
            };
            store.insert_measurement(&m).await.map(|_| ())
        }
        Pending::Table {
            machine,
            lobe,
            table_number,
            program_text,
            learning_params_json,
            reason,
            status,
            status_why,
            created_at_ms,
        } => {
            let status = TableStatus::parse(&status)?;
            let parent_version = store
                .latest_table_version(&machine, &lobe)
                .await?
                .map(|t| t.version);
            let t = NewTableVersion {
                machine,
                lobe,
                parent_version,
                table_number,
                program_text,
                learning_params_json,
                reason,
                status,
                status_why,
                created_at_ms,
            };
            store.insert_table_version(&t).await.map(|_| ())
        }
        Pending::Event {
            machine,
            at_ms,
            level,
            kind,
            message,
        } => {
            let level = EventLevel::parse(&level)?;
            store
                .insert_event(&NewEvent {
                    machine,
                    at_ms,
                    level,
                    kind,
                    message,
                })
                .await
                .map(|_| ())
        }
        Pending::Learning {
            machine,
            lobe,
            state_json,
            saved_at_ms,
        } => {
            store
                .save_learning_state(&machine, &lobe, &state_json, saved_at_ms)
                .await
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_survive_a_torn_last_line() {
        let dir = tempfile::tempdir().unwrap();
        let mut j = Journal::open(dir.path()).unwrap();
        let e = Pending::Event {
            machine: "M1".into(),
            at_ms: 5,
            level: "warn".into(),
            kind: "k".into(),
            message: "m".into(),
        };
        j.append(&[e.clone(), e.clone()]).unwrap();
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(dir.path().join("journal.jsonl"))
            .unwrap();
        f.write_all(b"{\"record\":\"event\",\"mach").unwrap();
        // Reopened after the crash: the torn tail is cut, so the next record stands alone.
        let mut j = Journal::open(dir.path()).unwrap();
        assert_eq!(j.pending(), [e.clone(), e.clone()]);
        j.append(std::slice::from_ref(&e)).unwrap();
        assert_eq!(Journal::open(dir.path()).unwrap().pending().len(), 3);
    }
}
