//! The write requests: rollback and dressing. The access layer has checked the caller's role
//! (from the headers, before the body is read); each checks the machine and lobe, then hands
//! a [`Command`] to the machine's loop, which owns the loop state, so a write never races a
//! part. Every write that reaches a machine is audited with its outcome.

use super::AppState;
use super::access::Principal;
use super::api::{ApiError, ApiJson, ApiPath, feature_name};
use crate::names::{FeatureName, MachineName};
use crate::service::http::ApiCode;
use crate::store::AuditResult;
use axum::Json;
use axum::extract::State;
use camloop_loop::{CommandError, CommandOutcome, MachineCommand, TableVersion};
use serde::{Deserialize, Serialize};

/// The reply to a write that was carried out.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct CommandReply {
    /// Always "ok".
    pub status: &'static str,
    /// The table version the write made, when it made one.
    pub version: Option<i64>,
    pub message: String,
}

impl From<CommandOutcome> for CommandReply {
    fn from(done: CommandOutcome) -> Self {
        Self {
            status: "ok",
            version: done.version.map(TableVersion::to_i64),
            message: done.message,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::ToSchema)]
pub(crate) struct RollbackBody {
    version: i64,
}

/// Deliver a stored table version again (as a new version, under the table number not in use).
#[utoipa::path(post, path = "/api/v1/machines/{machine}/lobes/{lobe}/rollback", tag = "writes", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name")), request_body = RollbackBody, responses((status = 200, description = "delivered as a new version", body = CommandReply)))]
pub(crate) async fn rollback(
    p: Principal,
    State(state): State<AppState>,
    ApiPath((machine, lobe)): ApiPath<(MachineName, FeatureName)>,
    ApiJson(body): ApiJson<RollbackBody>,
) -> Result<Json<CommandReply>, ApiError> {
    let machine = configured(&state, machine)?;
    let ground = state
        .machines
        .get(&machine)
        .is_some_and(|l| l.contains(&lobe));
    if !ground {
        return Err(ApiError::new(
            ApiCode::LobeNotFound,
            format!("machine {machine} does not grind a lobe or pin {lobe}"),
        ));
    }
    let version = TableVersion::from_i64(body.version)
        .map_err(|_| ApiError::new(ApiCode::InvalidVersion, "version must be ≥ 1".into()))?;
    let before = in_force(&state, &machine, std::slice::from_ref(&lobe));
    let mut entry = p.audit("rollback", AuditResult::Ok, String::new());
    entry.machine = Some(machine.to_string());
    entry.feature = Some(lobe.to_string());
    entry.version = Some(version.to_i64());
    entry.before = Some(before);
    let rollback = MachineCommand::Rollback {
        lobe: lobe.clone(),
        version,
    };
    let done = command(&state, &machine, ApiCode::RollbackRefused, rollback).await;
    audited(&state, entry, &done, || {
        in_force(&state, &machine, std::slice::from_ref(&lobe))
    })
    .await;
    Ok(Json(done?.into()))
}

/// The table versions on the control of `features` of `machine`, as JSON.
fn in_force(state: &AppState, machine: &MachineName, features: &[FeatureName]) -> String {
    let statuses = state.metrics.features();
    let versions: std::collections::BTreeMap<&str, i64> = features
        .iter()
        .filter_map(|f| {
            let s = statuses.get(&(machine.clone(), f.clone()))?;
            Some((f.as_str(), i64::try_from(s.in_force_version).ok()?))
        })
        .collect();
    serde_json::json!({ "in_force": versions }).to_string()
}

/// Appends the audit row of a write that reached the machine's loop, with its outcome.
async fn audited(
    state: &AppState,
    mut entry: crate::store::AuditEntry,
    done: &Result<CommandOutcome, ApiError>,
    after: impl FnOnce() -> String,
) {
    match done {
        Ok(d) => {
            entry.reason = d.message.clone();
            entry.after = Some(after());
        }
        Err(e) => {
            entry.result = match e.status().is_server_error() {
                true => AuditResult::Failed,
                false => AuditResult::Refused,
            };
            entry.reason = format!("{}: {}", e.code(), e.message());
        }
    }
    super::audit::record(state, entry).await;
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::ToSchema)]
pub(crate) struct PartRollbackBody {
    /// The version of each feature to go back to, by feature name.
    versions: std::collections::BTreeMap<String, i64>,
}

