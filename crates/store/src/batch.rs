//! Several history writes in one transaction on the writer: [`Batch`]. The service's journal
//! writes a step's records (a measurement, its table, the table's status, the learning
//! state, events) as one batch, so a part costs one `BEGIN … COMMIT` on the one SQLite
//! writer rather than one per record. The single-record methods of [`Store`]
//! (`insert_measurement`, `insert_table_version`, …) are a batch of one.
//!
//! Every write of a batch goes through its transaction, checks included: on SQLite the
//! writer pool has one connection, which the batch holds until it commits or is dropped (a
//! dropped batch rolls back, so a failed batch leaves nothing behind).

use super::chain::{LEARNING_STATES, TABLE_VERSIONS, next_link, texts_of};
use super::codec::{CODEC_PACKED, check_finite, check_json, check_name, encode_units, sha256_hex};
use super::measurements::{check_measurement, pack_data};
use super::pack::pack_text;
use super::{
    DressingId, EventId, MeasurementId, NewDressing, NewEvent, NewMeasurement, NewRecipeSnapshot,
    NewTableVersion, Pools, RecipeSnapshotId, Store, StoreError, VersionStatus,
};
use crate::BeginWrite;
use camloop_core::digest::Sha256;
use camloop_core::names::{FeatureName, MachineName};

/// The newest learning state of (machine, lobe) when it has meaning `$3` and no row is
/// packed against it: the one a snapshot with the same meaning replaces.
const REPLACEABLE_STATE: &str = "SELECT n.id, n.base_id FROM learning_states n WHERE n.id = \
     (SELECT MAX(id) FROM learning_states WHERE machine = $1 AND lobe = $2) \
     AND n.meaning_sha256 = $3 AND NOT EXISTS \
     (SELECT 1 FROM learning_states c WHERE c.base_id = n.id)";

const ENSURE_MACHINE: &str =
    "INSERT INTO machines (name, first_seen_ms) VALUES ($1, $2) ON CONFLICT (name) DO NOTHING";

/// Writes on one transaction of the writer pool, committed together by [`Batch::commit`].
#[derive(Debug)]
pub struct Batch<'s> {
    store: &'s Store,
    tx: Tx,
}

