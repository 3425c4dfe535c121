//! The store's group commit: one thread of its own writes every journal's new records to
//! the store, taking whatever is queued (records of many features and machines) into one
//! transaction ([`crate::store::Batch`]), and answers each journal once that transaction has
//! committed.
//!
//! Why a thread of its own: on SQLite there is one writer connection, held from `BEGIN` to
//! `COMMIT`. When each machine ran its own transaction, every statement's answer had to wake
//! that machine's thread, one of hundreds waiting for a core at plant scale, and the writer
//! sat idle, held, in between: measured at 200 machines, its thread was idle while 200
//! machine threads queued for it. Here the statements of a batch follow each other on one
//! warm thread, and a plant pays one commit per batch rather than one per record.
//!
//! Nothing is lost or reordered: a journal hands over its records in its order and waits
//! for the answer before it hands over more, and a batch applies each journal's records in
//! that order. A batch that fails is rolled back whole; each journal's records are then
//! tried alone, so one journal's bad record fails only that journal's write (which then
//! finds the record one at a time, as before).

use super::Pending;
use super::record::apply_in;
use crate::store::{Store, StoreError};
use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::{Arc, OnceLock};
use tokio::sync::{mpsc, oneshot};

/// Records one batch takes at most: a backlog (the database was down) is written in several,
/// so the one writer connection is never held for long.
const BATCH_RECORDS: usize = 256;

/// One journal's records waiting for a batch.
struct Request {
    store: Store,
    records: Vec<Pending>,
    done: oneshot::Sender<Result<(), StoreError>>,
}

/// The way to the writer thread.
pub(super) struct StoreWriter {
    tx: mpsc::UnboundedSender<Request>,
    stats: Arc<WriterStats>,
}

/// What the writer has done (for tests and the metrics).
#[derive(Debug, Default)]
pub(crate) struct WriterStats {
    /// Transactions committed.
    pub batches: AtomicU64,
    /// Records in them.
    pub records: AtomicU64,
    /// Groups that failed and were tried one journal at a time.
    pub split: AtomicU64,
}

impl StoreWriter {
    /// The process's writer, started on first use.
    pub(super) fn global() -> &'static StoreWriter {
        static WRITER: OnceLock<StoreWriter> = OnceLock::new();
        WRITER.get_or_init(|| StoreWriter::start(None))
    }

    /// Starts a writer thread. With `held`, the thread waits for that channel to close or
    /// send before its first batch (a test queues a whole group first).
    fn start(held: Option<std::sync::mpsc::Receiver<()>>) -> StoreWriter {
        let (tx, rx) = mpsc::unbounded_channel();
        let stats = Arc::new(WriterStats::default());
        let thread_stats = stats.clone();
        let spawned = std::thread::Builder::new()
            .name("camloop-store".into())
            .spawn(move || {
                if let Some(held) = held {
                    let _ = held.recv();
                }
                let runtime = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build();
                match runtime {
                    Ok(runtime) => runtime.block_on(run(rx, &thread_stats)),
                    // Without it every write answers "stopped": records stay in the journals.
                    Err(e) => {
                        tracing::error!(error = %e, "the store writer cannot start its runtime")
                    }
                }
            });
        if let Err(e) = spawned {
            tracing::error!(error = %e, "the store writer thread cannot start");
        }
        StoreWriter { tx, stats }
    }

    /// Writes `records` (one journal's, in its order) to `store` in the writer's next batch;
    /// returns once that batch has committed (or failed: then none of them is written).
    pub(super) async fn write(
        &self,
        store: &Store,
        records: Vec<Pending>,
    ) -> Result<(), StoreError> {
        let answer = self.submit(store, records);
        answer.await.unwrap_or_else(|_| Err(stopped(store)))
    }

    fn submit(
        &self,
        store: &Store,
        records: Vec<Pending>,
    ) -> oneshot::Receiver<Result<(), StoreError>> {
        let (done, answer) = oneshot::channel();
        let request = Request {
            store: store.clone(),
            records,
            done,
        };
        if let Err(mpsc::error::SendError(r)) = self.tx.send(request) {
            let _ = r.done.send(Err(stopped(store)));
        }
        answer
    }

    pub(crate) fn stats(&self) -> &WriterStats {
        &self.stats
    }
}

/// What the process's store writer has done so far: (batches, records) committed.
pub(crate) fn totals() -> (u64, u64) {
    let s = StoreWriter::global().stats();
    (s.batches.load(Relaxed), s.records.load(Relaxed))
}

fn stopped(store: &Store) -> StoreError {
    StoreError::unavailable(store.target(), "the store writer thread is not running")
}

