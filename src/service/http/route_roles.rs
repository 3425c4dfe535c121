//! The one table of every route with the [`Action`] it is, and so the role it needs (see
//! `access.rs`, which enforces it, and `tests/it/access_matrix.rs`, which walks it). A new
//! route needs a row here: without one the access layer refuses it for everyone.

use crate::service::action::Action;
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

/// One route: method, path as routed, the action it is (`None`: public), what it needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RouteRule {
    pub method: &'static str,
    pub path: &'static str,
    pub action: Option<Action>,
    /// The action's role (or public): derived from `action`, never written by hand.
    pub need: Need,
    pub kind: Kind,
}

const fn r(
    method: &'static str,
    path: &'static str,
    action: Option<Action>,
    kind: Kind,
) -> RouteRule {
    RouteRule {
        method,
        path,
        action,
        need: match action {
            Some(a) => Need::Role(a.role()),
            None => Need::Public,
        },
        kind,
    }
}

const PUBLIC: Option<Action> = None;
const READ: Option<Action> = Some(Action::Read);
const ACK: Option<Action> = Some(Action::Acknowledge);
const DRESS: Option<Action> = Some(Action::ReportDressing);
const ROLLBACK: Option<Action> = Some(Action::Rollback);
const ROLLBACK_PART: Option<Action> = Some(Action::RollbackPart);
const FREEZE: Option<Action> = Some(Action::FreezeLearning);
const AUDIT: Option<Action> = Some(Action::ReadAudit);

/// Every route of the router with the action it is. Reads are `viewer`; acknowledging and
/// reporting a dressing `operator`; rolling back, freezing learning and the audit trail
/// `engineer` (see [`Action::role`]).
pub const ROUTES: &[RouteRule] = &[
    r("GET", "/healthz", PUBLIC, Kind::Api),
    r("GET", "/metrics", READ, Kind::Api),
    r("GET", "/openapi.json", READ, Kind::Api),
    r("GET", "/api/v1/machines", READ, Kind::Api),
    r("GET", "/api/v1/cluster", READ, Kind::Api),
    r(
        "GET",
        "/api/v1/machines/{machine}/measurements",
        READ,
        Kind::Api,
    ),
    r("GET", "/api/v1/machines/{machine}/events", READ, Kind::Api),
    r(
        "GET",
        "/api/v1/machines/{machine}/parts/{part}",
        READ,
        Kind::Api,
    ),
    r(
        "POST",
        "/api/v1/machines/{machine}/rollback",
        ROLLBACK_PART,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/features/{feature}/capability",
        READ,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/lobes/{lobe}/tables",
        READ,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/program",
        READ,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/diff",
        READ,
        Kind::Api,
    ),
    r(
        "POST",
        "/api/v1/machines/{machine}/lobes/{lobe}/rollback",
        ROLLBACK,
        Kind::Api,
    ),
    r(
        "POST",
        "/api/v1/machines/{machine}/lobes/{lobe}/learning",
        FREEZE,
        Kind::Api,
    ),
    r(
        "GET",
        "/api/v1/machines/{machine}/dressings",
        READ,
        Kind::Api,
    ),
    r(
        "POST",
        "/api/v1/machines/{machine}/dressings",
        DRESS,
        Kind::Api,
    ),
    r("GET", "/api/v1/measurements/{id}", READ, Kind::Api),
    r(
        "POST",
        "/api/v1/machines/{machine}/events/{id}/ack",
        ACK,
        Kind::Api,
    ),
    r("GET", "/api/v1/audit", AUDIT, Kind::Api),
    r("GET", "/", READ, Kind::Page),
    r(
        "GET",
        "/machines/{machine}/features/{lobe}",
        READ,
        Kind::Page,
    ),
    r(
        "GET",
        "/machines/{machine}/features/{lobe}/versions",
        READ,
        Kind::Page,
    ),
    r(
        "GET",
        "/machines/{machine}/features/{lobe}/data",
        READ,
        Kind::Page,
    ),
    r(
        "GET",
        "/machines/{machine}/features/{lobe}/export.dfq",
        READ,
        Kind::Page,
    ),
    r("GET", "/dashboard/events", READ, Kind::Page),
    r("GET", "/audit", AUDIT, Kind::Page),
    r("GET", "/assets/app.js", PUBLIC, Kind::Api),
    r("GET", "/assets/app.css", PUBLIC, Kind::Api),
    r("GET", "/assets/icon.svg", PUBLIC, Kind::Api),
    r("GET", "/signin", PUBLIC, Kind::Page),
    r("POST", "/signin", PUBLIC, Kind::Form),
    r("POST", "/signout", PUBLIC, Kind::Form),
    r("GET", "/session", PUBLIC, Kind::Api),
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

    /// The roles each route has always needed, now by its action: a table of the writes and
    /// the audit trail (every other route reads, or is public).
    #[test]
    fn each_route_needs_its_actions_role() {
        let needs = |method: &str, path: &str| {
            ROUTES
                .iter()
                .find(|r| r.method == method && r.path == path)
                .map(|r| r.need)
        };
        let m = "/api/v1/machines/{machine}";
        let cases = [
            ("POST", format!("{m}/rollback"), Role::Engineer),
            (
                "POST",
                format!("{m}/lobes/{{lobe}}/rollback"),
                Role::Engineer,
            ),
            (
                "POST",
                format!("{m}/lobes/{{lobe}}/learning"),
                Role::Engineer,
            ),
            ("POST", format!("{m}/dressings"), Role::Operator),
            ("POST", format!("{m}/events/{{id}}/ack"), Role::Operator),
            ("GET", "/api/v1/audit".to_string(), Role::Engineer),
            ("GET", "/audit".to_string(), Role::Engineer),
            ("GET", format!("{m}/dressings"), Role::Viewer),
        ];
        for (method, path, role) in cases {
            assert_eq!(
                needs(method, &path),
                Some(Need::Role(role)),
                "{method} {path}"
            );
        }
        for r in ROUTES {
            let derived = r.action.map_or(Need::Public, |a| Need::Role(a.role()));
            assert_eq!(r.need, derived, "{} {}", r.method, r.path);
        }
    }
}