#[derive(Debug)]
enum Tx {
    Sqlite(sqlx::Transaction<'static, sqlx::Sqlite>),
    Postgres(sqlx::Transaction<'static, sqlx::Postgres>),
}

/// Runs `$body` with `$tx` bound to the batch's connection (inside its transaction); the
/// body is compiled once per backend, as `with_write!` does for the pools.
macro_rules! with_tx {
    ($batch:expr, $tx:ident => $body:expr) => {
        match &mut $batch.tx {
            Tx::Sqlite(t) => {
                let $tx: &mut sqlx::SqliteConnection = &mut *t;
                $body
            }
            Tx::Postgres(t) => {
                let $tx: &mut sqlx::PgConnection = &mut *t;
                $body
            }
        }
    };
}

/// Appends one row of a machine's log with the machine's first sight: `$sql` takes the
/// machine as `$1`, the time as `$2`, then `$bind…`, and returns the id.
macro_rules! append_logged {
    ($batch:expr, $op:expr, $machine:expr, $at_ms:expr, $sql:expr $(, $bind:expr)* $(,)?) => {{
        let store = $batch.store;
        with_tx!($batch, tx => {
            sqlx::query(ENSURE_MACHINE)
                .bind($machine)
                .bind($at_ms)
                .execute(&mut *tx)
                .await
                .map_err(store.db_error($op))?;
            let id: i64 = sqlx::query_scalar($sql)
                .bind($machine)
                .bind($at_ms)
                $(.bind($bind))*
                .fetch_one(&mut *tx)
                .await
                .map_err(store.db_error($op))?;
            Ok::<i64, StoreError>(id)
        })
    }};
}

impl Store {
    /// Starts a batch of writes: one transaction on the writer, which waits its turn there
    /// like any write.
    pub async fn begin_batch(&self) -> Result<Batch<'_>, StoreError> {
        self.begin_batch_for("starting a batch of writes").await
    }

    /// [`Self::begin_batch`], its failure named as `op` (a single-record write's name).
    pub(crate) async fn begin_batch_for(&self, op: &'static str) -> Result<Batch<'_>, StoreError> {
        let tx = match &self.pools {
            Pools::Sqlite { write, .. } => {
                Tx::Sqlite(write.begin_write().await.map_err(self.db_error(op))?)
            }
            Pools::Postgres { write, .. } => {
                Tx::Postgres(write.begin_write().await.map_err(self.db_error(op))?)
            }
        };
        Ok(Batch { store: self, tx })
    }
}

impl Batch<'_> {
    /// Commits every write of the batch at once.
    pub async fn commit(self) -> Result<(), StoreError> {
        self.commit_for("committing a batch of writes").await
    }

    pub(crate) async fn commit_for(self, op: &'static str) -> Result<(), StoreError> {
        let store = self.store;
        match self.tx {
            Tx::Sqlite(t) => t.commit().await,
            Tx::Postgres(t) => t.commit().await,
        }
        .map_err(store.db_error(op))
    }

    /// [`Store::insert_measurement`] in this batch.
    pub async fn insert_measurement(
        &mut self,
        m: &NewMeasurement,
    ) -> Result<MeasurementId, StoreError> {
        check_measurement(m)?;
        let raw = if m.raw_lift_mm.is_empty() {
            None
        } else {
            Some(encode_units(m.raw_lift_mm.iter().flatten().copied())?)
        };
        let averaged = encode_units(m.averaged_lift_mm.iter().copied())?;
        let (raw, averaged, analysis) = pack_data(raw.as_deref(), &averaged, &m.analysis_json)?;
        const OP: &str = "inserting a measurement";
        let store = self.store;
        with_tx!(self, tx => {
            sqlx::query(ENSURE_MACHINE)
                .bind(m.machine.as_str())
                .bind(m.received_at.as_millisecond())
                .execute(&mut *tx)
                .await
                .map_err(store.db_error(OP))?;
            let inserted: Option<i64> = sqlx::query_scalar(
                "INSERT INTO measurements (machine, part, lobe, received_at_ms, verdict, \
                 max_profile_error_um, base_radius_error_um, phase_error_deg, revolutions_used, \
                 points_per_rev, origin, sha256, recipe_snapshot_id, stage) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14) \
                 ON CONFLICT (sha256) DO NOTHING RETURNING id",
            )
            .bind(m.machine.as_str())
            .bind(m.part.as_str())
            .bind(m.lobe.as_str())
            .bind(m.received_at.as_millisecond())
            .bind(m.verdict.as_str())
            .bind(m.max_profile_error_um)
            .bind(m.base_radius_error_um)
            .bind(m.phase_error_deg)
            .bind(i64::from(m.revolutions_used))
            .bind(i64::from(m.points_per_rev))
            .bind(&m.origin)
            .bind(m.sha256.to_string())
            .bind(m.recipe_snapshot.map(|r| r.0))
            .bind(m.stage.as_str())
            .fetch_optional(&mut *tx)
            .await
            .map_err(store.db_error(OP))?;
            let id = match inserted {
                Some(id) => {
                    sqlx::query(
                        "INSERT INTO measurement_data (measurement_id, codec, raw_revolutions, \
                         averaged_profile, analysis_packed) VALUES ($1, $2, $3, $4, $5)",
                    )
                    .bind(id)
                    .bind(CODEC_PACKED)
                    .bind(raw)
                    .bind(averaged)
                    .bind(analysis)
                    .execute(&mut *tx)
                    .await
                    .map_err(store.db_error(OP))?;
                    id
                }
                None => sqlx::query_scalar("SELECT id FROM measurements WHERE sha256 = $1")
                    .bind(m.sha256.to_string())
                    .fetch_one(&mut *tx)
                    .await
                    .map_err(store.db_error(OP))?,
            };
            Ok(MeasurementId(id))
        })
    }

    /// [`Store::insert_table_version`] in this batch.
    pub async fn insert_table_version(
        &mut self,
        t: &NewTableVersion,
    ) -> Result<camloop_core::ids::TableVersion, StoreError> {
        check_name("machine", t.machine.as_str())?;
        check_name("lobe", &t.lobe)?;
        check_json("learning_params_json", &t.learning_params_json)?;
        let (status, why) = t.status.column()?;
        let sha256 = sha256_hex(t.program_text.as_bytes());
        const OP: &str = "inserting a table version";
        let store = self.store;
        with_tx!(self, tx => {
            sqlx::query(ENSURE_MACHINE)
                .bind(t.machine.as_str())
                .bind(t.created_at.as_millisecond())
                .execute(&mut *tx)
                .await
                .map_err(store.db_error(OP))?;
            if let Some(parent) = t.parent_version {
                let found: Option<i64> = sqlx::query_scalar(
                    "SELECT id FROM table_versions WHERE machine = $1 AND lobe = $2 AND version = $3",
                )
                .bind(t.machine.as_str())
                .bind(t.lobe.as_str())
                .bind(parent.to_i64())
                .fetch_optional(&mut *tx)
                .await
                .map_err(store.db_error(OP))?;
                if found.is_none() {
                    // A version derives from a stored one.
                    return Err(StoreError::NotFound {
                        what: format!(
                            "parent table version {parent} of machine {} lobe {}",
                            t.machine, t.lobe
                        ),
                    });
                }
            }
            let (base_id, depth, base) = next_link!(store, tx, TABLE_VERSIONS, t.machine.as_str(), t.lobe.as_str());
            let program = pack_text("program_packed", &t.program_text, &base[0])?;
            let learning = pack_text("learning_packed", &t.learning_params_json, &base[1])?;
            let (id, version): (i64, i64) = sqlx::query_as(
                "INSERT INTO table_versions (machine, lobe, version, parent_version, \
                 table_number, sha256, reason, created_at_ms, codec, base_id, chain_depth, \
                 program_packed, learning_packed) \
                 SELECT $1, $2, COALESCE($8, COALESCE(MAX(version), 0) + 1), $3, $4, $5, $6, $7, \
                 $9, $10, $11, $12, $13 \
                 FROM table_versions WHERE machine = $1 AND lobe = $2 \
                 RETURNING id, version",
            )
            .bind(t.machine.as_str())
            .bind(t.lobe.as_str())
            .bind(t.parent_version.map(|v| v.to_i64()))
            .bind(i64::from(t.table_number))
            .bind(&sha256)
            .bind(&t.reason)
            .bind(t.created_at.as_millisecond())
            .bind(t.version.map(|v| v.to_i64()))
            .bind(CODEC_PACKED)
            .bind(base_id)
            .bind(depth)
            .bind(&program)
            .bind(&learning)
            .fetch_one(&mut *tx)
            .await
            .map_err(store.db_error(OP))?;
            store.chains.put(
                (TABLE_VERSIONS.table, t.machine.as_str(), t.lobe.as_str()),
                id,
                vec![program, learning],
                vec![t.program_text.clone(), t.learning_params_json.clone()],
            );
            sqlx::query(
                "INSERT INTO table_version_status (table_version_id, status, why, at_ms) \
                 VALUES ($1, $2, $3, $4)",
            )
            .bind(id)
            .bind(status)
            .bind(why)
            .bind(t.created_at.as_millisecond())
            .execute(&mut *tx)
            .await
            .map_err(store.db_error(OP))?;
            crate::codec::version_of("version", version)
        })
    }

    /// [`Store::set_table_status`] in this batch.
    pub async fn set_table_status(
        &mut self,
        machine: &MachineName,
        lobe: &FeatureName,
        version: camloop_core::ids::TableVersion,
        status: &VersionStatus,
        at: jiff::Timestamp,
    ) -> Result<(), StoreError> {
        let (status, why) = status.column()?;
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let store = self.store;
        with_tx!(self, tx => {
            let done = sqlx::query(
                "INSERT INTO table_version_status (table_version_id, status, why, at_ms) \
                 SELECT id, $4, $5, $6 FROM table_versions \
                 WHERE machine = $1 AND lobe = $2 AND version = $3",
            )
            .bind(machine)
            .bind(lobe)
            .bind(version.to_i64())
            .bind(status)
            .bind(why)
            .bind(at.as_millisecond())
            .execute(&mut *tx)
            .await
            .map_err(store.db_error("recording a table status"))?;
            if done.rows_affected() == 0 {
                return Err(StoreError::NotFound {
                    what: format!("table version {version} of machine {machine} lobe {lobe}"),
                });
            }
            Ok(())
        })
    }

    /// Whether version `version` of (machine, lobe) is stored, as this batch sees it (its
    /// own writes included).
    pub async fn has_table_version(
        &mut self,
        machine: &MachineName,
        lobe: &FeatureName,
        version: camloop_core::ids::TableVersion,
    ) -> Result<bool, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let store = self.store;
        with_tx!(self, tx => {
            let found: Option<i64> = sqlx::query_scalar(
                "SELECT id FROM table_versions WHERE machine = $1 AND lobe = $2 AND version = $3",
            )
            .bind(machine)
            .bind(lobe)
            .bind(version.to_i64())
            .fetch_optional(&mut *tx)
            .await
            .map_err(store.db_error("looking up a table version"))?;
            Ok(found.is_some())
        })
    }

