//! The engineers' dashboard, served by `camloop run` on the API's listener: server-rendered
//! HTML with inline SVG charts and one small script, all compiled into the binary (no CDN,
//! no front-end toolchain).
//!
//! - `/`: the plant overview; `/machines/{m}/features/{f}`: trend, latest part, events,
//!   dressing form, setup drawing; `…/versions`: table versions, diff, rollback.
//! - `…/data?chart=…&format=csv|json`: the data of every chart; `…/export.dfq`: Q-DAS.
//! - `/dashboard/events`: Server-Sent Events of every stored part (`sse.rs`).
//! - `POST /api/v1/machines/{m}/events/{id}/ack` (routed with the API): acknowledges an
//!   event (operator).
//! - `/signin`, `/audit`: the sign-in form and the audit trail (`account.rs`).
//!
//! Writes from the page (rollback, dressing, acknowledgement) use the API with the signed-in
//! session's cookie and its CSRF token (see `http::session`).

mod account;
mod capability_panel;
mod charts;
mod data;
mod downloads;
mod feature;
mod overview;
#[cfg(test)]
mod overview_tests;
mod pages;
mod sse;

pub(super) use account::{audit_html, signin_html};
pub use sse::Stopping;

use super::AppState;
use super::access::Principal;
use super::api::{ApiError, ApiPath, ApiQuery};
use crate::names::{FeatureName, MachineName};
use crate::service::http::ApiCode;
use axum::Router;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;

pub use crate::quality::{FeatureSheet, FeatureSheets};

const APP_JS: &str = include_str!("assets/app.js");
const APP_CSS: &str = include_str!("assets/app.css");
const ICON_SVG: &str = include_str!("assets/icon.svg");

/// The dashboard's state: the API's, and the live channel.
#[derive(Clone)]
pub(super) struct Dash {
    app: AppState,
    live: sse::Live,
    frozen: overview::FrozenMemo,
    rows: overview::OverviewMemo,
}

/// The dashboard's routes, for the API description (`/openapi.json`).
#[derive(utoipa::OpenApi)]
#[openapi(paths(
    overview,
    feature_page,
    versions_page,
    downloads::chart_data,
    downloads::dfq,
    sse::events,
    asset_js,
    asset_css,
    asset_icon
))]
pub(super) struct DashboardDoc;

pub(super) fn router(app: AppState) -> Router {
    let f = "/machines/{machine}/features/{lobe}";
    let live = sse::Live::new(app.store.clone());
    Router::new()
        .route("/", get(overview))
        .route(f, get(feature_page))
        .route(&format!("{f}/versions"), get(versions_page))
        .route(&format!("{f}/data"), get(downloads::chart_data))
        .route(&format!("{f}/export.dfq"), get(downloads::dfq))
        .route("/dashboard/events", get(sse::events))
        .route("/assets/app.js", get(asset_js))
        .route("/assets/app.css", get(asset_css))
        .route("/assets/icon.svg", get(asset_icon))
        .with_state(Dash {
            app,
            live,
            frozen: overview::FrozenMemo::default(),
            rows: overview::OverviewMemo::default(),
        })
}

#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct PageQuery {
    fragment: Option<u8>,
    v: Option<i64>,
    /// The overview's page, from 1 (50 machines each).
    page: Option<u32>,
}

/// The plant overview page.
#[utoipa::path(get, path = "/", tag = "dashboard", params(PageQuery), responses((status = 200, description = "the plant overview", content_type = "text/html")))]
async fn overview(
    State(d): State<Dash>,
    ApiQuery(q): ApiQuery<PageQuery>,
) -> Result<Html<String>, ApiError> {
    let page = q.page.map_or(1, |p| p as usize);
    let page = overview::overview(&d.app, &d.rows, &d.frozen, page).await?;
    Ok(Html(pages::overview(&page, q.fragment.is_some())))
}

/// A feature's page.
#[utoipa::path(get, path = "/machines/{machine}/features/{lobe}", tag = "dashboard", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name"), PageQuery), responses((status = 200, description = "a feature: trend, latest part, events, capability, dressing form, setup drawing", content_type = "text/html")))]
async fn feature_page(
    State(d): State<Dash>,
    ApiPath((machine, lobe)): ApiPath<(MachineName, FeatureName)>,
    ApiQuery(q): ApiQuery<PageQuery>,
) -> Result<Html<String>, ApiError> {
    let store = data::store(&d.app).await?;
    let fd = data::feature(&store, &machine, &lobe).await?;
    let sheet = d.app.dashboard.get(&(machine.clone(), lobe.clone()));
    // Only on a full page: the live refresh after each part redraws the live part alone.
    let panel = match sheet {
        Some(sh) if q.fragment.is_none() => {
            capability_panel::panel(&store, &machine, &lobe, sh).await?
        }
        _ => maud::html! {},
    };
    Ok(Html(feature::feature(
        &machine,
        &lobe,
        &fd,
        sheet,
        q.fragment.is_some(),
        panel,
    )))
}

