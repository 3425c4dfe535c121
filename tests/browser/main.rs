//! The dashboard in a real headless Chromium, driven through chromedriver: one binary of its
//! own, so a browser never shares the harness's threads with the timing-bound tests.

#[path = "../browser_support/mod.rs"]
mod browser_support;
#[path = "../service_support/mod.rs"]
mod service_support;

mod dashboard_browser;
mod dashboard_signin;
