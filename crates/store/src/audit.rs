//! The audit trail: who did what, from where, to what, with what result. Appended only
//! (the schema's triggers refuse UPDATE and DELETE), and every row is chained to the one
//! before: `row_sha256` is the SHA-256 of the previous row's `row_sha256` and this row's
//! fields, so [`Store::verify_audit`] finds a row changed, inserted or removed in the middle
//! by anyone who got past the triggers (a database owner can drop them). Removing the newest
//! rows leaves a shorter chain that still holds: compare the row count with an earlier
//! `camloop audit verify` to see that.

use super::{AuditResult, Role, Store, StoreError, with_read, with_write};
use crate::BeginWrite;
use camloop_core::digest::sha256_hex;

/// The `prev_sha256` of the first row.
pub(crate) const AUDIT_GENESIS: &str =
    "0000000000000000000000000000000000000000000000000000000000000000";

/// Largest page of audit rows one query returns.
pub const MAX_AUDIT_PAGE: u32 = 1000;

/// One thing someone did (or tried to).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct AuditEntry {
    #[serde(with = "crate::unix_ms")]
    pub at_ms: jiff::Timestamp,
    /// A user name, `anonymous`, `api-token` (the deprecated shared token) or `cli:<login>`.
    pub actor: String,
    pub role: Role,
    /// The client address, or `local` for a command on this computer.
    pub client: String,
    /// `rollback`, `dressing`, `acknowledge`, `signin`, `user.add`, `token.create`, …
    pub action: String,
    /// Text, not `MachineName`/`FeatureName`: the trail is evidence, read back whatever a
    /// row holds (one edited by hand included) so that `audit verify` can report it.
    pub machine: Option<String>,
    pub feature: Option<String>,
    pub version: Option<i64>,
    /// JSON of what was there before, and what is there after, when the action changed it.
    pub before: Option<String>,
    pub after: Option<String>,
    pub result: AuditResult,
    pub reason: String,
}

/// A stored row: its id and the entry.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct AuditRow {
    pub id: i64,
    #[serde(flatten)]
    pub entry: AuditEntry,
}

/// What `verify_audit` found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AuditCheck {
    /// Rows read.
    pub rows: u64,
    /// The first rows that break the chain (at most 20): id and why.
    pub broken: Vec<(i64, String)>,
}

type AuditDbRow = (
    i64,
    i64,
    String,
    String,
    String,
    String,
    Option<String>,
    Option<String>,
    Option<i64>,
    Option<String>,
    Option<String>,
    String,
    String,
    String,
    String,
);

const COLUMNS: &str = "SELECT id, at_ms, actor, role, client, action, machine, feature, version, \
     before_json, after_json, result, reason, prev_sha256, row_sha256 FROM audit";

/// The chained digest of an entry after `prev`: SHA-256 of `prev`, a newline, and the
/// entry's fields as a JSON array (serde_json writes it the same way every time).
pub(crate) fn audit_digest(prev: &str, e: &AuditEntry) -> String {
    let fields = serde_json::json!([
        e.at_ms.as_millisecond(),
        e.actor,
        e.role.as_str(),
        e.client,
        e.action,
        e.machine,
        e.feature,
        e.version,
        e.before,
        e.after,
        e.result.as_str(),
        e.reason,
    ]);
    sha256_hex(format!("{prev}\n{fields}").as_bytes())
}

fn row_from(r: AuditDbRow) -> Result<(AuditRow, String, String), StoreError> {
    let (id, at_ms, actor, role, client, action, machine, feature, version, before, after) =
        (r.0, r.1, r.2, r.3, r.4, r.5, r.6, r.7, r.8, r.9, r.10);
    let entry = AuditEntry {
        at_ms: super::unix_ms::instant(at_ms, "at_ms")?,
        actor,
        role: Role::parse(&role)?,
        client,
        action,
        machine,
        feature,
        version,
        before,
        after,
        result: AuditResult::parse(&r.11)?,
        reason: r.12,
    };
    Ok((AuditRow { id, entry }, r.13, r.14))
}

