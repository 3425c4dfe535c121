//! Opening a store: the URL picks the backend; each backend gets a writer pool and a reader
//! pool (see the module doc of `store`), the SQLite file is checked for damage before SQLite
//! opens it, and the schema is brought up to date.

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use sqlx::migrate::MigrateError;
use sqlx::postgres::{PgConnectOptions, PgPoolOptions};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions};
use sqlx::{ConnectOptions, Connection};

use super::error::{Detail as D, connect_error, corrupt};
use super::{POSTGRES_MIGRATOR, Pools, SQLITE_MIGRATOR, Store, StoreError};

/// How long an operation waits for a pooled connection before reporting the store unavailable.
const ACQUIRE_TIMEOUT: Duration = Duration::from_secs(5);

/// SQLite memory map per connection, bytes (256 MiB; the OS shares the pages).
const SQLITE_MMAP_BYTES: u64 = 256 << 20;
/// SQLite page cache per connection, KiB (16 MiB; at most 5 connections).
const SQLITE_CACHE_KIB: u64 = 16 << 10;
/// WAL size (4 KiB pages) at which a committing writer checkpoints by itself. SQLite's
/// default of 1,000 pages put a checkpoint into every ~40th part's commit; the service calls
/// [`Store::checkpoint`] off the per-part path instead, and this larger limit (64 MiB) only
/// bounds the WAL of programs that never do.
const SQLITE_AUTOCHECKPOINT_PAGES: u32 = 16_384;
/// Writer connections on PostgreSQL (one per machine writing at once is plenty).
const PG_WRITERS: u32 = 4;
/// How long a PostgreSQL read may run before the server cancels it ([`StoreError::Busy`]).
const PG_READ_TIMEOUT: &str = "5s";

/// Reads admitted at once: one per core, at least 2 and at most 4. Every admitted read keeps
/// a core busy, and the machine loops need the rest.
fn readers() -> u32 {
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    cores.clamp(2, 4) as u32
}

impl Store {
    /// Opens the store at `url` and brings its schema up to date.
    ///
    /// `sqlite://path/to/file.db` (query options such as `?mode=rwc` allowed) creates the
    /// file and its parent folder when missing; `postgres://user:pass@host:port/db` (or
    /// `postgresql://`) connects to an existing database. Errors never echo the password. A
    /// SQLite file that is not a database, or shorter than its own header says, is refused
    /// with [`StoreError::Corrupt`].
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
            .busy_timeout(ACQUIRE_TIMEOUT)
            .foreign_keys(true)
            // History pages touch rows spread over the file: map it and cache more than the
            // 2 MiB default so a 1,000-row page is served without a syscall per page.
            .pragma("mmap_size", SQLITE_MMAP_BYTES.to_string())
            .pragma("cache_size", format!("-{SQLITE_CACHE_KIB}"))
            // Rows cross from sqlx's SQLite worker thread to the task through a channel: let a
            // whole history page through without the worker waiting on the task.
            .row_buffer_size(1024);
        let path = options.get_filename().to_path_buf();
        let target = path.display().to_string();
        if let Some(parent) = path.parent()
            && !parent.as_os_str().is_empty()
        {
            private_dirs(parent).map_err(|e| StoreError::Unavailable {
                target: target.clone(),
                reason: format!("cannot create folder {}: {}", parent.display(), e.kind()),
                detail: D(e.to_string()),
            })?;
        }
        check_sqlite_file(&path)
            .map_err(|reason| corrupt(&target, reason, format!("{}: {reason}", path.display())))?;
        // Made owner-only before SQLite opens it: SQLite gives the WAL and shared-memory
        // files the database file's mode, and the file holds password hashes.
        private_file(&path).map_err(|e| StoreError::Unavailable {
            target: target.clone(),
            reason: format!("cannot create {}: {}", path.display(), e.kind()),
            detail: D(e.to_string()),
        })?;
        let write_options = options
            .clone()
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(sqlx::sqlite::SqliteSynchronous::Normal)
            .pragma(
                "wal_autocheckpoint",
                SQLITE_AUTOCHECKPOINT_PAGES.to_string(),
            );
        // One writer: SQLite admits one at a time anyway, and a private connection means no
        // reader can ever hold the one the part path needs.
        let write = SqlitePoolOptions::new()
            .max_connections(1)
            .acquire_timeout(ACQUIRE_TIMEOUT)
            .connect_with(write_options)
            .await
            .map_err(|e| connect_error(&target, e))?;
        // The writer has created the file and switched it to WAL (a property of the file):
        // readers then never block it, and only ever run queries.
        let readers = readers();
        let read = SqlitePoolOptions::new()
            .max_connections(readers)
            .acquire_timeout(ACQUIRE_TIMEOUT)
            .connect_lazy_with(options);
        let store = Store::new(Pools::Sqlite { write, read }, readers, target);
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
        let write = PgPoolOptions::new()
            .max_connections(PG_WRITERS)
            .acquire_timeout(ACQUIRE_TIMEOUT)
            .connect_with(options.clone())
            .await
            .map_err(|e| connect_error(&target, e))?;
        let readers = readers();
        let read = PgPoolOptions::new()
            .max_connections(readers)
            .acquire_timeout(ACQUIRE_TIMEOUT)
            .connect_lazy_with(options.options([("statement_timeout", PG_READ_TIMEOUT)]));
        let store = Store::new(Pools::Postgres { write, read }, readers, target);
        store.migrate().await?;
        Ok(store)
    }

    async fn migrate(&self) -> Result<(), StoreError> {
        let migrator = match self.pools {
            Pools::Sqlite { .. } => &SQLITE_MIGRATOR,
            Pools::Postgres { .. } => &POSTGRES_MIGRATOR,
        };
        let result = super::with_write!(self, pool => migrator.run(pool).await);
        result.map_err(|e| self.migrate_error(e))?;
        // Schema version 4 packs the rows written before it; a no-op once done.
        let packed = self.pack_legacy_rows().await?;
        if packed != super::Converted::default() {
            tracing::info!(
                measurements = packed.measurements,
                table_versions = packed.table_versions,
                learning_states = packed.learning_states,
                left_as_they_were = packed.left_as_they_were,
                "history rows packed in place (schema version 4)"
            );
        }
        Ok(())
    }

    fn migrate_error(&self, e: MigrateError) -> StoreError {
        let reason = match e {
            MigrateError::Execute(inner) | MigrateError::ExecuteMigration(inner, _) => {
                // A damaged file or a full disk is found by the first statement that touches
                // it, often a migration's: report that, not a schema problem.
                match self.db_error("applying the schema")(inner) {
                    StoreError::Backend { detail, .. } => {
                        return StoreError::Migration {
                            reason: "could not apply the schema".to_owned(),
                            detail,
                        };
                    }
                    other => return other,
                }
            }
            MigrateError::VersionMissing(v) => {
                format!("database has migration {v} that this camloop does not know")
            }
            MigrateError::VersionMismatch(v) => {
                format!("migration {v} differs from the one applied to the database")
            }
            _ => "could not apply the schema".to_owned(),
        };
        StoreError::Migration {
            reason,
            detail: D(e.to_string()),
        }
    }
}