    /// [`Store::insert_event`] in this batch.
    pub async fn insert_event(&mut self, e: &NewEvent) -> Result<EventId, StoreError> {
        check_name("machine", e.machine.as_str())?;
        append_logged!(
            self,
            "inserting an event",
            e.machine.as_str(),
            e.at.as_millisecond(),
            "INSERT INTO events (machine, at_ms, level, kind, message) \
             VALUES ($1, $2, $3, $4, $5) RETURNING id",
            e.level.as_str(),
            e.kind.as_str(),
            &e.message,
        )
        .map(EventId)
    }

    /// [`Store::insert_dressing`] in this batch.
    pub async fn insert_dressing(&mut self, d: &NewDressing) -> Result<DressingId, StoreError> {
        check_name("machine", d.machine.as_str())?;
        check_finite("old_radius_mm", d.old_radius_mm)?;
        check_finite("new_radius_mm", d.new_radius_mm)?;
        if let Some(infeed) = d.infeed_um {
            check_finite("infeed_um", infeed)?;
        }
        append_logged!(
            self,
            "inserting a dressing",
            d.machine.as_str(),
            d.at.as_millisecond(),
            "INSERT INTO dressings (machine, at_ms, old_radius_mm, new_radius_mm, source, \
             infeed_um) VALUES ($1, $2, $3, $4, $5, $6) RETURNING id",
            d.old_radius_mm,
            d.new_radius_mm,
            &d.source,
            d.infeed_um,
        )
        .map(DressingId)
    }

