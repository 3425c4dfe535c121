//! The methods: `Rollback` and `AcknowledgeEvent` go the service's own write path (the
//! same checks, command to the machine's loop and audit row as the HTTP API's writes,
//! through the [`Service`] port), for the [`Write`] each is, with the role the service
//! gives it; `GetLatestResult` and `GetResultById` read the history store.

use camloop_core::names::{FeatureName, MachineName};
use opcua::types::{DataTypeId, DateTime, StatusCode, Variant};
use tracing::{info, warn};

use super::events::RowEventId;
use super::space::Method;
use crate::port::{AckRefused, Caller, Refusal, Service, Write, WriteRefused};
use camloop_loop::{CommandError, MachineCommand, TableVersion};
use camloop_store::{
    AckOutcome, HistoryFilter, MeasurementId, MeasurementSummary, Store, StoreError,
};

/// The write a method is (reads need no role beyond the session's).
fn write_of(method: Method) -> Option<Write> {
    match method {
        Method::Rollback => Some(Write::Rollback),
        Method::AcknowledgeEvent => Some(Write::Acknowledge),
        Method::GetLatestResult | Method::GetResultById => None,
    }
}

/// The history store, or `BadResourceUnavailable` while the database is down.
async fn store_of(service: &dyn Service) -> Result<Store, StatusCode> {
    service
        .store()
        .await
        .ok_or(StatusCode::BadResourceUnavailable)
}

/// Who called, as the service's writes know callers: the user as stored now (a user
/// disabled or demoted since sign-in is refused).
async fn caller(w: &dyn Service, user: &str) -> Result<Caller, StatusCode> {
    let store = store_of(w).await?;
    let user = store
        .user(user)
        .await
        .map_err(|_| StatusCode::BadResourceUnavailable)?
        .filter(|u| u.disabled_at.is_none())
        .ok_or(StatusCode::BadUserAccessDenied)?;
    Ok(Caller {
        user: user.name,
        role: user.role,
    })
}

/// Runs `method` of `machine` for the session's user (`None`: anonymous); a write refused
/// `BadUserAccessDenied` is audited (see `super::auth::refused_write`).
pub(crate) async fn call(
    w: &dyn Service,
    user: Option<&str>,
    client: &str,
    machine: &str,
    method: Method,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let done = call_as(w, user, client, machine, method, args).await;
    if done == Err(StatusCode::BadUserAccessDenied) {
        super::auth::refused_write(w, user, machine, method.name()).await;
    }
    done
}

async fn call_as(
    w: &dyn Service,
    user: Option<&str>,
    client: &str,
    machine: &str,
    method: Method,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let Some(write) = write_of(method) else {
        return read_method(w, machine, method, args).await;
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
    let caller = caller(w, user).await?;
    let needed = w.needed_role(write);
    if caller.role < needed {
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
        Method::Rollback => rollback(w, &caller, machine, args).await,
        _ => acknowledge(w, &caller, machine, args).await,
    }
}

async fn rollback(
    w: &dyn Service,
    caller: &Caller,
    machine: &str,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let (Some(Variant::String(feature)), Some(version)) = (args.first(), args.get(1).and_then(int))
    else {
        return Err(StatusCode::BadInvalidArgument);
    };
    let machine = MachineName::new(machine).map_err(|_| StatusCode::BadInvalidArgument)?;
    let lobe = FeatureName::new(feature.as_ref()).map_err(|_| StatusCode::BadInvalidArgument)?;
    // As the API answers: an unknown machine or feature before a version out of range.
    if !w
        .machines()
        .get(&machine)
        .is_some_and(|f| f.contains(&lobe))
    {
        warn!(machine = %machine, feature = %lobe, "OPC UA: write not carried out: no such machine or feature");
        return Err(StatusCode::BadNotFound);
    }
    let version = TableVersion::from_i64(version).map_err(|_| StatusCode::BadInvalidArgument)?;
    let rollback = MachineCommand::Rollback { lobe, version };
    let done = w
        .write(caller, &machine, rollback)
        .await
        .map_err(write_status)?;
    Ok(vec![
        Variant::Int64(done.version.map_or(0, TableVersion::to_i64)),
        Variant::from(done.message),
    ])
}

async fn acknowledge(
    w: &dyn Service,
    caller: &Caller,
    machine: &str,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let machine = MachineName::new(machine).map_err(|_| StatusCode::BadInvalidArgument)?;
    let id = match args.first() {
        Some(Variant::ByteString(b)) => {
            let bytes = b.value.clone().unwrap_or_default();
            stored_event_id(w, &machine, &bytes).await?
        }
        Some(v) => int(v).ok_or(StatusCode::BadTypeMismatch)?,
        None => return Err(StatusCode::BadArgumentsMissing),
    };
    let outcome = w.acknowledge(caller, &machine, id).await;
    match outcome {
        // The same words as the audit row's reason.
        Ok(AckOutcome::Acknowledged) => Ok(vec![Variant::from(format!("event {id} acknowledged"))]),
        Ok(AckOutcome::AlreadyAcknowledged) => Ok(vec![Variant::from(format!(
            "event {id} acknowledged before"
        ))]),
        Ok(AckOutcome::NotFound) => {
            warn!(machine = %machine, id, "OPC UA: write not carried out: no such event");
            Err(StatusCode::BadNotFound)
        }
        Err(e) => {
            warn!(machine = %machine, id, error = %e, "OPC UA: write not carried out");
            Err(match e {
                AckRefused::Forbidden { .. } => StatusCode::BadUserAccessDenied,
                AckRefused::StoreUnavailable => StatusCode::BadResourceUnavailable,
                AckRefused::Store(e) => store_status(&e),
            })
        }
    }
}

/// Why a call's arguments do not fit its method (OPC 10000-4 §5.11.2).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum ArgumentError {
    /// Fewer arguments than the method takes: `BadArgumentsMissing`.
    Missing,
    /// More: `BadTooManyArguments`.
    TooMany,
    /// Each argument's result, `BadTypeMismatch` where its type is wrong (the call's status
    /// is then `BadInvalidArgument`).
    Types(Vec<StatusCode>),
}

