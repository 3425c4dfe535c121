//! [`StoreError`]: what can go wrong with the history store, with stable codes and messages
//! that never carry SQL text or credentials.

use std::fmt;

/// Backend detail kept for logs (driver message, SQL error text), never shown by `Display`.
///
/// Read it with [`StoreError::detail`] and log it separately from the user-facing message.
#[derive(Clone, PartialEq, Eq)]
pub struct Detail(pub(crate) String);

impl fmt::Debug for Detail {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Errors of the history store. `Display` is safe to show to an operator or an API client;
/// [`StoreError::code`] is a stable machine-readable code.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StoreError {
    /// The database cannot be reached or opened (server down, file not writable, pool closed).
    #[error("store unavailable at {target}: {reason}")]
    Unavailable {
        /// The database without credentials: a file path or `host:port/db`.
        target: String,
        /// Short reason in plain words, e.g. `connection refused`.
        reason: String,
        detail: Detail,
    },
    /// The database file is damaged or is not a database at all. Retrying does not help.
    #[error(
        "database file {target} is damaged ({reason}): restore it from a backup, or move it \
         aside and start once with --accept-new-database to begin a new history"
    )]
    Corrupt {
        target: String,
        /// SQLite's words: `file is not a database` or `database disk image is malformed`.
        reason: String,
        detail: Detail,
    },
    /// The disk (or PostgreSQL's tablespace) holding the database is full: nothing more can
    /// be written until space is freed. Reads may still work.
    #[error("database {target} is out of disk space: free space on its file system")]
    Full { target: String, detail: Detail },
    /// Too many reads at once: a read waited longer than its bound for a turn, or (on
    /// PostgreSQL) ran past its statement timeout. Writes are not affected; retry later.
    #[error("store busy at {target}: {reason}")]
    Busy { target: String, reason: String },
    /// The thing asked for does not exist.
    #[error("{what} not found")]
    NotFound { what: String },
    /// The write collides with what is stored (e.g. two writers took the same table version).
    #[error("conflict: {what}")]
    Conflict { what: String, detail: Detail },
    /// The caller passed a value the store refuses, naming the field.
    #[error("invalid {field}: {reason}")]
    Invalid { field: &'static str, reason: String },
    /// The schema could not be brought up to date at start.
    #[error("store migration failed: {reason}")]
    Migration { reason: String, detail: Detail },
    /// Anything else the database reported while doing `operation`.
    #[error("store failed while {operation}")]
    Backend {
        operation: &'static str,
        detail: Detail,
    },
}

impl StoreError {
    /// Stable code for APIs and logs (`store_unavailable`, `store_corrupt`, `store_full`,
    /// `store_busy`, `not_found`, `conflict`, `invalid`, `migration_failed`, `store_failed`).
    pub fn code(&self) -> &'static str {
        match self {
            StoreError::Unavailable { .. } => "store_unavailable",
            StoreError::Corrupt { .. } => "store_corrupt",
            StoreError::Full { .. } => "store_full",
            StoreError::Busy { .. } => "store_busy",
            StoreError::NotFound { .. } => "not_found",
            StoreError::Conflict { .. } => "conflict",
            StoreError::Invalid { .. } => "invalid",
            StoreError::Migration { .. } => "migration_failed",
            StoreError::Backend { .. } => "store_failed",
        }
    }

    /// Whether the same call will fail the same way until an operator acts: a damaged
    /// database file, a schema this camloop cannot apply, or a refused value (including a
    /// bad database URL). A reconnect loop should report such an error once, as an ERROR,
    /// and not retry it every few seconds. A full disk is not permanent (space can be freed
    /// while camloop runs), nor are unavailable, busy or conflicting stores.
    pub fn is_permanent(&self) -> bool {
        matches!(
            self,
            StoreError::Corrupt { .. } | StoreError::Migration { .. } | StoreError::Invalid { .. }
        )
    }

    /// Whether the store refuses this one record, and would refuse it again however often it
    /// were sent: a value off its rule, a collision with what is stored, or a reference to a
    /// row that is not there. Unlike [`Self::is_permanent`] this says nothing of the
    /// database: the records after it may go in. A writer keeps such a record aside rather
    /// than retry it forever in front of the others.
    pub fn refuses_record(&self) -> bool {
        matches!(
            self,
            StoreError::Invalid { .. } | StoreError::Conflict { .. } | StoreError::NotFound { .. }
        )
    }

    /// Backend detail for logging (may contain SQL error text), if any.
    pub fn detail(&self) -> Option<&str> {
        match self {
            StoreError::Unavailable { detail, .. }
            | StoreError::Corrupt { detail, .. }
            | StoreError::Full { detail, .. }
            | StoreError::Conflict { detail, .. }
            | StoreError::Migration { detail, .. }
            | StoreError::Backend { detail, .. } => Some(&detail.0),
            StoreError::Busy { .. } | StoreError::NotFound { .. } | StoreError::Invalid { .. } => {
                None
            }
        }
    }

    pub fn invalid(field: &'static str, reason: impl Into<String>) -> Self {
        StoreError::Invalid {
            field,
            reason: reason.into(),
        }
    }

    /// The database at `target` cannot be written now, for `reason` (the detail says the
    /// same: it comes from camloop, not from a driver).
    pub fn unavailable(target: &str, reason: impl Into<String>) -> Self {
        let reason = reason.into();
        StoreError::Unavailable {
            target: target.to_owned(),
            detail: Detail(reason.clone()),
            reason,
        }
    }
}

