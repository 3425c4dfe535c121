//! `GET /api/v1/machines/{machine}/features/{feature}/capability?window=…[&chart=true]`:
//! the capability of every characteristic of a feature over a window of production parts
//! (master runs left out), with the limits from the recipe, and on request the control
//! chart of each (limits from the window's first 25 parts, the rules' flags per point).
//!
//! `window`: `parts:N` (the newest N, default `parts:125`; a bare number too), `since:TIME`
//! (`2026-11-21`, `…T10:00:00Z`, Unix ms or an age like `24h`), `dressing` (since the
//! machine's last wheel dressing) or `recipe` (since the feature's recipe last changed).

use super::AppState;
use super::api::{ApiError, ApiPath, ApiQuery};
use super::routes::store;
use crate::names::{FeatureName, MachineName};
use crate::quality::{self, CharacteristicStudy, Window};
use crate::service::http::ApiCode;
use axum::Json;
use axum::extract::State;
use serde::{Deserialize, Serialize};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct CapabilityQuery {
    /// `parts:N` (default `parts:125`), `since:TIME` (2026-11-21, or an age like 24h),
    /// `dressing` (since the last dressing) or `recipe` (since the recipe changed).
    window: Option<String>,
    /// `true` adds the I-MR/EWMA chart with the run rules' flags.
    chart: Option<bool>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct CapabilityReply {
    #[schema(value_type = String)]
    machine: MachineName,
    #[schema(value_type = String)]
    feature: FeatureName,
    /// The window as asked.
    window: String,
    parts: usize,
    /// Start of the window, Unix ms, when it has one.
    since_ms: Option<i64>,
    master_runs_left_out: usize,
    /// True when a characteristic's figures rest on fewer than `min_values` values: they
    /// are shown, but only indicative (each characteristic carries its own `indicative`).
    indicative: bool,
    /// The values a capability study needs (AIAG SPC manual: 100).
    min_values: usize,
    #[schema(value_type = Vec<Object>)]
    characteristics: Vec<CharacteristicStudy>,
}

fn bad_window(text: &str) -> ApiError {
    ApiError::new(
        ApiCode::InvalidWindow,
        format!(
            "window `{text}`: use parts:N, since:TIME (2026-11-21, an age like 24h), dressing or recipe"
        ),
    )
}

/// The window a query names.
pub(crate) fn parse_window(text: &str, now: jiff::Timestamp) -> Result<Window, ApiError> {
    let mut w = Window::default();
    let parts = |n: &str| {
        n.parse::<u32>()
            .ok()
            .filter(|n| (1..=crate::store::MAX_PAGE).contains(n))
    };
    match text.split_once(':') {
        _ if text == "dressing" => w.since_dressing = true,
        _ if text == "recipe" => w.since_recipe_change = true,
        Some(("parts", n)) => w.last = parts(n).ok_or_else(|| bad_window(text))?,
        Some(("since", t)) => {
            w.since = Some(crate::clock::parse_time(t, now).map_err(|_| bad_window(text))?);
            w.last = crate::store::MAX_PAGE;
        }
        None => w.last = parts(text).ok_or_else(|| bad_window(text))?,
        _ => return Err(bad_window(text)),
    }
    if w.since_dressing || w.since_recipe_change {
        w.last = crate::store::MAX_PAGE;
    }
    Ok(w)
}

/// Process capability of every characteristic of a feature (master runs left out).
#[utoipa::path(get, path = "/api/v1/machines/{machine}/features/{feature}/capability", tag = "quality", params(("machine" = String, Path, description = "machine name"), ("feature" = String, Path, description = "lobe or pin name"), CapabilityQuery), responses((status = 200, description = "process capability of every characteristic of the feature", body = CapabilityReply)))]
pub(super) async fn capability(
    State(state): State<AppState>,
    ApiPath((machine, feature)): ApiPath<(MachineName, FeatureName)>,
    ApiQuery(q): ApiQuery<CapabilityQuery>,
) -> Result<Json<CapabilityReply>, ApiError> {
    let window_text = q.window.unwrap_or_else(|| "parts:125".into());
    let window = parse_window(&window_text, crate::clock::now())?;
    let Some(sheet) = state.dashboard.get(&(machine.clone(), feature.clone())) else {
        return Err(ApiError::new(
            ApiCode::FeatureNotFound,
            format!(
                "machine {machine} has no configured feature {feature}: its limits come from the recipe"
            ),
        ));
    };
    let store = store(&state).await?;
    let (rows, since, masters) =
        quality::window_rows(&store, &machine, &feature, &window, false).await?;
    let characteristics = quality::study(&rows, &sheet.limits, q.chart.unwrap_or(false));
    Ok(Json(CapabilityReply {
        indicative: characteristics.iter().any(|c| c.indicative),
        min_values: quality::MIN_CAPABILITY_VALUES,
        characteristics,
        machine,
        feature,
        window: window_text,
        parts: rows.len(),
        since_ms: since.map(|at| at.as_millisecond()),
        master_runs_left_out: masters,
    }))
}

#[cfg(test)]
mod tests {
    /// The marks of a small window are in the published schema, with the types the reply
    /// writes, so a client generated from `/openapi.json` sees them.
    #[test]
    fn the_schema_carries_the_indicative_fields() {
        let doc = serde_json::to_value(super::super::openapi::document()).unwrap_or_default();
        let path = "/api/v1/machines/{machine}/features/{feature}/capability";
        let reply = &doc["paths"][path]["get"]["responses"]["200"]["content"]["application/json"]["schema"]
            ["$ref"];
        let name = reply.as_str().and_then(|r| r.rsplit('/').next());
        let schema = &doc["components"]["schemas"][name.unwrap_or_default()];
        assert_eq!(
            schema["properties"]["indicative"]["type"], "boolean",
            "{schema}"
        );
        assert_eq!(
            schema["properties"]["min_values"]["type"], "integer",
            "{schema}"
        );
        let required = schema["required"].as_array().cloned().unwrap_or_default();
        for field in ["indicative", "min_values"] {
            assert!(required.iter().any(|r| r == field), "{field}: {schema}");
        }
    }
}