/// Checks a SQLite file's header against its length before SQLite opens it: SQLite reads
/// missing pages of a cut-off file as zeros and only fails on a later query, when the damage
/// has been taken for an empty table. A missing or empty file is fine (a new database).
fn check_sqlite_file(path: &Path) -> Result<(), &'static str> {
    use std::io::Read;
    let Ok(mut file) = std::fs::File::open(path) else {
        return Ok(()); // missing or unreadable: SQLite creates it or reports why not
    };
    let len = file.metadata().map_or(0, |m| m.len());
    let mut header = [0u8; 100];
    let read = file.read(&mut header).unwrap_or(0);
    let wal = path.with_extension(match path.extension() {
        Some(ext) => format!("{}-wal", ext.to_string_lossy()),
        None => "-wal".to_owned(),
    });
    let wal_len = std::fs::metadata(wal).map_or(0, |m| m.len());
    sqlite_header_problem(&header[..read], len, wal_len)
}

/// The pure part of [`check_sqlite_file`]: `header` is the file's first (up to) 100 bytes,
/// `len` its length, `wal_len` the length of its write-ahead log (0 when none).
pub(crate) fn sqlite_header_problem(
    header: &[u8],
    len: u64,
    wal_len: u64,
) -> Result<(), &'static str> {
    const MAGIC: &[u8; 16] = b"SQLite format 3\0";
    if len == 0 {
        return Ok(());
    }
    if header.len() < 100 || &header[..16] != MAGIC {
        return Err("file is not a database");
    }
    let be32 = |at: usize| {
        u32::from_be_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]])
    };
    let page_size = match u16::from_be_bytes([header[16], header[17]]) {
        1 => 65_536,
        n => u64::from(n),
    };
    // The in-header page count is valid only when the change counter matches the
    // version-valid-for number; pages not yet checkpointed from a WAL may also be missing.
    let pages = u64::from(be32(28));
    let valid = pages != 0 && be32(24) == be32(92);
    if valid && wal_len == 0 && len < pages * page_size {
        return Err("file is shorter than its header says: it was cut off");
    }
    Ok(())
}

/// Creates `dir` and its missing parents, each new one 0700 (on Unix).
fn private_dirs(dir: &std::path::Path) -> std::io::Result<()> {
    let mut builder = std::fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::DirBuilderExt;
        builder.mode(0o700);
    }
    builder.create(dir)
}

/// Creates the empty file `path` 0600 when it does not exist (on Unix); leaves one that
/// does as it is.
fn private_file(path: &std::path::Path) -> std::io::Result<()> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    match options.open(path) {
        Ok(_) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(e),
    }
}
