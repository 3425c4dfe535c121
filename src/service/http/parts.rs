//! A whole part through the API: `GET /api/v1/machines/{machine}/parts/{part}` answers "did
//! shaft 1234 pass, lobe by lobe": every configured feature with its measurement of that part
//! (or none), and the part's verdict.

use super::AppState;
use super::api::{ApiError, ApiPath};
use super::routes::{MeasurementItem, store};
use crate::core::ids::PartId;
use crate::names::{FeatureName, MachineName};
use crate::service::http::ApiCode;
use axum::Json;
use axum::extract::State;
use serde::Serialize;

/// The reply: the part's verdict and its features in grinding order.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct PartReply {
    #[schema(value_type = String)]
    machine: MachineName,
    #[schema(value_type = String)]
    part: PartId,
    /// Every feature the machine grinds was measured on this part and passed its bands.
    pass: bool,
    /// Features of the machine with no measurement of this part (not yet gauged, or lost).
    #[schema(value_type = Vec<String>)]
    missing: Vec<FeatureName>,
    features: Vec<PartFeature>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct PartFeature {
    #[schema(value_type = String)]
    lobe: FeatureName,
    /// The newest measurement of this feature on this part, if any.
    measurement: Option<MeasurementItem>,
    /// Measurements of it on this part (more than one: it was gauged again).
    measurements: usize,
}

/// One part (a shaft), feature by feature: its measurements and whether it passed.
#[utoipa::path(get, path = "/api/v1/machines/{machine}/parts/{part}", tag = "history", params(("machine" = String, Path, description = "machine name"), ("part" = String, Path, description = "part id")), responses((status = 200, description = "the part, feature by feature, and whether it passed", body = PartReply)))]
pub(super) async fn part(
    State(state): State<AppState>,
    ApiPath((machine, part)): ApiPath<(MachineName, String)>,
) -> Result<Json<PartReply>, ApiError> {
    let part = PartId::new(&part).map_err(|_| {
        ApiError::new(
            ApiCode::InvalidName,
            format!(
                "part `{}`: must be 1–32 characters of A–Z a–z 0–9 . _ -",
                crate::names::quote(&part)
            ),
        )
    })?;
    let mut rows = store(&state)
        .await?
        .part_measurements(&machine, &part)
        .await?;
    // Whether the part passed is the finished part's answer: in-process rows have stock on.
    rows.retain(|r| r.stage == crate::store::MeasurementStage::Final);
    // Configured features first, in grinding order; then any the history alone knows.
    let mut lobes: Vec<FeatureName> = state.machines.get(&machine).cloned().unwrap_or_default();
    for r in &rows {
        if !lobes.contains(&r.lobe) {
            lobes.push(r.lobe.clone());
        }
    }
    let features: Vec<PartFeature> = lobes
        .into_iter()
        .map(|lobe| {
            let of: Vec<_> = rows.iter().filter(|r| r.lobe == lobe).collect();
            PartFeature {
                measurements: of.len(),
                measurement: of.last().map(|m| MeasurementItem::from((*m).clone())),
                lobe,
            }
        })
        .collect();
    let missing: Vec<FeatureName> = features
        .iter()
        .filter(|f| f.measurement.is_none())
        .map(|f| f.lobe.clone())
        .collect();
    let pass = missing.is_empty()
        && rows
            .iter()
            .all(|r| r.verdict == crate::store::Verdict::Pass)
        && !features.is_empty();
    Ok(Json(PartReply {
        machine,
        part,
        pass,
        missing,
        features,
    }))
}
