//! Measurements: idempotent append, the keyset-paginated history query, detail, export and
//! raw-blob retention.

use super::codec::{
    CODEC_PACKED, CODEC_PLAIN, check_finite, check_json, check_limit, check_name, decode_cursor,
    decode_units, encode_cursor, units_to_mm,
};
use super::pack::{pack_profile, pack_revolutions, unpack_profile, unpack_revolutions};
use super::pack_report::{pack_report, unpack_report};
use super::{
    HistoryFilter, MasterRuns, MeasurementDetail, MeasurementId, MeasurementSummary,
    NewMeasurement, Page, RecipeSnapshotId, Store, StoreError, Verdict, at_col, col, with_read,
    with_write,
};
use camloop_core::ids::PartId;
use camloop_core::measure::MASTER_PART_PREFIX;
use camloop_core::names::{FeatureName, MachineName};

const SUMMARY_COLUMNS: &str = "m.id, m.machine, m.part, m.lobe, m.received_at_ms, m.verdict, \
     m.max_profile_error_um, m.base_radius_error_um, m.phase_error_deg, m.revolutions_used, \
     m.points_per_rev, m.origin, m.sha256, m.recipe_snapshot_id, m.stage";

/// A value bound to a dynamically built query.
pub(crate) enum Bind {
    I64(i64),
    Text(String),
}

/// Builds `WHERE` clauses with numbered placeholders accepted by both backends.
#[derive(Default)]
pub(crate) struct Conditions {
    pub(crate) sql: Vec<String>,
    pub(crate) binds: Vec<Bind>,
}

impl Conditions {
    /// Adds `clause`, where each `?` is replaced by the next placeholder, bound in order.
    pub(crate) fn push(&mut self, clause: &str, binds: impl IntoIterator<Item = Bind>) {
        let mut text = String::new();
        let mut binds = binds.into_iter();
        for piece in clause.split_inclusive('?') {
            if let Some(head) = piece.strip_suffix('?') {
                let b = binds.next().expect("one bind per placeholder in store SQL");
                self.binds.push(b);
                text.push_str(head);
                text.push_str(&format!("${}", self.binds.len()));
            } else {
                text.push_str(piece);
            }
        }
        self.sql.push(text);
    }

    pub(crate) fn where_clause(&self) -> String {
        if self.sql.is_empty() {
            String::new()
        } else {
            format!("WHERE {}", self.sql.join(" AND "))
        }
    }

    pub(crate) fn next_placeholder(&self) -> String {
        format!("${}", self.binds.len() + 1)
    }
}

/// Runs a dynamically built query returning rows, binding `$binds` in order; errors name
/// `$store`'s database.
macro_rules! fetch_all_dynamic {
    ($store:expr, $pool:expr, $sql:expr, $binds:expr, $op:literal) => {{
        let mut q = sqlx::query($sql);
        for b in $binds {
            q = match b {
                $crate::measurements::Bind::I64(v) => q.bind(v),
                $crate::measurements::Bind::Text(v) => q.bind(v),
            };
        }
        q.fetch_all($pool).await.map_err($store.db_error($op))?
    }};
}
pub(crate) use fetch_all_dynamic;

macro_rules! summary_from_row {
    ($row:expr) => {{
        let row = $row;
        let verdict: String = col!(row, "verdict", "reading a measurement");
        let revolutions_used: i64 = col!(row, "revolutions_used", "reading a measurement");
        let points_per_rev: i64 = col!(row, "points_per_rev", "reading a measurement");
        let recipe: Option<i64> = col!(row, "recipe_snapshot_id", "reading a measurement");
        let stage: String = col!(row, "stage", "reading a measurement");
        MeasurementSummary {
            id: MeasurementId(col!(row, "id", "reading a measurement")),
            machine: $crate::codec::machine_of(col!(row, "machine", "reading a measurement"))?,
            part: $crate::codec::part_of(col!(row, "part", "reading a measurement"))?,
            lobe: $crate::codec::feature_of("lobe", col!(row, "lobe", "reading a measurement"))?,
            received_at: at_col!(row, "received_at_ms", "reading a measurement"),
            verdict: Verdict::parse(&verdict)?,
            max_profile_error_um: col!(row, "max_profile_error_um", "reading a measurement"),
            base_radius_error_um: col!(row, "base_radius_error_um", "reading a measurement"),
            phase_error_deg: col!(row, "phase_error_deg", "reading a measurement"),
            revolutions_used: to_u32("revolutions_used", revolutions_used)?,
            points_per_rev: to_u32("points_per_rev", points_per_rev)?,
            origin: col!(row, "origin", "reading a measurement"),
            sha256: $crate::codec::sha256_of(
                "sha256",
                col!(row, "sha256", "reading a measurement"),
            )?,
            recipe_snapshot: recipe.map(RecipeSnapshotId),
            stage: $crate::MeasurementStage::parse(&stage)?,
        }
    }};
}