/// `POST /api/v1/machines/{machine}/rollback` with `{"versions": {"IN1": 5, "EX1": 7}}`:
/// several features back together, or none of them.
#[utoipa::path(post, path = "/api/v1/machines/{machine}/rollback", tag = "writes", params(("machine" = String, Path, description = "machine name")), request_body = PartRollbackBody, responses((status = 200, description = "every feature delivered again", body = CommandReply)))]
pub(super) async fn rollback_part(
    p: Principal,
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<MachineName>,
    ApiJson(body): ApiJson<PartRollbackBody>,
) -> Result<Json<CommandReply>, ApiError> {
    let machine = configured(&state, machine)?;
    let grinds = state.machines.get(&machine).cloned().unwrap_or_default();
    if body.versions.is_empty() {
        return Err(ApiError::new(
            ApiCode::InvalidVersions,
            "versions names no feature".into(),
        ));
    }
    let mut versions = Vec::new();
    for (lobe, version) in body.versions {
        let lobe = feature_name(&lobe)?;
        if !grinds.contains(&lobe) {
            return Err(ApiError::new(
                ApiCode::LobeNotFound,
                format!("machine {machine} does not grind a lobe or pin {lobe}"),
            ));
        }
        let Ok(v) = TableVersion::from_i64(version) else {
            return Err(ApiError::new(
                ApiCode::InvalidVersion,
                format!("{lobe}: version must be ≥ 1"),
            ));
        };
        versions.push((lobe, v));
    }
    let features: Vec<FeatureName> = versions.iter().map(|(f, _)| f.clone()).collect();
    let mut entry = p.audit("rollback_part", AuditResult::Ok, String::new());
    entry.machine = Some(machine.to_string());
    entry.before = Some(in_force(&state, &machine, &features));
    let asked: std::collections::BTreeMap<&str, u64> = versions
        .iter()
        .map(|(f, v)| (f.as_str(), v.get()))
        .collect();
    entry.reason = serde_json::json!({ "to": asked }).to_string();
    let rollback = MachineCommand::RollbackPart { versions };
    let done = command(&state, &machine, ApiCode::RollbackRefused, rollback).await;
    audited(&state, entry, &done, || {
        in_force(&state, &machine, &features)
    })
    .await;
    Ok(Json(done?.into()))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::ToSchema)]
pub(crate) struct FreezeBody {
    frozen: bool,
    /// Why (kept with the state and in the audit trail); at most 200 characters.
    reason: Option<String>,
}

/// `POST /api/v1/machines/{machine}/lobes/{lobe}/learning` with `{"frozen": true, "reason":
/// "…"}` or `{"frozen": false}`: an engineer freezes a feature's learning (the correction
/// stays as it is) or lets it learn again.
#[utoipa::path(post, path = "/api/v1/machines/{machine}/lobes/{lobe}/learning", tag = "writes", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name")), request_body = FreezeBody, responses((status = 200, description = "learning frozen or resumed", body = CommandReply)))]
pub(super) async fn freeze(
    p: Principal,
    State(state): State<AppState>,
    ApiPath((machine, lobe)): ApiPath<(MachineName, FeatureName)>,
    ApiJson(body): ApiJson<FreezeBody>,
) -> Result<Json<CommandReply>, ApiError> {
    let machine = configured(&state, machine)?;
    if !state
        .machines
        .get(&machine)
        .is_some_and(|l| l.contains(&lobe))
    {
        return Err(ApiError::new(
            ApiCode::LobeNotFound,
            format!("machine {machine} does not grind a lobe or pin {lobe}"),
        ));
    }
    let reason = body.reason.unwrap_or_default();
    if reason.chars().count() > 200 || reason.chars().any(char::is_control) {
        return Err(ApiError::new(
            ApiCode::InvalidReason,
            "reason: at most 200 characters, no control characters".into(),
        ));
    }
    let frozen = body.frozen.then(|| match reason.is_empty() {
        true => format!("frozen by {}", p.actor),
        false => format!("frozen by {}: {reason}", p.actor),
    });
    let status = |s: &AppState| {
        let f = s.metrics.features();
        let now = f
            .get(&(machine.clone(), lobe.clone()))
            .and_then(|f| f.frozen.clone());
        serde_json::json!({ "frozen": now }).to_string()
    };
    let action = if body.frozen {
        "learning.freeze"
    } else {
        "learning.resume"
    };
    let mut entry = p.audit(action, AuditResult::Ok, String::new());
    entry.machine = Some(machine.to_string());
    entry.feature = Some(lobe.to_string());
    entry.before = Some(status(&state));
    let freeze = MachineCommand::Freeze {
        lobe: lobe.clone(),
        frozen,
    };
    let done = command(&state, &machine, ApiCode::FreezeRefused, freeze).await;
    audited(&state, entry, &done, || status(&state)).await;
    Ok(Json(done?.into()))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::ToSchema)]