impl Store {
    /// Appends `e` to the trail, chained to the newest row; returns its id.
    pub async fn append_audit(&self, e: &AuditEntry) -> Result<i64, StoreError> {
        const OP: &str = "appending to the audit trail";
        let postgres = self.backend() == "postgres";
        with_write!(self, pool => {
            let mut tx = pool.begin_write().await.map_err(self.db_error(OP))?;
            if postgres {
                // Several writers (and instances) may append at once: one at a time, so the
                // chain never forks. Readers are not blocked.
                sqlx::query("LOCK TABLE audit IN SHARE ROW EXCLUSIVE MODE")
                    .execute(&mut *tx)
                    .await
                    .map_err(self.db_error(OP))?;
            }
            let prev: Option<String> =
                sqlx::query_scalar("SELECT row_sha256 FROM audit ORDER BY id DESC LIMIT 1")
                    .fetch_optional(&mut *tx)
                    .await
                    .map_err(self.db_error(OP))?;
            let prev = prev.unwrap_or_else(|| AUDIT_GENESIS.to_string());
            let digest = audit_digest(&prev, e);
            let id: i64 = sqlx::query_scalar(
                "INSERT INTO audit (at_ms, actor, role, client, action, machine, feature, version, \
                 before_json, after_json, result, reason, prev_sha256, row_sha256) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14) RETURNING id",
            )
            .bind(e.at_ms.as_millisecond())
            .bind(&e.actor)
            .bind(e.role.as_str())
            .bind(&e.client)
            .bind(&e.action)
            .bind(&e.machine)
            .bind(&e.feature)
            .bind(e.version)
            .bind(&e.before)
            .bind(&e.after)
            .bind(e.result.as_str())
            .bind(&e.reason)
            .bind(&prev)
            .bind(&digest)
            .fetch_one(&mut *tx)
            .await
            .map_err(self.db_error(OP))?;
            tx.commit().await.map_err(self.db_error(OP))?;
            Ok(id)
        })
    }

    /// Rows from `since_ms` on, at most `limit` (≤ [`MAX_AUDIT_PAGE`]), after row `after_id`;
    /// newest first when `newest_first`, else oldest first.
    pub async fn audit(
        &self,
        since_ms: jiff::Timestamp,
        after_id: i64,
        limit: u32,
        newest_first: bool,
    ) -> Result<Vec<AuditRow>, StoreError> {
        const OP: &str = "reading the audit trail";
        let order = if newest_first { "DESC" } else { "ASC" };
        let limit = i64::from(limit.clamp(1, MAX_AUDIT_PAGE));
        with_read!(self, pool => {
            let rows: Vec<AuditDbRow> = sqlx::query_as(&format!(
                "{COLUMNS} WHERE at_ms >= $1 AND id > $2 ORDER BY id {order} LIMIT $3"
            ))
            .bind(since_ms.as_millisecond())
            .bind(after_id)
            .bind(limit)
            .fetch_all(pool)
            .await
            .map_err(self.db_error(OP))?;
            rows.into_iter().map(|r| row_from(r).map(|(row, _, _)| row)).collect()
        })
    }

    /// Walks the whole trail and checks every row's chain digest.
    pub async fn verify_audit(&self) -> Result<AuditCheck, StoreError> {
        const OP: &str = "verifying the audit trail";
        let mut check = AuditCheck {
            rows: 0,
            broken: Vec::new(),
        };
        let mut prev = AUDIT_GENESIS.to_string();
        let mut after = 0i64;
        loop {
            let page: Vec<AuditDbRow> = with_read!(self, pool => {
                sqlx::query_as(&format!("{COLUMNS} WHERE id > $1 ORDER BY id LIMIT $2"))
                    .bind(after)
                    .bind(i64::from(MAX_AUDIT_PAGE))
                    .fetch_all(pool)
                    .await
                    .map_err(self.db_error(OP))?
            });
            if page.is_empty() {
                return Ok(check);
            }
            for r in page {
                let (row, stored_prev, stored) = row_from(r)?;
                check.rows += 1;
                after = row.id;
                let why = if stored_prev != prev {
                    Some(
                        "its link to the row before does not match: a row before it was removed or changed",
                    )
                } else if audit_digest(&prev, &row.entry) != stored {
                    Some("its content does not match its digest: the row was changed")
                } else {
                    None
                };
                if let Some(why) = why
                    && check.broken.len() < 20
                {
                    check.broken.push((row.id, why.to_string()));
                }
                prev = stored;
            }
        }
    }
}
