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
use std::sync::OnceLock;
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
}

impl StoreWriter {
    /// The process's writer, started on first use.
    pub(super) fn global() -> &'static StoreWriter {
        static WRITER: OnceLock<StoreWriter> = OnceLock::new();
        WRITER.get_or_init(StoreWriter::start)
    }

    fn start() -> StoreWriter {
        let (tx, rx) = mpsc::unbounded_channel();
        let spawned = std::thread::Builder::new()
            .name("camloop-store".into())
            .spawn(move || {
                let runtime = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build();
                match runtime {
                    Ok(runtime) => runtime.block_on(run(rx)),
                    // Without it every write answers "stopped": records stay in the journals.
                    Err(e) => {
                        tracing::error!(error = %e, "the store writer cannot start its runtime")
                    }
                }
            });
        if let Err(e) = spawned {
            tracing::error!(error = %e, "the store writer thread cannot start");
        }
        StoreWriter { tx }
    }

    /// Writes `records` (one journal's, in its order) to `store` in the writer's next batch;
    /// returns once that batch has committed (or failed: then none of them is written).
    pub(super) async fn write(
        &self,
        store: &Store,
        records: Vec<Pending>,
    ) -> Result<(), StoreError> {
        let (done, answer) = oneshot::channel();
        let request = Request {
            store: store.clone(),
            records,
            done,
        };
        if self.tx.send(request).is_err() {
            return Err(stopped(store));
        }
        answer.await.unwrap_or_else(|_| Err(stopped(store)))
    }
}

fn stopped(store: &Store) -> StoreError {
    StoreError::unavailable(store.target(), "the store writer thread is not running")
}

/// The writer's loop: a batch is what is queued when the previous one is done, up to
/// [`BATCH_RECORDS`] records, for one store.
async fn run(mut rx: mpsc::UnboundedReceiver<Request>) {
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
        write_group(group).await;
    }
}

/// Writes a group in one transaction; when that fails, each request alone.
async fn write_group(group: Vec<Request>) {
    if group.len() > 1 && write_all(&group).await.is_ok() {
        for r in group {
            let _ = r.done.send(Ok(()));
        }
        return;
    }
    for r in group {
        let result = write_all(std::slice::from_ref(&r)).await;
        let _ = r.done.send(result);
    }
}

async fn write_all(requests: &[Request]) -> Result<(), StoreError> {
    let Some(store) = requests.first().map(|r| &r.store) else {
        return Ok(());
    };
    let mut batch = store.begin_batch().await?;
    for record in requests.iter().flat_map(|r| &r.records) {
        apply_in(&mut batch, record).await?;
    }
    batch.commit().await
}
