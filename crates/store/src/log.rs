//! Machines, recipe snapshots, wheel dressings, events and learning-state snapshots.

use super::chain::{LEARNING_STATES, fetch_chain};
use super::codec::{check_limit, feature_of, machine_of, part_name_of, sha256_hex};
use super::measurements::{Bind, Conditions, fetch_all_dynamic};
use super::unix_ms::instant;
use super::{
    Dressing, DressingId, Event, EventFilter, EventId, EventKind, EventLevel, Feature, FeatureKey,
    FeatureKind, LearningState, Machine, NewDressing, NewEvent, NewRecipeSnapshot,
    RecipeSnapshotId, Store, StoreError, at_col, col, with_read, with_write,
};
use camloop_core::digest::Sha256;
use camloop_core::names::{FeatureName, MachineName};

impl Store {
    /// Keeps a recipe snapshot of one lobe or pin. When the newest snapshot of that
    /// (machine, part, lobe) has the same JSON text, returns its id and writes nothing.
    pub async fn insert_recipe_snapshot(
        &self,
        r: &NewRecipeSnapshot,
    ) -> Result<RecipeSnapshotId, StoreError> {
        const OP: &str = "inserting a recipe snapshot";
        let mut batch = self.begin_batch_for(OP).await?;
        let id = batch.insert_recipe_snapshot(r).await?;
        batch.commit_for(OP).await?;
        Ok(id)
    }

    /// Machines seen by the store, by name.
    pub async fn machines(&self) -> Result<Vec<Machine>, StoreError> {
        with_read!(self, pool => {
            let rows: Vec<(String, i64)> =
                sqlx::query_as("SELECT name, first_seen_ms FROM machines ORDER BY name")
                    .fetch_all(pool)
                    .await
                    .map_err(self.db_error("listing machines"))?;
            rows.into_iter()
                .map(|(name, first_seen_ms)| {
                    Ok(Machine {
                        name: machine_of(name)?,
                        first_seen: instant(first_seen_ms, "first_seen_ms")?,
                    })
                })
                .collect()
        })
    }

    /// Lobes and pins of a machine with their newest recipe snapshot, by part then lobe.
    pub async fn features(&self, machine: &MachineName) -> Result<Vec<Feature>, StoreError> {
        let machine = machine.as_str();
        with_read!(self, pool => {
            let rows = sqlx::query(
                "SELECT r.id, r.part, r.lobe, r.kind, r.recipe_json, r.created_at_ms \
                 FROM recipe_snapshots r WHERE r.machine = $1 AND r.id = \
                 (SELECT MAX(r2.id) FROM recipe_snapshots r2 WHERE r2.machine = r.machine \
                  AND r2.part = r.part AND r2.lobe = r.lobe) ORDER BY r.part, r.lobe",
            )
            .bind(machine)
            .fetch_all(pool)
            .await
            .map_err(self.db_error("listing features"))?;
            rows.iter()
                .map(|row| {
                    let kind: String = col!(row, "kind", "reading a feature");
                    Ok(Feature {
                        recipe_snapshot: RecipeSnapshotId(col!(row, "id", "reading a feature")),
                        part: part_name_of(col!(row, "part", "reading a feature"))?,
                        lobe: feature_of("lobe", col!(row, "lobe", "reading a feature"))?,
                        kind: FeatureKind::parse(&kind)?,
                        recipe_json: col!(row, "recipe_json", "reading a feature"),
                        created_at: at_col!(row, "created_at_ms", "reading a feature"),
                    })
                })
                .collect()
        })
    }

    /// Every machine's lobes and pins with their newest recipe snapshot's kind, by machine,
    /// part then lobe: one query for a whole plant, where asking [`Self::features`] of each
    /// machine took one round trip per machine (500 at plant scale) and read every recipe.
    pub async fn feature_keys(&self) -> Result<Vec<FeatureKey>, StoreError> {
        const OP: &str = "listing features";
        with_read!(self, pool => {
            let rows: Vec<(String, String, String, String)> = sqlx::query_as(
                "SELECT r.machine, r.part, r.lobe, r.kind FROM recipe_snapshots r WHERE r.id = \
                 (SELECT MAX(r2.id) FROM recipe_snapshots r2 WHERE r2.machine = r.machine \
                  AND r2.part = r.part AND r2.lobe = r.lobe) ORDER BY r.machine, r.part, r.lobe",
            )
            .fetch_all(pool)
            .await
            .map_err(self.db_error(OP))?;
            rows.into_iter()
                .map(|(machine, part, lobe, kind)| {
                    Ok(FeatureKey {
                        machine: machine_of(machine)?,
                        part: part_name_of(part)?,
                        lobe: feature_of("lobe", lobe)?,
                        kind: FeatureKind::parse(&kind)?,
                    })
                })
                .collect()
        })
    }

    /// Appends a wheel dressing; returns its row id.
    pub async fn insert_dressing(&self, d: &NewDressing) -> Result<DressingId, StoreError> {
        const OP: &str = "inserting a dressing";
        let mut batch = self.begin_batch_for(OP).await?;
        let id = batch.insert_dressing(d).await?;
        batch.commit_for(OP).await?;
        Ok(id)
    }

