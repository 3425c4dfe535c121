//! The lockout under load, on a real service: 60 wrong sign-ins for one user sent at once
//! from one address check at most five passwords (counting and checking are one step), and
//! then even the right password is refused from there; but the lock holds that user from
//! that address only: the same user from another loopback address signs in, another user
//! from the same address signs in, and the user's valid API token is never refused.
//! Also: many sign-ins at once never run more argon2 hashes than there are cores (the
//! hasher's own count of the most at once, in /metrics), and those beyond its queue get 503
//! with Retry-After.

use crate::service_support;

use camloop::auth::{hash_password, new_token, token_digest};
use camloop::service::{self, RunOptions};
use camloop::store::{NewToken, Role, Store};
use service_support::sim_config;
use std::net::{IpAddr, SocketAddr};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

const PASSWORD: &str = "a-password-of-the-right-length";

/// Sends `request` from `from` (a loopback address) and returns the whole answer.
pub(crate) async fn exchange(addr: SocketAddr, from: IpAddr, request: &str) -> String {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::new(from, 0)).unwrap();
    let mut s = socket.connect(addr).await.unwrap();
    s.write_all(request.as_bytes()).await.unwrap();
    let mut text = Vec::new();
    tokio::time::timeout(Duration::from_secs(60), s.read_to_end(&mut text))
        .await
        .expect("an answer within 60 s")
        .unwrap();
    String::from_utf8_lossy(&text).into_owned()
}

pub(crate) fn status(answer: &str) -> u16 {
    answer
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0)
}

/// One sign-in of `name` with `password` from `from`, with a nonce of its own: the status.
pub(crate) async fn sign_in(addr: SocketAddr, from: IpAddr, name: &str, password: &str) -> u16 {
    status(&sign_in_answer(addr, from, name, password).await)
}

/// [`sign_in`]'s whole answer.
async fn sign_in_answer(addr: SocketAddr, from: IpAddr, name: &str, password: &str) -> String {
    let page = exchange(
        addr,
        from,
        "GET /signin HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
    )
    .await;
    let cookie = page
        .lines()
        .find_map(|l| l.strip_prefix("set-cookie: camloop_signin="))
        .and_then(|v| v.split(';').next())
        .expect("the sign-in page sets its nonce cookie")
        .to_string();
    let body = format!("name={name}&password={password}&csrf={cookie}");
    let request = format!(
        "POST /signin HTTP/1.1\r\nHost: localhost\r\nCookie: camloop_signin={cookie}\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    exchange(addr, from, &request).await
}

pub(crate) async fn with_token(addr: SocketAddr, from: IpAddr, token: &str) -> u16 {
    let request = format!(
        "GET /api/v1/machines/SIM1/dressings HTTP/1.1\r\nHost: localhost\r\nAuthorization: Bearer {token}\r\nConnection: close\r\n\r\n"
    );
    status(&exchange(addr, from, &request).await)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sixty_wrong_sign_ins_at_once_check_five_and_lock_one_user_from_one_address() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let mut running = service::start(
        sim_config(dir.path(), &url, 20, 3, |_| None),
        RunOptions::parts(1),
    )
    .await
    .unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    let store = Store::connect(&url).await.unwrap();
    let now = camloop::clock::now();
    let hash = hash_password(PASSWORD).unwrap();
    let eng = store
        .add_user("eng", Role::Engineer, &hash, now)
        .await
        .unwrap();
    store
        .add_user("op", Role::Operator, &hash, now)
        .await
        .unwrap();
    let token = new_token().unwrap();
    let t = NewToken {
        user: eng,
        label: String::new(),
        sha256: token_digest(&token),
        role: Role::Engineer,
        created_at: now,
        expires_at: now + jiff::SignedDuration::from_hours(1),
    };
    store.add_token(&t).await.unwrap();
    let (here, there): (IpAddr, IpAddr) =
        ("127.0.0.1".parse().unwrap(), "127.0.0.2".parse().unwrap());

    let attempts: Vec<_> = (0..60)
        .map(|_| tokio::spawn(sign_in(addr, here, "eng", "wrong-password-guess")))
        .collect();
    let mut statuses = Vec::new();
    for a in attempts {
        statuses.push(a.await.unwrap());
    }
    let checked = statuses.iter().filter(|s| **s == 401).count();
    let refused = statuses.iter().filter(|s| **s == 429).count();
    assert_eq!((checked, refused), (5, 55), "{statuses:?}");
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 1000, false)
        .await
        .unwrap();
    let wrong = rows
        .iter()
        .filter(|r| r.entry.action == "signin" && r.entry.reason.starts_with("wrong password"))
        .count();
    assert_eq!(wrong, 5, "passwords checked, as the trail has them");

    // The right password from there is refused now; everything else is not.
    assert_eq!(sign_in(addr, here, "eng", PASSWORD).await, 429);
    assert_eq!(
        sign_in(addr, there, "eng", PASSWORD).await,
        303,
        "eng elsewhere"
    );
    assert_eq!(
        sign_in(addr, here, "op", PASSWORD).await,
        303,
        "op from there"
    );
    assert_eq!(with_token(addr, here, &token).await, 200, "eng's token");
    hashes_stay_within_the_cores(addr).await;
    store.close().await;
    running.stop().await;
}

/// 60 sign-ins of 60 different names at once from one more address: none locks (one
/// attempt each), so each takes a hash or is refused for a full queue. The hasher's count
/// of the most hashes at once never passes its threads (one per core), and every 503 is
/// one the hasher counted as refused, with Retry-After.
async fn hashes_stay_within_the_cores(addr: SocketAddr) {
    let from: IpAddr = "127.0.0.3".parse().unwrap();
    let attempts: Vec<_> = (0..60)
        .map(|i| {
            let name = format!("nobody{i}");
            tokio::spawn(
                async move { sign_in_answer(addr, from, &name, "wrong-password-guess").await },
            )
        })
        .collect();
    let mut busy = 0;
    for a in attempts {
        let answer = a.await.unwrap();
        match status(&answer) {
            401 => {}
            503 => {
                busy += 1;
                assert!(answer.contains("retry-after: 1"), "{answer}");
            }
            other => panic!("{other}: {answer}"),
        }
    }
    let metrics = exchange(
        addr,
        from,
        "GET /metrics HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
    )
    .await;
    let value = |name: &str| -> u64 {
        metrics
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{name} ")))
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or_else(|| panic!("{name} in /metrics:\n{metrics}"))
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| u64::try_from(n.get()).unwrap());
    assert_eq!(value("camloop_password_hashes_parallel"), cores);
    let most = value("camloop_password_hashes_running_max");
    assert!(
        (1..=cores).contains(&most),
        "{most} hashes at once on {cores} cores"
    );
    assert_eq!(value("camloop_password_hashes_refused_total"), busy);
    assert_eq!(value("camloop_password_hashes_running"), 0);
}
