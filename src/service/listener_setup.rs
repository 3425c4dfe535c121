//! The listener's settings at start: TLS (the pair loaded and checked to be one before the
//! service makes anything, its certificate's days to expiry in `/metrics` and warned of at
//! start and at every SIGHUP reload), the host allow-list, and a warning for every insecure
//! setting the config allowed.

use super::http;
use super::metrics::Metrics;
use crate::config::Config;
use std::sync::Arc;
use tokio::sync::watch;
use tracing::{error, info, warn};

/// A certificate this close to its end is warned of at start and at every reload.
const EXPIRY_WARNING_DAYS: f64 = 30.0;

/// The listener's TLS pair when the config sets one, loaded and checked (a certificate, a
/// key, and the key the certificate's); its end of validity goes to `/metrics`.
pub(super) fn load_tls(
    config: &Config,
    metrics: &Metrics,
) -> anyhow::Result<Option<Arc<http::Tls>>> {
    let (Some(cert), Some(key)) = (&config.http.tls_cert, &config.http.tls_key) else {
        return Ok(None);
    };
    let tls = http::Tls::load(&config.resolve(cert), &config.resolve(key))?;
    report_expiry(&tls, metrics);
    Ok(Some(tls))
}

/// The listener's host allow-list and TLS (reloaded on SIGHUP until shutdown); logs a
/// warning for every insecure setting the config allowed, at every start.
pub(super) fn policy(
    config: &Config,
    http_addr: std::net::SocketAddr,
    tls: Option<&Arc<http::Tls>>,
    metrics: &Arc<Metrics>,
    shutdown: &watch::Receiver<bool>,
) -> anyhow::Result<http::Policy> {
    let warnings = crate::config::network_exposure(
        &config.http,
        config.auth.anonymous_read(config.http.listen),
        &config.lines,
    )
    .map_err(|p| anyhow::anyhow!("{}: {p}", config.file.display()))?;
    for w in warnings {
        warn!(reason = %w, "serving insecurely because http.allow_insecure_network = true");
    }
    if let Some(tls) = tls {
        tokio::spawn(reload_tls_on_hangup(
            tls.clone(),
            metrics.clone(),
            shutdown.clone(),
        ));
    }
    Ok(http::Policy {
        hosts: http::HostAllowList::new(http_addr, &config.http.allowed_hosts),
        tls: tls.is_some(),
    })
}

/// Puts the certificate's end of validity in `/metrics`, and warns when it is past or
/// within [`EXPIRY_WARNING_DAYS`].
fn report_expiry(tls: &http::Tls, metrics: &Metrics) {
    let not_after = tls.not_after();
    metrics.set_tls_not_after(not_after);
    let days = http::days_left(not_after, jiff::Timestamp::now());
    if days < 0.0 {
        warn!(not_after = %not_after, days_ago = format!("{:.1}", -days), "the TLS certificate has expired: clients refuse it; renew it and send SIGHUP");
    } else if days < EXPIRY_WARNING_DAYS {
        warn!(not_after = %not_after, days_left = format!("{days:.1}"), "the TLS certificate expires soon: renew it and send SIGHUP");
    }
}

/// Reads the TLS pair again at every SIGHUP; the accept loop goes on meanwhile.
async fn reload_tls_on_hangup(
    tls: Arc<http::Tls>,
    metrics: Arc<Metrics>,
    mut shutdown: watch::Receiver<bool>,
) {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let Ok(mut hangup) = signal(SignalKind::hangup()) else {
            warn!("SIGHUP cannot be caught: the TLS certificate is not reloaded");
            return;
        };
        loop {
            tokio::select! {
                _ = hangup.recv() => match tls.reload() {
                    Ok(()) => {
                        info!("SIGHUP: TLS certificate and key reloaded");
                        report_expiry(&tls, &metrics);
                    }
                    Err(e) => error!(error = %format!("{e:#}"), "SIGHUP: TLS reload failed; the previous certificate stays in force"),
                },
                _ = shutdown.changed() => return,
            }
        }
    }
    #[cfg(not(unix))]
    let _ = (tls, metrics, shutdown.changed().await);
}