macro_rules! detail_from_row {
    ($row:expr) => {{
        let row = $row;
        let summary = summary_from_row!(row);
        let data = StoredData {
            codec: col!(row, "codec", "reading a measurement"),
            raw: col!(row, "raw_revolutions", "reading a measurement"),
            averaged: col!(row, "averaged_profile", "reading a measurement"),
            analysis_json: col!(row, "analysis_json", "reading a measurement"),
            analysis_packed: col!(row, "analysis_packed", "reading a measurement"),
        };
        let (raw_lift_mm, averaged_lift_mm, analysis_json) = data.decode(summary.points_per_rev)?;
        MeasurementDetail {
            averaged_lift_mm,
            analysis_json,
            raw_lift_mm,
            summary,
        }
    }};
}

/// The columns of a `measurement_data` row, in either codec.
pub(crate) struct StoredData {
    pub(crate) codec: i64,
    pub(crate) raw: Option<Vec<u8>>,
    pub(crate) averaged: Vec<u8>,
    pub(crate) analysis_json: Option<String>,
    pub(crate) analysis_packed: Option<Vec<u8>>,
}

/// Raw revolutions (if kept), averaged profile and report of a measurement.
type Decoded = (Option<Vec<Vec<f64>>>, Vec<f64>, String);

impl StoredData {
    /// Lift units of the averaged profile and (if kept) the raw revolutions.
    pub(crate) fn units(
        &self,
        points_per_rev: u32,
    ) -> Result<(Vec<i32>, Option<Vec<i32>>), StoreError> {
        match self.codec {
            CODEC_PLAIN => Ok((
                decode_units(&self.averaged)?,
                self.raw.as_deref().map(decode_units).transpose()?,
            )),
            CODEC_PACKED => {
                let averaged = unpack_profile(&self.averaged, points_per_rev as usize)?;
                let raw = match &self.raw {
                    None => None,
                    Some(blob) => Some(unpack_revolutions(blob, &averaged)?),
                };
                Ok((averaged, raw))
            }
            other => Err(StoreError::invalid(
                "codec",
                format!("unknown codec {other}"),
            )),
        }
    }

    pub(crate) fn analysis(&self) -> Result<String, StoreError> {
        match (self.codec, &self.analysis_json, &self.analysis_packed) {
            (CODEC_PLAIN, Some(text), _) => Ok(text.clone()),
            (CODEC_PACKED, _, Some(blob)) => unpack_report(blob),
            (codec, _, _) => Err(StoreError::invalid(
                "analysis",
                format!("codec {codec} row without its report"),
            )),
        }
    }

    fn decode(&self, points_per_rev: u32) -> Result<Decoded, StoreError> {
        let (averaged, raw) = self.units(points_per_rev)?;
        let raw = match raw {
            None => None,
            Some(units) => Some(split_revolutions(units_to_mm(&units), points_per_rev)?),
        };
        Ok((raw, units_to_mm(&averaged), self.analysis()?))
    }
}

/// Packed `raw_revolutions`, `averaged_profile` and `analysis_packed`.
pub(crate) type PackedData = (Option<Vec<u8>>, Vec<u8>, Vec<u8>);

/// The packed columns of a new row: raw revolutions, averaged profile, report.
pub(crate) fn pack_data(
    raw: Option<&[i32]>,
    averaged: &[i32],
    analysis_json: &str,
) -> Result<PackedData, StoreError> {
    let raw = raw.map(|r| pack_revolutions(r, averaged)).transpose()?;
    Ok((raw, pack_profile(averaged)?, pack_report(analysis_json)?))
}

