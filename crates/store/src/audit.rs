//! The audit trail: who did what, from where, to what, with what result. Appended only:
//! the schema's triggers refuse UPDATE, DELETE, TRUNCATE (PostgreSQL) and any id but the
//! next (so `INSERT OR REPLACE` cannot swap a row), and every row is chained to the one
//! before. Rows since version 7 are keyed (`chain = 'hmac-sha256'`, see `audit_key`): their
//! digest is an HMAC under a key kept outside the database, so a database writer without
//! the key cannot rewrite or re-chain them. Older rows (`chain = 'sha256'`) carry the
//! unkeyed SHA-256 of the row before's digest and their fields: anyone who can write the
//! database can re-chain those. [`Store::verify_audit`] says which rows it could prove.

use super::{AuditResult, Role, Store, StoreError, with_read, with_write};
use crate::BeginWrite;
use crate::audit_key::{AuditHead, AuditKey};
use camloop_core::digest::sha256_hex;

/// The `prev_sha256` of the first row.
pub(crate) const AUDIT_GENESIS: &str =
    "0000000000000000000000000000000000000000000000000000000000000000";

/// Largest page of audit rows one query returns.
pub const MAX_AUDIT_PAGE: u32 = 1000;

/// One thing someone did (or tried to).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct AuditEntry {
    #[serde(rename = "at_ms", with = "crate::unix_ms")]
    pub at: jiff::Timestamp,
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
    /// Of those, rows keyed with the HMAC (checked only when the key was given).
    pub keyed_rows: u64,
    /// Whether the key was given, so the keyed rows' digests were checked.
    pub key_checked: bool,
    /// The first rows that break the chain (at most 20): id and why.
    pub broken: Vec<(i64, String)>,
    /// The signed head against the chain.
    pub head: HeadCheck,
}

/// A signed head compared with the chain.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HeadCheck {
    /// No head was given: a removed tail cannot be seen.
    NotGiven,
    /// The chain holds the head's row, with its digest and as many rows up to it.
    Holds,
    /// The chain does not hold the head: rows were removed or renumbered. Why.
    Broken(String),
}

impl AuditCheck {
    /// Nothing found wrong.
    pub fn intact(&self) -> bool {
        self.broken.is_empty() && !matches!(self.head, HeadCheck::Broken(_))
    }
}

/// The `chain` of an unkeyed row (before version 7) and of a keyed one.
const CHAIN_SHA256: &str = "sha256";
const CHAIN_HMAC: &str = "hmac-sha256";

