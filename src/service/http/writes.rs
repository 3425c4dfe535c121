//! The write requests: rollback, freezing learning, dressing. The access layer has checked
//! the caller's role (from the headers, before the body is read); each checks the machine,
//! lobe and values, then goes the service's write path (`service::command::write`, the one
//! OPC UA takes too), which hands the command to the machine's loop and audits it.

use super::AppState;
use super::access::Principal;
use super::api::{ApiError, ApiJson, ApiPath, feature_name};
use crate::names::{FeatureName, MachineName};
use crate::service::command::{self, WriteError};
use crate::service::http::ApiCode;
use crate::store::Role;
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
pub(super) async fn rollback(
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
    let rollback = MachineCommand::Rollback { lobe, version };
    let done = command::write(state.writes(), &p.caller(), &machine, rollback).await;
    Ok(Json(done.map_err(write_error)?.into()))
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
    let rollback = MachineCommand::RollbackPart { versions };
    let done = command::write(state.writes(), &p.caller(), &machine, rollback).await;
    Ok(Json(done.map_err(write_error)?.into()))
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
    // The text every reader sees (anonymous ones too: the machines list, the dashboard,
    // OPC UA, MQTT) names the role, not the user; the audit trail (engineers and admins)
    // names who.
    let by = by_role(&p);
    let frozen = body.frozen.then(|| match reason.is_empty() {
        true => format!("frozen by {by}"),
        false => format!("frozen by {by}: {reason}"),
    });
    let freeze = MachineCommand::Freeze { lobe, frozen };
    let done = command::write(state.writes(), &p.caller(), &machine, freeze).await;
    Ok(Json(done.map_err(write_error)?.into()))
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
    // The role, not the user: the dressing's source is shown to every reader; the audit
    // trail names who.
    let source = format!("api:{}", p.role.unwrap_or(Role::Viewer));
    let dressing = MachineCommand::Dressing {
        wheel_radius_mm: radius,
        infeed_um,
        source,
    };
    let done = command::write(state.writes(), &p.caller(), &machine, dressing).await;
    Ok(Json(done.map_err(write_error)?.into()))
}

/// "an operator", "an engineer", "an admin": who did something, as readers who may not see
/// user names are told.
fn by_role(p: &Principal) -> String {
    let role = p.role.unwrap_or(Role::Viewer);
    let article = match role.to_string().starts_with(['a', 'e', 'i', 'o', 'u']) {
        true => "an",
        false => "a",
    };
    format!("{article} {role}")
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

/// The API's error for a write the service did not carry out: the write path's own code
/// and message.
pub(crate) fn write_error(e: WriteError) -> ApiError {
    let code = match &e {
        WriteError::Forbidden { .. } => ApiCode::Forbidden,
        WriteError::NotConfigured { .. } => ApiCode::MachineNotFound,
        WriteError::NotGround { .. } => ApiCode::LobeNotFound,
        WriteError::Elsewhere { .. } => ApiCode::MachineElsewhere,
        WriteError::NotRunning { .. } | WriteError::Stopped { .. } => ApiCode::MachineStopped,
        WriteError::Command { action, error } => command_code(error, refused_code(*action)),
    };
    ApiError::new(code, e.to_string())
}

/// The code of a command the machine's loop refused: the action's own.
fn refused_code(action: crate::service::action::Action) -> ApiCode {
    use crate::service::action::Action;
    match action {
        Action::FreezeLearning => ApiCode::FreezeRefused,
        Action::ReportDressing => ApiCode::DressingRefused,
        _ => ApiCode::RollbackRefused,
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::action::Action;

    /// The write path's code (the audit trail keeps it) is the one the API answers with,
    /// and a service fault is exactly a 5xx: the audit's `failed` or `refused` agrees with
    /// the status.
    #[test]
    fn the_write_paths_codes_are_the_apis() {
        let m: MachineName = "G7".parse().unwrap();
        let f: FeatureName = "IN1".parse().unwrap();
        let mut errors = vec![
            WriteError::Forbidden {
                needed: crate::store::Role::Engineer,
                actor: "ann".into(),
                role: None,
            },
            WriteError::NotConfigured { machine: m.clone() },
            WriteError::NotGround {
                machine: m.clone(),
                feature: f.clone(),
            },
            WriteError::Elsewhere { machine: m.clone() },
            WriteError::NotRunning { machine: m.clone() },
            WriteError::Stopped { machine: m },
        ];
        let reason = String::from("x");
        for action in [
            Action::Rollback,
            Action::FreezeLearning,
            Action::ReportDressing,
        ] {
            for error in [
                CommandError::VersionNotFound {
                    lobe: f.clone(),
                    version: TableVersion::FIRST,
                },
                CommandError::StoreUnavailable {
                    reason: reason.clone(),
                },
                CommandError::Refused {
                    reason: reason.clone(),
                },
                CommandError::Failed {
                    reason: reason.clone(),
                },
                CommandError::JournalUnavailable {
                    reason: reason.clone(),
                },
                CommandError::ShareStateFailed {
                    reason: reason.clone(),
                },
                CommandError::Elsewhere {
                    reason: reason.clone(),
                },
            ] {
                errors.push(WriteError::Command { action, error });
            }
        }
        for e in errors {
            let api = write_error(e.clone());
            assert_eq!(api.code().as_str(), e.code(), "{e:?}");
            assert_eq!(
                api.status().is_server_error(),
                e.is_service_fault(),
                "{e:?}"
            );
            assert_eq!(api.message(), e.to_string(), "{e:?}");
        }
    }
}
