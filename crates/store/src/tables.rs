//! Table versions: each regenerated curve-table program, numbered per (machine, lobe), with
//! its status kept as appended rows (the newest row is the current status).

use super::chain::{TABLE_VERSIONS, fetch_chain};
use super::codec::{check_limit, sha256_hex};
use super::{
    NewTableVersion, Store, StoreError, StoredTableVersion, VersionStatus, at_col, col, with_read,
    with_write,
};
use camloop_core::names::{FeatureName, MachineName};

const SELECT_VERSION: &str = "SELECT t.id, t.machine, t.lobe, t.version, t.parent_version, \
     t.table_number, t.sha256, t.reason, \
     t.created_at_ms, s.status, s.why, s.at_ms \
     FROM table_versions t JOIN table_version_status s ON s.id = \
     (SELECT MAX(s2.id) FROM table_version_status s2 WHERE s2.table_version_id = t.id) \
     WHERE t.machine = $1 AND t.lobe = $2";

/// A table version with its texts: the row's summary columns, then the program and the
/// learning unpacked from its chain, the program checked against its SHA-256.
macro_rules! version_from_row {
    ($store:expr, $pool:expr, $row:expr) => {{
        let row = $row;
        let id: i64 = col!(row, "id", "reading a table version");
        let mut v = version_summary!(row);
        let mut texts = fetch_chain!($store, $pool, TABLE_VERSIONS, id).into_iter();
        v.program_text = texts.next().unwrap_or_default();
        v.learning_params_json = texts.next().unwrap_or_default();
        if camloop_core::digest::Sha256::of(v.program_text.as_bytes()) != v.sha256 {
            return Err(StoreError::invalid(
                "program_text",
                format!(
                    "table version {} of machine {} lobe {} does not match its SHA-256",
                    v.version, v.machine, v.lobe
                ),
            ));
        }
        v
    }};
}

macro_rules! version_summary {
    ($row:expr) => {{
        let row = $row;
        let status: String = col!(row, "status", "reading a table version");
        let status_at_ms: i64 = col!(row, "at_ms", "reading a table version");
        let table_number: i64 = col!(row, "table_number", "reading a table version");
        StoredTableVersion {
            machine: $crate::codec::machine_of(col!(row, "machine", "reading a table version"))?,
            lobe: $crate::codec::feature_of("lobe", col!(row, "lobe", "reading a table version"))?,
            version: $crate::codec::version_of(
                "version",
                col!(row, "version", "reading a table version"),
            )?,
            parent_version: match col!(row, "parent_version", "reading a table version") {
                Some(n) => Some($crate::codec::version_of("parent_version", n)?),
                None => None,
            },
            table_number: u32::try_from(table_number).map_err(|_| {
                StoreError::invalid(
                    "table_number",
                    format!("stored value {table_number} out of range"),
                )
            })?,
            program_text: String::new(),
            sha256: $crate::codec::sha256_of(
                "sha256",
                col!(row, "sha256", "reading a table version"),
            )?,
            learning_params_json: String::new(),
            reason: col!(row, "reason", "reading a table version"),
            created_at: at_col!(row, "created_at_ms", "reading a table version"),
            status: VersionStatus::from_column(
                &status,
                col!(row, "why", "reading a table version"),
                status_at_ms,
            )?,
            status_at: $crate::unix_ms::instant(status_at_ms, "at_ms")?,
        }
    }};
}

impl Store {
    /// Appends a table version and its first status; returns its version number, one more
    /// than the highest stored for this (machine, lobe), starting at 1. Two writers racing
    /// for the same number get [`StoreError::Conflict`] for the loser.
    pub async fn insert_table_version(
        &self,
        t: &NewTableVersion,
    ) -> Result<camloop_core::ids::TableVersion, StoreError> {
        const OP: &str = "inserting a table version";
        let mut batch = self.begin_batch_for(OP).await?;
        let version = batch.insert_table_version(t).await?;
        batch.commit_for(OP).await?;
        Ok(version)
    }

