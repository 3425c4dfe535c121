//! Seeds a history store with synthetic measurements for the benchmarks, inside the
//! database (a recursive CTE on SQLite, `generate_series` on PostgreSQL), so a million rows
//! take seconds instead of a million round trips.
//!
//! Shape of the seed: 8 machines `M0`…`M7` × 16 lobes `L0`…`L15`, one measurement per
//! second in round-robin (row n: machine n mod 8, lobe (n div 8) mod 16), so each lobe holds
//! n/128 measurements spread over the whole time range, as a busy plant would. 1 in 23 fails.
//! Each measurement has a 1,440-byte averaged profile (360 i32 values) and a small report;
//! raw revolutions are NULL, as retention leaves them in a store this old. The rows are in
//! the version-1 layout (`codec` 0), which every read understands; the store packs them
//! when it next connects.
//!
//! Used by `benches/store.rs` through `#[path]`; not part of the library.

use camloop::store::{RawPool, Store};

/// First `received_at_ms` of the seed (2023-11-14T22:13:20Z).
pub const SEED_START_MS: i64 = 1_700_000_000_000;

/// Rows in `measurements`.
pub async fn count(store: &Store) -> Result<i64, sqlx::Error> {
    let q = "SELECT COUNT(*) FROM measurements";
    match store.raw_pool() {
        RawPool::Sqlite(pool) => sqlx::query_scalar(q).fetch_one(pool).await,
        RawPool::Postgres(pool) => sqlx::query_scalar(q).fetch_one(pool).await,
    }
}

/// Empties the measurement tables and inserts `n` seeded measurements with their data rows,
/// then refreshes the planner statistics.
pub async fn seed(store: &Store, n: i64) -> Result<(), sqlx::Error> {
    match store.raw_pool() {
        RawPool::Sqlite(pool) => {
            let mut tx = pool.begin().await?;
            for sql in [
                "DELETE FROM measurement_data",
                "DELETE FROM measurements",
                "INSERT INTO machines (name, first_seen_ms) \
                 WITH RECURSIVE s(k) AS (SELECT 0 UNION ALL SELECT k + 1 FROM s WHERE k < 7) \
                 SELECT 'M' || k, 0 FROM s WHERE true ON CONFLICT (name) DO NOTHING",
            ] {
                sqlx::query(sql).execute(&mut *tx).await?;
            }
            sqlx::query(
                "INSERT INTO measurements (machine, part, lobe, received_at_ms, verdict, \
                 max_profile_error_um, base_radius_error_um, phase_error_deg, revolutions_used, \
                 points_per_rev, origin, sha256) \
                 WITH RECURSIVE s(k) AS (SELECT 0 UNION ALL SELECT k + 1 FROM s WHERE k < $1 - 1) \
                 SELECT 'M' || (k % 8), 'P-' || (k / 128), 'L' || ((k / 8) % 16), \
                 $2 + k * 1000, CASE WHEN k % 23 = 0 THEN 'fail' ELSE 'pass' END, \
                 1.0 + (k % 97) * 0.05, -0.5, 0.01 * (k % 7), 3, 360, 'seed', printf('%064x', k) \
                 FROM s",
            )
            .bind(n)
            .bind(SEED_START_MS)
            .execute(&mut *tx)
            .await?;
            sqlx::query(
                "INSERT INTO measurement_data (measurement_id, codec, raw_revolutions, \
                 averaged_profile, analysis_json) \
                 SELECT id, 0, NULL, zeroblob(1440), '{\"seeded\":true}' FROM measurements",
            )
            .execute(&mut *tx)
            .await?;
            tx.commit().await?;
            sqlx::query("ANALYZE").execute(pool).await?;
            // Fold the seed's WAL into the main file, as a long-running store would have.
            sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                .execute(pool)
                .await?;
        }
        RawPool::Postgres(pool) => {
            let mut tx = pool.begin().await?;
            for sql in [
                "TRUNCATE measurement_data, measurements",
                "INSERT INTO machines (name, first_seen_ms) \
                 SELECT 'M' || k, 0 FROM generate_series(0, 7) AS k ON CONFLICT (name) DO NOTHING",
            ] {
                sqlx::query(sql).execute(&mut *tx).await?;
            }
            sqlx::query(
                "INSERT INTO measurements (machine, part, lobe, received_at_ms, verdict, \
                 max_profile_error_um, base_radius_error_um, phase_error_deg, revolutions_used, \
                 points_per_rev, origin, sha256) \
                 SELECT 'M' || (k % 8), 'P-' || (k / 128), 'L' || ((k / 8) % 16), \
                 $2 + k * 1000, CASE WHEN k % 23 = 0 THEN 'fail' ELSE 'pass' END, \
                 1.0 + (k % 97) * 0.05, -0.5, 0.01 * (k % 7), 3, 360, 'seed', \
                 lpad(to_hex(k), 64, '0') FROM generate_series(0::bigint, $1 - 1) AS k",
            )
            .bind(n)
            .bind(SEED_START_MS)
            .execute(&mut *tx)
            .await?;
            sqlx::query(
                "INSERT INTO measurement_data (measurement_id, codec, raw_revolutions, \
                 averaged_profile, analysis_json) \
                 SELECT id, 0, NULL, decode(repeat('00', 1440), 'hex'), '{\"seeded\":true}' \
                 FROM measurements",
            )
            .execute(&mut *tx)
            .await?;
            tx.commit().await?;
            sqlx::query("VACUUM ANALYZE").execute(pool).await?;
        }
    }
    Ok(())
}
