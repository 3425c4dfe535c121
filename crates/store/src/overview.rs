//! The plant overview's reads as a few set queries over every feature at once, instead of a
//! handful of queries per feature: at 500 machines × 8 features the per-feature way was
//! some 13,000 round trips for one page. Each query is driven by the list of features it is
//! given (a JSON array on SQLite, two arrays on PostgreSQL) and reads each feature's newest
//! rows through the same indexes the per-feature reads use, so its cost grows with the rows
//! shown, never with the history kept. The per-feature reads stay the reference: a test
//! holds these answers equal to theirs.

use super::codec::{check_limit, feature_of, machine_of};
use super::unix_ms::instant;
use super::{
    LearningState, MeasurementId, Store, StoreError, TableVersionHead, Verdict, VersionStatus, col,
    with_read,
};
use camloop_core::ids::PartId;
use camloop_core::measure::MASTER_PART_PREFIX;
use camloop_core::names::{FeatureName, MachineName};
use jiff::Timestamp;
use std::collections::BTreeSet;

/// One finished production part as the overview shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct OverviewPart {
    pub id: MeasurementId,
    pub part: PartId,
    pub received_at: Timestamp,
    pub verdict: Verdict,
    pub max_profile_error_um: f64,
}

/// What the overview reads of one (machine, feature).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FeatureOverview {
    /// The newest finished production parts (no master run, no in-process measurement),
    /// oldest first.
    pub recent: Vec<OverviewPart>,
    /// The newest version with status pushed among the newest versions asked for.
    pub in_force: Option<TableVersionHead>,
    /// The newest learning-state row: its id and the SHA-256 of its text (none on a row
    /// older than packing), so a reader can tell whether it changed since it last looked.
    pub learning: Option<(i64, Option<String>)>,
}

/// What changed since a reader last looked: the measurements and table-version status rows
/// stored after the ids it gives, each with its id and feature (a reader that looks back
/// below its last newest id tells rows it has already seen by their ids), and the newest
/// ids now.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OverviewChanges {
    /// (measurement id, machine, feature), by id.
    pub measurements: Vec<(i64, MachineName, FeatureName)>,
    /// (status row id, machine, feature of its table version), by id.
    pub statuses: Vec<(i64, MachineName, FeatureName)>,
    /// The newest measurement id (0 with none).
    pub measurement: i64,
    /// The newest table-version status id (0 with none).
    pub status: i64,
}

/// The feature list as the query's driving rows: `f(k, machine, lobe)` with `k` the index
/// in `features`. SQLite reads a JSON array (`$1`); PostgreSQL two text arrays (`$1`, `$2`).
fn driver(postgres: bool) -> &'static str {
    if postgres {
        "SELECT (f.k - 1)::bigint AS k, f.machine, f.lobe \
         FROM unnest($1::text[], $2::text[]) WITH ORDINALITY AS f(machine, lobe, k)"
    } else {
        "SELECT CAST(j.key AS INTEGER) AS k, json_extract(j.value, '$[0]') AS machine, \
         json_extract(j.value, '$[1]') AS lobe FROM json_each($1) j"
    }
}

/// The same test as the history's: the master prefix, ASCII case ignored.
fn not_master(alias: &str) -> String {
    format!(
        "UPPER(SUBSTR({alias}.part, 1, {})) <> '{}'",
        MASTER_PART_PREFIX.len(),
        MASTER_PART_PREFIX.to_ascii_uppercase()
    )
}

/// Binds the feature list the way [`driver`] reads it.
macro_rules! bind_features {
    (sqlite, $q:expr, $json:expr, $pg:expr) => {
        $q.bind($json)
    };
    (postgres, $q:expr, $json:expr, $pg:expr) => {
        $q.bind(&$pg.0).bind(&$pg.1)
    };
}

/// Runs `$sql` (built by `$make(postgres)`) for the feature list on the reader pool.
macro_rules! fetch_features {
    ($store:expr, $make:expr, $features:expr, $extra:expr, $op:literal) => {{
        let json = serde_json::to_string(
            &$features
                .iter()
                .map(|(m, f)| [m.as_str(), f.as_str()])
                .collect::<Vec<_>>(),
        )
        .map_err(|e| StoreError::invalid("features", e.to_string()))?;
        let pg: (Vec<&str>, Vec<&str>) = $features
            .iter()
            .map(|(m, f)| (m.as_str(), f.as_str()))
            .unzip();
        let _turn = $store.read_turn().await?;
        match &$store.pools {
            $crate::Pools::Sqlite { read, .. } => {
                let sql = $make(false);
                let q = bind_features!(sqlite, sqlx::query(&sql), &json, pg);
                q.bind($extra)
                    .fetch_all(read)
                    .await
                    .map_err($store.db_error($op))?
                    .into_iter()
                    .map(Row::Sqlite)
                    .collect::<Vec<_>>()
            }
            $crate::Pools::Postgres { read, .. } => {
                let sql = $make(true);
                let q = bind_features!(postgres, sqlx::query(&sql), &json, pg);
                q.bind($extra)
                    .fetch_all(read)
                    .await
                    .map_err($store.db_error($op))?
                    .into_iter()
                    .map(Row::Postgres)
                    .collect::<Vec<_>>()
            }
        }
    }};
}

