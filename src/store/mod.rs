//! The history store: machines, recipe snapshots, measurements, table versions, dressings,
//! events and learning state, in SQLite (embedded default) or PostgreSQL (sites with many
//! machines), chosen by the database URL.
//!
//! [`Store`] is an enum over the two sqlx pools rather than a trait with two impls: the set
//! of backends is closed, the SQL is written once with `$n` placeholders that both accept,
//! and the [`with_pool!`] macro expands each method body once per backend, so there is no
//! boxing, no `async_trait` and no second copy of each query to drift apart. A backend that
//! needs different SQL matches on the variant explicitly.
//!
//! Invariant: history is appended. The only UPDATE is retention
//! ([`Store::prune_raw_older_than`]) setting a raw blob to NULL; table-version status
//! changes are appended rows; the newest learning-state row wins.

mod codec;
mod error;
mod log;
mod measurements;
mod tables;
mod types;

use std::borrow::Cow;
use std::str::FromStr;
use std::time::Duration;

use sqlx::migrate::{Migration, MigrationType, Migrator};
use sqlx::postgres::{PgConnectOptions, PgPool, PgPoolOptions};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions};
use sqlx::{ConnectOptions, Connection};

pub use codec::{UNITS_PER_MM, decode_lifts_mm, encode_lifts_mm, sha256_hex};
pub use error::{Detail, StoreError};
pub use types::*;

use error::{Detail as D, connect_error};

/// How long an operation waits for a pooled connection before reporting the store unavailable.
const ACQUIRE_TIMEOUT: Duration = Duration::from_secs(5);

/// SQLite memory map per connection, bytes (256 MiB; the OS shares the pages).
const SQLITE_MMAP_BYTES: u64 = 256 << 20;
/// SQLite page cache per connection, KiB (16 MiB; at most 4 connections).
const SQLITE_CACHE_KIB: u64 = 16 << 10;
/// WAL size (4 KiB pages) at which a committing writer checkpoints by itself. SQLite's
/// default of 1,000 pages put a checkpoint into every ~40th part's commit; the service calls
/// [`Store::checkpoint`] off the per-part path instead, and this larger limit (64 MiB) only
/// bounds the WAL of programs that never do.
const SQLITE_AUTOCHECKPOINT_PAGES: u32 = 16_384;

/// Migrations embedded in the binary: (version, description, SQLite SQL, PostgreSQL SQL).
/// A test checks that this list and both folders under `migrations/` hold the same versions.
pub const MIGRATIONS: &[(i64, &str, &str, &str)] = &[(
    1,
    "history",
    include_str!("../../migrations/sqlite/0001_history.sql"),
    include_str!("../../migrations/postgres/0001_history.sql"),
)];

/// The history store. Cheap to clone (pools are shared handles).
#[derive(Debug, Clone)]
pub enum Store {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

/// Runs `$body` with `$pool` bound to the backend's pool; the body is compiled once per
/// backend so sqlx infers the database type in each arm.
macro_rules! with_pool {
    ($store:expr, $pool:ident => $body:expr) => {
        match $store {
            $crate::store::Store::Sqlite($pool) => $body,
            $crate::store::Store::Postgres($pool) => $body,
        }
    };
}
pub(crate) use with_pool;

/// Reads a column or returns a `StoreError::Backend` for `$op`.
macro_rules! col {
    ($row:expr, $name:literal, $op:literal) => {
        sqlx::Row::try_get($row, $name).map_err($crate::store::error::db_error($op))?
    };
}
pub(crate) use col;

impl Store {
    /// Opens the store at `url` and brings its schema up to date.
    ///
    /// `sqlite://path/to/file.db` (query options such as `?mode=rwc` allowed) creates the
    /// file and its parent folder when missing; `postgres://user:pass@host:port/db` (or
    /// `postgresql://`) connects to an existing database. Errors never echo the password.
    pub async fn connect(url: &str) -> Result<Store, StoreError> {
        if url.starts_with("sqlite:") {
            Self::connect_sqlite(url).await
        } else if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            Self::connect_postgres(url).await
        } else {
            let scheme = url.split_once(':').map_or("", |(s, _)| s);
            Err(StoreError::invalid(
                "database url",
                format!("scheme `{scheme}` is not sqlite: or postgres://"),
            ))
        }
    }