type AuditDbRow = (
    String,
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

const COLUMNS: &str = "SELECT chain, id, at_ms, actor, role, client, action, machine, feature, version, \
     before_json, after_json, result, reason, prev_sha256, row_sha256 FROM audit";

/// The chained digest of an entry after `prev`: SHA-256 of `prev`, a newline, and the
/// entry's fields as a JSON array (serde_json writes it the same way every time).
pub(crate) fn audit_digest(prev: &str, e: &AuditEntry) -> String {
    let fields = fields_json(e);
    sha256_hex(format!("{prev}\n{fields}").as_bytes())
}

fn fields_json(e: &AuditEntry) -> serde_json::Value {
    serde_json::json!([
        e.at.as_millisecond(),
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
    ])
}

/// The keyed digest of row `id` holding `e` after `prev`: HMAC-SHA256 under `key` of the
/// id, `prev` and the fields as [`audit_digest`] writes them, each on its line.
pub(crate) fn audit_mac(key: &AuditKey, id: i64, prev: &str, e: &AuditEntry) -> String {
    let fields = fields_json(e);
    key.mac(format!("{id}\n{prev}\n{fields}").as_bytes())
}

/// A stored row: the row, its chain kind, its stored link and digest.
struct Stored {
    row: AuditRow,
    chain: String,
    prev: String,
    digest: String,
}

fn row_from(r: AuditDbRow) -> Result<Stored, StoreError> {
    let chain = r.0;
    let r = (
        r.1, r.2, r.3, r.4, r.5, r.6, r.7, r.8, r.9, r.10, r.11, r.12, r.13, r.14, r.15,
    );
    let (id, at_ms, actor, role, client, action, machine, feature, version, before, after) =
        (r.0, r.1, r.2, r.3, r.4, r.5, r.6, r.7, r.8, r.9, r.10);
    let entry = AuditEntry {
        at: super::unix_ms::instant(at_ms, "at_ms")?,
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
    Ok(Stored {
        row: AuditRow { id, entry },
        chain,
        prev: r.13,
        digest: r.14,
    })
}

impl Store {
    /// Appends `e` to the trail under the next id, keyed with `key` and chained to the
    /// newest row; returns the trail's new head (sign it and keep it outside the database).
    pub async fn append_audit(
        &self,
        key: &AuditKey,
        e: &AuditEntry,
    ) -> Result<AuditHead, StoreError> {
        const OP: &str = "appending to the audit trail";
        let postgres = self.backend() == "postgres";
        // The id is given, not drawn: the schema refuses any id but the next, and a
        // PostgreSQL sequence leaves gaps where a transaction rolled back.
        let insert = format!(
            "INSERT INTO audit (id, at_ms, actor, role, client, action, machine, feature, version, \
             before_json, after_json, result, reason, prev_sha256, row_sha256, chain) {} \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16)",
            if postgres {
                "OVERRIDING SYSTEM VALUE"
            } else {
                ""
            }
        );
        with_write!(self, pool => {
            let mut tx = pool.begin_write().await.map_err(self.db_error(OP))?;
            if postgres {
                // Several writers (and instances) may append at once: one at a time, so the
                // chain never forks. Readers are not blocked. An advisory lock needs no
                // privilege on the table beyond INSERT (the writing role has no more).
                sqlx::query("SELECT pg_advisory_xact_lock(7106231011)")
                    .execute(&mut *tx)
                    .await
                    .map_err(self.db_error(OP))?;
            }
            let newest: Option<(i64, String)> =
                sqlx::query_as("SELECT id, row_sha256 FROM audit ORDER BY id DESC LIMIT 1")
                    .fetch_optional(&mut *tx)
                    .await
                    .map_err(self.db_error(OP))?;
            let count: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM audit")
                .fetch_one(&mut *tx)
                .await
                .map_err(self.db_error(OP))?;
            let (id, prev) = match newest {
                Some((id, digest)) => (id + 1, digest),
                None => (1, AUDIT_GENESIS.to_string()),
            };
            let digest = audit_mac(key, id, &prev, e);
            sqlx::query(&insert)
                .bind(id)
                .bind(e.at.as_millisecond())
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
                .bind(CHAIN_HMAC)
                .execute(&mut *tx)
                .await
                .map_err(self.db_error(OP))?;
            tx.commit().await.map_err(self.db_error(OP))?;
            Ok(AuditHead {
                rows: u64::try_from(count).unwrap_or(0) + 1,
                last_id: id,
                last_digest: digest,
            })
        })
    }

    /// Rows from `since` on, at most `limit` (≤ [`MAX_AUDIT_PAGE`]), after row `after_id`;
    /// newest first when `newest_first`, else oldest first.
    pub async fn audit(
        &self,
        since: jiff::Timestamp,
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
            .bind(since.as_millisecond())
            .bind(after_id)
            .bind(limit)
            .fetch_all(pool)
            .await
            .map_err(self.db_error(OP))?;
            rows.into_iter().map(|r| row_from(r).map(|s| s.row)).collect()
        })
    }

    /// Walks the whole trail and checks every row's link and digest: keyed rows with `key`
    /// (unchecked without it), unkeyed rows by their SHA-256, and that no unkeyed row follows
    /// a keyed one; then that the chain holds `head` (a head signed earlier, read from
    /// outside the database).
    pub async fn verify_audit(
        &self,
        key: Option<&AuditKey>,
        head: Option<&AuditHead>,
    ) -> Result<AuditCheck, StoreError> {
        const OP: &str = "verifying the audit trail";
        let mut check = AuditCheck {
            rows: 0,
            keyed_rows: 0,
            key_checked: key.is_some(),
            broken: Vec::new(),
            head: HeadCheck::NotGiven,
        };
        let mut prev = AUDIT_GENESIS.to_string();
        let mut after = 0i64;
        let mut head_seen: Option<(u64, String)> = None;
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
                check.head = head_check(head, head_seen, &check);
                return Ok(check);
            }
            for r in page {
                let s = row_from(r)?;
                check.rows += 1;
                after = s.row.id;
                let why = row_fault(&s, &prev, key, check.keyed_rows > 0);
                if s.chain == CHAIN_HMAC {
                    check.keyed_rows += 1;
                }
                if let Some(why) = why
                    && check.broken.len() < 20
                {
                    check.broken.push((s.row.id, why.to_string()));
                }
                if head.is_some_and(|h| h.last_id == s.row.id) {
                    head_seen = Some((check.rows, s.digest.clone()));
                }
                prev = s.digest;
            }
        }
    }
}