/// A row of either backend, read by the same code.
enum Row {
    Sqlite(sqlx::sqlite::SqliteRow),
    Postgres(sqlx::postgres::PgRow),
}

/// Reads a column of a [`Row`] of either backend.
macro_rules! row_col {
    ($row:expr, $name:literal, $op:literal) => {
        match $row {
            Row::Sqlite(r) => col!(r, $name, $op),
            Row::Postgres(r) => col!(r, $name, $op),
        }
    };
}

/// The index a row answers for, checked against the list (a row for no feature is an
/// error, never a panic).
fn slot(k: i64, len: usize) -> Result<usize, StoreError> {
    usize::try_from(k)
        .ok()
        .filter(|&k| k < len)
        .ok_or_else(|| StoreError::invalid("k", format!("feature index {k} outside the list")))
}

impl Store {
    /// For each of `features`, in order: its newest `parts` finished production parts, the
    /// version in force among its newest `versions`, and its newest learning-state row.
    /// Reads what [`Store::measurement_history`] (final stage, masters excluded),
    /// [`Store::table_version_heads`] and the newest learning state give, feature by feature.
    pub async fn plant_overview(
        &self,
        features: &[(MachineName, FeatureName)],
        parts: u32,
        versions: u32,
    ) -> Result<Vec<FeatureOverview>, StoreError> {
        let parts = check_limit(parts)?;
        let versions = check_limit(versions)?;
        let mut out = vec![FeatureOverview::default(); features.len()];
        if features.is_empty() {
            return Ok(out);
        }
        self.overview_parts(features, parts, &mut out).await?;
        self.overview_in_force(features, versions, &mut out).await?;
        self.overview_learning(features, &mut out).await?;
        Ok(out)
    }

    async fn overview_parts(
        &self,
        features: &[(MachineName, FeatureName)],
        parts: i64,
        out: &mut [FeatureOverview],
    ) -> Result<(), StoreError> {
        // Each feature's newest parts from the history's covering index, newest first. SQLite
        // has no LATERAL: a correlated `IN` with its own LIMIT does the same there.
        let make = |postgres: bool| {
            let filter = format!(
                "x.machine = f.machine AND x.lobe = f.lobe AND x.stage = 'final' AND {}",
                not_master("x")
            );
            let order = "ORDER BY x.received_at_ms DESC, x.id DESC";
            let columns = "f.k, m.id, m.part, m.received_at_ms, m.verdict, m.max_profile_error_um";
            if postgres {
                format!(
                    "SELECT {columns} FROM ({}) f CROSS JOIN LATERAL ( \
                     SELECT x.id, x.part, x.received_at_ms, x.verdict, x.max_profile_error_um \
                     FROM measurements x WHERE {filter} {order} LIMIT $3) m \
                     ORDER BY f.k, m.received_at_ms, m.id",
                    driver(true)
                )
            } else {
                format!(
                    "SELECT {columns} FROM ({}) f JOIN measurements m ON m.id IN ( \
                     SELECT x.id FROM measurements x WHERE {filter} {order} LIMIT $2) \
                     ORDER BY f.k, m.received_at_ms, m.id",
                    driver(false)
                )
            }
        };
        let rows = fetch_features!(self, make, features, parts, "reading the overview's parts");
        for row in &rows {
            let k: i64 = row_col!(row, "k", "reading the overview's parts");
            let verdict: String = row_col!(row, "verdict", "reading the overview's parts");
            let at: i64 = row_col!(row, "received_at_ms", "reading the overview's parts");
            out[slot(k, features.len())?].recent.push(OverviewPart {
                id: MeasurementId(row_col!(row, "id", "reading the overview's parts")),
                part: super::codec::part_of(row_col!(row, "part", "reading the overview's parts"))?,
                received_at: instant(at, "received_at_ms")?,
                verdict: Verdict::parse(&verdict)?,
                max_profile_error_um: row_col!(
                    row,
                    "max_profile_error_um",
                    "reading the overview's parts"
                ),
            });
        }
        Ok(())
    }

