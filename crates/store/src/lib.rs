//! The history store: machines, recipe snapshots, measurements, table versions, dressings,
//! events and learning state, in SQLite (embedded default) or PostgreSQL (sites with many
//! machines), chosen by the database URL.
//!
//! [`Store`] is an enum over the two sqlx pools rather than a trait with two impls: the set
//! of backends is closed, the SQL is written once with `$n` placeholders that both accept,
//! and the `with_write!` / `with_read!` macros expand each method body once per backend, so there is no
//! boxing, no `async_trait` and no second copy of each query to drift apart. A backend that
//! needs different SQL matches on the variant explicitly.
//!
//! Writers and readers never share a connection. Every insert, save, status change,
//! retention and checkpoint goes through the writer pool (one connection on SQLite, which
//! serialises writes as SQLite does anyway); queries go through a separate reader pool behind
//! a semaphore that admits a bounded number at a time and turns a reader away with
//! [`StoreError::Busy`] when it waited too long. So a burst of history requests can slow
//! other history requests, but never makes a part wait for a connection. On PostgreSQL the
//! readers also run under a statement timeout.
//!
//! Users, API tokens and the chained audit trail are in `users.rs` and `audit.rs`.
//!
//! Invariant: history is appended. The only UPDATE is retention
//! ([`Store::prune_raw_older_than`]) setting a raw blob to NULL; table-version status
//! changes are appended rows; the newest learning-state row wins.

// No unwrap() in shipped code: bad input must become an error, not a panic (tests may).
#![warn(clippy::unwrap_used)]

mod audit;
mod audit_key;
mod batch;
mod chain;
mod codec;
mod connect;
mod convert;
mod error;
mod identity;
mod log;
mod measurements;
mod overview;
mod pack;
mod pack_numbers;
mod pack_report;
mod status;
mod tables;
mod types;
pub mod unix_ms;
mod users;
mod views;

use std::sync::Arc;
use std::time::Duration;

use sqlx::postgres::PgPool;
use sqlx::sqlite::SqlitePool;
use tokio::sync::{Semaphore, SemaphorePermit};

pub use audit::{AuditCheck, AuditEntry, AuditRow, HeadCheck, MAX_AUDIT_PAGE};
pub use audit_key::{AuditHead, AuditKey, AuditKeyError};
pub use batch::Batch;
pub use codec::{encode_lifts_mm, sha256_hex};
pub use convert::Converted;
pub use error::{Detail, StoreError};
pub use identity::StoreIdentity;
pub use overview::{FeatureOverview, OverviewChanges, OverviewPart};
pub use pack_report::REPORT_STEP;
pub use types::*;
pub use users::{NewToken, TokenGrant, TokenId, TokenInfo, User, UserId};
pub use views::{AckOutcome, EventAck, TableVersionHead};

/// The SQLite migrations, embedded from `migrations/sqlite` by sqlx (`build.rs` rebuilds
/// when a file there changes). sqlx records each with a SHA-384 checksum of its SQL and
/// refuses a changed one; it takes the database's migration lock while it runs.
pub static SQLITE_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("migrations/sqlite");

/// The PostgreSQL migrations, from `migrations/postgres`: the same versions (a test holds
/// the two folders to the same versions and tables).
pub static POSTGRES_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("migrations/postgres");

/// How long a read waits for its turn before it is refused with [`StoreError::Busy`].
pub const READ_WAIT: Duration = Duration::from_secs(2);

/// The history store. Cheap to clone (pools and the read gate are shared handles).
#[derive(Debug, Clone)]
pub struct Store {
    pools: Pools,
    /// Admits at most as many reads as the reader pool has connections.
    reads: Arc<Semaphore>,
    /// The database without credentials, for messages: a file path or `host:port/db`.
    target: Arc<str>,
    /// Plain texts of the newest packed rows, for packing the next ones.
    chains: Arc<chain::ChainCache>,
    /// When the newest checkpoint started and whether it was complete, held while one runs:
    /// callers share a checkpoint (see [`Store::checkpoint_covering`]).
    checkpoints: Arc<tokio::sync::Mutex<Option<(std::time::Instant, bool)>>>,
}

#[derive(Debug, Clone)]
enum Pools {
    Sqlite { write: SqlitePool, read: SqlitePool },
    Postgres { write: PgPool, read: PgPool },
}

