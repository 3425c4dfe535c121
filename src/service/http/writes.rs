//! The write requests: rollback and dressing. Each checks the token first (from the headers,
//! before the body is read), then the machine and lobe, then hands a [`Command`] to the
//! machine's loop, which owns the loop state, so a write never races a part.

use super::api::{ApiError, ApiJson, ApiPath, Authorized, feature_name, machine_name};
use super::{AppState, Command, CommandDone, CommandError, Reply};
use crate::names::MachineName;
use axum::Json;
use axum::extract::State;
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};

/// The reply to a write that was carried out.
#[derive(Debug, Serialize)]
pub struct CommandReply {
    /// Always "ok".
    pub status: &'static str,
    /// The table version the write made, when it made one.
    pub version: Option<i64>,
    pub message: String,
}

impl From<CommandDone> for CommandReply {
    fn from(done: CommandDone) -> Self {
        Self {
            status: "ok",
            version: done.version,
            message: done.message,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RollbackBody {
    version: i64,
}

/// Deliver a stored table version again (as a new version, under the table number not in use).
pub(super) async fn rollback(
    _: Authorized,
    State(state): State<AppState>,
    ApiPath((machine, lobe)): ApiPath<(String, String)>,
    ApiJson(body): ApiJson<RollbackBody>,
) -> Result<Json<CommandReply>, ApiError> {
    let machine = configured(&state, &machine)?;
    feature_name(&lobe)?;
    let ground = state
        .machines
        .get(&machine)
        .is_some_and(|l| l.contains(&lobe));
    if !ground {
        return Err(ApiError(
            StatusCode::NOT_FOUND,
            "lobe_not_found",
            format!("machine {machine} does not grind a lobe or pin {lobe}"),
        ));
    }
    if body.version < 1 {
        return Err(ApiError(
            StatusCode::BAD_REQUEST,
            "invalid_version",
            "version must be ≥ 1".into(),
        ));
    }
    let version = body.version;
    let done = command(&state, &machine, "rollback_refused", |reply| {
        Command::Rollback {
            lobe,
            version,
            reply,
        }
    })
    .await?;
    Ok(Json(done.into()))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartRollbackBody {
    /// The version of each feature to go back to, by feature name.
    versions: std::collections::BTreeMap<String, i64>,
}

/// `POST /api/v1/machines/{machine}/rollback` with `{"versions": {"IN1": 5, "EX1": 7}}`:
/// several features back together, or none of them.
pub(super) async fn rollback_part(
    _: Authorized,
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<String>,
    ApiJson(body): ApiJson<PartRollbackBody>,
) -> Result<Json<CommandReply>, ApiError> {
    let machine = configured(&state, &machine)?;
    let grinds = state.machines.get(&machine).cloned().unwrap_or_default();
    if body.versions.is_empty() {
        return Err(ApiError(
            StatusCode::BAD_REQUEST,
            "invalid_versions",
            "versions names no feature".into(),
        ));
    }
    let mut versions = Vec::new();
    for (lobe, version) in body.versions {
        feature_name(&lobe)?;
        if !grinds.contains(&lobe) {
            return Err(ApiError(
                StatusCode::NOT_FOUND,
                "lobe_not_found",
                format!("machine {machine} does not grind a lobe or pin {lobe}"),
            ));
        }
        let Ok(v) = u64::try_from(version) else {
            return Err(ApiError(
                StatusCode::BAD_REQUEST,
                "invalid_version",
                format!("{lobe}: version must be ≥ 1"),
            ));
        };
        if v == 0 {
            return Err(ApiError(
                StatusCode::BAD_REQUEST,
                "invalid_version",
                format!("{lobe}: version must be ≥ 1"),
            ));
        }
        versions.push((lobe, v));
    }
    let done = command(&state, &machine, "rollback_refused", |reply| {
        Command::RollbackPart { versions, reply }
    })
    .await?;
    Ok(Json(done.into()))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DressingBody {
    wheel_radius_mm: f64,
    /// The dresser's measured infeed (radius removed), µm; optional.
    #[serde(default)]
    infeed_um: Option<f64>,
}

/// A wheel dressing reported by the operator or a cell controller: the table is regenerated
/// for the new radius.
pub(super) async fn dress(
    _: Authorized,
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<String>,
    ApiJson(body): ApiJson<DressingBody>,
) -> Result<Json<CommandReply>, ApiError> {
    let machine = configured(&state, &machine)?;
    let radius =
        crate::core::compensate::check_wheel_radius(body.wheel_radius_mm).map_err(|e| {
            ApiError(
                StatusCode::BAD_REQUEST,
                "invalid_wheel_radius",
                e.to_string(),
            )
        })?;
    let infeed_um = body
        .infeed_um
        .map(crate::core::learn::check_dresser_infeed)
        .transpose()
        .map_err(|e| ApiError(StatusCode::BAD_REQUEST, "invalid_infeed", e.to_string()))?;
    let done = command(&state, &machine, "dressing_refused", |reply| {
        Command::Dressing {
            wheel_radius_mm: radius,
            infeed_um,
            reply,
        }
    })
    .await?;
    Ok(Json(done.into()))
}

/// A machine of this service: a valid name that is configured, else 400 or 404.
fn configured(state: &AppState, machine: &str) -> Result<MachineName, ApiError> {
    let name = machine_name(machine)?;
    if state.machines.contains_key(&name) {
        Ok(name)
    } else {
        Err(ApiError(
            StatusCode::NOT_FOUND,
            "machine_not_found",
            format!("machine {machine} is not configured"),
        ))
    }
}

/// Hands a write request to the machine's loop and waits for its answer; `refused` is the
/// command's code for [`CommandError::Refused`].
async fn command(
    state: &AppState,
    machine: &MachineName,
    refused: &'static str,
    make: impl FnOnce(Reply) -> Command,
) -> Result<CommandDone, ApiError> {
    let stopped = |what: &str| {
        ApiError(
            StatusCode::SERVICE_UNAVAILABLE,
            "machine_stopped",
            format!("machine {machine} {what}"),
        )
    };
    let sender = state
        .commands
        .read()
        .ok()
        .and_then(|routes| routes.get(machine.as_str()).cloned());
    let sender = match sender {
        Some(s) => s,
        // Configured, but another instance of the cluster owns it now.
        None if state.machines.contains_key(machine) => {
            return Err(ApiError(
                StatusCode::SERVICE_UNAVAILABLE,
                "machine_elsewhere",
                format!(
                    "machine {machine} does not run on this instance now: another instance of the cluster holds it; ask that one"
                ),
            ));
        }
        None => {
            return Err(ApiError(
                StatusCode::NOT_FOUND,
                "machine_not_found",
                format!("machine {machine} is not configured"),
            ));
        }
    };
    let (reply, answer) = tokio::sync::oneshot::channel();
    sender
        .send(make(reply))
        .await
        .map_err(|_| stopped("is not running"))?;
    let result: Result<CommandDone, CommandError> = answer.await.map_err(|_| stopped("stopped"))?;
    result.map_err(|e| ApiError(e.status(), e.code(refused), e.to_string()))
}
