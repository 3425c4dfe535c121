//! The local journal every record passes through on its way to the database: appended and
//! flushed to disk first (from then on it is acknowledged and cannot be lost), written to the
//! store when it can be, kept while the database is down, and dropped only once the store
//! says its copy is durable. Records read back after a crash may already be in the store;
//! they are checked before being written again, so a replay never duplicates history.

mod commit;
mod record;
mod reserve;
mod writer;

pub use record::{EventKind, Pending};
use record::{apply, apply_once};
pub use reserve::{RESERVE_BYTES, SharedReserve, share_under as share_reserve_under};
pub(crate) use writer::totals as store_totals;

use crate::failpoint::crash_point;
use crate::share::{Fence, Held};
use crate::store::{Store, StoreError};
use std::io::Write;
use std::path::{Path, PathBuf};

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
    quarantined: Vec<Quarantined>,
    reserve: SharedReserve,
    /// When the newest record this journal wrote to the store was committed: a checkpoint
    /// started after it covers every written record.
    committed_by: Option<std::time::Instant>,
    /// With several instances: this owner's fence, held around every write (the file and the
    /// store), so an instance that lost the machine writes nothing more for it.
    fence: Option<Fence>,
}

/// Why the journal could not do what was asked. Each names the file; the cause is in the
/// message (the callers log it whole), not chained behind it.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// A file of the journal (the journal, its quarantine or refused file, its folder)
    /// could not be read or written.
    #[error("cannot {what} {}: {source}", path.display())]
    File {
        what: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    /// A record could not be encoded as a journal line.
    #[error("cannot encode a record for journal {}: {source}", path.display())]
    Encode {
        path: PathBuf,
        source: serde_json::Error,
    },
    /// In a cluster: the machine's fence refused the write (another instance owns it).
    #[error("journal {}: {source}", path.display())]
    Fence {
        path: PathBuf,
        source: crate::share::StateError,
    },
    /// No record could be written: the database refused them or could not be reached.
    #[error("database write failed, records kept in the journal: {0}")]
    Unwritten(StoreError),
    /// The database could not say whether its copy is durable.
    #[error("{0}")]
    Checkpoint(StoreError),
}

impl JournalError {
    fn file(what: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.to_path_buf();
        move |source| JournalError::File { what, path, source }
    }
}

fn is_disk_full(e: &std::io::Error) -> bool {
    e.raw_os_error() == Some(28) || e.kind() == std::io::ErrorKind::StorageFull
}