    /// [`Store::insert_recipe_snapshot`] in this batch.
    pub async fn insert_recipe_snapshot(
        &mut self,
        r: &NewRecipeSnapshot,
    ) -> Result<RecipeSnapshotId, StoreError> {
        check_name("machine", r.machine.as_str())?;
        check_name("lobe", &r.lobe)?;
        check_json("recipe_json", &r.recipe_json)?;
        let sha256 = sha256_hex(r.recipe_json.as_bytes());
        const OP: &str = "inserting a recipe snapshot";
        let store = self.store;
        with_tx!(self, tx => {
            sqlx::query(ENSURE_MACHINE)
                .bind(r.machine.as_str())
                .bind(r.created_at.as_millisecond())
                .execute(&mut *tx)
                .await
                .map_err(store.db_error(OP))?;
            let newest: Option<(i64, String)> = sqlx::query_as(
                "SELECT id, sha256 FROM recipe_snapshots WHERE machine = $1 AND part = $2 \
                 AND lobe = $3 ORDER BY id DESC LIMIT 1",
            )
            .bind(r.machine.as_str())
            .bind(r.part.as_str())
            .bind(r.lobe.as_str())
            .fetch_optional(&mut *tx)
            .await
            .map_err(store.db_error(OP))?;
            if let Some((id, stored)) = newest
                && stored == sha256
            {
                return Ok(RecipeSnapshotId(id));
            }
            let id: i64 = sqlx::query_scalar(
                "INSERT INTO recipe_snapshots (machine, part, lobe, kind, recipe_json, sha256, \
                 created_at_ms) VALUES ($1, $2, $3, $4, $5, $6, $7) RETURNING id",
            )
            .bind(r.machine.as_str())
            .bind(r.part.as_str())
            .bind(r.lobe.as_str())
            .bind(r.kind.as_str())
            .bind(&r.recipe_json)
            .bind(&sha256)
            .bind(r.created_at.as_millisecond())
            .fetch_one(&mut *tx)
            .await
            .map_err(store.db_error(OP))?;
            Ok(RecipeSnapshotId(id))
        })
    }

