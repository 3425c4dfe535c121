//! Every route × every role, on a real service with the simulated machine: the table
//! `camloop::service::http::ROUTES` that the router's access layer reads is walked here, and
//! each route is called anonymously and with a token of each role. A caller below the
//! route's role is refused (401 anonymous, 403 with a token; an anonymous page visit is
//! sent to the sign-in page); a caller at or above it is not (what the handler then answers
//! — 200, 404 for a made-up id, 422 for an empty body — is the handler's business).
//! Run twice: with anonymous reading (the loopback default) and without.
//!
//! Every refused write (the layer's 401/403, a handler's 400/404/422) is audited, within
//! the trail's budget for refusals of one client.
//!
//! Also: per-user tokens (a ceiling below the user's role, an expired one, a revoked one),
//! the lockout of wrong tokens after 5 (a good one still passes), and the audit trail the
//! writes leave.

use crate::service_support;

use camloop::auth::{hash_password, new_token, token_digest};
use camloop::service::http::access::{Need, ROUTES};
use camloop::service::{self, RunOptions};
use camloop::store::{NewToken, Role, Store};
use service_support::sim_config;
use std::net::SocketAddr;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Status, the `Location` header and the start of the body (an event stream never ends:
/// what came within 300 ms of the headers).
async fn call(
    addr: SocketAddr,
    method: &str,
    path: &str,
    token: Option<&str>,
) -> (u16, String, String) {
    let auth = token
        .map(|t| format!("Authorization: Bearer {t}\r\n"))
        .unwrap_or_default();
    let body = if method == "POST" { "{}" } else { "" };
    let request = format!(
        "{method} {path} HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n{auth}Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(request.as_bytes()).await.unwrap();
    let mut text = Vec::new();
    loop {
        let mut buf = [0u8; 4096];
        let wait = if text.windows(4).any(|w| w == b"\r\n\r\n") {
            300
        } else {
            10_000
        };
        match tokio::time::timeout(Duration::from_millis(wait), s.read(&mut buf)).await {
            Ok(Ok(0)) | Ok(Err(_)) | Err(_) => break,
            Ok(Ok(n)) => text.extend_from_slice(&buf[..n]),
        }
    }
    let text = String::from_utf8_lossy(&text).into_owned();
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let location = text
        .lines()
        .find_map(|l| {
            l.to_ascii_lowercase()
                .strip_prefix("location: ")
                .map(|_| l[10..].to_string())
        })
        .unwrap_or_default();
    (status, location, text)
}

/// A route's path with every parameter filled by a valid value.
fn concrete(path: &str) -> String {
    path.replace("{machine}", "SIM1")
        .replace("{lobe}", "IN1")
        .replace("{version}", "1")
        .replace("{id}", "1")
        .replace("{part}", "P1")
}

/// The access layer said no: 401, 403 `forbidden`, or a page sending to the sign-in form.
fn refused(status: u16, location: &str, text: &str) -> bool {
    status == 401
        || (status == 403 && text.contains("\"code\":\"forbidden\""))
        || (status == 303 && location.starts_with("/signin?next="))
}

/// Users viewer, operator, engineer, admin, each with a token of its own role.
async fn tokens(store: &Store) -> Vec<(Role, String)> {
    let now = camloop::clock::now();
    let mut out = Vec::new();
    for role in Role::ALL {
        let hash = hash_password("a-password-of-the-right-length").unwrap();
        // `admin` exists: the first start made it.
        let user = store
            .add_user(&format!("matrix-{role}"), role, &hash, now)
            .await
            .unwrap();
        let secret = new_token().unwrap();
        let t = NewToken {
            user,
            label: "matrix".into(),
            sha256: token_digest(&secret),
            role,
            created_at: now,
            expires_at: now + jiff::SignedDuration::from_hours(1),
        };
        store.add_token(&t).await.unwrap();
        out.push((role, secret));
    }
    out
}

/// The refusal a write's answer should leave in the audit trail, as `actor: reason`: every
/// 4xx to a write, but for the sign-in form (its handler audits its failures itself) and
/// the write path's own refusals (audited with their before and after).
fn expected_refusal(
    method: &str,
    path: &str,
    who: &str,
    status: u16,
    text: &str,
) -> Option<String> {
    let body = text.split("\r\n\r\n").nth(1).unwrap_or_default();
    let code = serde_json::from_str::<serde_json::Value>(body)
        .ok()
        .and_then(|v| v["code"].as_str().map(str::to_string))
        .unwrap_or_else(|| "-".into());
    let audited_by_the_write_path = [
        "rollback_refused",
        "freeze_refused",
        "dressing_refused",
        "table_version_not_found",
        "event_not_found",
    ];
    let refused = (400..500).contains(&status) && status != 429;
    (method == "POST"
        && path != "/signin"
        && refused
        && !audited_by_the_write_path.contains(&code.as_str()))
    .then(|| format!("{who}: {method} {path}: {status} {code}"))
}

/// Every route × caller; the number of pairs, and the refusal each write's answer should
/// have audited (in order).
async fn walk(
    addr: SocketAddr,
    tokens: &[(Role, String)],
    anonymous_read: bool,
) -> (usize, Vec<String>) {
    let mut checked = 0;
    let mut refusals = Vec::new();
    let mut callers: Vec<(Option<Role>, Option<&str>)> = vec![(None, None)];
    callers.extend(tokens.iter().map(|(r, t)| (Some(*r), Some(t.as_str()))));
    for route in ROUTES {
        for (role, token) in &callers {
            let path = concrete(route.path);
            let (status, location, text) = call(addr, route.method, &path, *token).await;
            let acting = match role {
                Some(r) => Some(*r),
                None => anonymous_read.then_some(Role::Viewer),
            };
            let allowed = match route.need {
                Need::Public => true,
                Need::Role(needed) => acting.is_some_and(|r| r >= needed),
            };
            let who = role.map_or("anonymous", |r| r.as_str());
            let actor = role.map_or("anonymous".to_string(), |r| format!("matrix-{r}"));
            refusals.extend(expected_refusal(route.method, &path, &actor, status, &text));
            let what = format!(
                "{} {path} as {who} (anonymous read {anonymous_read}): {status}",
                route.method
            );
            assert!(status != 500 && status != 0, "{what}\n{text}");
            if allowed {
                assert!(!refused(status, &location, &text), "{what} refused\n{text}");
            } else {
                assert!(
                    refused(status, &location, &text),
                    "{what} not refused\n{text}"
                );
                if role.is_some() {
                    assert_eq!(
                        status, 403,
                        "{what}: a known caller below the role gets 403"
                    );
                }
            }
            checked += 1;
        }
    }
    (checked, refusals)
}

/// Every refused write is in the audit trail, in order, within the budget for refusals of
/// one client (all the walk's calls come from 127.0.0.1): the rest are counted in
/// `camloop_audit_refusals_unrecorded_total`, and nothing else is.
async fn refusals_audited(store: &Store, addr: SocketAddr, viewer: &str, expected: &[String]) {
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 1000, false)
        .await
        .unwrap();
    let audited: Vec<String> = rows
        .iter()
        .filter(|r| r.entry.action == "refused")
        .map(|r| format!("{}: {}", r.entry.actor, r.entry.reason))
        .collect();
    let (_, _, metrics) = call(addr, "GET", "/metrics", Some(viewer)).await;
    let unrecorded: usize = metrics
        .lines()
        .find_map(|l| l.strip_prefix("camloop_audit_refusals_unrecorded_total "))
        .and_then(|v| v.parse().ok())
        .expect("the unrecorded refusals are counted");
    let budget = camloop::auth::PER_CLIENT_PER_MINUTE as usize;
    assert!(expected.len() > budget, "{expected:#?}");
    assert_eq!(
        audited.len() + unrecorded,
        expected.len(),
        "{audited:#?}\n{expected:#?}"
    );
    assert!(audited.len() >= budget, "{audited:#?}");
    // The first minute's rows are the first refusals, in order; a walk that ran into a
    // second minute has more, each one of the expected (the reason may add how many went
    // unrecorded before it).
    assert_eq!(audited[..budget], expected[..budget]);
    for a in &audited[budget..] {
        assert!(expected.iter().any(|e| a.starts_with(e.as_str())), "{a}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_refuses_every_role_below_its_own_and_no_other() {
    for anonymous_read in [true, false] {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
        let mut config = sim_config(dir.path(), &url, 20, 3, |_| None);
        config.auth.anonymous_read = Some(anonymous_read);
        let mut running = service::start(config, RunOptions::parts(2)).await.unwrap();
        running.machines_done().await;
        let store = Store::connect(&url).await.unwrap();
        let tokens = tokens(&store).await;
        let (checked, refusals) = walk(running.http_addr, &tokens, anonymous_read).await;
        assert_eq!(checked, ROUTES.len() * 5);
        eprintln!("{checked} route × caller pairs checked (anonymous read {anonymous_read})");
        refusals_audited(&store, running.http_addr, &tokens[0].1, &refusals).await;
        store.close().await;
        running.stop().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tokens_carry_a_ceiling_expire_are_revoked_and_five_wrong_ones_lock_wrong_ones_from_the_address()
 {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let mut running = service::start(
        sim_config(dir.path(), &url, 20, 3, |_| None),
        RunOptions::parts(2),
    )
    .await
    .unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    // The first start made `admin` and wrote its password to a file only its owner reads.
    let file = dir.path().join("var/admin-password");
    let password = std::fs::read_to_string(&file).unwrap();
    assert!(password.trim().chars().count() >= 12);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&file).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600, "the password file is the owner's only");
    }
    let store = Store::connect(&url).await.unwrap();
    let now = camloop::clock::now();
    let hash = hash_password("a-password-of-the-right-length").unwrap();
    let eng = store
        .add_user("eng", Role::Engineer, &hash, now)
        .await
        .unwrap();
    let make = |role: Role, expires_at_ms: jiff::Timestamp| {
        let secret = new_token().unwrap();
        let t = NewToken {
            user: eng,
            label: String::new(),
            sha256: token_digest(&secret),
            role,
            created_at: now,
            expires_at: expires_at_ms,
        };
        (secret, t)
    };
    let hour = jiff::SignedDuration::from_hours(1);
    let (viewer_of_eng, t1) = make(Role::Viewer, now + hour);
    let (expired, t2) = make(Role::Engineer, now - jiff::SignedDuration::from_millis(1));
    let (revoked, t3) = make(Role::Engineer, now + hour);
    store.add_token(&t1).await.unwrap();
    store.add_token(&t2).await.unwrap();
    let revoked_id = store.add_token(&t3).await.unwrap();
    store.revoke_token(revoked_id, now).await.unwrap();
    let dress = "/api/v1/machines/SIM1/dressings";
    // The ceiling holds: an engineer's viewer token reads, and may not report a dressing.
    assert_eq!(call(addr, "GET", dress, Some(&viewer_of_eng)).await.0, 200);
    assert_eq!(call(addr, "POST", dress, Some(&viewer_of_eng)).await.0, 403);
    // Expired and revoked tokens are refused: 2 failures.
    assert_eq!(call(addr, "GET", dress, Some(&expired)).await.0, 401);
    assert_eq!(call(addr, "GET", dress, Some(&revoked)).await.0, 401);
    // Three more wrong tokens make five: wrong tokens from this address are refused
    // unchecked now; a good token is never refused for that.
    for i in 0..3 {
        assert_eq!(
            call(addr, "GET", dress, Some(&format!("clt_wrong{i}")))
                .await
                .0,
            401
        );
    }
    let (status, _, text) = call(addr, "GET", dress, Some("clt_wrong3")).await;
    assert_eq!(status, 429, "{text}");
    assert!(text.contains("locked_out"), "{text}");
    assert_eq!(call(addr, "GET", dress, Some(&viewer_of_eng)).await.0, 200);
    // Reading without a token still works (nothing to guess).
    assert_eq!(call(addr, "GET", dress, None).await.0, 200);
    let (_, _, metrics) = call(addr, "GET", "/metrics", None).await;
    assert!(
        metrics.contains("camloop_auth_failures_total{kind=\"token\"} 5"),
        "{metrics}"
    );
    assert!(
        metrics.contains("camloop_auth_failures_total{kind=\"locked\"} 1"),
        "{metrics}"
    );
    assert!(
        metrics.contains("camloop_auth_lockouts_total 1"),
        "{metrics}"
    );
    // Every failure is in the audit trail, with the address; the chain holds.
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 100, false)
        .await
        .unwrap();
    let failures: Vec<_> = rows.iter().filter(|r| r.entry.action == "token").collect();
    assert_eq!(failures.len(), 5, "{rows:?}");
    assert!(
        failures.iter().all(|r| r.entry.client == "127.0.0.1"),
        "{failures:?}"
    );
    assert_eq!(
        failures[0].entry.actor, "eng",
        "a known but expired token names its user"
    );
    assert!(
        failures[4].entry.reason.contains("locked out"),
        "{:?}",
        failures[4]
    );
    assert_eq!(
        rows[0].entry.action, "user.add",
        "the first admin is audited first"
    );
    let seal = camloop::audit_seal::AuditSeal::open(&dir.path().join("var"))
        .unwrap()
        .expect("the service made the audit key beside the admin password");
    let head = seal.head().unwrap().expect("and keeps the head there");
    let check = store
        .verify_audit(Some(seal.key()), Some(&head))
        .await
        .unwrap();
    assert!(
        check.intact() && check.rows == rows.len() as u64 && check.keyed_rows == check.rows,
        "{check:?}"
    );
    store.close().await;
    running.stop().await;
}

/// An engineer freezes a feature's learning and lets it learn again; the state shows in the
/// API and in `/metrics`, and both changes are audited with before and after. An operator
/// may not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_engineer_freezes_and_resumes_learning_and_the_trail_says_who() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let config = sim_config(dir.path(), &url, 20, 3, |_| None);
    let mut running = service::start(config, RunOptions::parts(2)).await.unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    let store = Store::connect(&url).await.unwrap();
    let tokens = tokens(&store).await;
    let token = |role: Role| tokens.iter().find(|(r, _)| *r == role).unwrap().1.clone();
    let path = "/api/v1/machines/SIM1/lobes/IN1/learning";
    let post = |body: &'static str, token: String| async move {
        let request = format!(
            "POST {path} HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\nAuthorization: Bearer {token}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        );
        service_support::exchange(addr, &request).await
    };
    let frozen_metric = |text: &str| {
        text.lines()
            .find(|l| l.starts_with("camloop_learning_frozen{machine=\"SIM1\",lobe=\"IN1\"}"))
            .map(|l| l.rsplit(' ').next().unwrap().to_string())
    };
    let freeze = r#"{"frozen":true,"reason":"wheel change"}"#;
    let (status, body) = post(freeze, token(Role::Operator)).await;
    assert_eq!(status, 403, "{body}");
    let (status, body) = post(freeze, token(Role::Engineer)).await;
    assert_eq!(status, 200, "{body}");
    let (_, machines) = service_support::get(addr, "/api/v1/machines").await;
    let lobe = &service_support::json(&machines)["machines"][0]["lobes"][0];
    let shown = lobe["status"]["frozen"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert_eq!(shown, "frozen by an engineer: wheel change", "{machines}");
    // Anonymous readers are told the role; the audit trail (below) names the user.
    assert!(!machines.contains("matrix-engineer"), "{machines}");
    let (_, metrics) = service_support::get(addr, "/metrics").await;
    assert_eq!(frozen_metric(&metrics).as_deref(), Some("1"), "{metrics}");
    let (status, body) = post(r#"{"frozen":false}"#, token(Role::Engineer)).await;
    assert_eq!(status, 200, "{body}");
    let (_, metrics) = service_support::get(addr, "/metrics").await;
    assert_eq!(frozen_metric(&metrics).as_deref(), Some("0"), "{metrics}");
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 100, false)
        .await
        .unwrap();
    let changes: Vec<_> = rows
        .iter()
        .filter(|r| r.entry.action.starts_with("learning."))
        .map(|r| {
            (
                r.entry.action.as_str(),
                r.entry.actor.as_str(),
                r.entry.before.clone(),
                r.entry.after.clone(),
            )
        })
        .collect();
    let frozen = r#"{"frozen":"frozen by an engineer: wheel change"}"#.to_string();
    let free = r#"{"frozen":null}"#.to_string();
    assert_eq!(
        changes,
        [
            (
                "learning.freeze",
                "matrix-engineer",
                Some(free.clone()),
                Some(frozen.clone())
            ),
            (
                "learning.resume",
                "matrix-engineer",
                Some(frozen),
                Some(free)
            ),
        ]
    );
    store.close().await;
    running.stop().await;
}

/// Every `.route(…)` in the router's source has a row in the table for each of its
/// methods, so a route added without one is found here, not by its users (the access layer
/// would refuse it for everyone with 500 `route_without_role`).
#[test]
fn every_routed_path_and_method_has_a_row_in_the_table() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/service/http");
    let mut routed = Vec::new();
    for file in ["mod.rs", "dashboard/mod.rs"] {
        let text = std::fs::read_to_string(root.join(file)).unwrap();
        // The prefixes the two routers build paths from.
        let text = text
            .replace("{m}", "/api/v1/machines/{machine}")
            .replace("{f}", "/machines/{machine}/features/{lobe}")
            .replace("{{", "{")
            .replace("}}", "}");
        for call in text.split(".route(").skip(1) {
            let arg = call[..call.find(',').unwrap()].trim();
            let path = match arg.split_once('"') {
                Some((_, rest)) => rest.split('"').next().unwrap(),
                // `.route(f, …)`: the feature page's own prefix.
                None if arg == "f" => "/machines/{machine}/features/{lobe}",
                None => panic!("{file}: a route whose path is `{arg}`"),
            };
            // The call's handlers: up to the next `.route(` or the end of the chain.
            let end = call.find(".with_state").unwrap_or(call.len());
            let handlers = &call[..end];
            for (method, marker) in [("GET", "get("), ("POST", "post(")] {
                if handlers.contains(marker) {
                    routed.push((method, path.to_string()));
                }
            }
        }
    }
    assert!(routed.len() >= 30, "{routed:?}");
    for (method, path) in &routed {
        assert!(
            ROUTES.iter().any(|r| r.method == *method && r.path == path),
            "{method} {path} is routed but has no row in ROUTES"
        );
    }
    assert_eq!(
        routed.len(),
        ROUTES.len(),
        "rows without a route: {routed:?}"
    );
}