fn to_u32(field: &'static str, value: i64) -> Result<u32, StoreError> {
    u32::try_from(value)
        .map_err(|_| StoreError::invalid(field, format!("stored value {value} out of range")))
}

fn split_revolutions(lifts: Vec<f64>, points_per_rev: u32) -> Result<Vec<Vec<f64>>, StoreError> {
    let n = points_per_rev as usize;
    if n == 0 || !lifts.len().is_multiple_of(n) {
        return Err(StoreError::invalid(
            "raw blob",
            format!("{} values are not whole revolutions of {n}", lifts.len()),
        ));
    }
    Ok(lifts.chunks_exact(n).map(<[f64]>::to_vec).collect())
}

pub(crate) fn check_measurement(m: &NewMeasurement) -> Result<(), StoreError> {
    check_name("machine", m.machine.as_str())?;
    check_name("lobe", &m.lobe)?;
    check_json("analysis_json", &m.analysis_json)?;
    check_finite("max_profile_error_um", m.max_profile_error_um)?;
    check_finite("base_radius_error_um", m.base_radius_error_um)?;
    check_finite("phase_error_deg", m.phase_error_deg)?;
    let n = m.points_per_rev as usize;
    if n == 0 {
        return Err(StoreError::invalid("points_per_rev", "must be at least 1"));
    }
    if m.averaged_lift_mm.len() != n {
        return Err(StoreError::invalid(
            "averaged_lift_mm",
            format!(
                "{} values, expected points_per_rev = {n}",
                m.averaged_lift_mm.len()
            ),
        ));
    }
    if let Some((i, rev)) = m.raw_lift_mm.iter().enumerate().find(|(_, r)| r.len() != n) {
        return Err(StoreError::invalid(
            "raw_lift_mm",
            format!("revolution {i} has {} values, expected {n}", rev.len()),
        ));
    }
    Ok(())
}

impl Store {
    /// Appends a measurement with its blobs and report. Idempotent on `sha256`: inserting a
    /// measurement whose hash is stored returns the stored id and changes nothing.
    pub async fn insert_measurement(
        &self,
        m: &NewMeasurement,
    ) -> Result<MeasurementId, StoreError> {
        const OP: &str = "inserting a measurement";
        let mut batch = self.begin_batch_for(OP).await?;
        let id = batch.insert_measurement(m).await?;
        batch.commit_for(OP).await?;
        Ok(id)
    }

    /// Lists measurements of one machine, newest first (by `received_at_ms`, then id), one
    /// page at a time. Pass the returned `next_cursor` to get the next page; pages stay
    /// consistent while new measurements arrive (keyset pagination, not offsets).
    pub async fn measurement_history(
        &self,
        filter: &HistoryFilter,
    ) -> Result<Page<MeasurementSummary>, StoreError> {
        check_name("machine", &filter.machine)?;
        let limit = check_limit(filter.limit)?;
        let mut c = Conditions::default();
        c.push("m.machine = ?", [Bind::Text(filter.machine.to_string())]);
        if let Some(lobe) = &filter.lobe {
            c.push("m.lobe = ?", [Bind::Text(lobe.to_string())]);
        }
        if let Some(since) = filter.since {
            c.push("m.received_at_ms >= ?", [Bind::I64(since.as_millisecond())]);
        }
        if let Some(until) = filter.until {
            c.push("m.received_at_ms < ?", [Bind::I64(until.as_millisecond())]);
        }
        if let Some(verdict) = filter.verdict {
            c.push("m.verdict = ?", [Bind::Text(verdict.as_str().to_owned())]);
        }
        if let Some(stage) = filter.stage {
            c.push("m.stage = ?", [Bind::Text(stage.as_str().to_owned())]);
        }
        // The same test as `is_master_part`: the prefix, ASCII case ignored (PostgreSQL's LIKE
        // is case-sensitive, SQLite's is not, so both compare the upper case).
        let master = format!(
            "UPPER(SUBSTR(m.part, 1, {})) = '{}'",
            MASTER_PART_PREFIX.len(),
            MASTER_PART_PREFIX.to_ascii_uppercase()
        );
        match filter.masters {
            MasterRuns::Included => {}
            MasterRuns::Excluded => c.push(&format!("NOT {master}"), []),
            MasterRuns::Only => c.push(&master, []),
        }
        if let Some(cursor) = &filter.cursor {
            let (at, id) = decode_cursor(cursor)?;
            // The first term bounds the index range; the second picks up ties on the time.
            c.push("m.received_at_ms <= ?", [Bind::I64(at)]);
            c.push(
                "(m.received_at_ms < ? OR (m.received_at_ms = ? AND m.id < ?))",
                [Bind::I64(at), Bind::I64(at), Bind::I64(id)],
            );
        }
        let sql = format!(
            "SELECT {SUMMARY_COLUMNS} FROM measurements m {} \
             ORDER BY m.received_at_ms DESC, m.id DESC LIMIT {}",
            c.where_clause(),
            c.next_placeholder()
        );
        let mut binds = c.binds;
        binds.push(Bind::I64(limit + 1));
        let mut items = with_read!(self, pool => {
            let rows = fetch_all_dynamic!(self, pool, &sql, binds, "listing measurement history");
            rows.iter().map(|row| Ok(summary_from_row!(row))).collect::<Result<Vec<_>, StoreError>>()?
        });
        let next_cursor = if items.len() > filter.limit as usize {
            items.truncate(filter.limit as usize);
            items
                .last()
                .map(|s| encode_cursor(s.received_at.as_millisecond(), s.id.0))
        } else {
            None
        };
        Ok(Page { items, next_cursor })
    }