/// What is wrong with stored row `s` after `prev`, if anything.
fn row_fault(
    s: &Stored,
    prev: &str,
    key: Option<&AuditKey>,
    keyed_before: bool,
) -> Option<&'static str> {
    if s.prev != prev {
        return Some(
            "its link to the row before does not match: a row before it was removed or changed",
        );
    }
    match s.chain.as_str() {
        CHAIN_HMAC => match key {
            Some(k) if audit_mac(k, s.row.id, prev, &s.row.entry) != s.digest => Some(
                "its keyed digest does not match: the row was changed, renumbered or made without the key",
            ),
            _ => None,
        },
        CHAIN_SHA256 if keyed_before => {
            Some("an unkeyed row after keyed ones: written without the key")
        }
        CHAIN_SHA256 if audit_digest(prev, &s.row.entry) != s.digest => {
            Some("its content does not match its digest: the row was changed")
        }
        CHAIN_SHA256 => None,
        _ => Some("its chain kind is unknown"),
    }
}

/// The head against what the walk saw of its row: (rows up to it, its digest).
fn head_check(
    head: Option<&AuditHead>,
    seen: Option<(u64, String)>,
    check: &AuditCheck,
) -> HeadCheck {
    let Some(h) = head else {
        return HeadCheck::NotGiven;
    };
    match seen {
        None => HeadCheck::Broken(format!(
            "the signed head names row {} ({} rows), which the trail ({} rows) no longer holds: rows were removed",
            h.last_id, h.rows, check.rows
        )),
        Some((_, digest)) if digest != h.last_digest => HeadCheck::Broken(format!(
            "row {} is not the row the signed head names: rows were replaced or renumbered",
            h.last_id
        )),
        Some((rows, _)) if rows != h.rows => HeadCheck::Broken(format!(
            "{rows} rows up to row {}, the signed head says {}: rows before it were removed or added",
            h.last_id, h.rows
        )),
        Some(_) => HeadCheck::Holds,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The API's audit page serialises rows as they are: the instant is `at` in Rust and
    /// stays `at_ms` (integer milliseconds) on the wire.
    #[test]
    fn a_row_keeps_its_wire_names() {
        let row = AuditRow {
            id: 3,
            entry: AuditEntry {
                at: jiff::Timestamp::from_millisecond(1_795_443_845_123).unwrap(),
                actor: "ana".into(),
                role: Role::Engineer,
                client: "local".into(),
                action: "rollback".into(),
                machine: Some("G7".into()),
                feature: None,
                version: Some(4),
                before: None,
                after: None,
                result: AuditResult::Ok,
                reason: String::new(),
            },
        };
        let json = serde_json::to_value(&row).unwrap();
        assert_eq!(
            json["at_ms"],
            serde_json::json!(1_795_443_845_123_i64),
            "{json}"
        );
        assert!(json.get("at").is_none(), "{json}");
        assert_eq!(json["id"], 3, "{json}");
    }
}