impl Journal {
    /// Opens the journal in `dir`, cutting off a torn last line left by a crash mid-append
    /// (otherwise the next record would be glued onto it and lost), and loads what it holds.
    pub fn open(dir: &Path) -> Result<Self, JournalError> {
        std::fs::create_dir_all(dir).map_err(JournalError::file("create", dir))?;
        let path = dir.join("journal.jsonl");
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
            Err(e) => return Err(JournalError::file("read journal", &path)(e)),
        };
        let keep = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        if keep < bytes.len() {
            std::fs::OpenOptions::new()
                .write(true)
                .open(&path)
                .and_then(|file| file.set_len(keep as u64).and_then(|()| file.sync_all()))
                .map_err(JournalError::file("cut the torn line of journal", &path))?;
        }
        let mut records = Vec::new();
        let mut bad = Vec::new();
        for (i, line) in String::from_utf8_lossy(&bytes[..keep]).lines().enumerate() {
            match record::read_line(line) {
                Ok(r) => records.push(r),
                Err(e) => bad.push(Quarantined {
                    line: i + 1,
                    reason: e.to_string(),
                    text: line.to_string(),
                }),
            }
        }
        let reserve = reserve::for_journal(dir);
        let mut journal = Self {
            path,
            replayed: records.len(),
            records,
            written: 0,
            committed_by: None,
            quarantined: Vec::new(),
            fence: None,
            reserve,
        };
        if !bad.is_empty() {
            journal.quarantine(bad)?;
        }
        Ok(journal)
    }

    /// Moves lines that do not parse into `journal.quarantine.jsonl` beside the journal
    /// (kept, never dropped: a newer camloop or a person may still read them), then rewrites
    /// the journal without them, so they are reported once.
    fn quarantine(&mut self, bad: Vec<Quarantined>) -> Result<(), JournalError> {
        let qpath = self.path.with_file_name(QUARANTINE_FILE);
        let mut text = String::new();
        for q in &bad {
            text.push_str(&q.text);
            text.push('\n');
        }
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&qpath)
            .map_err(JournalError::file("open", &qpath))?;
        file.write_all(text.as_bytes())
            .and_then(|()| file.sync_data())
            .map_err(JournalError::file("write", &qpath))?;
        self.rewrite(&self.records)?;
        self.quarantined = bad;
        Ok(())
    }

    /// Lines found unreadable at open and moved to the quarantine file (for the caller to
    /// report), with their line numbers in the journal as it was.
    pub(crate) fn quarantined(&self) -> &[Quarantined] {
        &self.quarantined
    }

    /// Fences every later write with `fence` (an owner in a cluster): once another instance
    /// claims the machine, appends, flushes and releases fail with the fence's error.
    pub fn set_fence(&mut self, fence: Fence) {
        self.fence = Some(fence);
    }

    /// In a cluster: whether another instance has claimed the machine since this journal was
    /// fenced (its fence holds a newer epoch). Asked after a failed write, so the failure is
    /// told apart by the fence itself, not by digging through the error.
    pub(crate) fn fenced_out(&self) -> bool {
        self.fence
            .as_ref()
            .is_some_and(|f| matches!(f.hold(), Err(crate::share::StateError::Fenced { .. })))
    }

    fn hold(&self) -> Result<Option<Held>, JournalError> {
        let held = self.fence.as_ref().map(Fence::hold).transpose();
        held.map_err(|source| JournalError::Fence {
            path: self.path.clone(),
            source,
        })
    }

    fn encode(&self, record: &Pending) -> Result<String, JournalError> {
        serde_json::to_string(record).map_err(|source| JournalError::Encode {
            path: self.path.clone(),
            source,
        })
    }

    /// Appends the records and flushes them to disk before returning. When the disk is
    /// full, the space of the reserve file is given up to take them (see [`Self::on_reserve`]).
    pub fn append(&mut self, records: &[Pending]) -> Result<(), JournalError> {
        let _held = self.hold()?;
        let mut text = String::new();
        for r in records {
            text.push_str(&self.encode(r)?);
            text.push('\n');
        }
        match self.write(text.as_bytes()) {
            Err(e) if is_disk_full(&e) && self.reserve_lock().release() => {
                self.write(text.as_bytes())
            }
            other => other,
        }
        .map_err(JournalError::file("write journal", &self.path))?;
        for step in records.iter().filter_map(Pending::journaled_step) {
            crash_point(step);
        }
        self.records.extend_from_slice(records);
        Ok(())
    }

    /// Appends and syncs `bytes` through the process's group commit (see [`commit`]):
    /// returns once they are durable, batched with whatever other journals append meanwhile;
    /// on failure the file is cut back to where it was, so a partial line never glues itself
    /// to the next record.
    fn write(&self, bytes: &[u8]) -> std::io::Result<()> {
        commit::GroupCommit::global()
            .submit(&self.path, bytes.to_vec())
            .wait()
    }

    /// Whether the journal is running on its reserve: the disk was full, and only the space
    /// given up by the reserve file keeps records durable. Bounded: the machine records
    /// measurements and stops learning until [`Self::restore_reserve`] succeeds.
    pub(crate) fn on_reserve(&self) -> bool {
        self.reserve_lock().in_use()
    }

    /// Tries to write the reserve again (space was freed); true when the journal is off its
    /// reserve.
    pub(crate) fn restore_reserve(&mut self) -> bool {
        self.reserve_lock().ensure()
    }

    fn reserve_lock(&self) -> std::sync::MutexGuard<'_, reserve::DiskReserve> {
        // Every change is one flag and one file: a panic elsewhere leaves it usable.
        self.reserve.lock().unwrap_or_else(|p| p.into_inner())
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

    /// Writes pending records to the store in order. Returns how many went, and the records
    /// the store refused for good ([`StoreError::refuses_record`]): each is moved to
    /// [`REFUSED_FILE`] beside the journal (kept, with the store's reason) and taken out of
    /// the journal, so one bad record never holds up the history behind it. The rest stay
    /// for the next attempt (e.g. the database is down). Records that went stay in the file
    /// until [`Journal::release_durable`] finds the store's copy durable.
    pub async fn flush(&mut self, store: &Store) -> Result<Flushed, JournalError> {
        let _held = self.hold()?;
        let mut flushed = Flushed::default();
        while self.written >= self.replayed && self.written < self.records.len() {
            match self.flush_batch(store).await {
                Ok(n) => flushed.written += n,
                // The batch is rolled back; one record at a time below finds which record the
                // store refuses (set aside) or that it is unavailable (kept).
                Err(_) => break,
            }
        }
        let mut failure = None;
        let mut i = self.written;
        while i < self.records.len() {
            let record = &self.records[i];
            let result = if i < self.replayed {
                apply_once(store, record).await
            } else {
                apply(store, record).await
            };
            match result {
                Ok(()) => {
                    crash_point(record.committed_step());
                    self.committed_by = Some(std::time::Instant::now());
                    flushed.written += 1;
                    self.written += 1;
                    i += 1;
                }
                Err(e) if e.refuses_record() => {
                    // Not advanced: the next record moves into this place.
                    flushed.refused.push(self.set_aside(i, &e)?);
                }
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
        match failure {
            Some(e) if flushed.written == 0 && flushed.refused.is_empty() => {
                Err(JournalError::Unwritten(e))
            }
            _ => Ok(flushed),
        }
    }

    /// Writes up to [`BATCH_RECORDS`] new records (none replayed) through the store's group
    /// commit ([`writer`]): in one transaction with whatever other journals write meanwhile,
    /// rather than one each. Returns how many went; on an error none did.
    async fn flush_batch(&mut self, store: &Store) -> Result<usize, StoreError> {
        let end = self.records.len().min(self.written + BATCH_RECORDS);
        let records = &self.records[self.written..end];
        writer::StoreWriter::global()
            .write(store, records.to_vec())
            .await?;
        for record in records {
            crash_point(record.committed_step());
        }
        self.committed_by = Some(std::time::Instant::now());
        self.written = end;
        Ok(records.len())
    }

    /// Moves record `i` (pending) out of the journal into [`REFUSED_FILE`], synced there
    /// before the journal is rewritten without it: a crash between the two leaves it in both,
    /// never in neither.
    fn set_aside(&mut self, i: usize, e: &StoreError) -> Result<Refused, JournalError> {
        let record = &self.records[i];
        let refused = Refused {
            kind: record.kind_name(),
            reason: e.to_string(),
        };
        let line = serde_json::json!({
            "refused": refused.reason,
            "code": e.code(),
            "record": record,
        });
        let path = self.path.with_file_name(REFUSED_FILE);
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(JournalError::file("open", &path))?;
        file.write_all(format!("{line}\n").as_bytes())
            .and_then(|()| file.sync_data())
            .map_err(JournalError::file("write", &path))?;
        let mut rest = self.records.clone();
        rest.remove(i);
        self.rewrite(&rest)?;
        self.records = rest;
        if i < self.replayed {
            self.replayed -= 1;
        }
        Ok(refused)
    }

    /// Drops the written records from the journal once the store answers that everything
    /// committed so far is durable ([`Store::checkpoint`]). Returns how many were dropped.
    pub async fn release_durable(&mut self, store: &Store) -> Result<usize, JournalError> {
        let written = self.written;
        let _held = self.hold()?;
        // Shared with every other journal releasing meanwhile: one checkpoint covers all
        // that was committed before it started.
        let committed_by = self.committed_by.unwrap_or_else(std::time::Instant::now);
        if written == 0
            || !store
                .checkpoint_covering(committed_by)
                .await
                .map_err(JournalError::Checkpoint)?
        {
            return Ok(0);
        }
        self.forget(written)?;
        Ok(written)
    }

    /// Drops the first `done` records from the file and the mirror. All of them (the usual
    /// case): the file is cut to nothing. Some: the rest replaces the file atomically
    /// (temporary file, rename), so a crash leaves the old or the new list. Either way a
    /// crash before this reaches the disk only means a replay, which writes nothing twice.
    ///
    /// The newest learning state among the dropped records stays (at the front, as written)
    /// when the rest holds none: a restart then finds the loop's memory here even while the
    /// database is down, and never mistakes an unreachable database for a new machine.
    fn forget(&mut self, done: usize) -> Result<(), JournalError> {
        let rest = &self.records[done..];
        let keep = if rest.iter().any(|r| matches!(r, Pending::Learning { .. })) {
            None
        } else {
            self.records[..done]
                .iter()
                .rev()
                .find(|r| matches!(r, Pending::Learning { .. }))
                .cloned()
        };
        let next: Vec<Pending> = keep.iter().cloned().chain(rest.iter().cloned()).collect();
        if next.is_empty() {
            let file = std::fs::OpenOptions::new()
                .write(true)
                .open(&self.path)
                .and_then(|f| f.set_len(0).and_then(|()| f.sync_data()));
            file.map_err(JournalError::file("empty journal", &self.path))?;
        } else {
            self.rewrite(&next)?;
        }
        let kept = usize::from(keep.is_some());
        self.records = next;
        self.written = self.written - done + kept;
        self.replayed = self.replayed.saturating_sub(done);
        Ok(())
    }

    /// Replaces the journal file with `records` atomically (temporary file, rename), so a
    /// crash leaves the old or the new list.
    fn rewrite(&self, records: &[Pending]) -> Result<(), JournalError> {
        let dir = self.path.parent().unwrap_or(Path::new("."));
        let mut text = String::new();
        for r in records {
            text.push_str(&self.encode(r)?);
            text.push('\n');
        }
        let replace = JournalError::file("replace journal", &self.path);
        let written = tempfile::Builder::new()
            .prefix(".journal-")
            .tempfile_in(dir)
            .and_then(|mut tmp| {
                tmp.write_all(text.as_bytes())?;
                tmp.as_file().sync_all()?;
                Ok(tmp)
            });
        written
            .and_then(|tmp| tmp.persist(&self.path).map_err(|e| e.error))
            .map_err(replace)?;
        Ok(())
    }
}

/// What the process's group commit has done so far: appends made durable, syncs issued,
/// batches written (for `/metrics`).
pub(crate) fn commit_totals() -> (u64, u64, u64) {
    use std::sync::atomic::Ordering::Relaxed;
    let s = commit::GroupCommit::global().stats();
    (
        s.appends.load(Relaxed),
        s.syncs.load(Relaxed),
        s.batches.load(Relaxed),
    )
}

/// Records written in one transaction at most: a journal that kept records while the
/// database was down writes them in several, so the one writer is never held for long.
const BATCH_RECORDS: usize = 64;

/// The quarantine file beside the journal.
pub(crate) const QUARANTINE_FILE: &str = "journal.quarantine.jsonl";

/// Records the store refused for good, beside the journal: one JSON line each, with the
/// store's reason and code and the record as it was journalled.
pub(crate) const REFUSED_FILE: &str = "journal.refused.jsonl";

/// What a flush did.
#[derive(Debug, Default, PartialEq)]
pub struct Flushed {
    /// Records now in the store.
    pub written: usize,
    /// Records the store refused for good, moved to [`REFUSED_FILE`].
    pub refused: Vec<Refused>,
}

/// A record the store refused for good (see [`Journal::flush`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Refused {
    /// The record's kind, as the journal spells it (`measurement`, `table`, …).
    pub kind: &'static str,
    /// The store's reason.
    pub reason: String,
}

/// A journal line that could not be read back.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Quarantined {
    /// 1-based line number in the journal as it was found.
    pub line: usize,
    pub reason: String,
    pub text: String,
}

#[cfg(test)]
mod tests;
