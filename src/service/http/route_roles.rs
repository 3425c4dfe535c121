//! The one table of every route with the role it needs (see `access.rs`, which enforces
//! it, and `tests/it/access_matrix.rs`, which walks it). A new route needs a row here: without
//! one the access layer refuses it for everyone.

use crate::store::Role;
use axum::http::Method;

/// What a route needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Need {
    /// Anyone, signed in or not (health, assets, the sign-in page).
    Public,
    /// At least this role.
    Role(Role),
}

/// How a route answers one who may not call it, and how it is protected from cross-site
/// requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// JSON API: 401/403 with `{code, message}`; a session's writes need `X-CSRF-Token`.
    Api,
    /// A dashboard page: an anonymous visitor is sent to the sign-in page.
    Page,
    /// An HTML form post (sign-in, sign-out): its handler checks the form's CSRF field.
    Form,
}

/// One route: method, path as routed, what it needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RouteRule {
    pub method: &'static str,
    pub path: &'static str,
    pub need: Need,
    pub kind: Kind,
}

const fn r(method: &'static str, path: &'static str, need: Need, kind: Kind) -> RouteRule {
    RouteRule {
        method,
        path,
        need,
        kind,
    }
}

const VIEW: Need = Need::Role(Role::Viewer);
const OPERATE: Need = Need::Role(Role::Operator);
const ENGINEER: Need = Need::Role(Role::Engineer);

/// Every route of the router with what it needs. Reads are `viewer`; acknowledging and
/// reporting a dressing `operator`; rolling back, freezing learning and the audit trail
/// `engineer`.
pub const ROUTES: &[RouteRule] = &[
    r("GET", "/healthz", Need::Public, Kind::Api),
    r("GET", "/metrics", VIEW, Kind::Api),
    r("GET", "/openapi.json", VIEW, Kind::Api),
    r("GET", "/api/v1/machines", VIEW, Kind::Api),
    r("GET", "/api/v1/cluster", VIEW, Kind::Api),
    r(
        "GET",
        "/api/v1/machines/{machine}/measurements",
        VIEW,
        Kind::Api,
    ),
    r("GET", "/api/v1/machines/{machine}/events", VIEW, Kind::Api),
    r(
        "GET",
        "/api/v1/machines/{machine}/parts/{part}",
        VIEW,
        Kind::Api,
    ),
    r(
        "POST",
        "/api/v1/machines/{machine}/rollback",
        ENGINEER,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/features/{feature}/capability",
        VIEW,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/lobes/{lobe}/tables",
        VIEW,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/program",
        VIEW,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/diff",
        VIEW,
        Kind::Api,
    ),
    r(
        "POST",
        "/api/v1/machines/{machine}/lobes/{lobe}/rollback",
        ENGINEER,
        Kind::Api,
    ),
    r(
        "POST",
        "/api/v1/machines/{machine}/lobes/{lobe}/learning",
        ENGINEER,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/dressings",
        VIEW,
        Kind::Api,
    ),
    r(
        "POST",
        "/api/v1/machines/{machine}/dressings",
        OPERATE,
        Kind::Api,
    ),
    r("GET", "/api/v1/measurements/{id}", VIEW, Kind::Api),
    r(
        "POST",
        "/api/v1/machines/{machine}/events/{id}/ack",
        OPERATE,
        Kind::Api,
    ),
    r("GET", "/api/v1/audit", ENGINEER, Kind::Api),
    r("GET", "/", VIEW, Kind::Page),
    r(
        "GET",
        "/machines/{machine}/features/{lobe}",
        VIEW,
        Kind::Page,
    ),
    r(
        "GET",
        "/machines/{machine}/features/{lobe}/versions",
        VIEW,
        Kind::Page,
    ),
    r(
        "GET",
        "/machines/{machine}/features/{lobe}/data",
        VIEW,
        Kind::Page,
    ),
    r(
        "GET",
        "/machines/{machine}/features/{lobe}/export.dfq",
        VIEW,
        Kind::Page,
    ),
    r("GET", "/dashboard/events", VIEW, Kind::Page),
    r("GET", "/audit", ENGINEER, Kind::Page),
    r("GET", "/assets/app.js", Need::Public, Kind::Api),
    r("GET", "/assets/app.css", Need::Public, Kind::Api),
    r("GET", "/assets/icon.svg", Need::Public, Kind::Api),
    r("GET", "/signin", Need::Public, Kind::Page),
    r("POST", "/signin", Need::Public, Kind::Form),
    r("POST", "/signout", Need::Public, Kind::Form),
    r("GET", "/session", Need::Public, Kind::Api),
];

/// The rule of a routed path, if the table has one.
pub fn rule_for(method: &Method, path: &str) -> Option<&'static RouteRule> {
    let head = *method == Method::HEAD;
    ROUTES
        .iter()
        .find(|r| r.path == path && (r.method == method.as_str() || (head && r.method == "GET")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_route_is_in_the_table_once() {
        let mut seen = std::collections::BTreeSet::new();
        for r in ROUTES {
            assert!(
                seen.insert((r.method, r.path)),
                "{} {} twice",
                r.method,
                r.path
            );
        }
        assert_eq!(
            rule_for(&Method::HEAD, "/healthz").map(|r| r.need),
            Some(Need::Public)
        );
        assert!(rule_for(&Method::DELETE, "/healthz").is_none());
    }
}
