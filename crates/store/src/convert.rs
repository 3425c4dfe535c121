//! The in-place conversion of schema version 4: rows still in the version-1 layout
//! (`codec` 0) are packed, a batch per transaction, oldest first, when the store connects.
//! It can stop anywhere (a kill, a full disk) and continues at the next start, since every
//! read understands both layouts. A row that cannot be packed (a report that is not JSON)
//! stays as it is and is counted.

use super::chain::{Chained, LEARNING_STATES, TABLE_VERSIONS, fetch_chain};
use super::codec::{CODEC_PACKED, CODEC_PLAIN, sha256_hex};
use super::measurements::{StoredData, pack_data};
use super::pack::pack_text;
use super::{Store, StoreError, with_write};
use crate::BeginWrite;

/// SQLite `user_version` once every version-1 row is packed.
const PACKED_USER_VERSION: i64 = 4;

/// Rows packed per transaction.
const BATCH: i64 = 200;

/// What a conversion did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Converted {
    pub measurements: u64,
    pub table_versions: u64,
    pub learning_states: u64,
    /// Rows left in the version-1 layout because they could not be packed.
    pub left_as_they_were: u64,
}

type LegacyData = (i64, i64, Option<Vec<u8>>, Vec<u8>, Option<String>);

impl Store {
    /// Packs every row still in the version-1 layout (see the module doc).
    pub async fn pack_legacy_rows(&self) -> Result<Converted, StoreError> {
        let mut done = Converted::default();
        if self.packed_mark(None).await? {
            return Ok(done);
        }
        self.pack_measurements(&mut done).await?;
        for chained in [&TABLE_VERSIONS, &LEARNING_STATES] {
            self.pack_chained(chained, &mut done).await?;
        }
        self.packed_mark(Some(PACKED_USER_VERSION)).await?;
        Ok(done)
    }

    /// On SQLite, whether the file's header says every row is packed (`user_version`, which
    /// a start reads without touching a table page, so a later start never scans); with
    /// `Some`, says so. PostgreSQL has no such header: its check reads the partial indexes.
    async fn packed_mark(&self, set: Option<i64>) -> Result<bool, StoreError> {
        let super::Pools::Sqlite { write, .. } = &self.pools else {
            return Ok(false);
        };
        const OP: &str = "reading the file's packing mark";
        if let Some(v) = set {
            sqlx::query(&format!("PRAGMA user_version = {v}"))
                .execute(write)
                .await
                .map_err(self.db_error(OP))?;
            // The migration and the packing rewrote whole tables through the log: fold it
            // into the file now, at start, rather than in the last connection's close.
            sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                .execute(write)
                .await
                .map_err(self.db_error(OP))?;
            return Ok(true);
        }
        let v: i64 = sqlx::query_scalar("PRAGMA user_version")
            .fetch_one(write)
            .await
            .map_err(self.db_error(OP))?;
        Ok(v >= PACKED_USER_VERSION)
    }

    async fn pack_measurements(&self, done: &mut Converted) -> Result<(), StoreError> {
        const OP: &str = "packing stored measurements";
        let mut after = i64::MIN;
        loop {
            let more = with_write!(self, pool => {
                let rows: Vec<LegacyData> = sqlx::query_as(
                    "SELECT d.measurement_id, m.points_per_rev, d.raw_revolutions, \
                     d.averaged_profile, d.analysis_json FROM measurement_data d \
                     JOIN measurements m ON m.id = d.measurement_id \
                     WHERE d.codec = 0 AND d.measurement_id > $1 \
                     ORDER BY d.measurement_id LIMIT $2",
                )
                .bind(after)
                .bind(BATCH)
                .fetch_all(pool)
                .await
                .map_err(self.db_error(OP))?;
                let mut tx = pool.begin_write().await.map_err(self.db_error(OP))?;
                for (id, points, raw, averaged, analysis_json) in &rows {
                    after = *id;
                    let data = StoredData {
                        codec: CODEC_PLAIN,
                        raw: raw.clone(),
                        averaged: averaged.clone(),
                        analysis_json: analysis_json.clone(),
                        analysis_packed: None,
                    };
                    let packed = u32::try_from(*points)
                        .map_err(|_| StoreError::invalid("points_per_rev", "out of range"))
                        .and_then(|p| data.units(p))
                        .and_then(|(avg, raw)| {
                            pack_data(raw.as_deref(), &avg, &data.analysis()?)
                        });
                    let Ok((raw, averaged, analysis)) = packed else {
                        done.left_as_they_were += 1;
                        continue;
                    };
                    sqlx::query(
                        "UPDATE measurement_data SET codec = $1, raw_revolutions = $2, \
                         averaged_profile = $3, analysis_json = NULL, analysis_packed = $4 \
                         WHERE measurement_id = $5 AND codec = $6",
                    )
                    .bind(CODEC_PACKED)
                    .bind(raw)
                    .bind(averaged)
                    .bind(analysis)
                    .bind(id)
                    .bind(CODEC_PLAIN)
                    .execute(&mut *tx)
                    .await
                    .map_err(self.db_error(OP))?;
                    done.measurements += 1;
                }
                tx.commit().await.map_err(self.db_error(OP))?;
                rows.len() as i64 == BATCH
            });
            if !more {
                return Ok(());
            }
        }
    }

