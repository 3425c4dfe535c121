//! HTTP helpers for the service tests: plain HTTP/1.1 over a TCP stream, so the tests need
//! no HTTP client of their own.

#![allow(dead_code)]

use camloop::config::Config;
use std::path::Path;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// A plain HTTP/1.1 POST of a JSON body, with an optional bearer token.
pub async fn post(
    addr: std::net::SocketAddr,
    path: &str,
    body: &str,
    token: Option<&str>,
) -> (u16, String) {
    let auth = token
        .map(|t| format!("Authorization: Bearer {t}\r\n"))
        .unwrap_or_default();
    let request = format!(
        "POST {path} HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n{auth}Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    exchange(addr, &request).await
}

/// A plain HTTP/1.1 GET on the service's listener; returns status and body.
pub async fn get(addr: std::net::SocketAddr, path: &str) -> (u16, String) {
    exchange(
        addr,
        &format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n"),
    )
    .await
}

/// Sends one request on a new connection and reads the whole response: status and body.
pub async fn exchange(addr: std::net::SocketAddr, request: &str) -> (u16, String) {
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut response = String::new();
    // A server that resets after answering still gave its answer.
    let _ = stream.read_to_string(&mut response).await;
    let status = response
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let body = response
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_string())
        .unwrap_or_default();
    (status, body)
}

/// Bodies may come chunked; the JSON ones here are small, so take the JSON object inside.
pub fn json(body: &str) -> serde_json::Value {
    let start = body.find('{').unwrap();
    let end = body.rfind('}').unwrap();
    serde_json::from_str(&body[start..=end]).unwrap()
}

/// Stops `running` once the first feature of the first machine has `parts` parts measured
/// (its status in `GET /api/v1/machines`, asked every 2 ms), so the stop falls mid-shaft:
/// the simulator stops before the next feature's measurement goes out. Returns the resume
/// point the share's `resume` program then names, checked to lie inside the shaft.
pub async fn stop_mid_shaft(
    running: camloop::service::Running,
    parts: u64,
    resume: &Path,
) -> usize {
    loop {
        let (_, body) = get(running.http_addr, "/api/v1/machines").await;
        let done = json(&body)["machines"][0]["lobes"][0]["status"]["parts"]
            .as_u64()
            .unwrap_or(0);
        if done >= parts {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(2)).await;
    }
    running.stop().await;
    let text = std::fs::read_to_string(resume).unwrap();
    let from = camloop::core::program::parse_resume_program(&text).unwrap();
    assert!(
        (2..=8).contains(&from),
        "stopped mid-shaft: resume at {from}\n{text}"
    );
    from
}

/// A service with one simulated machine SIM1 on the demo lobe: history at `database_url`,
/// working folder `var`, share `share/SIM1`, a part every `part_interval_ms`, noise `seed`;
/// `env` answers the environment (the API token).
pub fn sim_config(
    dir: &Path,
    database_url: &str,
    part_interval_ms: u32,
    seed: u64,
    env: impl Fn(&str) -> Option<String>,
) -> Config {
    sim_config_with_masters(dir, database_url, part_interval_ms, seed, 0, env)
}

/// [`sim_config`] whose simulated gauge measures the master part `master_runs` times
/// before the 3rd shaft (a type-1 study among the production parts; 0: never).
pub fn sim_config_with_masters(
    dir: &Path,
    database_url: &str,
    part_interval_ms: u32,
    seed: u64,
    master_runs: u32,
    env: impl Fn(&str) -> Option<String>,
) -> Config {
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let text = format!(
        r#"
[service]
var_dir = "var"
[database]
url = "{database_url}"
[http]
listen = "127.0.0.1:0"
[[machines]]
name = "SIM1"
recipe = "{}"
lobe = "IN1"
share = "share/SIM1"
[machines.gauge]
kind = "sim"
part_interval_ms = {part_interval_ms}
seed = {seed}
[machines.gauge.grinder.gauge]
master_runs = {master_runs}
master_before_part = 3
"#,
        recipe.display()
    );
    Config::parse(&text, &dir.join("camloop.toml"), env).unwrap()
}