    /// [`Store::save_learning_snapshot`] in this batch.
    pub async fn save_learning_snapshot(
        &mut self,
        machine: &MachineName,
        lobe: &FeatureName,
        state_json: &str,
        meaning_sha256: Option<&Sha256>,
        saved_at: jiff::Timestamp,
    ) -> Result<(), StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        check_name("machine", machine)?;
        check_name("lobe", lobe)?;
        check_json("state_json", state_json)?;
        let meaning_sha256 = meaning_sha256.map(Sha256::to_string);
        let state_sha256 = sha256_hex(state_json.as_bytes());
        const OP: &str = "saving learning state";
        let store = self.store;
        with_tx!(self, tx => {
            sqlx::query(ENSURE_MACHINE)
                .bind(machine)
                .bind(saved_at.as_millisecond())
                .execute(&mut *tx)
                .await
                .map_err(store.db_error(OP))?;
            let replace: Option<(i64, Option<i64>)> = match &meaning_sha256 {
                None => None,
                Some(meaning) => sqlx::query_as(REPLACEABLE_STATE)
                    .bind(machine)
                    .bind(lobe)
                    .bind(meaning)
                    .fetch_optional(&mut *tx)
                    .await
                    .map_err(store.db_error(OP))?,
            };
            let saved_ms = saved_at.as_millisecond();
            match replace {
                Some((id, base_id)) => {
                    // A snapshot with the same meaning as the newest, which nothing is packed
                    // against yet: it replaces that row.
                    let base = match base_id {
                        Some(b) => texts_of!(store, tx, LEARNING_STATES, machine, lobe, b).remove(0),
                        None => String::new(),
                    };
                    let packed = pack_text("state_packed", state_json, &base)?;
                    store.chains.put(
                        (LEARNING_STATES.table, machine, lobe),
                        id,
                        vec![packed.clone()],
                        vec![state_json.to_string()],
                    );
                    sqlx::query(
                        "UPDATE learning_states SET state_packed = $1, state_sha256 = $2, \
                         saved_at_ms = $3 WHERE id = $4",
                    )
                    .bind(packed)
                    .bind(&state_sha256)
                    .bind(saved_ms)
                    .bind(id)
                    .execute(&mut *tx)
                    .await
                    .map_err(store.db_error(OP))?;
                }
                None => {
                    let (base_id, depth, base) = next_link!(store, tx, LEARNING_STATES, machine, lobe);
                    let packed = pack_text("state_packed", state_json, &base[0])?;
                    let id: i64 = sqlx::query_scalar(
                        "INSERT INTO learning_states (machine, lobe, saved_at_ms, codec, base_id, \
                         chain_depth, state_packed, state_sha256, meaning_sha256) \
                         VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) RETURNING id",
                    )
                    .bind(machine)
                    .bind(lobe)
                    .bind(saved_ms)
                    .bind(CODEC_PACKED)
                    .bind(base_id)
                    .bind(depth)
                    .bind(&packed)
                    .bind(&state_sha256)
                    .bind(meaning_sha256)
                    .fetch_one(&mut *tx)
                    .await
                    .map_err(store.db_error(OP))?;
                    store.chains.put(
                        (LEARNING_STATES.table, machine, lobe),
                        id,
                        vec![packed],
                        vec![state_json.to_string()],
                    );
                }
            }
            Ok(())
        })
    }
}
