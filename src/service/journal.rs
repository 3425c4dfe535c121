//! The local journal every record passes through on its way to the database: appended and
//! flushed to disk first (from then on it is acknowledged and cannot be lost), written to the
//! store when it can be, kept while the database is down, and dropped only once the store
//! says its copy is durable. Records read back after a crash may already be in the store;
//! they are checked before being written again, so a replay never duplicates history.

use crate::store::{
    EventLevel, NewDressing, NewEvent, NewMeasurement, NewTableVersion, Store, StoreError,
    TableStatus, Verdict,
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
    Dressing {
        machine: String,
        at_ms: i64,
        old_radius_mm: f64,
        new_radius_mm: f64,
        /// Who reported it: "sim", "drop file <path>", "api".
        source: String,
    },
}

impl Pending {
    /// The event to store, for a [`Pending::Event`] (its level checked).
    fn event(&self) -> Option<Result<NewEvent, StoreError>> {
        match self {
            Pending::Event {
                machine,
                at_ms,
                level,
                kind,
                message,
            } => Some(EventLevel::parse(level).map(|level| NewEvent {
                machine: machine.clone(),
                at_ms: *at_ms,
                level,
                kind: kind.clone(),
                message: message.clone(),
            })),
            _ => None,
        }
    }

    /// The dressing to store, for a [`Pending::Dressing`].
    fn dressing(&self) -> Option<NewDressing> {
        match self {
            Pending::Dressing {
                machine,
                at_ms,
                old_radius_mm,
                new_radius_mm,
                source,
            } => Some(NewDressing {
                machine: machine.clone(),
                at_ms: *at_ms,
                old_radius_mm: *old_radius_mm,
                new_radius_mm: *new_radius_mm,
                source: source.clone(),
            }),
            _ => None,
        }
    }
}

/// The journal of one machine: `<dir>/journal.jsonl`, mirrored in memory so a part's flush
/// does not read and parse the file again. The file is the truth after a crash; the mirror is
/// loaded from it at open and changed only together with it.
///
/// The mirror's records are, in order: `written` ones already in the store (kept until the
/// store says they are durable), then those waiting. The first `replayed` were read from the
/// file at open and may be in the store already.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    records: Vec<Pending>,
    written: usize,
    replayed: usize,
}

