//! What the dashboard reads and writes beyond the API's queries: acknowledgements of events
//! and alarms (appended, once per event), and the learning state read through the readers'
//! gate (the machine loop reads it through the writer; a dashboard must never take that).

use crate::BeginWrite;
use jiff::Timestamp;

use super::codec::check_limit;
use super::{
    EventId, LearningState, Store, StoreError, VersionStatus, at_col, col, with_read, with_write,
};
use camloop_core::names::{FeatureName, MachineName};

/// An event's acknowledgement.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EventAck {
    pub event: EventId,
    pub at: Timestamp,
    /// Who acknowledged ("dashboard").
    pub source: String,
}

/// A table version without its program: what lists and charts show.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TableVersionHead {
    pub version: camloop_core::ids::TableVersion,
    pub table_number: u32,
    pub reason: String,
    pub created_at: Timestamp,
    pub status: VersionStatus,
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
    /// Acknowledges event `id` of `machine` at `at`. Appended: a second acknowledgement
    /// changes nothing and says so.
    pub async fn acknowledge_event(
        &self,
        machine: &MachineName,
        id: EventId,
        at: Timestamp,
        source: &str,
    ) -> Result<AckOutcome, StoreError> {
        let machine = machine.as_str();
        const OP: &str = "acknowledging an event";
        with_write!(self, pool => {
            let mut tx = pool.begin_write().await.map_err(self.db_error(OP))?;
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
            .bind(at.as_millisecond())
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
        machine: &MachineName,
        from: EventId,
        limit: u32,
    ) -> Result<Vec<EventAck>, StoreError> {
        let machine = machine.as_str();
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
                        at: at_col!(row, "at_ms", "reading an acknowledgement"),
                        source: col!(row, "source", "reading an acknowledgement"),
                    })
                })
                .collect()
        })
    }

    /// The newest learning-state snapshot of (machine, lobe), read through the readers' gate:
    /// a packed row's chain resolved and checked, as the machine loop's load does (reading
    /// the plain column alone gave an empty text for a packed row on SQLite, so a frozen
    /// feature never showed, and an error on PostgreSQL).
    pub async fn learning_state_for_view(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
    ) -> Result<Option<LearningState>, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let newest: Option<i64> = with_read!(self, pool => {
            sqlx::query_scalar(
                "SELECT id FROM learning_states \
                 WHERE machine = $1 AND lobe = $2 ORDER BY id DESC LIMIT 1",
            )
            .bind(machine)
            .bind(lobe)
            .fetch_optional(pool)
            .await
            .map_err(self.db_error("loading learning state"))?
        });
        match newest {
            None => Ok(None),
            Some(id) => self.learning_state_row_for_view(id).await,
        }
    }

    /// The newest `limit` table versions of (machine, lobe) without their programs, highest
    /// first: the overview and the trend read these, never the program texts.
    pub async fn table_version_heads(
        &self,
        machine: &MachineName,
        lobe: &FeatureName,
        limit: u32,
    ) -> Result<Vec<TableVersionHead>, StoreError> {
        let (machine, lobe) = (machine.as_str(), lobe.as_str());
        let limit = check_limit(limit)?;
        with_read!(self, pool => {
            let rows = sqlx::query(
                "SELECT t.version, t.table_number, t.reason, t.created_at_ms, s.status, s.why, s.at_ms \
                 FROM table_versions t JOIN table_version_status s ON s.id = \
                 (SELECT MAX(s2.id) FROM table_version_status s2 WHERE s2.table_version_id = t.id) \
                 WHERE t.machine = $1 AND t.lobe = $2 ORDER BY t.version DESC LIMIT $3",
            )
            .bind(machine)
            .bind(lobe)
            .bind(limit)
            .fetch_all(pool)
            .await
            .map_err(self.db_error("listing table versions"))?;
            rows.iter()
                .map(|row| {
                    let status: String = col!(row, "status", "reading a table version");
                    let number: i64 = col!(row, "table_number", "reading a table version");
                    let at_ms: i64 = col!(row, "at_ms", "reading a table version");
                    Ok(TableVersionHead {
                        version: crate::codec::version_of(
                            "version",
                            col!(row, "version", "reading a table version"),
                        )?,
                        table_number: u32::try_from(number).map_err(|_| {
                            StoreError::invalid("table_number", format!("stored value {number} out of range"))
                        })?,
                        reason: col!(row, "reason", "reading a table version"),
                        created_at: at_col!(row, "created_at_ms", "reading a table version"),
                        status: VersionStatus::from_column(
                            &status,
                            col!(row, "why", "reading a table version"),
                            at_ms,
                        )?,
                    })
                })
                .collect()
        })
    }
}