/// Checks the arguments' number and types against the method's declared inputs (integers
/// as Int64, Int32 or UInt32; `AcknowledgeEvent`'s id as an integer or a ByteString).
pub(crate) fn check_arguments(method: Method, args: &[Variant]) -> Result<(), ArgumentError> {
    let (inputs, _) = method.arguments();
    match args.len().cmp(&inputs.len()) {
        std::cmp::Ordering::Less => return Err(ArgumentError::Missing),
        std::cmp::Ordering::Greater => return Err(ArgumentError::TooMany),
        std::cmp::Ordering::Equal => {}
    }
    let results: Vec<StatusCode> = inputs
        .iter()
        .zip(args)
        .map(|((_, ty), arg)| {
            let fits = match ty {
                DataTypeId::Int64 => int(arg).is_some(),
                DataTypeId::String => matches!(arg, Variant::String(_)),
                DataTypeId::BaseDataType => {
                    int(arg).is_some() || matches!(arg, Variant::ByteString(_))
                }
                _ => false,
            };
            match fits {
                true => StatusCode::Good,
                false => StatusCode::BadTypeMismatch,
            }
        })
        .collect();
    match results.iter().all(|s| s.is_good()) {
        true => Ok(()),
        false => Err(ArgumentError::Types(results)),
    }
}