    async fn connect_sqlite(url: &str) -> Result<Store, StoreError> {
        let options = SqliteConnectOptions::from_str(url)
            .map_err(|e| StoreError::invalid("database url", format!("not a sqlite url: {e}")))?
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(sqlx::sqlite::SqliteSynchronous::Normal)
            .busy_timeout(ACQUIRE_TIMEOUT)
            .foreign_keys(true)
            // History pages touch rows spread over the file: map it and cache more than the
            // 2 MiB default so a 1,000-row page is served without a syscall per page.
            .pragma("mmap_size", SQLITE_MMAP_BYTES.to_string())
            .pragma("cache_size", format!("-{SQLITE_CACHE_KIB}"))
            .pragma(
                "wal_autocheckpoint",
                SQLITE_AUTOCHECKPOINT_PAGES.to_string(),
            )
            // Rows cross from sqlx's SQLite worker thread to the task through a channel: let a
            // whole history page through without the worker waiting on the task.
            .row_buffer_size(1024);
        let path = options.get_filename().to_path_buf();
        let target = path.display().to_string();
        if let Some(parent) = path.parent()
            && !parent.as_os_str().is_empty()
        {
            std::fs::create_dir_all(parent).map_err(|e| StoreError::Unavailable {
                target: target.clone(),
                reason: format!("cannot create folder {}: {}", parent.display(), e.kind()),
                detail: D(e.to_string()),
            })?;
        }
        let pool = SqlitePoolOptions::new()
            .max_connections(4)
            .acquire_timeout(ACQUIRE_TIMEOUT)
            .connect_with(options)
            .await
            .map_err(|e| connect_error(&target, e))?;
        let store = Store::Sqlite(pool);
        store.migrate().await?;
        Ok(store)
    }

    async fn connect_postgres(url: &str) -> Result<Store, StoreError> {
        let options = PgConnectOptions::from_str(url).map_err(|_| {
            StoreError::invalid("database url", "not a valid postgres:// url".to_owned())
        })?;
        let target = format!(
            "{}:{}/{}",
            options.get_host(),
            options.get_port(),
            options.get_database().unwrap_or("")
        );
        // One direct attempt first: the pool retries refused connections until its timeout,
        // which would turn "connection refused" into a vaguer "timed out".
        let probe = options
            .connect()
            .await
            .map_err(|e| connect_error(&target, e))?;
        let _ = probe.close().await;
        let pool = PgPoolOptions::new()
            .max_connections(8)
            .acquire_timeout(ACQUIRE_TIMEOUT)
            .connect_with(options)
            .await
            .map_err(|e| connect_error(&target, e))?;
        let store = Store::Postgres(pool);
        store.migrate().await?;
        Ok(store)
    }

    /// Backend name for logs: `sqlite` or `postgres`.
    pub fn backend(&self) -> &'static str {
        match self {
            Store::Sqlite(_) => "sqlite",
            Store::Postgres(_) => "postgres",
        }
    }

    /// Makes every transaction committed before the call durable and says whether that
    /// succeeded. On SQLite (WAL, `synchronous = NORMAL`) a commit reaches the disk only at a
    /// checkpoint: this runs a passive one (it waits for no reader or writer) and answers
    /// `true` when it copied the whole log, which SQLite flushes to disk first. The service
    /// runs it between parts, off the per-part path, and keeps journal records until it
    /// answers `true`. On PostgreSQL every commit is already durable: always `true`.
    pub async fn checkpoint(&self) -> Result<bool, StoreError> {
        match self {
            Store::Sqlite(pool) => {
                let (busy, log, done): (i64, i64, i64) =
                    sqlx::query_as("PRAGMA wal_checkpoint(PASSIVE)")
                        .fetch_one(pool)
                        .await
                        .map_err(error::db_error("checkpointing the write-ahead log"))?;
                Ok(busy == 0 && log >= 0 && done == log)
            }
            Store::Postgres(_) => Ok(true),
        }
    }

    /// Closes the pool; later calls fail with [`StoreError::Unavailable`].
    pub async fn close(&self) {
        with_pool!(self, pool => pool.close().await)
    }

    async fn migrate(&self) -> Result<(), StoreError> {
        let sqlite = matches!(self, Store::Sqlite(_));
        let migrations = MIGRATIONS
            .iter()
            .map(|&(version, description, sqlite_sql, pg_sql)| {
                Migration::new(
                    version,
                    Cow::Borrowed(description),
                    MigrationType::Simple,
                    Cow::Borrowed(if sqlite { sqlite_sql } else { pg_sql }),
                    false,
                )
            })
            .collect::<Vec<_>>();
        let migrator = Migrator {
            migrations: Cow::Owned(migrations),
            ignore_missing: false,
            locking: true,
            no_tx: false,
        };
        let result = with_pool!(self, pool => migrator.run(pool).await);
        result.map_err(|e| StoreError::Migration {
            reason: match &e {
                sqlx::migrate::MigrateError::VersionMissing(v) => {
                    format!("database has migration {v} that this camloop does not know")
                }
                sqlx::migrate::MigrateError::VersionMismatch(v) => {
                    format!("migration {v} differs from the one applied to the database")
                }
                _ => "could not apply the schema".to_owned(),
            },
            detail: D(e.to_string()),
        })
    }
}
