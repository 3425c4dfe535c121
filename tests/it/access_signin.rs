//! Sign-in CSRF and session binding, on a real service: the sign-in form's one-time value
//! must be one the service issued to that client address and has not taken back; a value
//! a page made up itself (another port of this host can set the `camloop_signin` cookie)
//! signs nobody in. A session key is honoured only from the address it was made at.

use crate::access_lockout::{exchange, status};
use crate::service_support;

use camloop::auth::hash_password;
use camloop::service::{self, RunOptions};
use camloop::store::{Role, Store};
use service_support::sim_config;
use std::net::{IpAddr, SocketAddr};

const PASSWORD: &str = "a-password-of-the-right-length";

/// `POST /signin` of eng from `from` with `nonce` as both cookie and form value: the answer.
async fn post_signin(addr: SocketAddr, from: IpAddr, nonce: &str) -> String {
    post_signin_to(addr, from, nonce, "%2F").await
}

/// The same, going to `next` (urlencoded) after.
async fn post_signin_to(addr: SocketAddr, from: IpAddr, nonce: &str, next: &str) -> String {
    let body = format!("name=eng&password={PASSWORD}&csrf={nonce}&next={next}");
    let request = format!(
        "POST /signin HTTP/1.1\r\nHost: localhost\r\nCookie: camloop_signin={nonce}\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    exchange(addr, from, &request).await
}

/// The value of the cookie `name` the answer sets.
fn set_cookie(answer: &str, name: &str) -> Option<String> {
    answer
        .lines()
        .find_map(|l| l.strip_prefix(&format!("set-cookie: {name}=")))
        .and_then(|v| v.split(';').next())
        .map(str::to_string)
}

/// A nonce the sign-in page issues to `from`.
async fn issued(addr: SocketAddr, from: IpAddr) -> String {
    let page = exchange(
        addr,
        from,
        "GET /signin HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
    )
    .await;
    set_cookie(&page, "camloop_signin").expect("the sign-in page sets its nonce cookie")
}

/// Who `GET /session` says the browser with session `key` is, asked from `from`.
async fn who(addr: SocketAddr, from: IpAddr, key: &str) -> serde_json::Value {
    let request = format!(
        "GET /session HTTP/1.1\r\nHost: localhost\r\nCookie: camloop_session={key}\r\nConnection: close\r\n\r\n"
    );
    let answer = exchange(addr, from, &request).await;
    let body = answer.split("\r\n\r\n").nth(1).unwrap_or_default();
    service_support::json(body)["user"].clone()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_a_nonce_the_service_issued_to_this_address_signs_in_once() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let config = sim_config(dir.path(), &url, 20, 3, |_| None);
    let mut running = service::start(config, RunOptions::parts(1)).await.unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    let store = Store::connect(&url).await.unwrap();
    let hash = hash_password(PASSWORD).unwrap();
    let now = camloop::clock::now();
    store
        .add_user("eng", Role::Engineer, &hash, now)
        .await
        .unwrap();
    let (here, there): (IpAddr, IpAddr) =
        ("127.0.0.1".parse().unwrap(), "127.0.0.2".parse().unwrap());

    // A page on another port set the cookie and the form field to a value of its own.
    let forged = post_signin(addr, here, "0123456789abcdef0123456789abcdef").await;
    assert_eq!(status(&forged), 403, "{forged}");
    assert!(set_cookie(&forged, "camloop_session").is_none(), "{forged}");
    // A value issued to another address.
    let elsewhere = issued(addr, there).await;
    assert_eq!(status(&post_signin(addr, here, &elsewhere).await), 403);
    // A `next` with a tab or a newline is refused before anything is checked or made.
    for next in ["%2Fa%09b", "%2Fa%0D%0ASet-Cookie:x=1"] {
        let answer = post_signin_to(addr, here, &issued(addr, here).await, next).await;
        assert_eq!(status(&answer), 400, "{answer}");
        assert!(set_cookie(&answer, "camloop_session").is_none(), "{answer}");
    }
    // The value issued here signs in, once.
    let nonce = issued(addr, here).await;
    let answer = post_signin(addr, here, &nonce).await;
    assert_eq!(status(&answer), 303, "{answer}");
    let key = set_cookie(&answer, "camloop_session").expect("a session cookie");
    assert_eq!(
        status(&post_signin(addr, here, &nonce).await),
        403,
        "used twice"
    );

    // The session is honoured from where it was made only.
    assert_eq!(who(addr, here, &key).await, "eng");
    assert_eq!(who(addr, there, &key).await, serde_json::Value::Null);
    assert_eq!(who(addr, here, &key).await, "eng", "and lives on there");
    let (_, metrics) = service_support::get(addr, "/metrics").await;
    assert!(
        metrics.contains("camloop_auth_failures_total{kind=\"csrf\"} 3"),
        "{metrics}"
    );
    store.close().await;
    running.stop().await;
}

/// `camloop user passwd` (the command line, beside the running service) ends the user's
/// dashboard sessions: the next request of the session is anonymous.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_password_changed_on_the_command_line_ends_the_users_sessions() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let config = sim_config(dir.path(), &url, 20, 3, |_| None);
    let mut running = service::start(config, RunOptions::parts(1)).await.unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    let store = Store::connect(&url).await.unwrap();
    let hash = hash_password(PASSWORD).unwrap();
    store
        .add_user("eng", Role::Engineer, &hash, camloop::clock::now())
        .await
        .unwrap();
    let here: IpAddr = "127.0.0.1".parse().unwrap();
    let answer = post_signin(addr, here, &issued(addr, here).await).await;
    let key = set_cookie(&answer, "camloop_session").expect("signed in");
    assert_eq!(who(addr, here, &key).await, "eng");

    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_camloop"))
        .args(["user", "passwd", "eng", "--database", &url, "--audit-dir"])
        .arg(dir.path().join("var"))
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write as _;
    let mut stdin = child.stdin.take().unwrap();
    writeln!(stdin, "a-new-long-enough-secret").unwrap();
    drop(stdin);
    let done = child.wait_with_output().unwrap();
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    assert_eq!(who(addr, here, &key).await, serde_json::Value::Null);
    store.close().await;
    running.stop().await;
}
