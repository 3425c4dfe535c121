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
        self.pack_measurements(&mut done).await?;
        for chained in [&TABLE_VERSIONS, &LEARNING_STATES] {
            self.pack_chained(chained, &mut done).await?;
        }
        Ok(done)
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
                     WHERE d.codec = $1 AND d.measurement_id > $2 \
                     ORDER BY d.measurement_id LIMIT $3",
                )
                .bind(CODEC_PLAIN)
                .bind(after)
                .bind(BATCH)
                .fetch_all(pool)
                .await
                .map_err(self.db_error(OP))?;
                let mut tx = pool.begin().await.map_err(self.db_error(OP))?;
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
        let texts: Vec<&str> = c.fields.iter().map(|f| f.0).collect();
        let select = format!(
            "SELECT id, machine, lobe, {} FROM {} WHERE codec = $1 AND id > $2 \
             ORDER BY id LIMIT $3",
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
        let learning = c.table == LEARNING_STATES.table;
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
        let mut after = i64::MIN;
        loop {
            let more = with_write!(self, pool => {
                let mut tx = pool.begin().await.map_err(self.db_error(OP))?;
                let rows = sqlx::query(&select)
                    .bind(CODEC_PLAIN)
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