    /// Every measurement of one part (a shaft, by the number the gauge gave) on one machine,
    /// oldest first: what answers "did shaft 1234 pass, lobe by lobe". At most `MAX_PAGE`.
    pub async fn part_measurements(
        &self,
        machine: &MachineName,
        part: &PartId,
    ) -> Result<Vec<MeasurementSummary>, StoreError> {
        check_name("machine", machine)?;
        let sql = format!(
            "SELECT {SUMMARY_COLUMNS} FROM measurements m \
             WHERE m.machine = $1 AND m.part = $2 ORDER BY m.id LIMIT {}",
            super::MAX_PAGE
        );
        with_read!(self, pool => {
            let rows = sqlx::query(&sql)
                .bind(machine.as_str())
                .bind(part.as_str())
                .fetch_all(pool)
                .await
                .map_err(self.db_error("reading a part's measurements"))?;
            rows.iter().map(|row| Ok(summary_from_row!(row))).collect::<Result<Vec<_>, StoreError>>()
        })
    }

    /// One measurement with its profiles and report, or `None` when no such id.
    pub async fn measurement(
        &self,
        id: MeasurementId,
    ) -> Result<Option<MeasurementDetail>, StoreError> {
        let sql = format!(
            "SELECT {SUMMARY_COLUMNS}, d.codec, d.raw_revolutions, d.averaged_profile, \
             d.analysis_json, d.analysis_packed \
             FROM measurements m JOIN measurement_data d ON d.measurement_id = m.id WHERE m.id = $1"
        );
        with_read!(self, pool => {
            let row = sqlx::query(&sql)
                .bind(id.0)
                .fetch_optional(pool)
                .await
                .map_err(self.db_error("reading a measurement"))?;
            match row {
                None => Ok(None),
                Some(row) => Ok(Some(detail_from_row!(&row))),
            }
        })
    }

    /// Measurements received in `[since, until)` with their profiles, oldest id first,
    /// after `after` (exclusive), at most `limit`: call again with the last id to continue.
    pub async fn export(
        &self,
        since: jiff::Timestamp,
        until: jiff::Timestamp,
        after: Option<MeasurementId>,
        limit: u32,
    ) -> Result<Vec<MeasurementDetail>, StoreError> {
        let limit = check_limit(limit)?;
        let sql = format!(
            "SELECT {SUMMARY_COLUMNS}, d.codec, d.raw_revolutions, d.averaged_profile, \
             d.analysis_json, d.analysis_packed \
             FROM measurements m JOIN measurement_data d ON d.measurement_id = m.id \
             WHERE m.received_at_ms >= $1 AND m.received_at_ms < $2 AND m.id > $3 \
             ORDER BY m.id LIMIT $4"
        );
        with_read!(self, pool => {
            let rows = sqlx::query(&sql)
                .bind(since.as_millisecond())
                .bind(until.as_millisecond())
                .bind(after.map_or(i64::MIN, |a| a.0))
                .bind(limit)
                .fetch_all(pool)
                .await
                .map_err(self.db_error("exporting measurements"))?;
            rows.iter().map(|row| Ok(detail_from_row!(row))).collect()
        })
    }

