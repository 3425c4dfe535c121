//! Signing in to the dashboard in a real headless Chromium against a real service:
//! - an operator signs in (the session cookie is `HttpOnly` and `SameSite=Strict`: the
//!   page's script cannot read it) and reports a dressing from the feature page: the write
//!   carries the session's CSRF token and is audited under the operator's name;
//! - a page on another port of the same host (the same site, so the browser sends the
//!   session cookie along) posts a form to the API: refused by the CSRF check, nothing
//!   dressed, and the attempt audited;
//! - signing out ends the session;
//! - five wrong passwords lock that user out from this address: the sixth attempt is
//!   refused (other users, and this user from elsewhere, are not locked).
//!
//! Without Chromium the test prints why and passes, unless `CAMLOOP_REQUIRE_BROWSER=1`.

use crate::service_support;

use crate::browser_support::{browser, browser_or_skip, click, start_driver, text_of, until};
use camloop::service::{self, RunOptions};
use camloop::store::{Role, Store};
use fantoccini::{Client, Locator};
use service_support::{get, json, sim_config};
use std::io::{Read, Write};
use std::time::Duration;

const PASSWORD: &str = "a-long-enough-secret";

/// A page on `127.0.0.1:<other port>` whose form posts a dressing to the service as soon as
/// it loads; served to any request until the test ends.
fn attacker_page(target: std::net::SocketAddr) -> std::net::SocketAddr {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let html = format!(
        r#"<!doctype html><html><body><form id="f" method="post" enctype="text/plain" action="http://{target}/api/v1/machines/SIM1/dressings"><input name='{{"wheel_radius_mm":249.5,"x":"' value='"}}'></form><script>document.getElementById("f").submit();</script></body></html>"#
    );
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut s) = stream else { continue };
            let mut buf = [0u8; 4096];
            let _ = s.read(&mut buf);
            let reply = format!(
                "HTTP/1.1 200 OK\r\nContent-Type: text/html\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{html}",
                html.len()
            );
            let _ = s.write_all(reply.as_bytes());
        }
    });
    addr
}