impl Journal {
    /// Opens the journal in `dir`, cutting off a torn last line left by a crash mid-append
    /// (otherwise the next record would be glued onto it and lost), and loads what it holds.
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
        let records: Vec<Pending> = String::from_utf8_lossy(&bytes[..keep])
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect();
        Ok(Self {
            path,
            replayed: records.len(),
            records,
            written: 0,
        })
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
        self.records.extend_from_slice(records);
        Ok(())
    }

    /// Records not yet written to the database, oldest first.
    pub fn pending(&self) -> &[Pending] {
        &self.records[self.written..]
    }

    /// Every record the journal holds: those waiting and those written but not yet known to
    /// be durable, oldest first. The newest learning state of a machine is found here first.
    pub fn records(&self) -> &[Pending] {
        &self.records
    }

    /// Writes pending records to the store in order. Returns how many went; the rest stay
    /// for the next attempt (e.g. the database is down). Records that went stay in the file
    /// until [`Journal::release_durable`] finds the store's copy durable.
    pub async fn flush(&mut self, store: &Store) -> anyhow::Result<usize> {
        let mut done = 0;
        let mut failure = None;
        for (i, record) in self.records.iter().enumerate().skip(self.written) {
            let result = if i < self.replayed {
                apply_once(store, record).await
            } else {
                apply(store, record).await
            };
            match result {
                Ok(()) => done += 1,
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
        self.written += done;
        match failure {
            Some(e) if done == 0 => {
                Err(anyhow::Error::new(e)
                    .context("database write failed, records kept in the journal"))
            }
            _ => Ok(done),
        }
    }

    /// Drops the written records from the journal once the store answers that everything
    /// committed so far is durable ([`Store::checkpoint`]). Returns how many were dropped.
    pub async fn release_durable(&mut self, store: &Store) -> anyhow::Result<usize> {
        let written = self.written;
        if written == 0 || !store.checkpoint().await? {
            return Ok(0);
        }
        self.forget(written)?;
        Ok(written)
    }

    /// Drops the first `done` records from the file and the mirror. All of them (the usual
    /// case): the file is cut to nothing. Some: the rest replaces the file atomically
    /// (temporary file, rename), so a crash leaves the old or the new list. Either way a
    /// crash before this reaches the disk only means a replay, which writes nothing twice.
    fn forget(&mut self, done: usize) -> anyhow::Result<()> {
        let rest = &self.records[done..];
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
        self.records.drain(..done);
        self.written -= done;
        self.replayed = self.replayed.saturating_sub(done);
        Ok(())
    }
}

/// [`apply`] for a record read back after a crash: skipped when the store already holds it
/// (measurements are idempotent by their SHA-256 anyway).
async fn apply_once(store: &Store, record: &Pending) -> Result<(), StoreError> {
    let present = match record {
        Pending::Measurement { .. } => false,
        Pending::Table {
            machine,
            lobe,
            program_text,
            created_at_ms,
            ..
        } => {
            store
                .table_version_exists(machine, lobe, *created_at_ms, program_text)
                .await?
        }
        Pending::Event { .. } => match record.event() {
            Some(e) => store.event_exists(&e?).await?,
            None => false,
        },
        Pending::Learning {
            machine,
            lobe,
            state_json,
            saved_at_ms,
        } => {
            store
                .learning_state_exists(machine, lobe, state_json, *saved_at_ms)
                .await?
        }
        Pending::Dressing { .. } => match record.dressing() {
            Some(d) => store.dressing_exists(&d).await?,
            None => false,
        },
    };
    if present {
        Ok(())
    } else {
        apply(store, record).await
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
        Pending::Event { .. } => match record.event() {
            Some(e) => store.insert_event(&e?).await.map(|_| ()),
            None => Ok(()),
        },
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
        Pending::Dressing { .. } => match record.dressing() {
            Some(d) => store.insert_dressing(&d).await.map(|_| ()),
            None => Ok(()),
        },
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

    /// Every kind of record replayed after a crash (written, not yet released) is recognised
    /// in the store and not written again; a second event that differs only in its message
    /// still goes in.
    #[tokio::test]
    async fn a_replay_writes_nothing_twice() {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
        let store = Store::connect(&url).await.unwrap();
        let event = |message: &str| Pending::Event {
            machine: "M1".into(),
            at_ms: 7,
            level: "info".into(),
            kind: "wheel_dressed".into(),
            message: message.into(),
        };
        let records = [
            event("a"),
            Pending::Table {
                machine: "M1".into(),
                lobe: "IN1".into(),
                table_number: 1,
                program_text: "CTABDEF(X,C,1,1)\nCTABEND\n".into(),
                learning_params_json: "{}".into(),
                reason: "nominal table".into(),
                status: "pushed".into(),
                status_why: "pushed to the share".into(),
                created_at_ms: 7,
            },
            Pending::Learning {
                machine: "M1".into(),
                lobe: "IN1".into(),
                state_json: "{}".into(),
                saved_at_ms: 7,
            },
            Pending::Dressing {
                machine: "M1".into(),
                at_ms: 7,
                old_radius_mm: 250.0,
                new_radius_mm: 249.998,
                source: "api".into(),
            },
        ];
        let mut j = Journal::open(dir.path()).unwrap();
        j.append(&records).unwrap();
        assert_eq!(j.flush(&store).await.unwrap(), 4);
        // The crash: the journal is read back with every record still in it.
        let mut j = Journal::open(dir.path()).unwrap();
        j.append(&[event("b")]).unwrap();
        assert_eq!(j.flush(&store).await.unwrap(), 5);
        let crate::store::RawPool::Sqlite(pool) = store.raw_pool() else {
            panic!("a SQLite store")
        };
        for (table, rows) in [
            ("events", 2),
            ("table_versions", 1),
            ("learning_states", 1),
            ("dressings", 1),
        ] {
            let n: i64 = sqlx::query_scalar(&format!("SELECT COUNT(*) FROM {table}"))
                .fetch_one(pool)
                .await
                .unwrap();
            assert_eq!(n, rows, "{table}");
        }
        assert_eq!(j.release_durable(&store).await.unwrap(), 5);
        assert!(Journal::open(dir.path()).unwrap().records().is_empty());
    }
}