    /// One feature's measurements received in `[since, until)` with their reports,
    /// newest first, before id `before` (exclusive; call again with the last id to go on),
    /// at most `limit`: the window of a capability study or a control chart.
    pub async fn feature_measurements(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        (since_ms, until_ms): (jiff::Timestamp, jiff::Timestamp),
        before: Option<MeasurementId>,
        limit: u32,
    ) -> Result<Vec<MeasurementDetail>, StoreError> {
        check_name("machine", machine)?;
        let limit = check_limit(limit)?;
        let sql = format!(
            "SELECT {SUMMARY_COLUMNS}, d.codec, d.raw_revolutions, d.averaged_profile, \
             d.analysis_json, d.analysis_packed \
             FROM measurements m JOIN measurement_data d ON d.measurement_id = m.id \
             WHERE m.machine = $1 AND m.lobe = $2 AND m.received_at_ms >= $3 \
             AND m.received_at_ms < $4 AND m.id < $5 ORDER BY m.id DESC LIMIT $6"
        );
        with_read!(self, pool => {
            let rows = sqlx::query(&sql)
                .bind(machine.as_str())
                .bind(lobe.as_str())
                .bind(since_ms.as_millisecond())
                .bind(until_ms.as_millisecond())
                .bind(before.map_or(i64::MAX, |b| b.0))
                .bind(limit)
                .fetch_all(pool)
                .await
                .map_err(self.db_error("reading a feature's measurements"))?;
            rows.iter().map(|row| Ok(detail_from_row!(row))).collect()
        })
    }

    /// The id of the newest measurement, `None` while there is none: what the dashboard's
    /// live channel polls (one index lookup).
    pub async fn newest_measurement_id(&self) -> Result<Option<MeasurementId>, StoreError> {
        with_read!(self, pool => {
            let id: Option<i64> = sqlx::query_scalar("SELECT MAX(id) FROM measurements")
                .fetch_one(pool)
                .await
                .map_err(self.db_error("reading the newest measurement id"))?;
            Ok(id.map(MeasurementId))
        })
    }

    /// Summaries of the measurements after `after` (exclusive), oldest first, at most `limit`.
    pub async fn measurements_after(
        &self,
        after: MeasurementId,
        limit: u32,
    ) -> Result<Vec<MeasurementSummary>, StoreError> {
        let limit = check_limit(limit)?;
        let sql = format!(
            "SELECT {SUMMARY_COLUMNS} FROM measurements m WHERE m.id > $1 ORDER BY m.id LIMIT $2"
        );
        with_read!(self, pool => {
            let rows = sqlx::query(&sql)
                .bind(after.0)
                .bind(limit)
                .fetch_all(pool)
                .await
                .map_err(self.db_error("listing new measurements"))?;
            rows.iter().map(|row| Ok(summary_from_row!(row))).collect()
        })
    }

    /// Retention: drops the raw revolutions of measurements received before `cutoff`,
    /// keeping their summaries, averaged profiles and reports. Returns how many were pruned.
    pub async fn prune_raw_older_than(&self, cutoff: jiff::Timestamp) -> Result<u64, StoreError> {
        with_write!(self, pool => {
            let done = sqlx::query(
                "UPDATE measurement_data SET raw_revolutions = NULL \
                 WHERE raw_revolutions IS NOT NULL AND measurement_id IN \
                 (SELECT id FROM measurements WHERE received_at_ms < $1)",
            )
            .bind(cutoff.as_millisecond())
            .execute(pool)
            .await
            .map_err(self.db_error("pruning raw revolutions"))?;
            Ok(done.rows_affected())
        })
    }
}
