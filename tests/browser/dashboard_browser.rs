//! The dashboard as an engineer uses it: a real headless Chromium, driven through WebDriver
//! (chromedriver), against a real service with the simulated machine. The overview shows the
//! machine with the last error the API reports; a new part appears without a reload within
//! 2 s of being measured; a rollback before signing in is refused in the page, signed in as
//! an engineer it delivers a new version that the page shows; no script errors, no failed requests; the
//! pages fit a 1024-pixel tablet. Screenshots go to the target folder
//! (`target/tmp/dashboard/`).
//!
//! Without Chromium the test prints why and passes, unless `CAMLOOP_REQUIRE_BROWSER=1`
//! (CI sets it), which makes a missing browser a failure.

use crate::browser_support::{browser, browser_or_skip, click, start_driver, text_of, until};
use crate::service_support;

use camloop::service::{self, RunOptions};
use fantoccini::{Client, Locator};
use service_support::{get, json, sim_config};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

const TOKEN: &str = "let-me-write-a-token-of-32-chars";
/// The engineer `eng`'s password.
const PASSWORD: &str = "a-long-enough-secret";

/// The newest part the API lists for SIM1 IN1: (id, max profile error µm, received ms).
async fn newest_part(addr: SocketAddr) -> Option<(i64, f64, i64)> {
    let (status, body) = get(addr, "/api/v1/machines/SIM1/measurements?lobe=IN1&limit=1").await;
    if status != 200 {
        return None;
    }
    let v = json(&body);
    let item = v["items"].as_array()?.first()?.clone();
    Some((
        item["id"].as_i64()?,
        item["max_profile_error_um"].as_f64()?,
        item["received_at_ms"].as_i64()?,
    ))
}

async fn attr_of(c: &Client, css: &str, name: &str) -> Option<String> {
    let v = c
        .execute(
            "const e = document.querySelector(arguments[0]); return e ? e.getAttribute(arguments[1]) : null;",
            vec![serde_json::json!(css), serde_json::json!(name)],
        )
        .await
        .ok()?;
    v.as_str().map(str::to_string)
}

/// Every script error and failed request the page recorded must be none.
async fn assert_clean(c: &Client, page: &str) {
    let seen = c
        .execute("return window.camloopSeen;", vec![])
        .await
        .unwrap();
    assert_eq!(
        seen["errors"],
        serde_json::json!([]),
        "{page}: script errors"
    );
    assert_eq!(
        seen["failed"],
        serde_json::json!([]),
        "{page}: failed requests"
    );
}

fn shots() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("dashboard");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A screenshot of the whole page: the window is made as tall as the page for it.
async fn screenshot(c: &Client, name: &str) {
    let size = c
        .execute(
            "return [window.innerHeight, document.documentElement.scrollHeight];",
            vec![],
        )
        .await
        .unwrap();
    let (inner, page) = (size[0].as_u64().unwrap(), size[1].as_u64().unwrap());
    let (w, h) = c.get_window_size().await.unwrap();
    let tall = (page + h.saturating_sub(inner)).clamp(h, 4000);
    c.set_window_size(w as u32, tall as u32).await.unwrap();
    let png = c.screenshot().await.unwrap();
    c.set_window_size(w as u32, h as u32).await.unwrap();
    assert!(png.starts_with(b"\x89PNG"), "{name}: a PNG");
    std::fs::write(shots().join(name), png).unwrap();
}