/// What a driver error means for the caller, in plain words.
enum Kind {
    /// The database cannot be reached: the reason.
    Unavailable(String),
    /// The file is not a database or is malformed: SQLite's reason.
    Corrupt(&'static str),
    Full,
    /// A read ran past its time: the reason.
    Busy(String),
    /// The database answered with an error about this statement.
    Other,
}

/// SQLite primary result codes (the low byte of an extended code).
const SQLITE_BUSY: i32 = 5;
const SQLITE_READONLY: i32 = 8;
const SQLITE_CORRUPT: i32 = 11;
const SQLITE_FULL: i32 = 13;
const SQLITE_CANTOPEN: i32 = 14;
const SQLITE_NOTADB: i32 = 26;

fn kind_of(e: &sqlx::Error) -> Kind {
    match e {
        sqlx::Error::Io(io) => Kind::Unavailable(io.kind().to_string()),
        sqlx::Error::Tls(_) => Kind::Unavailable("tls handshake failed".to_owned()),
        sqlx::Error::PoolTimedOut => {
            Kind::Unavailable("timed out waiting for a connection".to_owned())
        }
        sqlx::Error::PoolClosed => Kind::Unavailable("connection pool closed".to_owned()),
        sqlx::Error::WorkerCrashed => Kind::Unavailable("database worker stopped".to_owned()),
        sqlx::Error::Database(db) => {
            if let Some(sqlite) = db.try_downcast_ref::<sqlx::sqlite::SqliteError>() {
                sqlite_kind(sqlite)
            } else {
                postgres_kind(&db.code().map(|c| c.into_owned()).unwrap_or_default())
            }
        }
        _ => Kind::Other,
    }
}

fn sqlite_kind(e: &sqlx::sqlite::SqliteError) -> Kind {
    // sqlx reports the extended result code; its low byte is the primary code.
    let extended: i32 = sqlx::error::DatabaseError::code(e)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    match extended & 0xff {
        SQLITE_CANTOPEN => Kind::Unavailable("cannot open the database file".to_owned()),
        SQLITE_READONLY => Kind::Unavailable("database file is read-only".to_owned()),
        SQLITE_NOTADB => Kind::Corrupt("file is not a database"),
        SQLITE_CORRUPT => Kind::Corrupt("database disk image is malformed"),
        SQLITE_FULL => Kind::Full,
        SQLITE_BUSY => Kind::Busy("another process holds the database's write lock".to_owned()),
        _ => Kind::Other,
    }
}

fn postgres_kind(sqlstate: &str) -> Kind {
    // Classes 08 (connection), 28 (authorization), 3D (no such database), 57P (shutdown);
    // 53100 disk_full; 57014 query_canceled, which is how a statement timeout ends.
    match sqlstate {
        "53100" => Kind::Full,
        "57014" => Kind::Busy("the read ran past its statement timeout".to_owned()),
        c if c.starts_with("28") => Kind::Unavailable("authentication refused".to_owned()),
        c if c.starts_with("3D") => Kind::Unavailable("database does not exist".to_owned()),
        c if c.starts_with("08") || c.starts_with("57P") => {
            Kind::Unavailable("server closed or refused the connection".to_owned())
        }
        _ => Kind::Other,
    }
}

/// Maps a driver error met while connecting to `target`.
pub(crate) fn connect_error(target: &str, e: sqlx::Error) -> StoreError {
    match kind_of(&e) {
        Kind::Corrupt(reason) => corrupt(target, reason, e.to_string()),
        Kind::Full => StoreError::Full {
            target: target.to_owned(),
            detail: Detail(e.to_string()),
        },
        Kind::Unavailable(reason) | Kind::Busy(reason) => StoreError::Unavailable {
            target: target.to_owned(),
            reason,
            detail: Detail(e.to_string()),
        },
        Kind::Other => StoreError::Unavailable {
            target: target.to_owned(),
            reason: "cannot connect".to_owned(),
            detail: Detail(e.to_string()),
        },
    }
}

pub(crate) fn corrupt(target: &str, reason: &str, detail: String) -> StoreError {
    StoreError::Corrupt {
        target: target.to_owned(),
        reason: reason.to_owned(),
        detail: Detail(detail),
    }
}

/// Maps a driver error met during `operation` (a gerund phrase: "inserting a measurement")
/// on a store whose database is named by `target` in messages.
pub(crate) fn db_error_at<'a>(
    target: &'a str,
    operation: &'static str,
) -> impl Fn(sqlx::Error) -> StoreError + 'a {
    move |e| match kind_of(&e) {
        Kind::Unavailable(reason) => StoreError::Unavailable {
            target: target.to_owned(),
            reason,
            detail: Detail(format!("{operation}: {e}")),
        },
        Kind::Corrupt(reason) => corrupt(target, reason, format!("{operation}: {e}")),
        Kind::Full => StoreError::Full {
            target: target.to_owned(),
            detail: Detail(format!("{operation}: {e}")),
        },
        Kind::Busy(reason) => StoreError::Busy {
            target: target.to_owned(),
            reason,
        },
        Kind::Other => match &e {
            sqlx::Error::Database(db) if db.is_unique_violation() => StoreError::Conflict {
                what: format!("a concurrent write while {operation}"),
                detail: Detail(e.to_string()),
            },
            _ => StoreError::Backend {
                operation,
                detail: Detail(e.to_string()),
            },
        },
    }
}

/// [`db_error_at`] where the store is not at hand (reading a column of a fetched row).
pub(crate) fn db_error(operation: &'static str) -> impl Fn(sqlx::Error) -> StoreError {
    move |e| db_error_at("the database", operation)(e)
}

impl From<camloop_core::levels::UnknownValue> for StoreError {
    /// A stored text that names no variant: the column's value is invalid.
    fn from(e: camloop_core::levels::UnknownValue) -> Self {
        StoreError::invalid(e.field, format!("unknown value `{}`", e.text))
    }
}
