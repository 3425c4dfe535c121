//! Downloads: the data of every chart as CSV or JSON, and a feature's parts as a Q-DAS
//! `.dfq` file.

use super::Dash;
use super::data::{self, diff_um};
use crate::dfq::{DfqSeries, row_from, write_dfq};
use crate::names::{FeatureName, MachineName};
use crate::service::http::ApiCode;
use crate::service::http::api::{ApiError, ApiPath, ApiQuery};
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use std::fmt::Write as _;

/// Parts in the dashboard's `.dfq` download (the CLI exports any range).
const DFQ_PARTS: u32 = 500;

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[derive(utoipa::ToSchema)]
pub(super) enum Chart {
    Trend,
    Latest,
    Diff,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[derive(utoipa::ToSchema)]
pub(super) enum Format {
    Csv,
    Json,
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct DataQuery {
    chart: Chart,
    format: Format,
    v: Option<i64>,
}

/// A table of numbers: column names (with units) and rows.
struct Table {
    name: String,
    columns: Vec<&'static str>,
    rows: Vec<Vec<f64>>,
}

impl Table {
    fn csv(&self) -> String {
        let mut s = self.columns.join(",") + "\n";
        for r in &self.rows {
            let cells: Vec<String> = r.iter().map(|v| v.to_string()).collect();
            let _ = writeln!(s, "{}", cells.join(","));
        }
        s
    }