/// The writer's loop: a batch is what is queued when the previous one is done, up to
/// [`BATCH_RECORDS`] records, for one store.
async fn run(mut rx: mpsc::UnboundedReceiver<Request>, stats: &WriterStats) {
    let mut next: Option<Request> = None;
    loop {
        let first = match next.take() {
            Some(r) => r,
            None => match rx.recv().await {
                Some(r) => r,
                None => return,
            },
        };
        let mut records = first.records.len();
        let mut group = vec![first];
        while records < BATCH_RECORDS {
            match rx.try_recv() {
                // Another store (a test's, a reconnected database): in a batch of its own.
                Ok(r) if r.store.target() != group[0].store.target() => {
                    next = Some(r);
                    break;
                }
                Ok(r) => {
                    records += r.records.len();
                    group.push(r);
                }
                Err(_) => break,
            }
        }
        write_group(group, stats).await;
    }
}

/// Writes a group in one transaction; when that fails, each request alone.
async fn write_group(group: Vec<Request>, stats: &WriterStats) {
    if group.len() > 1 {
        if write_all(&group, stats).await.is_ok() {
            for r in group {
                let _ = r.done.send(Ok(()));
            }
            return;
        }
        stats.split.fetch_add(1, Relaxed);
    }
    for r in group {
        let result = write_all(std::slice::from_ref(&r), stats).await;
        let _ = r.done.send(result);
    }
}

async fn write_all(requests: &[Request], stats: &WriterStats) -> Result<(), StoreError> {
    let Some(store) = requests.first().map(|r| &r.store) else {
        return Ok(());
    };
    let mut batch = store.begin_batch().await?;
    let mut records = 0;
    for record in requests.iter().flat_map(|r| &r.records) {
        apply_in(&mut batch, record).await?;
        records += 1;
    }
    batch.commit().await?;
    // Counted before any journal hears its answer, so a reader woken by it sees the batch.
    stats.batches.fetch_add(1, Relaxed);
    stats.records.fetch_add(records, Relaxed);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{EventFilter, EventLevel, VersionStatus};

    fn event(machine: &str, at_ms: i64) -> Pending {
        Pending::Event {
            machine: machine.parse().unwrap(),
            at: jiff::Timestamp::from_millisecond(at_ms).unwrap(),
            level: EventLevel::Info,
            kind: super::super::EventKind::LearningHeld,
            message: format!("held at {at_ms}"),
        }
    }

    async fn events(store: &Store, machine: &str) -> Vec<i64> {
        let filter = EventFilter {
            machine: Some(machine.parse().unwrap()),
            limit: 100,
            ..Default::default()
        };
        let mut at: Vec<i64> = store
            .events(&filter)
            .await
            .unwrap()
            .iter()
            .map(|e| e.at.as_millisecond())
            .collect();
        at.sort_unstable();
        at
    }

    /// Records of several machines queued together go to the store in one transaction,
    /// each machine's in its order; a group with a record the store refuses is tried one
    /// journal at a time, so only that journal's write fails.
    #[tokio::test]
    async fn journals_queued_together_share_one_transaction() {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}/w.db?mode=rwc", dir.path().display());
        let store = Store::connect(&url).await.unwrap();
        let (release, held) = std::sync::mpsc::channel();
        let writer = StoreWriter::start(Some(held));
        let answers: Vec<_> = ["M1", "M2", "M3"]
            .iter()
            .map(|m| writer.submit(&store, vec![event(m, 1_000), event(m, 2_000)]))
            .collect();
        release.send(()).unwrap();
        for a in answers {
            a.await.unwrap().unwrap();
        }
        let stats = writer.stats();
        assert_eq!(stats.batches.load(Relaxed), 1);
        assert_eq!(stats.records.load(Relaxed), 6);
        for m in ["M1", "M2", "M3"] {
            assert_eq!(events(&store, m).await, vec![1_000, 2_000], "{m}");
        }

        // A status of a version the store never had is refused (not found): its journal's
        // write fails, the other journal's records are written all the same.
        let (release, held) = std::sync::mpsc::channel();
        let writer = StoreWriter::start(Some(held));
        let bad = Pending::VersionStatus {
            machine: "M4".parse().unwrap(),
            lobe: "IN1".parse().unwrap(),
            version: crate::core::ids::TableVersion::new(9).unwrap(),
            status: VersionStatus::Refused {
                reason: "no such version".into(),
            },
            at: jiff::Timestamp::from_millisecond(3_000).unwrap(),
        };
        let failing = writer.submit(&store, vec![event("M4", 3_000), bad]);
        let good = writer.submit(&store, vec![event("M5", 3_000)]);
        release.send(()).unwrap();
        assert!(matches!(
            failing.await.unwrap(),
            Err(StoreError::NotFound { .. })
        ));
        good.await.unwrap().unwrap();
        assert_eq!(writer.stats().split.load(Relaxed), 1);
        assert_eq!(events(&store, "M4").await, Vec::<i64>::new());
        assert_eq!(events(&store, "M5").await, vec![3_000]);
    }
}
