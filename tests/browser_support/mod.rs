//! A headless Chromium driven through WebDriver (chromedriver) for the dashboard tests:
//! the pieces, the driver as a child process (killed on drop), and waits that poll.

#![allow(dead_code)]

use fantoccini::{Client, ClientBuilder, Locator};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub const CHROMIUM: &str = "/usr/bin/chromium";
pub const DRIVER: &str = "/usr/bin/chromedriver";

/// The browser pieces, or why they are missing.
pub fn browser_present() -> Result<(), String> {
    for p in [CHROMIUM, DRIVER] {
        if !Path::new(p).exists() {
            return Err(format!(
                "{p} is not installed (apt-get install chromium chromium-driver)"
            ));
        }
    }
    Ok(())
}

/// Whether the browser test can run: `false` (with a skip line) when the pieces are missing,
/// a panic instead when `CAMLOOP_REQUIRE_BROWSER=1` (CI) says they must be there.
pub fn browser_or_skip() -> bool {
    match browser_present() {
        Ok(()) => true,
        Err(why) if std::env::var("CAMLOOP_REQUIRE_BROWSER").as_deref() == Ok("1") => {
            panic!("CAMLOOP_REQUIRE_BROWSER=1 but {why}")
        }
        Err(why) => {
            eprintln!("skipping the browser test: {why}");
            false
        }
    }
}

/// chromedriver on a free port, started as a child; killed on drop.
pub struct Driver {
    child: Child,
    url: String,
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub fn start_driver() -> Driver {
    // A port the kernel just handed out and released: not fixed, and free at this moment.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut child = Command::new(DRIVER)
        .arg(format!("--port={port}"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromedriver starts");
    // It says when it listens; read until then.
    let out = child.stdout.take().unwrap();
    let mut lines = BufReader::new(out).lines();
    let ready = lines
        .by_ref()
        .take(20)
        .map_while(Result::ok)
        .any(|l| l.contains("started successfully"));
    assert!(ready, "chromedriver did not report that it started");
    std::thread::spawn(move || for _ in lines {});
    Driver {
        child,
        url: format!("http://127.0.0.1:{port}"),
    }
}

pub async fn browser(driver: &Driver, profile: &Path) -> Client {
    let args = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--window-size=1280,800",
    ];
    let mut args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
    args.push(format!("--user-data-dir={}", profile.display()));
    let caps = serde_json::json!({
        "browserName": "chrome",
        "goog:chromeOptions": { "binary": CHROMIUM, "args": args },
    });
    let serde_json::Value::Object(caps) = caps else {
        unreachable!()
    };
    let connector = hyper_util::client::legacy::connect::HttpConnector::new();
    ClientBuilder::new(connector)
        .capabilities(caps)
        .connect(&driver.url)
        .await
        .expect("chromedriver starts a headless Chromium")
}

/// Polls `check` every 50 ms until it answers `Some`, at most `limit`.
pub async fn until<T, F, Fut>(limit: Duration, what: &str, mut check: F) -> T
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Option<T>>,
{
    let start = Instant::now();
    loop {
        if let Some(v) = check().await {
            return v;
        }
        assert!(start.elapsed() < limit, "{what}: not within {limit:?}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// The rendered text of `css`, read in one script call: the live region may be replaced at
/// any moment, and a found element could go stale before its text is read.
pub async fn text_of(c: &Client, css: &str) -> String {
    let v = c
        .execute(
            "const e = document.querySelector(arguments[0]); return e ? e.innerText : null;",
            vec![serde_json::json!(css)],
        )
        .await
        .unwrap();
    v.as_str()
        .unwrap_or_else(|| panic!("{css} not on the page"))
        .to_string()
}

/// Clicks `css`, waiting (at most 10 s) until the click goes through: the live region may
/// be replaced between finding and clicking (a part arrived), and on a loaded machine the
/// page may still be laying out, so a stale or covered element is found again until the
/// click lands. Five attempts in a row, with no wait, failed on 2 busy cores.
pub async fn click(c: &Client, css: &str) {
    let limit = Duration::from_secs(10);
    let start = Instant::now();
    loop {
        let tried = match c.find(Locator::Css(css)).await {
            Ok(e) => e.click().await.map(|_| ()),
            Err(e) => Err(e),
        };
        match tried {
            Ok(()) => return,
            Err(e) => assert!(
                start.elapsed() < limit,
                "{css} could not be clicked within {limit:?}: {e}"
            ),
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}