    fn json(&self) -> String {
        let rows: Vec<serde_json::Map<String, serde_json::Value>> = self
            .rows
            .iter()
            .map(|r| {
                self.columns
                    .iter()
                    .zip(r)
                    .map(|(c, v)| (c.to_string(), serde_json::json!(v)))
                    .collect()
            })
            .collect();
        serde_json::json!({ "chart": self.name, "rows": rows }).to_string()
    }
}

fn not_found(what: String) -> ApiError {
    ApiError::new(ApiCode::NoData, what)
}

/// `GET …/data?chart=trend|latest|diff&format=csv|json[&v=N]`.
#[utoipa::path(get, path = "/machines/{machine}/features/{lobe}/data", tag = "dashboard", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name"), DataQuery), responses((status = 200, description = "a chart's data as CSV or JSON", content_type = "text/csv")))]
pub(super) async fn chart_data(
    State(d): State<Dash>,
    ApiPath((machine, lobe)): ApiPath<(MachineName, FeatureName)>,
    ApiQuery(q): ApiQuery<DataQuery>,
) -> Result<Response, ApiError> {
    let store = data::store(&d.app).await?;
    let table = match q.chart {
        Chart::Trend => {
            let mut parts = data::history(&store, &machine, &lobe, data::TREND_PARTS).await?;
            parts.reverse();
            Table {
                name: format!("{machine} {lobe} trend"),
                columns: vec![
                    "id",
                    "received_at_ms",
                    "max_profile_error_um",
                    "base_radius_error_um",
                    "phase_error_deg",
                ],
                rows: parts
                    .iter()
                    .map(|p| {
                        vec![
                            p.id.0 as f64,
                            p.received_at.as_millisecond() as f64,
                            p.max_profile_error_um,
                            p.base_radius_error_um,
                            p.phase_error_deg,
                        ]
                    })
                    .collect(),
            }
        }
        Chart::Latest => latest_table(&store, &machine, &lobe).await?,
        Chart::Diff => {
            let v =
                q.v.ok_or_else(|| ApiError::new(ApiCode::InvalidQuery, "diff needs v".into()))?;
            diff_table(&store, &machine, &lobe, v).await?
        }
    };
    let (body, kind, ext) = match q.format {
        Format::Csv => (table.csv(), "text/csv; charset=utf-8", "csv"),
        Format::Json => (table.json(), "application/json", "json"),
    };
    let file = format!(
        "attachment; filename=\"{machine}_{lobe}_{:?}.{ext}\"",
        q.chart
    )
    .to_lowercase();
    Ok((
        [
            (header::CONTENT_TYPE, kind.to_string()),
            (header::CONTENT_DISPOSITION, file),
        ],
        body,
    )
        .into_response())
}

async fn diff_table(
    store: &crate::store::Store,
    machine: &MachineName,
    lobe: &FeatureName,
    v: i64,
) -> Result<Table, ApiError> {
    let not_there = || not_found(format!("version {v} not found"));
    let asked = crate::core::ids::TableVersion::from_i64(v).map_err(|_| not_there())?;
    let newer = store
        .table_version(machine, lobe, asked)
        .await?
        .ok_or_else(not_there)?;
    let parent = newer
        .parent_version
        .ok_or_else(|| not_found(format!("version {v} is the first")))?;
    let older = store
        .table_version(machine, lobe, parent)
        .await?
        .ok_or_else(|| not_found(format!("version {parent} not found")))?;
    let points = diff_um(&newer, &older)
        .ok_or_else(|| not_found(format!("version {v} or {parent} unreadable")))?;
    Ok(Table {
        name: format!("{machine} {lobe} v{v} minus v{parent}"),
        columns: vec!["c_deg", "delta_x_um"],
        rows: points.into_iter().map(|(c, x)| vec![c, x]).collect(),
    })
}

async fn latest_table(
    store: &crate::store::Store,
    machine: &MachineName,
    lobe: &FeatureName,
) -> Result<Table, ApiError> {
    let fd = data::feature(store, machine, lobe).await?;
    let l = fd
        .latest
        .ok_or_else(|| not_found(format!("{machine} {lobe} has no part yet")))?;
    let c = &l.curves;
    let k = fd.learning.correction_um.len();
    let rows = (0..c.angle_deg.len())
        .map(|i| {
            // The correction lives on the gauge grid; the same index when the grids agree.
            let correction = if k == c.angle_deg.len() {
                fd.learning.correction_um[i]
            } else {
                f64::NAN
            };
            vec![
                c.angle_deg[i],
                l.lift_mm.get(i).copied().unwrap_or(f64::NAN),
                c.error_um.get(i).copied().unwrap_or(f64::NAN),
                c.profile_error_um.get(i).copied().unwrap_or(f64::NAN),
                correction,
            ]
        })
        .collect();
    Ok(Table {
        name: format!("{machine} {lobe} part {}", l.summary.id.0),
        columns: vec![
            "angle_deg",
            "measured_lift_mm",
            "error_um",
            "profile_error_um",
            "correction_um",
        ],
        rows,
    })
}

/// `GET …/export.dfq`: the newest parts of the feature as Q-DAS AQDEF.
#[utoipa::path(get, path = "/machines/{machine}/features/{lobe}/export.dfq", tag = "dashboard", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name")), responses((status = 200, description = "the newest parts as Q-DAS AQDEF", content_type = "text/plain")))]
pub(super) async fn dfq(
    State(d): State<Dash>,
    ApiPath((machine, lobe)): ApiPath<(MachineName, FeatureName)>,
) -> Result<Response, ApiError> {
    let store = data::store(&d.app).await?;
    let mut parts = data::history(&store, &machine, &lobe, DFQ_PARTS).await?;
    parts.reverse();
    let part_name = store
        .features(&machine)
        .await?
        .into_iter()
        .find(|f| f.lobe == lobe)
        .map(|f| f.part.to_string())
        .unwrap_or_default();
    let mut rows = Vec::with_capacity(parts.len());
    for p in &parts {
        let detail = store.measurement(p.id).await?;
        rows.push(row_from(
            p,
            detail.as_ref().map(|d| d.analysis_json.as_str()),
        ));
    }
    let sheet = d.app.dashboard.get(&(machine.clone(), lobe.clone()));
    let series = DfqSeries {
        machine: machine.clone(),
        feature: lobe.clone(),
        profile_band_um: sheet
            .and_then(super::FeatureSheet::symmetric_band_um)
            .map(|b| (-b, b)),
        limits: sheet.map_or_else(Default::default, |s| {
            crate::dfq::DfqLimits::from_feature(&s.limits)
        }),
        rows,
    };
    let text = write_dfq(
        &part_name,
        &format!("{part_name} ground on {machine}"),
        &[series],
    )
    .map_err(|e| not_found(format!("{machine} {lobe}: {e}")))?;
    let file = format!("attachment; filename=\"{machine}_{lobe}.dfq\"");
    Ok((
        [
            (
                header::CONTENT_TYPE,
                "text/plain; charset=utf-8".to_string(),
            ),
            (header::CONTENT_DISPOSITION, file),
        ],
        text,
    )
        .into_response())
}
