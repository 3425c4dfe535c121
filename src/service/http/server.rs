//! The listener loop. axum's own `serve` has no header timeout and no connection cap, so a
//! few hundred half-sent requests could hold the process's file descriptors and starve the
//! gauge, the journal and the share. Here:
//! - at most `max_connections` connections are served at once; the loop takes a slot before
//!   it accepts, so the rest wait in the kernel's queue and hold none of ours;
//! - at most `max_connections_per_client` of them from one client address: a connection
//!   beyond it is closed at once, so one client cannot hold every slot;
//! - a client has `header_timeout` to send a request's headers (hyper's header read timeout,
//!   which also runs while a kept-alive connection is idle), else the connection is closed;
//! - a body has `body_timeout` to arrive (enforced where a body is read, see `ApiJson`);
//! - on shutdown, idle connections close at once and requests in flight finish;
//! - the cap is lowered to half the process's open-file limit where that is lower, so the
//!   gauges, the journals, the shares and the database always have descriptors left.

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Semaphore, watch};
use tracing::{debug, warn};

use super::harden::{HostAllowList, PerClient, Policy};

/// How much the API may take of the process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HttpLimits {
    /// Connections served at once.
    pub max_connections: usize,
    /// Connections served at once to one client address.
    pub max_connections_per_client: usize,
    /// Time to send a request's headers (and an idle kept-alive connection's limit).
    pub header_timeout: Duration,
    /// Time to send a request's body once its headers are in.
    pub body_timeout: Duration,
}

impl HttpLimits {
    pub(crate) fn from_config(http: &crate::config::HttpSection) -> Self {
        Self {
            max_connections: http.max_connections.max(1),
            max_connections_per_client: http.per_client_connections(),
            header_timeout: Duration::from_millis(http.header_timeout_ms),
            body_timeout: Duration::from_millis(http.body_timeout_ms),
        }
    }
}

/// After shutdown, requests in flight get this long to finish.
const DRAIN: Duration = Duration::from_secs(10);

/// Serves `app` on `listener` until `shutdown` turns true, answering to the listen address
/// and `localhost` only, without TLS.
pub async fn serve(
    listener: tokio::net::TcpListener,
    app: Router,
    limits: HttpLimits,
    shutdown: watch::Receiver<bool>,
) {
    let policy = match listener.local_addr() {
        Ok(addr) => Policy {
            hosts: HostAllowList::new(addr, &[]),
            tls: false,
        },
        Err(_) => return,
    };
    serve_with(listener, app, limits, policy, None, shutdown).await
}

/// Serves `app` on `listener` under `policy` (and TLS when given) until `shutdown`.
pub async fn serve_with(
    listener: tokio::net::TcpListener,
    app: Router,
    limits: HttpLimits,
    policy: Policy,
    tls: Option<Arc<super::tls::Tls>>,
    mut shutdown: watch::Receiver<bool>,
) {
    let limits = fit_to_open_files(limits);
    // Open event streams end when the server stops (see `dashboard::Stopping`).
    let app = app.layer(axum::Extension(super::Stopping(shutdown.clone())));
    let app = super::harden::apply(app, policy);
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    let clients = PerClient::new(limits.max_connections_per_client);
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    loop {
        let slot = tokio::select! {
            slot = slots.clone().acquire_owned() => match slot {
                Ok(slot) => slot,
                Err(_) => break,
            },
            _ = shutdown.changed() => break,
        };
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) => {
                    // Out of descriptors or a connection reset while queued: wait a moment
                    // rather than spin.
                    warn!(error = %e, "http accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
            _ = shutdown.changed() => break,
        };
        let Some(client) = clients.admit(peer.ip()) else {
            // Closed at once: its global slot goes back with it.
            debug!(peer = %peer, "http connection refused: the client holds its connection cap");
            continue;
        };
        let conn = Conn {
            app: app.clone(),
            http: http.clone(),
            stop: shutdown.clone(),
            peer,
            handshake_timeout: limits.header_timeout,
        };
        let tls = tls.clone();
        tokio::spawn(async move {
            let _slots = (slot, client);
            match tls {
                None => conn.serve(stream).await,
                Some(tls) => match tls.accept(stream, conn.handshake_timeout).await {
                    Ok(stream) => conn.serve(stream).await,
                    Err(e) => debug!(peer = %peer, error = %e, "TLS handshake failed"),
                },
            }
        });
    }
    // Every slot back means every connection has ended.
    let all = u32::try_from(limits.max_connections).unwrap_or(u32::MAX);
    let _ = tokio::time::timeout(DRAIN, slots.acquire_many(all)).await;
}

/// One accepted connection, ready to serve over plain TCP or TLS.
struct Conn {
    app: Router,
    http: hyper::server::conn::http1::Builder,
    stop: watch::Receiver<bool>,
    peer: std::net::SocketAddr,
    /// The TLS handshake gets as long as a request's headers.
    handshake_timeout: Duration,
}

impl Conn {
    async fn serve<I>(mut self, stream: I)
    where
        I: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send + 'static,
    {
        // The client's address, for the access layer (lockout, audit).
        let with_peer = self
            .app
            .clone()
            .layer(axum::Extension(axum::extract::ConnectInfo(self.peer)));
        let service = TowerToHyperService::new(with_peer);
        let connection = self.http.serve_connection(TokioIo::new(stream), service);
        tokio::pin!(connection);
        let result = tokio::select! {
            r = connection.as_mut() => r,
            _ = self.stop.changed() => {
                connection.as_mut().graceful_shutdown();
                connection.await
            }
        };
        if let Err(e) = result {
            debug!(peer = %self.peer, error = %e, "http connection ended");
        }
    }
}

/// `limits` with the caps lowered to half the process's open-file limit where that is
/// lower: the other half stays for the gauges, the journals, the shares and the database.
fn fit_to_open_files(mut limits: HttpLimits) -> HttpLimits {
    if let Some(files) = open_file_limit() {
        let cap = usize::try_from(files / 2).unwrap_or(usize::MAX).max(1);
        if limits.max_connections > cap {
            warn!(
                max_connections = limits.max_connections,
                open_file_limit = files,
                cap,
                "http.max_connections lowered to half the open-file limit"
            );
            limits.max_connections = cap;
        }
    }
    limits.max_connections_per_client = limits
        .max_connections_per_client
        .clamp(1, limits.max_connections);
    limits
}

/// The process's soft limit on open files (Linux: from /proc/self/limits); `None` where
/// unknown or unlimited.
fn open_file_limit() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/limits").ok()?;
    parse_open_file_limit(&text)
}

/// The soft limit on the `Max open files` line of a /proc/<pid>/limits text.
fn parse_open_file_limit(limits: &str) -> Option<u64> {
    let line = limits.lines().find(|l| l.starts_with("Max open files"))?;
    line["Max open files".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_soft_open_file_limit_is_read_from_proc_limits() {
        let text = "Limit                     Soft Limit           Hard Limit           Units     \n\
                    Max cpu time              unlimited            unlimited            seconds   \n\
                    Max open files            1024                 524288               files     \n";
        assert_eq!(parse_open_file_limit(text), Some(1024));
        let unlimited =
            "Max open files            unlimited            unlimited            files\n";
        assert_eq!(parse_open_file_limit(unlimited), None);
        assert_eq!(parse_open_file_limit(""), None);
    }
}
