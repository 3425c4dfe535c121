//! The API description served at `/openapi.json`, derived by utoipa from the handlers'
//! `#[utoipa::path]` attributes and their request and reply types, so it cannot drift from
//! the code. Two things are added to every operation here, from the one place each lives:
//! the `{code, message}` error replies ([`ApiCode`] lists every code) and the role the route
//! needs (from the access table, `route_roles.rs`).

use super::ApiCode;
use super::api::ErrorBody;
use super::route_roles::{Need, ROUTES};
use axum::Json;
use utoipa::OpenApi;
use utoipa::openapi::path::Operation;
use utoipa::openapi::{ContentBuilder, Ref, RefOr, Response, ResponseBuilder};

/// Every route the router serves, with its handler's description.
#[derive(OpenApi)]
#[openapi(
    info(
        title = "camloop",
        description = "Every route needs a role (viewer reads; operator acknowledges and \
            reports dressings; engineer rolls back, freezes learning and reads the audit trail; \
            admin manages users): send `Authorization: Bearer <token>` (`camloop token create`) \
            or sign in on the dashboard. On a loopback listener anonymous callers read as viewer \
            unless `auth.anonymous_read = false`. Every error is `{code, message}`."
    ),
    paths(
        super::routes::healthz,
        super::routes::metrics,
        openapi,
        super::routes::machines,
        super::routes::cluster,
        super::routes::history,
        super::routes::events,
        super::parts::part,
        super::capability::capability,
        super::writes::rollback_part,
        super::table_routes::tables,
        super::table_routes::program,
        super::table_routes::diff,
        super::writes::rollback,
        super::writes::freeze,
        super::routes::dressings,
        super::writes::dress,
        super::routes::measurement,
        super::dashboard::ack,
        super::audit::audit,
        super::audit::audit_page,
        super::session::signin_page,
        super::session::signin,
        super::session::signout,
        super::session::session,
    ),
    components(schemas(ErrorBody, ApiCode)),
    modifiers(&Errors, &Roles)
)]
pub(crate) struct ApiDoc;

/// The whole document: the API's routes and the dashboard's.
pub(crate) fn document() -> utoipa::openapi::OpenApi {
    ApiDoc::openapi().merge_from(super::dashboard::DashboardDoc::openapi())
}

/// This document.
#[utoipa::path(get, path = "/openapi.json", tag = "service",
    responses((status = 200, description = "this document (OpenAPI 3.1)", content_type = "application/json")))]
pub(super) async fn openapi() -> Json<utoipa::openapi::OpenApi> {
    Json(document())
}

/// The operations of a path item this service routes (GET and POST).
fn operations(
    item: &mut utoipa::openapi::PathItem,
) -> impl Iterator<Item = (&'static str, &mut Operation)> {
    [("GET", item.get.as_mut()), ("POST", item.post.as_mut())]
        .into_iter()
        .filter_map(|(m, op)| op.map(|op| (m, op)))
}

/// The `{code, message}` error replies, on every operation that has none of its own.
struct Errors;

impl utoipa::Modify for Errors {
    fn modify(&self, doc: &mut utoipa::openapi::OpenApi) {
        let error = |description: &str| -> RefOr<Response> {
            let content = ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("ErrorBody")))
                .build();
            ResponseBuilder::new()
                .description(description)
                .content("application/json", content)
                .build()
                .into()
        };
        for item in doc.paths.paths.values_mut() {
            for (_, op) in operations(item) {
                let r = &mut op.responses.responses;
                r.entry("4XX".into()).or_insert_with(|| {
                    error("refused: `code` says why (unauthorized, forbidden, csrf_mismatch, locked_out, invalid_…, …_not_found, …_refused)")
                });
                r.entry("5XX".into()).or_insert_with(|| {
                    error("not served now: `code` says why (store_unavailable, machine_stopped, machine_elsewhere, …)")
                });
            }
        }
    }
}

/// The role each operation needs, from the access table.
struct Roles;