/// The writer pool of a store, for tools and tests that run their own SQL (seeding a
/// benchmark, counting rows). The service never needs it.
#[derive(Debug, Clone, Copy)]
pub enum RawPool<'a> {
    Sqlite(&'a SqlitePool),
    Postgres(&'a PgPool),
}

/// Runs `$body` with `$pool` bound to the store's writer pool; the body is compiled once per
/// backend so sqlx infers the database type in each arm.
macro_rules! with_write {
    ($store:expr, $pool:ident => $body:expr) => {
        match &$store.pools {
            $crate::Pools::Sqlite { write: $pool, .. } => $body,
            $crate::Pools::Postgres { write: $pool, .. } => $body,
        }
    };
}
pub(crate) use with_write;

/// Starts a write transaction on the writer pool.
///
/// On SQLite it takes the write lock at `BEGIN` (`BEGIN IMMEDIATE`). A deferred transaction
/// that reads and then writes cannot wait for another process's writer: SQLite answers
/// `SQLITE_BUSY` at once rather than risk a deadlock. So `camloop user add`, which reads the
/// audit chain's newest row and then appends, failed beside a running service under load; an
/// immediate transaction waits the busy timeout like any writer.
pub(crate) trait BeginWrite {
    type Db: sqlx::Database;
    async fn begin_write(&self) -> Result<sqlx::Transaction<'static, Self::Db>, sqlx::Error>;
}

impl BeginWrite for SqlitePool {
    type Db = sqlx::Sqlite;
    async fn begin_write(&self) -> Result<sqlx::Transaction<'static, sqlx::Sqlite>, sqlx::Error> {
        match self.begin_with("BEGIN IMMEDIATE").await {
            // A COMMIT refused by a full disk makes SQLite roll the transaction back itself;
            // the driver's ROLLBACK then fails, and it goes on counting a transaction that
            // is not there. Its own `BEGIN` would nest a savepoint, but a custom one is
            // refused for ever: the writer would never write again once space is back.
            // Closing that connection lets the pool open a clean one.
            Err(sqlx::Error::InvalidSavePointStatement) => {
                tracing::warn!("database writer left inside a failed transaction: reopened");
                self.acquire().await?.close().await?;
                self.begin_with("BEGIN IMMEDIATE").await
            }
            other => other,
        }
    }
}

impl BeginWrite for PgPool {
    type Db = sqlx::Postgres;
    async fn begin_write(&self) -> Result<sqlx::Transaction<'static, sqlx::Postgres>, sqlx::Error> {
        self.begin().await
    }
}

/// Runs `$body` with `$pool` bound to the store's reader pool once the read gate admits it;
/// returns [`StoreError::Busy`] from the enclosing function when it waited [`READ_WAIT`].
macro_rules! with_read {
    ($store:expr, $pool:ident => $body:expr) => {{
        let _turn = $store.read_turn().await?;
        match &$store.pools {
            $crate::Pools::Sqlite { read: $pool, .. } => $body,
            $crate::Pools::Postgres { read: $pool, .. } => $body,
        }
    }};
}
pub(crate) use with_read;

/// Reads a column or returns a `StoreError::Backend` for `$op`.
macro_rules! col {
    ($row:expr, $name:literal, $op:literal) => {
        sqlx::Row::try_get($row, $name).map_err($crate::error::db_error($op))?
    };
}
pub(crate) use col;

/// Reads an integer-millisecond column as an instant (see [`unix_ms::instant`]).
macro_rules! at_col {
    ($row:expr, $name:literal, $op:literal) => {
        $crate::unix_ms::instant($crate::col!($row, $name, $op), $name)?
    };
}
pub(crate) use at_col;

impl Store {
    fn new(pools: Pools, readers: u32, target: String) -> Self {
        Store {
            pools,
            reads: Arc::new(Semaphore::new(readers as usize)),
            target: target.into(),
            chains: Arc::default(),
            checkpoints: Arc::default(),
        }
    }