pub(crate) struct DressingBody {
    wheel_radius_mm: f64,
    /// The dresser's measured infeed (radius removed), µm; optional.
    #[serde(default)]
    infeed_um: Option<f64>,
}

/// A wheel dressing reported by the operator or a cell controller: the table is regenerated
/// for the new radius.
#[utoipa::path(post, path = "/api/v1/machines/{machine}/dressings", tag = "writes", params(("machine" = String, Path, description = "machine name")), request_body = DressingBody, responses((status = 200, description = "recorded, the tables regenerated for the new radius", body = CommandReply)))]
pub(super) async fn dress(
    p: Principal,
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<MachineName>,
    ApiJson(body): ApiJson<DressingBody>,
) -> Result<Json<CommandReply>, ApiError> {
    let machine = configured(&state, machine)?;
    let radius = crate::core::compensate::check_wheel_radius(body.wheel_radius_mm)
        .map_err(|e| ApiError::new(ApiCode::InvalidWheelRadius, e.to_string()))?;
    let infeed_um = body
        .infeed_um
        .map(crate::core::learn::check_dresser_infeed)
        .transpose()
        .map_err(|e| ApiError::new(ApiCode::InvalidInfeed, e.to_string()))?;
    let mut entry = p.audit("dressing", AuditResult::Ok, String::new());
    entry.machine = Some(machine.to_string());
    let features = state.machines.get(&machine).cloned().unwrap_or_default();
    entry.before = Some(in_force(&state, &machine, &features));
    let source = format!("api:{}", p.actor);
    let dressing = MachineCommand::Dressing {
        wheel_radius_mm: radius,
        infeed_um,
        source,
    };
    let done = command(&state, &machine, ApiCode::DressingRefused, dressing).await;
    audited(&state, entry, &done, || {
        let mut after: serde_json::Value =
            serde_json::from_str(&in_force(&state, &machine, &features)).unwrap_or_default();
        after["wheel_radius_mm"] = serde_json::json!(radius);
        after.to_string()
    })
    .await;
    Ok(Json(done?.into()))
}

/// A machine of this service: one that is configured, else 404 (the name's rule was checked
/// where it was read).
fn configured(state: &AppState, machine: MachineName) -> Result<MachineName, ApiError> {
    if state.machines.contains_key(&machine) {
        Ok(machine)
    } else {
        Err(ApiError::new(
            ApiCode::MachineNotFound,
            format!("machine {machine} is not configured"),
        ))
    }
}

/// Hands a write request to the machine's loop and waits for its answer; `refused` is the
/// command's code for [`CommandError::Refused`].
async fn command(
    state: &AppState,
    machine: &MachineName,
    refused: ApiCode,
    command: MachineCommand,
) -> Result<CommandOutcome, ApiError> {
    let stopped =
        |what: &str| ApiError::new(ApiCode::MachineStopped, format!("machine {machine} {what}"));
    let sender = state
        .commands
        .read()
        .ok()
        .and_then(|routes| routes.get(machine).cloned());
    let sender = match sender {
        Some(s) => s,
        // Configured, but another instance of the cluster owns it now.
        None if state.machines.contains_key(machine) => {
            return Err(ApiError::new(
                ApiCode::MachineElsewhere,
                format!(
                    "machine {machine} does not run on this instance now: another instance of the cluster holds it; ask that one"
                ),
            ));
        }
        None => {
            return Err(ApiError::new(
                ApiCode::MachineNotFound,
                format!("machine {machine} is not configured"),
            ));
        }
    };
    let (reply, answer) = tokio::sync::oneshot::channel();
    sender
        .send((command, reply))
        .await
        .map_err(|_| stopped("is not running"))?;
    let result: Result<CommandOutcome, CommandError> =
        answer.await.map_err(|_| stopped("stopped"))?;
    result.map_err(|e| ApiError::new(command_code(&e, refused), e.to_string()))
}

/// The stable code of a command's error (its HTTP status is the code's); `refused` is the
/// command's own (`rollback_refused`, …).
pub fn command_code(e: &CommandError, refused: ApiCode) -> ApiCode {
    match e {
        CommandError::VersionNotFound { .. } => ApiCode::TableVersionNotFound,
        CommandError::StoreUnavailable { .. } => ApiCode::StoreUnavailable,
        CommandError::Refused { .. } => refused,
        CommandError::Failed { .. } => ApiCode::CommandFailed,
        CommandError::JournalUnavailable { .. } => ApiCode::JournalUnavailable,
        CommandError::ShareStateFailed { .. } => ApiCode::ShareStateFailed,
        CommandError::Elsewhere { .. } => ApiCode::MachineElsewhere,
    }
}
