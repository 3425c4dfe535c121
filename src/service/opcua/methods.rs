//! The methods: `Rollback` and `AcknowledgeEvent` go through the HTTP API's own write
//! handlers (same checks, same command to the machine's loop, same audit row), with the
//! role the API route needs; `GetLatestResult` and `GetResultById` read the history store.

use crate::names::{FeatureName, MachineName};
use axum::extract::State;
use opcua::types::{DateTime, StatusCode, Variant};
use tracing::{info, warn};

use super::auth::OPCUA_CLIENT;
use super::space::Method;
use crate::service::http::access::{Need, rule_for};
use crate::service::http::{self, ApiError, ApiJson, ApiPath, AppState, Principal, Via};
use crate::store::{HistoryFilter, MeasurementId, MeasurementSummary};

/// The route whose role a method needs: the HTTP route doing the same write.
fn route(method: Method) -> Option<&'static str> {
    match method {
        Method::Rollback => Some("/api/v1/machines/{machine}/lobes/{lobe}/rollback"),
        Method::AcknowledgeEvent => Some("/api/v1/machines/{machine}/events/{id}/ack"),
        Method::GetLatestResult | Method::GetResultById => None,
    }
}

/// The history store, or `BadResourceUnavailable` while the database is down.
async fn store_of(app: &AppState) -> Result<crate::store::Store, StatusCode> {
    app.store
        .read()
        .await
        .clone()
        .ok_or(StatusCode::BadResourceUnavailable)
}

/// Who called, as the HTTP writes know callers: the user as stored now (a user disabled or
/// demoted since sign-in is refused).
async fn caller(app: &AppState, user: &str) -> Result<Principal, StatusCode> {
    let store = store_of(app).await?;
    let user = store
        .user(user)
        .await
        .map_err(|_| StatusCode::BadResourceUnavailable)?
        .filter(|u| u.disabled_at_ms.is_none())
        .ok_or(StatusCode::BadUserAccessDenied)?;
    Ok(Principal {
        actor: user.name,
        role: Some(user.role),
        address: OPCUA_CLIENT,
        via: Via::Token,
    })
}

/// Runs `method` of `machine` for the session's user (`None`: anonymous).
pub(crate) async fn call(
    app: &AppState,
    user: Option<&str>,
    client: &str,
    machine: &str,
    method: Method,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let Some(path) = route(method) else {
        return read_method(app, machine, method, args).await;
    };
    let Some(user) = user else {
        warn!(
            machine,
            method = method.name(),
            client,
            "OPC UA: anonymous write refused"
        );
        return Err(StatusCode::BadUserAccessDenied);
    };
    let p = caller(app, user).await?;
    let needed = rule_for(&axum::http::Method::POST, path).map(|r| r.need);
    if let Some(Need::Role(needed)) = needed
        && p.role.is_none_or(|r| r < needed)
    {
        warn!(user, machine, method = method.name(), client, %needed, "OPC UA: write refused, role too low");
        return Err(StatusCode::BadUserAccessDenied);
    }
    info!(
        user,
        machine,
        method = method.name(),
        client,
        "OPC UA: write"
    );
    match method {
        Method::Rollback => rollback(app, p, machine, args).await,
        _ => acknowledge(app, p, machine, args).await,
    }
}

async fn rollback(
    app: &AppState,
    p: Principal,
    machine: &str,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let (Some(Variant::String(feature)), Some(version)) = (args.first(), args.get(1).and_then(int))
    else {
        return Err(StatusCode::BadInvalidArgument);
    };
    let body: http::RollbackBody =
        serde_json::from_value(serde_json::json!({ "version": version }))
            .map_err(|_| StatusCode::BadInvalidArgument)?;
    let machine = http::machine_name(machine).map_err(status)?;
    let feature = http::feature_name(feature.as_ref()).map_err(status)?;
    let path = ApiPath((machine, feature));
    let reply = http::rollback_write(p, State(app.clone()), path, ApiJson(body))
        .await
        .map_err(status)?;
    Ok(vec![
        Variant::Int64(reply.0.version.unwrap_or(0)),
        Variant::from(reply.0.message.clone()),
    ])
}

async fn acknowledge(
    app: &AppState,
    p: Principal,
    machine: &str,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let id = args
        .first()
        .and_then(int)
        .ok_or(StatusCode::BadInvalidArgument)?;
    let path = ApiPath((http::machine_name(machine).map_err(status)?, id));
    http::ack_write(p, State(app.clone()), path)
        .await
        .map_err(status)?;
    Ok(vec![Variant::from(format!("event {id} acknowledged"))])
}

