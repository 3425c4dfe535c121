//! The audit trail on the HTTP side: [`record`] appends what a handler did (every write
//! calls it), `GET /api/v1/audit` and the dashboard's `/audit` page read it (engineers and
//! admins, see `access::ROUTES`).

use super::AppState;
use super::api::{ApiError, ApiQuery};
use crate::store::{AuditEntry, AuditRow};
use axum::Json;
use axum::extract::State;
use axum::response::Html;
use serde::{Deserialize, Serialize};

/// Appends `entry` to the trail and logs it, through the service's one write path for audit
/// rows ([`crate::service::command::record_audit`]): when the database cannot take it, the
/// whole entry goes to the log at error level and `camloop_audit_failures_total` counts it.
pub async fn record(app: &AppState, entry: AuditEntry) {
    crate::service::command::record_audit(app.writes(), entry).await;
}

/// Appends `entry`, a refusal (a refused write, a failed sign-in), within the trail's budget
/// for refusals of its client; over it, `camloop_audit_refusals_unrecorded_total` counts it
/// and the client's next row says how many went unrecorded.
pub async fn record_refusal(app: &AppState, entry: AuditEntry) {
    crate::service::sign_in::record_refusal(app, entry).await;
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct AuditQuery {
    /// From this time, Unix ms.
    #[serde(rename = "since_ms", default, with = "crate::clock::unix_ms::option")]
    #[param(value_type = Option<i64>)]
    since: Option<jiff::Timestamp>,
    /// At most this many (default 200, at most 1000).
    limit: Option<u32>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct AuditReply {
    /// Newest first.
    #[schema(value_type = Vec<Object>)]
    items: Vec<AuditRow>,
}

/// `GET /api/v1/audit?since_ms=…&limit=…`: the newest rows (at most 1,000).
#[utoipa::path(get, path = "/api/v1/audit", tag = "access", params(AuditQuery), responses((status = 200, description = "the audit trail, newest first", body = AuditReply)))]
pub(super) async fn audit(
    State(app): State<AppState>,
    ApiQuery(q): ApiQuery<AuditQuery>,
) -> Result<Json<AuditReply>, ApiError> {
    let store = super::routes::store(&app).await?;
    let items = store
        .audit(
            q.since.unwrap_or(jiff::Timestamp::UNIX_EPOCH),
            0,
            q.limit.unwrap_or(200),
            true,
        )
        .await?;
    Ok(Json(AuditReply { items }))
}

/// `GET /audit`: the newest 200 rows as a table.
#[utoipa::path(get, path = "/audit", tag = "dashboard", responses((status = 200, description = "the audit trail as a page", content_type = "text/html")))]
pub(super) async fn audit_page(State(app): State<AppState>) -> Result<Html<String>, ApiError> {
    let store = super::routes::store(&app).await?;
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 200, true)
        .await?;
    Ok(Html(super::dashboard::audit_html(&rows)))
}

#[cfg(test)]
mod tests {
    use super::AuditQuery;
    use axum::extract::Query;

    fn query(uri: &str) -> Result<AuditQuery, String> {
        let uri: axum::http::Uri = uri.parse().unwrap();
        Query::<AuditQuery>::try_from_uri(&uri)
            .map(|q| q.0)
            .map_err(|e| e.body_text())
    }

    /// The time a query names is an instant from its integer milliseconds, checked once
    /// where the query is read: one no instant has is refused there, not passed on.
    #[test]
    fn a_query_time_is_read_as_an_instant_and_checked_at_the_edge() {
        let q = query("/api/v1/audit?since_ms=1795443845123").unwrap();
        assert_eq!(
            q.since.map(|t| t.to_string()),
            Some("2026-11-23T14:24:05.123Z".into())
        );
        assert_eq!(query("/api/v1/audit?limit=5").unwrap().since, None);
        let err = query("/api/v1/audit?since_ms=9223372036854775807").unwrap_err();
        assert!(err.contains("not a time"), "{err}");
    }
}
