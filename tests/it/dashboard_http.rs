//! The dashboard's pages, downloads and acknowledgements over plain HTTP on a real service
//! with the simulated machine, checked against the API's own answers; and `camloop export
//! --format dfq` on the database it wrote.

use crate::service_support;

use camloop::service::{self, RunOptions};
use service_support::{get, json, post, sim_config_with_masters};
use std::net::SocketAddr;

const TOKEN: &str = "let-me-write-a-token-of-32-chars";
const PARTS: usize = 4;
/// Master runs the simulated gauge measures before the 3rd shaft: never a part of any
/// listing below, only of the gauge study and of `?masters=true`.
const MASTER_RUNS: usize = 5;

/// The K-field lines of a .dfq text as (key, index, value).
fn fields(text: &str) -> Vec<(String, Option<usize>, String)> {
    text.split("\r\n")
        .filter(|l| !l.is_empty())
        .map(|l| {
            let (k, v) = l.split_once(' ').unwrap_or((l, ""));
            let (k, i) = match k.split_once('/') {
                Some((k, i)) => (k, Some(i.parse().unwrap())),
                None => (k, None),
            };
            (k.to_string(), i, v.to_string())
        })
        .collect()
}

fn values(f: &[(String, Option<usize>, String)], key: &str, i: Option<usize>) -> Vec<String> {
    f.iter()
        .filter(|x| x.0 == key && x.1 == i)
        .map(|x| x.2.clone())
        .collect()
}

