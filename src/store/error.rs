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
    /// Stable code for APIs and logs (`store_unavailable`, `not_found`, `conflict`,
    /// `invalid`, `migration_failed`, `store_failed`).
    pub fn code(&self) -> &'static str {
        match self {
            StoreError::Unavailable { .. } => "store_unavailable",
            StoreError::NotFound { .. } => "not_found",
            StoreError::Conflict { .. } => "conflict",
            StoreError::Invalid { .. } => "invalid",
            StoreError::Migration { .. } => "migration_failed",
            StoreError::Backend { .. } => "store_failed",
        }
    }

    /// Backend detail for logging (may contain SQL error text), if any.
    pub fn detail(&self) -> Option<&str> {
        match self {
            StoreError::Unavailable { detail, .. }
            | StoreError::Conflict { detail, .. }
            | StoreError::Migration { detail, .. }
            | StoreError::Backend { detail, .. } => Some(&detail.0),
            StoreError::NotFound { .. } | StoreError::Invalid { .. } => None,
        }
    }

    pub(crate) fn invalid(field: &'static str, reason: impl Into<String>) -> Self {
        StoreError::Invalid {
            field,
            reason: reason.into(),
        }
    }
}

/// Why a driver error means the database is unreachable, in plain words, or `None` when the
/// database answered.
fn unavailable_reason(e: &sqlx::Error) -> Option<String> {
    match e {
        sqlx::Error::Io(io) => Some(io.kind().to_string()),
        sqlx::Error::Tls(_) => Some("tls handshake failed".to_owned()),
        sqlx::Error::PoolTimedOut => Some("timed out waiting for a connection".to_owned()),
        sqlx::Error::PoolClosed => Some("connection pool closed".to_owned()),
        sqlx::Error::WorkerCrashed => Some("database worker stopped".to_owned()),
        sqlx::Error::Database(db) => {
            // PostgreSQL classes 08 (connection), 28 (authorization), 3D (no such database),
            // 57P (shutdown); SQLite CANTOPEN (14) and READONLY (8).
            let code = db.code().map(|c| c.into_owned()).unwrap_or_default();
            let gone = code.starts_with("08")
                || code.starts_with("28")
                || code.starts_with("3D")
                || code.starts_with("57P")
                || code == "14"
                || code == "8";
            gone.then(|| match code.as_str() {
                c if c.starts_with("28") => "authentication refused".to_owned(),
                c if c.starts_with("3D") => "database does not exist".to_owned(),
                "14" => "cannot open the database file".to_owned(),
                "8" => "database file is read-only".to_owned(),
                _ => "server closed or refused the connection".to_owned(),
            })
        }
        _ => None,
    }
}

/// Maps a driver error met while connecting to `target`.
pub(crate) fn connect_error(target: &str, e: sqlx::Error) -> StoreError {
    let reason = unavailable_reason(&e).unwrap_or_else(|| "cannot connect".to_owned());
    StoreError::Unavailable {
        target: target.to_owned(),
        reason,
        detail: Detail(e.to_string()),
    }
}

/// Maps a driver error met during `operation` (a gerund phrase: "inserting a measurement").
pub(crate) fn db_error(operation: &'static str) -> impl Fn(sqlx::Error) -> StoreError {
    move |e| {
        if let Some(reason) = unavailable_reason(&e) {
            return StoreError::Unavailable {
                target: "the database".to_owned(),
                reason,
                detail: Detail(format!("{operation}: {e}")),
            };
        }
        if let sqlx::Error::Database(db) = &e
            && db.is_unique_violation()
        {
            return StoreError::Conflict {
                what: format!("a concurrent write while {operation}"),
                detail: Detail(e.to_string()),
            };
        }
        StoreError::Backend {
            operation,
            detail: Detail(e.to_string()),
        }
    }
}