/// A feature's table versions page.
#[utoipa::path(get, path = "/machines/{machine}/features/{lobe}/versions", tag = "dashboard", params(("machine" = String, Path, description = "machine name"), ("lobe" = String, Path, description = "lobe or pin name"), PageQuery), responses((status = 200, description = "the feature's table versions with rollback", content_type = "text/html")))]
async fn versions_page(
    State(d): State<Dash>,
    ApiPath((machine, lobe)): ApiPath<(MachineName, FeatureName)>,
    ApiQuery(q): ApiQuery<PageQuery>,
) -> Result<Html<String>, ApiError> {
    let store = data::store(&d.app).await?;
    let versions = store.table_versions(&machine, &lobe, 50).await?;
    Ok(Html(pages::versions(
        &machine,
        &lobe,
        &versions,
        q.v,
        q.fragment.is_some(),
    )))
}

/// `POST /api/v1/machines/{machine}/events/{id}/ack`: the caller (an operator, checked by
/// the access layer), then the event; audited.
#[utoipa::path(post, path = "/api/v1/machines/{machine}/events/{id}/ack", tag = "writes", params(("machine" = String, Path, description = "machine name"), ("id" = i64, Path, description = "event id")), responses((status = 200, description = "acknowledged (or acknowledged before)", body = super::CommandReply)))]
pub(super) async fn ack(
    p: Principal,
    State(app): State<AppState>,
    ApiPath((machine, id)): ApiPath<(MachineName, i64)>,
) -> Result<Response, ApiError> {
    use crate::service::command::{AckError, acknowledge};
    use crate::store::AckOutcome;
    let outcome = match acknowledge(app.writes(), &p.caller(), &machine, id).await {
        Ok(outcome) => outcome,
        Err(e @ AckError::Forbidden { .. }) => {
            return Err(ApiError::new(ApiCode::Forbidden, e.to_string()));
        }
        Err(AckError::StoreUnavailable) => return Err(data::unavailable()),
        Err(AckError::Store(e)) => return Err(e.into()),
    };
    let (status, message) = match outcome {
        AckOutcome::Acknowledged => (StatusCode::OK, format!("event {id} acknowledged")),
        AckOutcome::AlreadyAcknowledged => (
            StatusCode::OK,
            format!("event {id} was acknowledged before"),
        ),
        AckOutcome::NotFound => {
            return Err(ApiError::new(
                ApiCode::EventNotFound,
                format!("machine {machine} has no event {id}"),
            ));
        }
    };
    let body = super::CommandReply {
        status: "ok",
        version: None,
        message,
    };
    Ok((status, axum::Json(body)).into_response())
}

/// The dashboard's script.
#[utoipa::path(get, path = "/assets/app.js", tag = "dashboard", responses((status = 200, description = "the dashboard's script", content_type = "text/javascript")))]
async fn asset_js() -> Response {
    asset("text/javascript; charset=utf-8", APP_JS)
}

/// The dashboard's style sheet.
#[utoipa::path(get, path = "/assets/app.css", tag = "dashboard", responses((status = 200, description = "the dashboard's style sheet", content_type = "text/css")))]
async fn asset_css() -> Response {
    asset("text/css; charset=utf-8", APP_CSS)
}

/// The icon.
#[utoipa::path(get, path = "/assets/icon.svg", tag = "dashboard", responses((status = 200, description = "the icon", content_type = "image/svg+xml")))]
async fn asset_icon() -> Response {
    asset("image/svg+xml", ICON_SVG)
}

fn asset(kind: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, kind),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::FeatureSheet;
    use crate::recipe::Recipe;
    use std::path::Path;

    /// The feature page's speed plan chart is there exactly when the recipe asks for a plan.
    #[test]
    fn the_speed_plan_chart_comes_with_the_recipe_switch() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
        let mut recipe = Recipe::load(&path).unwrap();
        let off = FeatureSheet::from_setup(&recipe.feature_setup(&path, "IN1").unwrap());
        assert!(off.speed_plan_svg.is_none());
        recipe.speed_plan.enabled = true;
        let on = FeatureSheet::from_setup(&recipe.feature_setup(&path, "IN1").unwrap());
        let svg = on.speed_plan_svg.expect("the demo lobe has a plan");
        assert!(
            svg.starts_with("<svg") && svg.contains("removal rate Q'w"),
            "{svg}"
        );
    }
}