async fn sign_in(c: &Client, base: &str, name: &str, password: &str) -> String {
    c.goto(&format!("{base}/signin?next=/machines/SIM1/features/IN1"))
        .await
        .unwrap();
    c.find(Locator::Css("#name"))
        .await
        .unwrap()
        .send_keys(name)
        .await
        .unwrap();
    c.find(Locator::Css("#password"))
        .await
        .unwrap()
        .send_keys(password)
        .await
        .unwrap();
    click(c, "#signin button[type=submit]").await;
    until(
        Duration::from_secs(10),
        "the answer to signing in",
        || async {
            let url = c.current_url().await.ok()?;
            let page = c.source().await.ok()?;
            let done = url.path() != "/signin" || page.contains("signin-result");
            done.then_some(page)
        },
    )
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn signing_in_csrf_and_lockout_in_a_real_browser() {
    if !browser_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let config = sim_config(dir.path(), &url, 20, 5, |_| None);
    let mut running = service::start(config, RunOptions::parts(3)).await.unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    let base = format!("http://{addr}");
    let store = Store::connect(&url).await.unwrap();
    let hash = camloop::auth::hash_password(PASSWORD).unwrap();
    let now = camloop::clock::now();
    store
        .add_user("op", Role::Operator, &hash, now)
        .await
        .unwrap();
    store
        .add_user("eve", Role::Viewer, &hash, now)
        .await
        .unwrap();

    let driver = start_driver();
    let profile = tempfile::tempdir().unwrap();
    let c = browser(&driver, profile.path()).await;

    // Signed in, on the page asked for, with a cookie the page's script cannot read.
    sign_in(&c, &base, "op", PASSWORD).await;
    assert_eq!(
        c.current_url().await.unwrap().path(),
        "/machines/SIM1/features/IN1"
    );
    until(Duration::from_secs(10), "the user shown", || async {
        c.find(Locator::Css("#user"))
            .await
            .ok()?
            .text()
            .await
            .ok()
            .filter(|t| t.contains("op (operator)"))
    })
    .await;
    let cookies = c.execute("return document.cookie;", vec![]).await.unwrap();
    assert!(
        !cookies.as_str().unwrap().contains("camloop_session"),
        "{cookies}"
    );
    let jar = c.get_all_cookies().await.unwrap();
    let session = jar
        .iter()
        .find(|k| k.name() == "camloop_session")
        .expect("a session cookie");
    assert_eq!(session.http_only(), Some(true));
    assert_eq!(format!("{:?}", session.same_site()), "Some(Strict)");

    // A dressing from the page: with the CSRF token, audited as op.
    c.find(Locator::Css("#dressing input[name=wheel_radius_mm]"))
        .await
        .unwrap()
        .send_keys("249.9")
        .await
        .unwrap();
    click(&c, "#dressing button[type=submit]").await;
    let done = until(Duration::from_secs(20), "the dressing's answer", || async {
        let t = text_of(&c, "#dressing-result").await;
        (!t.is_empty()).then_some(t)
    })
    .await;
    assert!(!done.contains("refused"), "{done}");
    let (_, body) = get(addr, "/api/v1/machines/SIM1/dressings").await;
    let items = json(&body)["items"].as_array().unwrap().clone();
    assert_eq!(items.len(), 1, "{body}");
    assert_eq!(items[0]["source"], "api:operator");

    // Another port of this host is the same site: the cookie goes along, the token cannot.
    let evil = attacker_page(addr);
    c.goto(&format!("http://{evil}/")).await.unwrap();
    let refused = until(
        Duration::from_secs(10),
        "the cross-site post's answer",
        || async {
            let page = c.source().await.ok()?;
            page.contains("\"code\"").then_some(page)
        },
    )
    .await;
    assert!(refused.contains("csrf_mismatch"), "{refused}");
    let (_, body) = get(addr, "/api/v1/machines/SIM1/dressings").await;
    assert_eq!(
        json(&body)["items"].as_array().unwrap().len(),
        1,
        "nothing dressed: {body}"
    );
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 100, false)
        .await
        .unwrap();
    let csrf = rows
        .iter()
        .find(|r| r.entry.action == "csrf")
        .expect("the refusal is audited");
    assert_eq!(
        (csrf.entry.actor.as_str(), csrf.entry.result.as_str()),
        ("op", "refused")
    );
    let dressing = rows.iter().find(|r| r.entry.action == "dressing").unwrap();
    assert_eq!(
        (
            dressing.entry.actor.as_str(),
            dressing.entry.client.as_str()
        ),
        ("op", "127.0.0.1")
    );
    assert!(
        dressing.entry.after.as_deref().unwrap().contains("249.9"),
        "{dressing:?}"
    );

    // Sign out: the session is gone.
    c.goto(&format!("{base}/")).await.unwrap();
    click(&c, "#signout button[type=submit]").await;
    until(Duration::from_secs(10), "signed out", || async {
        (c.current_url().await.ok()?.path() == "/signin").then_some(())
    })
    .await;
    c.goto(&format!("{base}/")).await.unwrap();
    until(Duration::from_secs(10), "anonymous again", || async {
        c.find(Locator::Css("#signin-link")).await.ok().map(|_| ())
    })
    .await;

    // Five wrong passwords: eve is locked out from this address.
    for attempt in 1..=5 {
        let page = sign_in(&c, &base, "eve", "not-the-password").await;
        assert!(
            page.contains("Wrong user name or password"),
            "attempt {attempt}: {page}"
        );
    }
    let page = sign_in(&c, &base, "eve", "not-the-password").await;
    assert!(page.contains("Locked out"), "{page}");
    assert_eq!(c.current_url().await.unwrap().path(), "/signin");
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 100, false)
        .await
        .unwrap();
    let failed: Vec<_> = rows
        .iter()
        .filter(|r| r.entry.action == "signin" && r.entry.result.as_str() == "refused")
        .collect();
    assert_eq!(failed.len(), 5, "{failed:?}");
    assert!(
        failed[4].entry.reason.contains("locked out"),
        "{:?}",
        failed[4]
    );
    assert!(
        store
            .verify_audit(None, None)
            .await
            .unwrap()
            .broken
            .is_empty()
    );

    c.close().await.unwrap();
    drop(driver);
    store.close().await;
    running.stop().await;
}