    /// Whether this dressing (same machine, time and new radius) is stored: how a journal
    /// replayed after a crash recognises what it had already written.
    pub async fn dressing_exists(&self, d: &NewDressing) -> Result<bool, StoreError> {
        with_write!(self, pool => {
            let found: Option<i64> = sqlx::query_scalar(
                "SELECT id FROM dressings WHERE machine = $1 AND at_ms = $2 \
                 AND new_radius_mm = $3 LIMIT 1",
            )
            .bind(d.machine.as_str())
            .bind(d.at.as_millisecond())
            .bind(d.new_radius_mm)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("looking up a dressing"))?;
            Ok(found.is_some())
        })
    }

    /// The newest `limit` dressings of a machine, newest first.
    pub async fn dressings(
        &self,
        machine: &MachineName,
        limit: u32,
    ) -> Result<Vec<Dressing>, StoreError> {
        let machine = machine.as_str();
        let limit = check_limit(limit)?;
        with_read!(self, pool => {
            type Row = (i64, String, i64, f64, f64, String, Option<f64>);
            let rows: Vec<Row> = sqlx::query_as(
                "SELECT id, machine, at_ms, old_radius_mm, new_radius_mm, source, infeed_um \
                 FROM dressings WHERE machine = $1 ORDER BY at_ms DESC, id DESC LIMIT $2",
            )
            .bind(machine)
            .bind(limit)
            .fetch_all(pool)
            .await
            .map_err(self.db_error("listing dressings"))?;
            rows.into_iter()
                .map(|(id, machine, at_ms, old_radius_mm, new_radius_mm, source, infeed_um)| {
                    Ok(Dressing {
                        id: DressingId(id),
                        machine: machine_of(machine)?,
                        at: instant(at_ms, "at_ms")?,
                        old_radius_mm,
                        new_radius_mm,
                        infeed_um,
                        source,
                    })
                })
                .collect()
        })
    }

    /// Appends an alarm or event; returns its row id.
    pub async fn insert_event(&self, e: &NewEvent) -> Result<EventId, StoreError> {
        const OP: &str = "inserting an event";
        let mut batch = self.begin_batch_for(OP).await?;
        let id = batch.insert_event(e).await?;
        batch.commit_for(OP).await?;
        Ok(id)
    }

    /// Whether this event (same machine, time, kind and message) is stored: how a journal
    /// replayed after a crash recognises what it had already written.
    pub async fn event_exists(&self, e: &NewEvent) -> Result<bool, StoreError> {
        with_write!(self, pool => {
            let found: Option<i64> = sqlx::query_scalar(
                "SELECT id FROM events WHERE machine = $1 AND at_ms = $2 AND kind = $3 \
                 AND message = $4 LIMIT 1",
            )
            .bind(e.machine.as_str())
            .bind(e.at.as_millisecond())
            .bind(e.kind.as_str())
            .bind(&e.message)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("looking up an event"))?;
            Ok(found.is_some())
        })
    }

    /// Events matching `filter`, newest first.
    pub async fn events(&self, filter: &EventFilter) -> Result<Vec<Event>, StoreError> {
        let limit = check_limit(filter.limit)?;
        let mut c = Conditions::default();
        if let Some(machine) = &filter.machine {
            c.push("machine = ?", [Bind::Text(machine.to_string())]);
        }
        if let Some(since) = filter.since {
            c.push("at_ms >= ?", [Bind::I64(since.as_millisecond())]);
        }
        if let Some(until) = filter.until {
            c.push("at_ms < ?", [Bind::I64(until.as_millisecond())]);
        }
        if let Some(level) = filter.level {
            c.push("level = ?", [Bind::Text(level.as_str().to_owned())]);
        }
        let sql = format!(
            "SELECT id, machine, at_ms, level, kind, message FROM events {} \
             ORDER BY at_ms DESC, id DESC LIMIT {}",
            c.where_clause(),
            c.next_placeholder()
        );
        let mut binds = c.binds;
        binds.push(Bind::I64(limit));
        with_read!(self, pool => {
            let rows = fetch_all_dynamic!(self, pool, &sql, binds, "listing events");
            rows.iter()
                .map(|row| {
                    let level: String = col!(row, "level", "reading an event");
                    let kind: String = col!(row, "kind", "reading an event");
                    Ok(Event {
                        id: EventId(col!(row, "id", "reading an event")),
                        machine: machine_of(col!(row, "machine", "reading an event"))?,
                        at: at_col!(row, "at_ms", "reading an event"),
                        level: EventLevel::parse(&level)?,
                        kind: EventKind::parse(&kind)?,
                        message: col!(row, "message", "reading an event"),
                    })
                })
                .collect()
        })
    }

    /// Appends a learning-state snapshot of (machine, lobe); the newest one wins on load.
    /// Every call keeps a row (see [`Store::save_learning_snapshot`] to keep fewer).
    pub async fn save_learning_state(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        state_json: &str,
        saved_at: jiff::Timestamp,
    ) -> Result<(), StoreError> {
        self.save_learning_snapshot(machine, lobe, state_json, None, saved_at)
            .await
    }

    /// Saves a learning-state snapshot of (machine, lobe). `meaning_sha256` identifies what
    /// of the state matters to history (the caller decides, e.g. a digest of the correction
    /// and the learning's mode): when the newest row has the same one, that row is replaced
    /// by this snapshot instead of a row being added, so history keeps each meaningful change
    /// plus the latest. `None` always adds a row.
    pub async fn save_learning_snapshot(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        state_json: &str,
        meaning_sha256: Option<&Sha256>,
        saved_at: jiff::Timestamp,
    ) -> Result<(), StoreError> {
        const OP: &str = "saving learning state";
        let mut batch = self.begin_batch_for(OP).await?;
        batch
            .save_learning_snapshot(machine, lobe, state_json, meaning_sha256, saved_at)
            .await?;
        batch.commit_for(OP).await
    }

    /// Whether this learning-state snapshot of (machine, lobe) is stored: how a journal
    /// replayed after a crash recognises what it had already written.
    pub async fn learning_state_exists(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        state_json: &str,
        saved_at: jiff::Timestamp,
    ) -> Result<bool, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let state_sha256 = sha256_hex(state_json.as_bytes());
        with_write!(self, pool => {
            let found: Option<i64> = sqlx::query_scalar(
                "SELECT id FROM learning_states WHERE machine = $1 AND lobe = $2 \
                 AND saved_at_ms = $3 AND (state_sha256 = $4 OR state_json = $5) LIMIT 1",
            )
            .bind(machine)
            .bind(lobe)
            .bind(saved_at.as_millisecond())
            .bind(&state_sha256)
            .bind(state_json)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("looking up a learning state"))?;
            Ok(found.is_some())
        })
    }

    /// Whether the store holds this snapshot of (machine, lobe) or a later one: its newest
    /// row was saved after `saved_at`, or then with this very state. How a journal
    /// replayed after a crash recognises learning it had already written, now that a
    /// snapshot may have been replaced by a later one with the same meaning.
    pub async fn learning_state_covered(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        state_json: &str,
        saved_at: jiff::Timestamp,
    ) -> Result<bool, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let state_sha256 = sha256_hex(state_json.as_bytes());
        with_write!(self, pool => {
            let newest: Option<(i64, Option<String>, Option<String>)> = sqlx::query_as(
                "SELECT saved_at_ms, state_sha256, state_json FROM learning_states \
                 WHERE machine = $1 AND lobe = $2 ORDER BY id DESC LIMIT 1",
            )
            .bind(machine)
            .bind(lobe)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("looking up a learning state"))?;
            Ok(newest.is_some_and(|(at, sha, text)| {
                at > saved_at.as_millisecond()
                    || (at == saved_at.as_millisecond()
                        && (sha.as_deref() == Some(state_sha256.as_str())
                            || text.as_deref() == Some(state_json)))
            }))
        })
    }

    /// Every (machine, lobe) the store holds a learning state for, in one query: a plant's
    /// start asks this once instead of asking each of its thousands of features (a new
    /// plant's have none). Through the writer, as [`Self::load_learning_state`] reads.
    pub async fn learning_state_keys(&self) -> Result<Vec<(MachineName, FeatureName)>, StoreError> {
        with_write!(self, pool => {
            let rows: Vec<(String, String)> =
                sqlx::query_as("SELECT DISTINCT machine, lobe FROM learning_states")
                    .fetch_all(pool)
                    .await
                    .map_err(self.db_error("listing learning states"))?;
            rows.into_iter()
                .map(|(machine, lobe)| Ok((machine_of(machine)?, feature_of("lobe", lobe)?)))
                .collect()
        })
    }

    /// The newest learning-state snapshot of (machine, lobe), or `None` before the first save.
    pub async fn load_learning_state(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
    ) -> Result<Option<LearningState>, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        with_write!(self, pool => {
            let row: Option<(i64, i64, Option<String>)> = sqlx::query_as(
                "SELECT id, saved_at_ms, state_sha256 FROM learning_states \
                 WHERE machine = $1 AND lobe = $2 ORDER BY id DESC LIMIT 1",
            )
            .bind(machine)
            .bind(lobe)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("loading learning state"))?;
            match row {
                None => Ok(None),
                Some((id, saved_at_ms, sha256)) => {
                    let state_json = fetch_chain!(self, pool, LEARNING_STATES, id).remove(0);
                    // A packed state is checked like a program: a damaged chain is an error,
                    // never a learning state with other numbers.
                    if sha256.is_some_and(|s| s != sha256_hex(state_json.as_bytes())) {
                        return Err(StoreError::invalid(
                            "state_json",
                            format!("learning state of machine {machine} lobe {lobe} does not match its SHA-256"),
                        ));
                    }
                    let saved_at = instant(saved_at_ms, "saved_at_ms")?;
                    Ok(Some(LearningState { state_json, saved_at }))
                }
            }
        })
    }
}