/// The page is no wider than the window (no sideways scrolling).
async fn assert_fits(c: &Client, page: &str) {
    let v = c
        .execute(
            "return [document.documentElement.scrollWidth, window.innerWidth];",
            vec![],
        )
        .await
        .unwrap();
    let (w, inner) = (v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
    assert!(w <= inner, "{page}: {w} px wide in a {inner} px window");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_works_in_a_real_browser() {
    if !browser_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let env = |k: &str| (k == camloop::config::ENV_API_TOKEN).then(|| TOKEN.to_string());
    // A part every 1.5 s: the live check sees several arrive.
    let config = sim_config(dir.path(), &url, 1500, 7, env);
    let running = service::start(config, RunOptions::default()).await.unwrap();
    let addr = running.http_addr;
    let base = format!("http://{addr}");
    until(Duration::from_secs(30), "first part stored", || {
        newest_part(addr)
    })
    .await;
    let store = camloop::store::Store::connect(&url).await.unwrap();
    let hash = camloop::auth::hash_password(PASSWORD).unwrap();
    let now = camloop::clock::now();
    let engineer = camloop::store::Role::Engineer;
    store.add_user("eng", engineer, &hash, now).await.unwrap();
    store.close().await;

    let driver = start_driver();
    let profile = tempfile::tempdir().unwrap();
    let c = browser(&driver, profile.path()).await;

    overview(&c, &base, addr).await;
    live_part(&c, addr).await;
    feature(&c, &base).await;
    versions(&c, &base, addr).await;

    c.close().await.unwrap();
    drop(driver);
    running.stop().await;
}

/// The overview lists every configured machine, with the last error the API reports.
async fn overview(c: &Client, base: &str, addr: SocketAddr) {
    c.goto(&format!("{base}/")).await.unwrap();
    let (status, body) = get(addr, "/api/v1/machines").await;
    assert_eq!(status, 200);
    for name in json(&body)["configured"].as_array().unwrap() {
        let name = name.as_str().unwrap();
        let row = text_of(c, &format!("tr[data-machine=\"{name}\"]")).await;
        assert!(row.contains(name), "{row}");
    }
    // Compared for the part the page shows. The live channel may put a newer part in the
    // row at any moment: its id, error and text are read in one script, which the page's
    // own updates cannot interleave with.
    let shown = c
        .execute(
            "const r = document.querySelector('tr[data-machine=\"SIM1\"]'); \
             const e = r.querySelector('.err'); \
             return [r.getAttribute('data-last-id'), e.getAttribute('data-last-error-um'), e.textContent.trim()];",
            vec![],
        )
        .await
        .unwrap();
    let field = |i: usize| shown[i].as_str().unwrap().to_owned();
    let shown_id: i64 = field(0).parse().unwrap();
    let shown_error: f64 = field(1).parse().unwrap();
    let shown_text = field(2);
    let (_, body) = get(addr, "/api/v1/machines/SIM1/measurements?lobe=IN1&limit=50").await;
    let items = json(&body)["items"].as_array().unwrap().clone();
    let api = items
        .iter()
        .find(|i| i["id"].as_i64() == Some(shown_id))
        .expect("the part shown is in the API's history");
    let api_error = api["max_profile_error_um"].as_f64().unwrap();
    assert_eq!(
        shown_error, api_error,
        "the same number, not a rounding of it"
    );
    assert_eq!(shown_text, format!("{api_error:.2}"));
    assert!(
        c.find(Locator::Css("tr[data-machine=\"SIM1\"] svg.spark polyline"))
            .await
            .is_ok()
    );
    screenshot(c, "overview.png").await;
    assert_fits(c, "overview at 1280").await;
    assert_clean(c, "overview").await;
}

/// A part stored after the page loaded shows in it, without a reload, within 2 s of its
/// measurement being received (which is before it is stored).
async fn live_part(c: &Client, addr: SocketAddr) {
    c.execute("window.loadedOnce = true;", vec![])
        .await
        .unwrap();
    until(
        Duration::from_secs(10),
        "live channel connected",
        || async {
            let s = text_of(c, "#live-status").await;
            (!s.contains("connecting")).then_some(())
        },
    )
    .await;
    let shown = || async {
        attr_of(c, "tr[data-machine=\"SIM1\"]", "data-last-id")
            .await?
            .parse::<i64>()
            .ok()
    };
    let before = shown().await.unwrap();
    let (id, _, received_ms) = until(Duration::from_secs(10), "a new part stored", || async {
        newest_part(addr).await.filter(|p| p.0 > before)
    })
    .await;
    until(
        Duration::from_secs(3),
        "the new part on the page",
        || async { shown().await.filter(|s| *s >= id) },
    )
    .await;
    let delay_ms = camloop::clock::now().as_millisecond() - received_ms;
    eprintln!("part {id} shown on the page {delay_ms} ms after it was measured");
    assert!(
        delay_ms <= 2000,
        "part {id} shown {delay_ms} ms after it was measured"
    );
    let same = c
        .execute("return window.loadedOnce === true;", vec![])
        .await
        .unwrap();
    assert_eq!(same, serde_json::json!(true), "the page was not reloaded");
    assert_clean(c, "overview after live parts").await;
}

async fn feature(c: &Client, base: &str) {
    c.goto(&format!("{base}/machines/SIM1/features/IN1"))
        .await
        .unwrap();
    let charts = c.find_all(Locator::Css("svg.chart")).await.unwrap();
    // Three trend charts, the polar plot and the unrolled error.
    assert!(charts.len() >= 5, "{} charts", charts.len());
    assert!(
        c.find(Locator::Css(".setup svg")).await.is_ok(),
        "setup drawing"
    );
    assert!(c.find(Locator::Css("table#events")).await.is_ok());
    let polar = text_of(c, "#latest-h").await;
    assert!(polar.starts_with("Latest part #"), "{polar}");
    screenshot(c, "feature.png").await;
    assert_fits(c, "feature at 1280").await;
    c.set_window_size(1024, 768).await.unwrap();
    assert_fits(c, "feature at 1024").await;
    screenshot(c, "feature-1024.png").await;
    c.set_window_size(1280, 800).await.unwrap();
    assert_clean(c, "feature").await;
}

/// Rollback from the versions page: refused in the page before signing in; signed in as an
/// engineer, a new version is delivered and shown.
async fn versions(c: &Client, base: &str, addr: SocketAddr) {
    c.goto(&format!("{base}/machines/SIM1/features/IN1/versions"))
        .await
        .unwrap();
    let button = "button.rollback[data-version=\"1\"]";
    click(c, button).await;
    let refused = until(Duration::from_secs(5), "the refusal", || async {
        let t = text_of(c, "#rollback-result").await;
        (!t.is_empty()).then_some(t)
    })
    .await;
    assert!(refused.contains("refused"), "{refused}");
    let (_, body) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables?limit=50").await;
    let reasons = body.matches("rollback to v1").count();
    assert_eq!(reasons, 0, "nothing was rolled back: {body}");

    click(c, "#signin-link").await;
    c.find(Locator::Css("#name"))
        .await
        .unwrap()
        .send_keys("eng")
        .await
        .unwrap();
    c.find(Locator::Css("#password"))
        .await
        .unwrap()
        .send_keys(PASSWORD)
        .await
        .unwrap();
    click(c, "#signin button[type=submit]").await;
    // Back on the versions page, signed in.
    until(Duration::from_secs(10), "signed in", || async {
        let who = c
            .execute(
                "const e = document.querySelector('#user'); return e ? e.innerText : null;",
                vec![],
            )
            .await
            .ok()?;
        who.as_str()
            .filter(|t| t.contains("eng (engineer)"))
            .map(|_| ())
    })
    .await;
    click(c, button).await;
    let done = until(Duration::from_secs(20), "the rollback's answer", || async {
        let class = attr_of(c, "#rollback-result", "class").await?;
        (class == "ok").then_some(())
    })
    .await;
    let () = done;
    let message = text_of(c, "#rollback-result").await;
    let version: i64 = message
        .split("delivered as v")
        .nth(1)
        .and_then(|r| r.split(|ch: char| !ch.is_ascii_digit()).next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no new version in {message:?}"));
    let row = format!("tr[data-version=\"{version}\"]");
    let shown = until(
        Duration::from_secs(5),
        "the new version in the table",
        || async { c.find(Locator::Css(&row)).await.ok()?.text().await.ok() },
    )
    .await;
    assert!(shown.contains("rollback to v1"), "{shown}");
    let (_, body) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables?limit=50").await;
    let listed = json(&body)["items"]
        .as_array()
        .unwrap()
        .iter()
        .any(|t| t["version"].as_i64() == Some(version) && t["reason"] == "rollback to v1");
    assert!(listed, "the API lists v{version} as the rollback: {body}");
    assert!(c.find(Locator::Css("svg.chart")).await.is_ok(), "diff plot");
    screenshot(c, "versions.png").await;
    assert_fits(c, "versions at 1280").await;
    c.set_window_size(1024, 768).await.unwrap();
    assert_fits(c, "versions at 1024").await;
    c.goto(&format!("{base}/")).await.unwrap();
    assert_fits(c, "overview at 1024").await;
    c.set_window_size(1280, 800).await.unwrap();
    assert_clean(c, "versions").await;
}