/// An integer argument (clients send Int64, some Int32).
fn int(v: &Variant) -> Option<i64> {
    match v {
        Variant::Int64(n) => Some(*n),
        Variant::Int32(n) => Some(i64::from(*n)),
        Variant::UInt32(n) => Some(i64::from(*n)),
        _ => None,
    }
}

/// The OPC UA status of an API error (its code is logged: a status says less).
fn status(e: ApiError) -> StatusCode {
    warn!(code = e.code().as_str(), message = %e.message(), "OPC UA: write not carried out");
    match e.status().as_u16() {
        400 | 422 => StatusCode::BadInvalidArgument,
        401 | 403 => StatusCode::BadUserAccessDenied,
        404 => StatusCode::BadNotFound,
        409 => StatusCode::BadInvalidState,
        503 => StatusCode::BadResourceUnavailable,
        _ => StatusCode::BadInternalError,
    }
}

async fn read_method(
    app: &AppState,
    machine: &str,
    method: Method,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let store = store_of(app).await?;
    let unavailable = |_| StatusCode::BadResourceUnavailable;
    let summary = match (method, args.first()) {
        (Method::GetLatestResult, Some(Variant::String(feature))) => {
            // A name off the rule names no feature: no result, as for an unknown one.
            match (
                MachineName::new(machine),
                FeatureName::new(feature.as_ref()),
            ) {
                (Ok(machine), Ok(lobe)) => {
                    let filter = HistoryFilter {
                        lobe: Some(lobe),
                        masters: crate::store::MasterRuns::Excluded,
                        ..HistoryFilter::new(machine, 1)
                    };
                    let page = store
                        .measurement_history(&filter)
                        .await
                        .map_err(unavailable)?;
                    page.items.into_iter().next()
                }
                _ => None,
            }
        }
        (Method::GetResultById, Some(v)) => {
            let id = int(v).ok_or(StatusCode::BadInvalidArgument)?;
            store
                .measurement(MeasurementId(id))
                .await
                .map_err(unavailable)?
                .map(|d| d.summary)
                .filter(|s| s.machine == machine)
        }
        _ => return Err(StatusCode::BadInvalidArgument),
    };
    let s = summary.ok_or(StatusCode::BadNotFound)?;
    Ok(result_outputs(&s))
}

/// ResultId, PartId, Time, Verdict and the result as JSON (units in the field names).
pub(crate) fn result_outputs(s: &MeasurementSummary) -> Vec<Variant> {
    let json = serde_json::json!({
        "result_id": s.id.0,
        "machine": s.machine,
        "part": s.part,
        "feature": s.lobe,
        "received_at_ms": s.received_at_ms.as_millisecond(),
        "verdict": s.verdict.as_str(),
        "max_profile_error_um": s.max_profile_error_um,
        "base_radius_error_um": s.base_radius_error_um,
        "phase_error_deg": s.phase_error_deg,
        "revolutions_used": s.revolutions_used,
        "points_per_rev": s.points_per_rev,
    });
    vec![
        Variant::Int64(s.id.0),
        Variant::from(s.part.clone()),
        Variant::from(date_time(s.received_at_ms)),
        Variant::from(s.verdict.as_str().to_string()),
        Variant::from(json.to_string()),
    ]
}

/// An OPC UA DateTime from an instant (to the millisecond, as camloop keeps times).
pub(crate) fn date_time(at: jiff::Timestamp) -> DateTime {
    // OPC UA counts 100 ns ticks from 1601-01-01, 11 644 473 600 s before the Unix epoch.
    const EPOCH_OFFSET_MS: i64 = 11_644_473_600_000;
    let at_ms = at.as_millisecond();
    DateTime::from(at_ms.saturating_add(EPOCH_OFFSET_MS).saturating_mul(10_000))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unix_milliseconds_become_the_same_instant_in_opc_ua_time() {
        let ms = |unix_ms| jiff::Timestamp::from_millisecond(unix_ms).unwrap();
        assert_eq!(date_time(ms(0)), DateTime::ymd_hms(1970, 1, 1, 0, 0, 0));
        // 2026-11-27T10:00:00.250Z: 1 795 773 600 s after the epoch.
        let at = date_time(ms(1_795_773_600_250));
        assert_eq!(at.as_chrono().to_rfc3339(), "2026-11-27T10:00:00.250+00:00");
    }
}