    /// Appends a status for a stored table version (e.g. waiting → pushed), as of `at`.
    pub async fn set_table_status(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        version: camloop_core::ids::TableVersion,
        status: &VersionStatus,
        at: jiff::Timestamp,
    ) -> Result<(), StoreError> {
        const OP: &str = "recording a table status";
        let mut batch = self.begin_batch_for(OP).await?;
        batch
            .set_table_status(machine, lobe, version, status, at)
            .await?;
        batch.commit_for(OP).await
    }

    /// Whether a table version of (machine, lobe) made at `created_at` with exactly this
    /// program is stored: how a journal replayed after a crash recognises what it had already
    /// written.
    pub async fn table_version_exists(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        created_at: jiff::Timestamp,
        program_text: &str,
    ) -> Result<bool, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let sha256 = sha256_hex(program_text.as_bytes());
        with_write!(self, pool => {
            let found: Option<i64> = sqlx::query_scalar(
                "SELECT id FROM table_versions WHERE machine = $1 AND lobe = $2 \
                 AND created_at_ms = $3 AND sha256 = $4 LIMIT 1",
            )
            .bind(machine)
            .bind(lobe)
            .bind(created_at.as_millisecond())
            .bind(&sha256)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("looking up a table version"))?;
            Ok(found.is_some())
        })
    }

    /// The newest status of version `version` of (machine, lobe), or `None` when the store
    /// has no such version. On the writer's connection: the journal asks this for every
    /// table record, and must never wait behind history readers.
    pub async fn table_version_status(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        version: camloop_core::ids::TableVersion,
    ) -> Result<Option<VersionStatus>, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        with_write!(self, pool => {
            let status: Option<(String, String, i64)> = sqlx::query_as(
                "SELECT s.status, s.why, s.at_ms FROM table_versions t JOIN table_version_status s \
                 ON s.table_version_id = t.id WHERE t.machine = $1 AND t.lobe = $2 \
                 AND t.version = $3 ORDER BY s.id DESC LIMIT 1",
            )
            .bind(machine)
            .bind(lobe)
            .bind(version.to_i64())
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("looking up a table version's status"))?;
            status
                .map(|(status, why, at_ms)| VersionStatus::from_column(&status, why, at_ms))
                .transpose()
        })
    }

    /// The highest-numbered table version of (machine, lobe), whatever its status.
    pub async fn latest_table_version(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
    ) -> Result<Option<StoredTableVersion>, StoreError> {
        Ok(self
            .table_versions(machine, lobe, 1)
            .await?
            .into_iter()
            .next())
    }

    /// The newest `limit` table versions of (machine, lobe), highest version first.
    pub async fn table_versions(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        limit: u32,
    ) -> Result<Vec<StoredTableVersion>, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let limit = check_limit(limit)?;
        let sql = format!("{SELECT_VERSION} ORDER BY t.version DESC LIMIT $3");
        with_read!(self, pool => {
            let rows = sqlx::query(&sql)
                .bind(machine)
                .bind(lobe)
                .bind(limit)
                .fetch_all(pool)
                .await
                .map_err(self.db_error("listing table versions"))?;
            let mut versions = Vec::with_capacity(rows.len());
            for row in &rows {
                versions.push(version_from_row!(self, pool, row));
            }
            Ok(versions)
        })
    }

    /// One table version, or `None`.
    pub async fn table_version(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        version: camloop_core::ids::TableVersion,
    ) -> Result<Option<StoredTableVersion>, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let sql = format!("{SELECT_VERSION} AND t.version = $3");
        with_read!(self, pool => {
            let row = sqlx::query(&sql)
                .bind(machine)
                .bind(lobe)
                .bind(version.to_i64())
                .fetch_optional(pool)
                .await
                .map_err(self.db_error("reading a table version"))?;
            match row {
                None => Ok(None),
                Some(row) => Ok(Some(version_from_row!(self, pool, &row))),
            }
        })
    }
}