impl utoipa::Modify for Roles {
    fn modify(&self, doc: &mut utoipa::openapi::OpenApi) {
        for (path, item) in doc.paths.paths.iter_mut() {
            for (method, op) in operations(item) {
                let need = ROUTES
                    .iter()
                    .find(|r| r.method == method && r.path == path)
                    .map(|r| r.need);
                let role = match need {
                    Some(Need::Public) => "anyone".to_string(),
                    Some(Need::Role(role)) => format!("role {}", role.as_str()),
                    None => "nobody (no row in the access table)".to_string(),
                };
                let text = op.description.get_or_insert_with(String::new);
                if !text.is_empty() {
                    text.push_str("\n\n");
                }
                text.push_str(&format!("Who may call it: {role}."));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// Every route of the access table (which the router's routes must each have a row in,
    /// see `tests/it/access_matrix.rs`) is in the document, and the document has no other.
    #[test]
    fn every_route_is_documented_and_nothing_else() {
        let mut doc = document();
        let mut documented = BTreeSet::new();
        for (path, item) in doc.paths.paths.iter_mut() {
            for (method, _) in operations(item) {
                documented.insert((method.to_string(), path.clone()));
            }
        }
        let routed: BTreeSet<(String, String)> = ROUTES
            .iter()
            .map(|r| (r.method.to_string(), r.path.to_string()))
            .collect();
        let missing: Vec<_> = routed.difference(&documented).collect();
        let extra: Vec<_> = documented.difference(&routed).collect();
        assert!(
            missing.is_empty(),
            "routed, not in /openapi.json: {missing:?}"
        );
        assert!(extra.is_empty(), "in /openapi.json, not routed: {extra:?}");
    }

    #[test]
    fn errors_carry_every_code_and_each_operation_its_role() {
        let json = serde_json::to_value(document()).unwrap_or_default();
        let codes = &json["components"]["schemas"]["ApiCode"]["enum"];
        let codes: Vec<&str> = codes
            .as_array()
            .map(|a| a.iter().filter_map(|c| c.as_str()).collect())
            .unwrap_or_default();
        use strum::IntoEnumIterator;
        assert_eq!(codes.len(), ApiCode::iter().count(), "{codes:?}");
        assert!(codes.contains(&"table_version_not_found"), "{codes:?}");
        let rollback = &json["paths"]["/api/v1/machines/{machine}/lobes/{lobe}/rollback"]["post"];
        let text = rollback["description"].as_str().unwrap_or_default();
        assert!(text.contains("role engineer"), "{rollback}");
        assert!(rollback["responses"]["4XX"].is_object(), "{rollback}");
        assert!(rollback["requestBody"].is_object(), "{rollback}");
    }

    /// The query fields that hold instants are named for what they are in Rust (`since`,
    /// `until`) and keep their wire names: the document and a request both say `since_ms`.
    #[test]
    fn time_parameters_keep_their_wire_names() {
        let json = serde_json::to_value(document()).unwrap_or_default();
        let names = |path: &str| -> Vec<String> {
            json["paths"][path]["get"]["parameters"]
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|p| p["name"].as_str().map(str::to_string))
                        .collect()
                })
                .unwrap_or_default()
        };
        let history = names("/api/v1/machines/{machine}/measurements");
        for name in ["since_ms", "until_ms"] {
            assert!(history.iter().any(|n| n == name), "{history:?}");
        }
        assert!(!history.iter().any(|n| n == "since"), "{history:?}");
        let audit = names("/api/v1/audit");
        assert!(audit.iter().any(|n| n == "since_ms"), "{audit:?}");
        let uri: axum::http::Uri = "/x?since_ms=1000&until_ms=2000".parse().unwrap();
        let q = axum::extract::Query::<super::super::routes::HistoryQuery>::try_from_uri(&uri)
            .map(|q| q.0)
            .map_err(|e| e.body_text());
        let q = format!("{:?}", q.unwrap());
        assert!(q.contains("since: Some(1970-01-01T00:00:01Z)"), "{q}");
        assert!(q.contains("until: Some(1970-01-01T00:00:02Z)"), "{q}");
    }
}
