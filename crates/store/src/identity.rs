//! The store's identity: a random id and creation time written once, by the migration that
//! creates the `store_identity` table, so a database that was replaced or emptied under
//! camloop is told apart from the one it last wrote (see `service::store_guard`).

use super::{Store, StoreError, with_write};

/// Who a database is: a random id (32 lower-case hex digits) made when its schema was first
/// created, and when that was (unix ms). A copy restored from a backup keeps its identity; a
/// new or emptied database gets a new one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoreIdentity {
    pub id: String,
    pub created_at: jiff::Timestamp,
}

impl Store {
    /// The identity of this database.
    pub async fn identity(&self) -> Result<StoreIdentity, StoreError> {
        const OP: &str = "reading the store identity";
        let row: Option<(String, i64)> = with_write!(self, pool => {
            sqlx::query_as("SELECT id, created_at_ms FROM store_identity WHERE singleton = 1")
                .fetch_optional(pool)
                .await
                .map_err(self.db_error(OP))?
        });
        match row {
            Some((id, created_at_ms)) => Ok(StoreIdentity {
                id,
                created_at: super::unix_ms::instant(created_at_ms, "created_at_ms")?,
            }),
            None => Err(StoreError::NotFound {
                what: format!("store identity of {}", self.target),
            }),
        }
    }
}