    async fn overview_in_force(
        &self,
        features: &[(MachineName, FeatureName)],
        versions: i64,
        out: &mut [FeatureOverview],
    ) -> Result<(), StoreError> {
        // The newest of the newest `versions` whose newest status row says pushed.
        let make = |postgres: bool| {
            format!(
                "SELECT f.k, t.version, t.table_number, t.reason, t.created_at_ms, \
                 s.status, s.why, s.at_ms FROM ({}) f \
                 JOIN table_versions t ON t.id = ( \
                   SELECT v.id FROM (SELECT w.id, w.version FROM table_versions w \
                     WHERE w.machine = f.machine AND w.lobe = f.lobe \
                     ORDER BY w.version DESC LIMIT {}) v \
                   WHERE (SELECT s2.status FROM table_version_status s2 \
                     WHERE s2.table_version_id = v.id ORDER BY s2.id DESC LIMIT 1) = 'pushed' \
                   ORDER BY v.version DESC LIMIT 1) \
                 JOIN table_version_status s ON s.id = \
                   (SELECT MAX(s3.id) FROM table_version_status s3 WHERE s3.table_version_id = t.id)",
                driver(postgres),
                if postgres { "$3" } else { "$2" }
            )
        };
        let rows = fetch_features!(
            self,
            make,
            features,
            versions,
            "reading the versions in force"
        );
        for row in &rows {
            let k: i64 = row_col!(row, "k", "reading the versions in force");
            let status: String = row_col!(row, "status", "reading the versions in force");
            let number: i64 = row_col!(row, "table_number", "reading the versions in force");
            let at_ms: i64 = row_col!(row, "at_ms", "reading the versions in force");
            let created: i64 = row_col!(row, "created_at_ms", "reading the versions in force");
            out[slot(k, features.len())?].in_force = Some(TableVersionHead {
                version: crate::codec::version_of(
                    "version",
                    row_col!(row, "version", "reading the versions in force"),
                )?,
                table_number: u32::try_from(number).map_err(|_| {
                    StoreError::invalid(
                        "table_number",
                        format!("stored value {number} out of range"),
                    )
                })?,
                reason: row_col!(row, "reason", "reading the versions in force"),
                created_at: instant(created, "created_at_ms")?,
                status: VersionStatus::from_column(
                    &status,
                    row_col!(row, "why", "reading the versions in force"),
                    at_ms,
                )?,
            });
        }
        Ok(())
    }

    async fn overview_learning(
        &self,
        features: &[(MachineName, FeatureName)],
        out: &mut [FeatureOverview],
    ) -> Result<(), StoreError> {
        let make = |postgres: bool| {
            format!(
                "SELECT f.k, l.id, l.state_sha256 FROM ({}) f \
                 JOIN learning_states l ON l.id = (SELECT l2.id FROM learning_states l2 \
                   WHERE l2.machine = f.machine AND l2.lobe = f.lobe ORDER BY l2.id DESC LIMIT {})",
                driver(postgres),
                if postgres { "$3" } else { "$2" }
            )
        };
        let rows = fetch_features!(self, make, features, 1i64, "reading the learning states");
        for row in &rows {
            let k: i64 = row_col!(row, "k", "reading the learning states");
            let id: i64 = row_col!(row, "id", "reading the learning states");
            let sha: Option<String> = row_col!(row, "state_sha256", "reading the learning states");
            out[slot(k, features.len())?].learning = Some((id, sha));
        }
        Ok(())
    }

    /// Each feature's newest learning-state row (id and SHA-256 of its text), in order.
    pub async fn plant_learning(
        &self,
        features: &[(MachineName, FeatureName)],
    ) -> Result<Vec<Option<(i64, Option<String>)>>, StoreError> {
        let mut out = vec![FeatureOverview::default(); features.len()];
        if !features.is_empty() {
            self.overview_learning(features, &mut out).await?;
        }
        Ok(out.into_iter().map(|f| f.learning).collect())
    }