/// The API's parts of SIM1 IN1, oldest first: (id, part, max profile error µm).
async fn api_parts(addr: SocketAddr) -> Vec<(i64, String, f64)> {
    let (_, body) = get(
        addr,
        "/api/v1/machines/SIM1/measurements?lobe=IN1&limit=100",
    )
    .await;
    let mut v: Vec<(i64, String, f64)> = json(&body)["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| {
            (
                i["id"].as_i64().unwrap(),
                i["part"].as_str().unwrap().to_string(),
                i["max_profile_error_um"].as_f64().unwrap(),
            )
        })
        .collect();
    v.reverse();
    v
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pages_downloads_and_acknowledgements_agree_with_the_api() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let env = |k: &str| (k == camloop::config::ENV_API_TOKEN).then(|| TOKEN.to_string());
    let config = sim_config_with_masters(dir.path(), &url, 20, 3, MASTER_RUNS as u32, env);
    let mut running = service::start(config, RunOptions::parts(PARTS as u64))
        .await
        .unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    let parts = api_parts(addr).await;
    assert_eq!(parts.len(), PARTS, "{parts:?}");
    assert!(
        parts.iter().all(|p| !p.1.starts_with("MASTER")),
        "{parts:?}"
    );
    let (_, body) = get(
        addr,
        "/api/v1/machines/SIM1/measurements?lobe=IN1&masters=true",
    )
    .await;
    let masters = json(&body)["items"].as_array().unwrap().clone();
    assert_eq!(masters.len(), MASTER_RUNS, "{body}");
    assert!(masters.iter().all(|m| m["part"] == "MASTER"), "{body}");

    let (status, page) = get(addr, "/").await;
    assert_eq!(status, 200);
    assert!(
        page.contains(r#"<tr data-machine="SIM1" data-lobe="IN1""#),
        "{page}"
    );
    let (status, page) = get(addr, "/machines/SIM1/features/IN1").await;
    assert_eq!(status, 200);
    assert!(
        page.contains(&format!("Latest part #{}", parts[PARTS - 1].0)),
        "{page}"
    );
    // The capability panel, and the API it quotes: every part of the window, the four
    // characteristics of a lobe, the chart on request; a bad window or feature is refused.
    assert!(page.contains(r#"<table id="capability">"#), "{page}");
    // 4 parts: the figures are shown, marked indicative (fewer than the 100 values a
    // capability study needs).
    assert!(
        page.contains(r#"<p id="capability-indicative" class="indicative" role="note"><strong>Indicative only: </strong>4 values, fewer than the 100 a capability study needs"#),
        "{page}"
    );
    assert!(
        page.contains(&format!(
            "Gauge study (type 1, latest {MASTER_RUNS} master runs)"
        )),
        "{page}"
    );
    let (status, body) = get(
        addr,
        "/api/v1/machines/SIM1/features/IN1/capability?window=parts:500&chart=true",
    )
    .await;
    assert_eq!(status, 200, "{body}");
    let cap = json(&body);
    assert_eq!(cap["parts"].as_u64(), Some(PARTS as u64));
    let items = cap["characteristics"].as_array().unwrap();
    assert_eq!(items.len(), 4);
    let timing = items
        .iter()
        .find(|c| c["characteristic"] == "timing")
        .unwrap();
    assert_eq!(timing["capability"]["n"].as_u64(), Some(PARTS as u64));
    assert_eq!(timing["chart"]["points"].as_array().unwrap().len(), PARTS);
    assert_eq!(
        (&cap["indicative"], &cap["min_values"]),
        (&true.into(), &100.into())
    );
    assert_eq!(timing["indicative"], true, "{timing}");
    for (path, status_code, code) in [
        (
            "/api/v1/machines/SIM1/features/IN1/capability?window=weekly",
            400,
            "invalid_window",
        ),
        (
            "/api/v1/machines/SIM1/features/XX9/capability",
            404,
            "feature_not_found",
        ),
    ] {
        let (status, body) = get(addr, path).await;
        assert_eq!(
            (status, json(&body)["code"].as_str()),
            (status_code, Some(code))
        );
    }
    let (status, body) = get(addr, "/machines/SIM1/features/IN..1").await;
    assert_eq!(
        (status, json(&body)["code"].as_str()),
        (400, Some("invalid_name"))
    );

    // The trend's CSV: the API's parts, in order, with the same numbers.
    let (status, csv) = get(
        addr,
        "/machines/SIM1/features/IN1/data?chart=trend&format=csv",
    )
    .await;
    assert_eq!(status, 200);
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip_while(|l| !l.starts_with("id,"))
        .skip(1)
        .filter(|l| l.contains(','))
        .map(|l| l.split(',').map(|c| c.trim().parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), PARTS, "{csv}");
    for (row, api) in rows.iter().zip(&parts) {
        // The same number, but for the last bit: serde_json's default float parser is not
        // correctly rounded (it can be one ulp off), the CSV's text parses exactly.
        assert_eq!(row[0] as i64, api.0);
        assert!(
            (row[2] - api.2).abs() <= 4.0 * f64::EPSILON * api.2.abs(),
            "{row:?} vs {api:?}"
        );
    }
    // The latest part's curves as JSON: one row per gauge angle.
    let (status, body) = get(
        addr,
        "/machines/SIM1/features/IN1/data?chart=latest&format=json",
    )
    .await;
    assert_eq!(status, 200);
    assert_eq!(json(&body)["rows"].as_array().unwrap().len(), 360);
    // The diff plot's data is the API's diff.
    let (_, api) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables/3/diff").await;
    let api = json(&api);
    let (status, body) = get(
        addr,
        "/machines/SIM1/features/IN1/data?chart=diff&format=json&v=3",
    )
    .await;
    assert_eq!(status, 200);
    let ours = json(&body);
    let ours = ours["rows"].as_array().unwrap();
    let theirs = api["points"].as_array().unwrap();
    assert_eq!(ours.len(), theirs.len());
    for (a, b) in ours.iter().zip(theirs) {
        assert_eq!(a["c_deg"], b["c_deg"]);
        assert_eq!(a["delta_x_um"], b["delta_x_um"]);
    }

    // The .dfq download: one part, four characteristics, the API's values, the demo band.
    let (status, dfq) = get(addr, "/machines/SIM1/features/IN1/export.dfq").await;
    assert_eq!(status, 200);
    let f = fields(&dfq[dfq.find("K0100").unwrap()..]);
    assert_eq!(values(&f, "K0100", None), vec!["4"]);
    assert_eq!(values(&f, "K1001", None), vec!["DEMO-CAM"]);
    assert_eq!(values(&f, "K2001", Some(2)), vec!["SIM1.IN1.PROFILE"]);
    assert_eq!(values(&f, "K2111", Some(2)), vec!["2.500"]);
    let expected: Vec<String> = parts.iter().map(|p| format!("{:.3}", p.2)).collect();
    assert_eq!(values(&f, "K0001", Some(2)), expected);
    let idents: Vec<String> = parts.iter().map(|p| p.1.clone()).collect();
    assert_eq!(values(&f, "K0014", Some(1)), idents);

    acknowledgements(addr).await;
    let stream = catch_up(addr, &parts).await;
    running.stop().await;
    // The open stream ends with the service instead of holding its shutdown.
    let mut rest = Vec::new();
    let ended = tokio::time::timeout(
        std::time::Duration::from_secs(5),
        tokio::io::AsyncReadExt::read_to_end(&mut { stream }, &mut rest),
    )
    .await;
    assert!(ended.is_ok(), "the event stream did not end at shutdown");
    cli_export(dir.path(), &url, &parts);
}

async fn acknowledgements(addr: SocketAddr) {
    // A dressing, as the page's form sends it, records an event.
    let (status, body) = post(
        addr,
        "/api/v1/machines/SIM1/dressings",
        r#"{"wheel_radius_mm": 249.5}"#,
        Some(TOKEN),
    )
    .await;
    assert_eq!(status, 200, "{body}");
    let (_, body) = get(addr, "/api/v1/machines/SIM1/events?limit=100").await;
    let events = json(&body)["items"].as_array().unwrap().clone();
    assert!(!events.is_empty(), "the run records events: {body}");
    // The API's event list carries no id; the page's buttons do.
    let (_, page) = get(addr, "/machines/SIM1/features/IN1").await;
    let marker = "/api/v1/machines/SIM1/events/";
    let at = page.find(marker).expect("an Acknowledge button");
    let rest = &page[at + marker.len()..];
    let id: i64 = rest[..rest.find('/').unwrap()].parse().unwrap();
    let path = format!("{marker}{id}/ack");
    let (status, body) = post(addr, &path, "{}", None).await;
    assert_eq!(
        (status, json(&body)["code"].as_str()),
        (401, Some("unauthorized"))
    );
    let (status, body) = post(addr, &path, "{}", Some(TOKEN)).await;
    assert_eq!(status, 200, "{body}");
    assert!(
        json(&body)["message"]
            .as_str()
            .unwrap()
            .contains("acknowledged")
    );
    let (status, body) = post(addr, &path, "{}", Some(TOKEN)).await;
    assert_eq!(status, 200);
    assert!(
        json(&body)["message"].as_str().unwrap().contains("before"),
        "{body}"
    );
    let (status, body) = post(
        addr,
        "/api/v1/machines/OTHER/events/1/ack",
        "{}",
        Some(TOKEN),
    )
    .await;
    assert_eq!(
        (status, json(&body)["code"].as_str()),
        (404, Some("event_not_found"))
    );
    let (_, page) = get(addr, "/machines/SIM1/features/IN1").await;
    assert!(
        !page.contains(&path),
        "the acknowledged event has no button any more"
    );
    // Who: the caller (here the deprecated shared token, named `api-token`), not "dashboard".
    assert!(
        page.contains("(api-token)"),
        "and shows who acknowledged it"
    );
}

/// A page that reconnects with `Last-Event-ID` gets the parts after it, in order, as the
/// script reads them, and not the master runs measured among them; the stream stays open.
async fn catch_up(addr: SocketAddr, parts: &[(i64, String, f64)]) -> tokio::net::TcpStream {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let request = format!(
        "GET /dashboard/events HTTP/1.1\r\nHost: localhost\r\nLast-Event-ID: {}\r\n\r\n",
        parts[1].0
    );
    s.write_all(request.as_bytes()).await.unwrap();
    let mut text = String::new();
    let last = format!("id: {}\n", parts[PARTS - 1].0);
    while !text.contains(&last) {
        let mut buf = [0u8; 4096];
        let n = s.read(&mut buf).await.unwrap();
        assert!(n > 0, "stream ended early: {text}");
        text.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
    assert!(text.contains("content-type: text/event-stream"), "{text}");
    let ids: Vec<i64> = text
        .lines()
        .filter_map(|l| l.strip_prefix("id: ")?.parse().ok())
        .collect();
    let expected: Vec<i64> = parts[2..].iter().map(|p| p.0).collect();
    assert_eq!(ids, expected);
    let data = text.lines().find(|l| l.starts_with("data: ")).unwrap();
    let event: serde_json::Value = serde_json::from_str(&data[6..]).unwrap();
    assert_eq!(event["id"].as_i64(), Some(parts[2].0));
    assert_eq!(event["max_profile_error_um"].as_f64(), Some(parts[2].2));
    assert_eq!(event["part"].as_str(), Some(parts[2].1.as_str()));
    s
}

fn cli_export(dir: &std::path::Path, url: &str, parts: &[(i64, String, f64)]) {
    let out = dir.join("history.dfq");
    // The repository's service configuration grinds SIM1 IN1 on the demo recipe: its band.
    let config = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/camloop.toml");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_camloop"))
        .args(["export", "--format", "dfq", "--database", url, "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    let f = fields(&text);
    assert_eq!(values(&f, "K1001", None), vec!["DEMO-CAM"]);
    assert_eq!(values(&f, "K0001", Some(1)).len(), parts.len());
    let expected: Vec<String> = parts.iter().map(|p| format!("{:.3}", p.2)).collect();
    assert_eq!(values(&f, "K0001", Some(2)), expected);
    assert_eq!(values(&f, "K2111", Some(2)), vec!["2.500"], "{text}");
    // A configuration that cannot be read: no limits rather than guessed ones.
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_camloop"))
        .args([
            "export",
            "--format",
            "dfq",
            "--database",
            url,
            "--config",
            "missing.toml",
        ])
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let f = fields(&String::from_utf8(o.stdout).unwrap());
    assert_eq!(values(&f, "K0001", Some(2)), expected);
    assert!(values(&f, "K2111", Some(2)).is_empty());
}

/// At 100 values the capability is a study, below it indicative: the API's field, and the
/// panel's note (the page's window is the newest 125 parts) only when it applies.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn capability_under_100_values_is_marked_indicative() {
    const PARTS: u64 = 100;
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let config = service_support::sim_config(dir.path(), &url, 1, 5, |_| None);
    let mut running = service::start(config, RunOptions::parts(PARTS))
        .await
        .unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    for (window, indicative) in [(7, true), (PARTS, false)] {
        let path = format!("/api/v1/machines/SIM1/features/IN1/capability?window=parts:{window}");
        let (status, body) = get(addr, &path).await;
        assert_eq!(status, 200, "{body}");
        let cap = json(&body);
        assert_eq!(cap["parts"], window, "{body}");
        assert_eq!(cap["indicative"], indicative, "{body}");
        for c in cap["characteristics"].as_array().unwrap() {
            assert_eq!(
                (&c["capability"]["n"], &c["indicative"]),
                (&window.into(), &indicative.into()),
                "{c}"
            );
        }
    }
    let (status, page) = get(addr, "/machines/SIM1/features/IN1").await;
    assert_eq!(status, 200);
    assert!(page.contains("Capability (newest 100 parts)"), "{page}");
    assert!(!page.contains("indicative"), "{page}");
    running.stop().await;
}
