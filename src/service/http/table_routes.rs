//! The read handlers of table versions: a feature's versions, one version's program text,
//! and its difference from its parent. Each reply is a typed record serialised as JSON.

use super::AppState;
use super::api::{ApiError, ApiPath, ApiQuery};
use super::routes::{Items, LimitQuery, store};
use crate::core::digest::Sha256;
use crate::core::ids::TableVersion;
use crate::names::{FeatureName, MachineName};
use crate::service::http::ApiCode;
use axum::Json;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::Serialize;

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct TableItem {
    version: i64,
    parent_version: Option<i64>,
    table_number: u32,
    #[schema(value_type = String)]
    sha256: Sha256,
    reason: String,
    status: &'static str,
    status_why: String,
    created_at_ms: i64,
}

/// Table versions of a feature, newest first.
#[utoipa::path(get, path = "/api/v1/machines/{machine}/lobes/{lobe}/tables", tag = "tables", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name"), LimitQuery), responses((status = 200, description = "table versions, newest first", body = Items<TableItem>)))]
pub(super) async fn tables(
    State(state): State<AppState>,
    ApiPath((machine, lobe)): ApiPath<(MachineName, FeatureName)>,
    ApiQuery(q): ApiQuery<LimitQuery>,
) -> Result<Json<Items<TableItem>>, ApiError> {
    let versions = store(&state)
        .await?
        .table_versions(&machine, &lobe, q.limit.unwrap_or(50))
        .await?;
    let items = versions
        .into_iter()
        .map(|t| TableItem {
            version: t.version.to_i64(),
            parent_version: t.parent_version.map(TableVersion::to_i64),
            table_number: t.table_number,
            sha256: t.sha256,
            reason: t.reason,
            status: t.status.name(),
            status_why: t.status.why().to_string(),
            created_at_ms: t.created_at.as_millisecond(),
        })
        .collect();
    Ok(Json(Items { items }))
}

/// The program text of a table version.
#[utoipa::path(get, path = "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/program", tag = "tables", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name"), ("version" = i64, Path, description = "table version")), responses((status = 200, description = "the program text of the version", content_type = "text/plain")))]
pub(super) async fn program(
    State(state): State<AppState>,
    ApiPath((machine, lobe, version)): ApiPath<(MachineName, FeatureName, i64)>,
) -> Result<Response, ApiError> {
    let t = store(&state)
        .await?
        .table_version(&machine, &lobe, path_version(version)?)
        .await?
        .ok_or_else(|| version_not_found(version))?;
    Ok((
        [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
        t.program_text,
    )
        .into_response())
}

/// The path's version as the store takes it; 0 or less is a version that is not there.
fn path_version(version: i64) -> Result<TableVersion, ApiError> {
    TableVersion::from_i64(version).map_err(|_| version_not_found(version))
}

fn version_not_found(version: impl std::fmt::Display) -> ApiError {
    ApiError::new(
        ApiCode::TableVersionNotFound,
        format!("version {version} not found"),
    )
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct DiffReply {
    version: i64,
    parent_version: i64,
    /// Table numbers of the parent and of this version.
    table_numbers: [u32; 2],
    max_abs_delta_x_um: f64,
    at_c_deg: f64,
    rms_delta_x_um: f64,
    points: Vec<DiffPoint>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct DiffPoint {
    c_deg: f64,
    delta_x_um: f64,
}

/// How a table version differs from its parent: X (as the control interpolates it) at every
/// point of the newer table, newer minus older, µm.
#[utoipa::path(get, path = "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/diff", tag = "tables", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name"), ("version" = i64, Path, description = "table version")), responses((status = 200, description = "X of the version minus X of its parent at every table point, µm", body = DiffReply)))]
pub(super) async fn diff(
    State(state): State<AppState>,
    ApiPath((machine, lobe, version)): ApiPath<(MachineName, FeatureName, i64)>,
) -> Result<Json<DiffReply>, ApiError> {
    let store = store(&state).await?;
    let newer = store
        .table_version(&machine, &lobe, path_version(version)?)
        .await?
        .ok_or_else(|| version_not_found(version))?;
    let Some(parent) = newer.parent_version else {
        return Err(ApiError::new(
            ApiCode::NoParentVersion,
            format!("version {version} is the first"),
        ));
    };
    let older = store
        .table_version(&machine, &lobe, parent)
        .await?
        .ok_or_else(|| version_not_found(parent))?;
    let parse = |text: &str, v: i64| {
        crate::core::program::parse_table_program(text)
            .map_err(|e| ApiError::new(ApiCode::ProgramUnreadable, format!("version {v}: {e}")))
    };
    let (new_t, old_t) = (
        parse(&newer.program_text, version)?,
        parse(&older.program_text, parent.to_i64())?,
    );
    let points: Vec<DiffPoint> = new_t
        .c_knots_deg()
        .into_iter()
        .filter_map(|c| {
            Some(DiffPoint {
                c_deg: c,
                delta_x_um: (new_t.x_at(c)? - old_t.x_at(c)?) * 1000.0,
            })
        })
        .collect();
    let (at, max) = points.iter().fold((0.0, 0.0f64), |(a, m), p| {
        if p.delta_x_um.abs() > m {
            (p.c_deg, p.delta_x_um.abs())
        } else {
            (a, m)
        }
    });
    let sum_sq: f64 = points.iter().map(|p| p.delta_x_um * p.delta_x_um).sum();
    let rms = (sum_sq / points.len().max(1) as f64).sqrt();
    Ok(Json(DiffReply {
        version,
        parent_version: parent.to_i64(),
        table_numbers: [older.table_number, newer.table_number],
        max_abs_delta_x_um: max,
        at_c_deg: at,
        rms_delta_x_um: rms,
        points,
    }))
}
