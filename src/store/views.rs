//! What the dashboard reads and writes beyond the API's queries: acknowledgements of events
//! and alarms (appended, once per event), and the learning state read through the readers'
//! gate (the machine loop reads it through the writer; a dashboard must never take that).

use super::codec::check_limit;
use super::{EventId, LearningState, Store, StoreError, col, with_read, with_write};

/// An event's acknowledgement.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EventAck {
    pub event: EventId,
    pub at_ms: i64,
    /// Who acknowledged ("dashboard").
    pub source: String,
}

/// What acknowledging an event did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AckOutcome {
    /// Recorded now.
    Acknowledged,
    /// It was acknowledged before; the first acknowledgement stays.
    AlreadyAcknowledged,
    /// No such event on that machine.
    NotFound,
}

impl Store {
    /// Acknowledges event `id` of `machine` at `at_ms`. Appended: a second acknowledgement
    /// changes nothing and says so.
    pub async fn acknowledge_event(
        &self,
        machine: &str,
        id: EventId,
        at_ms: i64,
        source: &str,
    ) -> Result<AckOutcome, StoreError> {
        const OP: &str = "acknowledging an event";
        with_write!(self, pool => {
            let mut tx = pool.begin().await.map_err(self.db_error(OP))?;
            let found: Option<i64> =
                sqlx::query_scalar("SELECT id FROM events WHERE id = $1 AND machine = $2")
                    .bind(id.0)
                    .bind(machine)
                    .fetch_optional(&mut *tx)
                    .await
                    .map_err(self.db_error(OP))?;
            if found.is_none() {
                return Ok(AckOutcome::NotFound);
            }
            let done = sqlx::query(
                "INSERT INTO event_acks (event_id, at_ms, source) VALUES ($1, $2, $3) \
                 ON CONFLICT (event_id) DO NOTHING",
            )
            .bind(id.0)
            .bind(at_ms)
            .bind(source)
            .execute(&mut *tx)
            .await
            .map_err(self.db_error(OP))?;
            tx.commit().await.map_err(self.db_error(OP))?;
            Ok(if done.rows_affected() == 1 {
                AckOutcome::Acknowledged
            } else {
                AckOutcome::AlreadyAcknowledged
            })
        })
    }

    /// The acknowledgements of `machine`'s events with id ≥ `from`, oldest first, at most
    /// `limit`.
    pub async fn event_acks(
        &self,
        machine: &str,
        from: EventId,
        limit: u32,
    ) -> Result<Vec<EventAck>, StoreError> {
        let limit = check_limit(limit)?;
        with_read!(self, pool => {
            let rows = sqlx::query(
                "SELECT a.event_id, a.at_ms, a.source FROM event_acks a \
                 JOIN events e ON e.id = a.event_id \
                 WHERE e.machine = $1 AND a.event_id >= $2 ORDER BY a.event_id LIMIT $3",
            )
            .bind(machine)
            .bind(from.0)
            .bind(limit)
            .fetch_all(pool)
            .await
            .map_err(self.db_error("listing event acknowledgements"))?;
            rows.iter()
                .map(|row| {
                    Ok(EventAck {
                        event: EventId(col!(row, "event_id", "reading an acknowledgement")),
                        at_ms: col!(row, "at_ms", "reading an acknowledgement"),
                        source: col!(row, "source", "reading an acknowledgement"),
                    })
                })
                .collect()
        })
    }

    /// The newest learning-state snapshot of (machine, lobe), read through the readers' gate.
    pub async fn learning_state_for_view(
        &self,
        machine: &str,
        lobe: &str,
    ) -> Result<Option<LearningState>, StoreError> {
        with_read!(self, pool => {
            let row: Option<(String, i64)> = sqlx::query_as(
                "SELECT state_json, saved_at_ms FROM learning_states \
                 WHERE machine = $1 AND lobe = $2 ORDER BY id DESC LIMIT 1",
            )
            .bind(machine)
            .bind(lobe)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("loading learning state"))?;
            Ok(row.map(|(state_json, saved_at_ms)| LearningState { state_json, saved_at_ms }))
        })
    }
}