    /// Backend name for logs: `sqlite` or `postgres`.
    pub fn backend(&self) -> &'static str {
        match self.pools {
            Pools::Sqlite { .. } => "sqlite",
            Pools::Postgres { .. } => "postgres",
        }
    }

    /// The database without credentials: the SQLite file path or PostgreSQL's `host:port/db`.
    pub fn target(&self) -> &str {
        &self.target
    }

    /// The writer pool, for tools and tests that run their own SQL.
    pub fn raw_pool(&self) -> RawPool<'_> {
        match &self.pools {
            Pools::Sqlite { write, .. } => RawPool::Sqlite(write),
            Pools::Postgres { write, .. } => RawPool::Postgres(write),
        }
    }

    /// Maps a driver error met during `operation`, naming this store's database.
    fn db_error(&self, operation: &'static str) -> impl Fn(sqlx::Error) -> StoreError + '_ {
        error::db_error_at(&self.target, operation)
    }

    /// Waits for a turn to read, at most [`READ_WAIT`].
    async fn read_turn(&self) -> Result<SemaphorePermit<'_>, StoreError> {
        match tokio::time::timeout(READ_WAIT, self.reads.acquire()).await {
            Ok(Ok(permit)) => Ok(permit),
            Ok(Err(_closed)) => Err(StoreError::Unavailable {
                target: self.target.to_string(),
                reason: "connection pool closed".to_owned(),
                detail: Detail("the read gate is closed".to_owned()),
            }),
            Err(_elapsed) => Err(StoreError::Busy {
                target: self.target.to_string(),
                reason: format!(
                    "{} reads already running, this one waited {} ms for a turn",
                    self.reads_running(),
                    READ_WAIT.as_millis()
                ),
            }),
        }
    }

    fn reads_running(&self) -> usize {
        let readers = match &self.pools {
            Pools::Sqlite { read, .. } => read.options().get_max_connections(),
            Pools::Postgres { read, .. } => read.options().get_max_connections(),
        };
        (readers as usize).saturating_sub(self.reads.available_permits())
    }

    /// Makes every transaction committed before the call durable and says whether that
    /// succeeded. On SQLite (WAL, `synchronous = NORMAL`) a commit reaches the disk only at a
    /// checkpoint: this runs a passive one (it waits for no reader or writer) and answers
    /// `true` when it copied the whole log, which SQLite flushes to disk first. The service
    /// runs it between parts, off the per-part path, and keeps journal records until it
    /// answers `true`. On PostgreSQL every commit is already durable: always `true`.
    pub async fn checkpoint(&self) -> Result<bool, StoreError> {
        let started = std::time::Instant::now();
        let done = self.checkpoint_now().await?;
        *self.checkpoints.lock().await = Some((started, done));
        Ok(done)
    }

    /// [`Self::checkpoint`] for a caller whose transactions were all committed by
    /// `committed_by`: a complete checkpoint that started after that has made them durable
    /// already, so it answers `true` without another. Callers wait for a checkpoint under
    /// way rather than run their own beside it: a plant's journals, each releasing every
    /// 2 s, share one checkpoint instead of queueing hundreds a second on the one writer.
    pub async fn checkpoint_covering(
        &self,
        committed_by: std::time::Instant,
    ) -> Result<bool, StoreError> {
        let mut last = self.checkpoints.lock().await;
        if let Some((started, true)) = *last
            && started >= committed_by
        {
            return Ok(true);
        }
        let started = std::time::Instant::now();
        let done = self.checkpoint_now().await?;
        *last = Some((started, done));
        Ok(done)
    }

    async fn checkpoint_now(&self) -> Result<bool, StoreError> {
        match &self.pools {
            Pools::Sqlite { write, .. } => {
                let (busy, log, done): (i64, i64, i64) =
                    sqlx::query_as("PRAGMA wal_checkpoint(PASSIVE)")
                        .fetch_one(write)
                        .await
                        .map_err(self.db_error("checkpointing the write-ahead log"))?;
                Ok(busy == 0 && log >= 0 && done == log)
            }
            Pools::Postgres { .. } => Ok(true),
        }
    }

    /// Whether the database answers now: one `SELECT 1` on a reading connection (for the
    /// service's health; a pool holds connections that look open after the server went).
    pub async fn ping(&self) -> Result<(), StoreError> {
        match &self.pools {
            Pools::Sqlite { read, .. } => sqlx::query("SELECT 1").execute(read).await.map(drop),
            Pools::Postgres { read, .. } => sqlx::query("SELECT 1").execute(read).await.map(drop),
        }
        .map_err(self.db_error("checking that the database answers"))
    }

    /// Closes the pools; later calls fail with [`StoreError::Unavailable`].
    pub async fn close(&self) {
        self.reads.close();
        match &self.pools {
            Pools::Sqlite { write, read } => {
                read.close().await;
                // Leaves a file that holds everything, with an empty log, whenever the last
                // connection's own checkpoint would finish (best effort: a failure leaves the
                // log, which SQLite folds in at the next open).
                let _ = sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                    .execute(write)
                    .await;
                write.close().await;
            }
            Pools::Postgres { write, read } => {
                read.close().await;
                write.close().await;
            }
        }
    }
}