    /// Packs the version-1 rows of a chained table in id order, each against the newest
    /// older row of its (machine, lobe), which is already packed (or left plain).
    async fn pack_chained(&self, c: &Chained, done: &mut Converted) -> Result<(), StoreError> {
        const OP: &str = "packing stored history";
        let learning = c.table == LEARNING_STATES.table;
        let (select, base_sql, update) = chained_sql(c, learning);
        let mut after = i64::MIN;
        loop {
            let more = with_write!(self, pool => {
                let mut tx = pool.begin_write().await.map_err(self.db_error(OP))?;
                let rows = sqlx::query(&select)
                    .bind(after)
                    .bind(BATCH)
                    .fetch_all(&mut *tx)
                    .await
                    .map_err(self.db_error(OP))?;
                for row in &rows {
                    let id: i64 = super::col!(row, "id", "packing stored history");
                    let machine: String = super::col!(row, "machine", "packing stored history");
                    let lobe: String = super::col!(row, "lobe", "packing stored history");
                    after = id;
                    let plain: Vec<String> = (0..c.fields.len())
                        .map(|i| sqlx::Row::try_get(row, 3 + i))
                        .collect::<Result<_, _>>()
                        .map_err(super::error::db_error(OP))?;
                    let base: Option<(i64, i64)> = sqlx::query_as(&base_sql)
                        .bind(&machine)
                        .bind(&lobe)
                        .bind(id)
                        .fetch_optional(&mut *tx)
                        .await
                        .map_err(self.db_error(OP))?;
                    let (base_id, depth, dictionaries) = match base {
                        Some((b, d)) if d + 1 < super::chain::MAX_DEPTH => {
                            (Some(b), d + 1, fetch_chain!(self, &mut *tx, *c, b))
                        }
                        _ => (None, 0, vec![String::new(); c.fields.len()]),
                    };
                    let mut q = sqlx::query(&update).bind(CODEC_PACKED).bind(base_id).bind(depth);
                    for (i, (_, packed)) in c.fields.iter().enumerate() {
                        q = q.bind(pack_text(packed, &plain[i], &dictionaries[i])?);
                    }
                    if learning {
                        q = q.bind(sha256_hex(plain[0].as_bytes()));
                    }
                    q.bind(id).execute(&mut *tx).await.map_err(self.db_error(OP))?;
                    if learning {
                        done.learning_states += 1;
                    } else {
                        done.table_versions += 1;
                    }
                }
                tx.commit().await.map_err(self.db_error(OP))?;
                rows.len() as i64 == BATCH
            });
            if !more {
                return Ok(());
            }
        }
    }
}

/// The statements of [`Store::pack_chained`]: the version-1 rows after `$1` (the literal
/// `codec = 0` lets the partial index `*_plain` answer), the newest
/// older row of a (machine, lobe), and the update that packs a row.
fn chained_sql(c: &Chained, learning: bool) -> (String, String, String) {
    let texts: Vec<&str> = c.fields.iter().map(|f| f.0).collect();
    let select = format!(
        "SELECT id, machine, lobe, {} FROM {} WHERE codec = 0 AND id > $1 \
         ORDER BY id LIMIT $2",
        texts.join(", "),
        c.table
    );
    let base_sql = format!(
        "SELECT id, chain_depth FROM {} WHERE machine = $1 AND lobe = $2 AND id < $3 \
         ORDER BY id DESC LIMIT 1",
        c.table
    );
    let sets: Vec<String> = c
        .fields
        .iter()
        .enumerate()
        .map(|(i, (text, packed))| format!("{text} = NULL, {packed} = ${}", i + 4))
        .collect();
    let next = c.fields.len() + 4;
    let (digest, id_at) = if learning {
        (format!(", state_sha256 = ${next}"), next + 1)
    } else {
        (String::new(), next)
    };
    let update = format!(
        "UPDATE {} SET codec = $1, base_id = $2, chain_depth = $3, {}{digest} WHERE id = ${id_at}",
        c.table,
        sets.join(", "),
    );
    (select, base_sql, update)
}