    /// The newest ids first (so a row stored meanwhile is seen now or next time), then the
    /// measurements with an id above `after_measurement` and the status rows above
    /// `after_status`, each with its feature: each a range of the primary key, as cheap as
    /// what is new.
    pub async fn overview_changes(
        &self,
        after_measurement: i64,
        after_status: i64,
    ) -> Result<OverviewChanges, StoreError> {
        const OP: &str = "reading what changed since the overview";
        with_read!(self, pool => {
            let measurement: i64 =
                sqlx::query_scalar("SELECT COALESCE(MAX(id), 0) FROM measurements")
                    .fetch_one(pool)
                    .await
                    .map_err(self.db_error(OP))?;
            let status: i64 =
                sqlx::query_scalar("SELECT COALESCE(MAX(id), 0) FROM table_version_status")
                    .fetch_one(pool)
                    .await
                    .map_err(self.db_error(OP))?;
            let measurements: Vec<(i64, String, String)> = sqlx::query_as(
                "SELECT id, machine, lobe FROM measurements WHERE id > $1 ORDER BY id",
            )
            .bind(after_measurement)
            .fetch_all(pool)
            .await
            .map_err(self.db_error(OP))?;
            let statuses: Vec<(i64, String, String)> = sqlx::query_as(
                "SELECT s.id, t.machine, t.lobe FROM table_version_status s \
                 JOIN table_versions t ON t.id = s.table_version_id WHERE s.id > $1 ORDER BY s.id",
            )
            .bind(after_status)
            .fetch_all(pool)
            .await
            .map_err(self.db_error(OP))?;
            let typed = |rows: Vec<(i64, String, String)>| {
                rows.into_iter()
                    .map(|(id, m, f)| Ok((id, machine_of(m)?, feature_of("lobe", f)?)))
                    .collect::<Result<Vec<_>, StoreError>>()
            };
            Ok(OverviewChanges {
                measurements: typed(measurements)?,
                statuses: typed(statuses)?,
                measurement,
                status,
            })
        })
    }

    /// Every (machine, feature) the store knows a recipe snapshot of, and every machine it
    /// has seen (with no feature when it has no snapshot), by name.
    pub async fn known_features(
        &self,
    ) -> Result<Vec<(MachineName, Option<FeatureName>)>, StoreError> {
        with_read!(self, pool => {
            let rows: Vec<(String, Option<String>)> = sqlx::query_as(
                "SELECT m.name, r.lobe FROM machines m LEFT JOIN \
                 (SELECT DISTINCT machine, lobe FROM recipe_snapshots) r ON r.machine = m.name \
                 ORDER BY m.name, r.lobe",
            )
            .fetch_all(pool)
            .await
            .map_err(self.db_error("listing the features"))?;
            rows.into_iter()
                .map(|(m, f)| Ok((machine_of(m)?, f.map(|f| feature_of("lobe", f)).transpose()?)))
                .collect()
        })
    }

    /// The machines with an error event nobody acknowledged among their newest `events`
    /// events (newest by time, then id: the order [`Store::events`] lists them in).
    pub async fn machines_in_alarm(
        &self,
        events: u32,
    ) -> Result<BTreeSet<MachineName>, StoreError> {
        let events = check_limit(events)?;
        with_read!(self, pool => {
            let rows: Vec<String> = sqlx::query_scalar(
                "SELECT m.name FROM machines m WHERE EXISTS ( \
                   SELECT 1 FROM (SELECT e.id, e.level FROM events e WHERE e.machine = m.name \
                     ORDER BY e.at_ms DESC, e.id DESC LIMIT $1) n \
                   WHERE n.level = 'error' \
                     AND NOT EXISTS (SELECT 1 FROM event_acks a WHERE a.event_id = n.id))",
            )
            .bind(events)
            .fetch_all(pool)
            .await
            .map_err(self.db_error("finding the machines in alarm"))?;
            rows.into_iter().map(machine_of).collect()
        })
    }

    /// The learning-state row `id` as text, through the readers' gate: a packed row's chain
    /// resolved and checked against its SHA-256, as the machine loop's load does.
    pub async fn learning_state_row_for_view(
        &self,
        id: i64,
    ) -> Result<Option<LearningState>, StoreError> {
        with_read!(self, pool => {
            let row: Option<(i64, Option<String>, String, String)> = sqlx::query_as(
                "SELECT saved_at_ms, state_sha256, machine, lobe FROM learning_states WHERE id = $1",
            )
            .bind(id)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("loading learning state"))?;
            let Some((saved_at_ms, sha256, machine, lobe)) = row else {
                return Ok(None);
            };
            let state_json =
                super::chain::fetch_chain!(self, pool, super::chain::LEARNING_STATES, id).remove(0);
            if sha256.is_some_and(|s| s != super::sha256_hex(state_json.as_bytes())) {
                return Err(StoreError::invalid(
                    "state_json",
                    format!("learning state of machine {machine} lobe {lobe} does not match its SHA-256"),
                ));
            }
            let saved_at = instant(saved_at_ms, "saved_at_ms")?;
            Ok(Some(LearningState { state_json, saved_at }))
        })
    }
}