/// camloop's id of the stored event an OPC UA EventId names: the history's row of
/// `machine` at the EventId's time whose message has its digest, the occurrence-th of
/// those (see [`super::events::EventIds`]). Needs no memory of this process: an EventId
/// from before a restart names the same row.
async fn stored_event_id(
    w: &dyn Service,
    machine: &MachineName,
    event_id: &[u8],
) -> Result<i64, StatusCode> {
    let Some(named) = RowEventId::parse(event_id) else {
        warn!(machine = %machine, "OPC UA: AcknowledgeEvent: an EventId of no history row (a result's, or not this server's)");
        return Err(StatusCode::BadNotFound);
    };
    let store = store_of(w).await?;
    let filter = camloop_store::EventFilter {
        machine: Some(machine.clone()),
        since: Some(named.at),
        until: named
            .at
            .checked_add(jiff::SignedDuration::from_millis(1))
            .ok(),
        level: None,
        limit: camloop_store::MAX_PAGE,
    };
    let mut events = store.events(&filter).await.map_err(|e| store_status(&e))?;
    // Newest first from the store: the occurrence counts in the rows' order.
    events.sort_by_key(|e| e.id.0);
    let found = events
        .into_iter()
        .filter(|e| named.matches(machine.as_str(), &e.message))
        .nth(usize::try_from(named.occurrence).unwrap_or(usize::MAX))
        .map(|e| e.id.0);
    if found.is_none() {
        warn!(machine = %machine, at = %named.at, "OPC UA: AcknowledgeEvent: no history row of the machine for the EventId");
    }
    found.ok_or(StatusCode::BadNotFound)
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

/// The OPC UA status of a write the service did not carry out (its code is logged: a status
/// says less).
fn write_status(e: WriteRefused) -> StatusCode {
    warn!(code = e.code, message = %e, "OPC UA: write not carried out");
    match e.kind {
        Refusal::Forbidden => StatusCode::BadUserAccessDenied,
        Refusal::NotFound => StatusCode::BadNotFound,
        Refusal::Unavailable => StatusCode::BadResourceUnavailable,
        Refusal::Command(error) => match error {
            CommandError::VersionNotFound { .. } => StatusCode::BadNotFound,
            CommandError::Refused { .. } => StatusCode::BadInvalidState,
            CommandError::StoreUnavailable { .. }
            | CommandError::JournalUnavailable { .. }
            | CommandError::Elsewhere { .. } => StatusCode::BadResourceUnavailable,
            CommandError::Failed { .. } | CommandError::ShareStateFailed { .. } => {
                StatusCode::BadInternalError
            }
        },
    }
}

/// The OPC UA status of a store error.
fn store_status(e: &StoreError) -> StatusCode {
    match e {
        StoreError::Unavailable { .. }
        | StoreError::Corrupt { .. }
        | StoreError::Full { .. }
        | StoreError::Busy { .. } => StatusCode::BadResourceUnavailable,
        StoreError::NotFound { .. } => StatusCode::BadNotFound,
        StoreError::Conflict { .. } => StatusCode::BadInvalidState,
        StoreError::Invalid { .. } => StatusCode::BadInvalidArgument,
        StoreError::Migration { .. } | StoreError::Backend { .. } => StatusCode::BadInternalError,
    }
}

async fn read_method(
    service: &dyn Service,
    machine: &str,
    method: Method,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let store = store_of(service).await?;
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
                        masters: camloop_store::MasterRuns::Excluded,
                        stage: Some(camloop_store::MeasurementStage::Final),
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
        "received_at_ms": s.received_at.as_millisecond(),
        "verdict": s.verdict.as_str(),
        "max_profile_error_um": s.max_profile_error_um,
        "base_radius_error_um": s.base_radius_error_um,
        "phase_error_deg": s.phase_error_deg,
        "revolutions_used": s.revolutions_used,
        "points_per_rev": s.points_per_rev,
    });
    vec![
        Variant::Int64(s.id.0),
        Variant::from(s.part.to_string()),
        Variant::from(date_time(s.received_at)),
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
    fn arguments_of_the_wrong_type_or_number_get_the_specs_codes() {
        let feature = Variant::from("IN1");
        let version = Variant::Int64(3);
        assert_eq!(
            check_arguments(Method::Rollback, &[feature.clone(), version.clone()]),
            Ok(())
        );
        assert_eq!(
            check_arguments(Method::Rollback, &[feature.clone(), Variant::Int32(3)]),
            Ok(())
        );
        assert_eq!(
            check_arguments(Method::Rollback, &[version.clone(), Variant::from("3")]),
            Err(ArgumentError::Types(vec![
                StatusCode::BadTypeMismatch,
                StatusCode::BadTypeMismatch
            ]))
        );
        assert_eq!(
            check_arguments(Method::Rollback, &[feature.clone(), Variant::Double(3.0)]),
            Err(ArgumentError::Types(vec![
                StatusCode::Good,
                StatusCode::BadTypeMismatch
            ]))
        );
        assert_eq!(
            check_arguments(Method::Rollback, std::slice::from_ref(&feature)),
            Err(ArgumentError::Missing)
        );
        assert_eq!(
            check_arguments(Method::GetLatestResult, &[feature.clone(), version.clone()]),
            Err(ArgumentError::TooMany)
        );
        // AcknowledgeEvent takes camloop's id or the OPC UA EventId, nothing else.
        let event_id = Variant::ByteString(opcua::types::ByteString::from(b"1-2".to_vec()));
        assert_eq!(
            check_arguments(Method::AcknowledgeEvent, &[event_id]),
            Ok(())
        );
        assert_eq!(
            check_arguments(Method::AcknowledgeEvent, &[version]),
            Ok(())
        );
        assert_eq!(
            check_arguments(Method::AcknowledgeEvent, &[feature]),
            Err(ArgumentError::Types(vec![StatusCode::BadTypeMismatch]))
        );
    }

    #[test]
    fn unix_milliseconds_become_the_same_instant_in_opc_ua_time() {
        let ms = |unix_ms| jiff::Timestamp::from_millisecond(unix_ms).unwrap();
        assert_eq!(date_time(ms(0)), DateTime::ymd_hms(1970, 1, 1, 0, 0, 0));
        // 2026-11-27T10:00:00.250Z: 1 795 773 600 s after the epoch.
        let at = date_time(ms(1_795_773_600_250));
        assert_eq!(at.as_chrono().to_rfc3339(), "2026-11-27T10:00:00.250+00:00");
    }
}
