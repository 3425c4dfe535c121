//! HTTPS for the listener (rustls on ring): the certificate chain and key come from
//! `http.tls_cert` and `http.tls_key` (PEM), and are read again on SIGHUP: connections
//! accepted after a successful reload get the new pair, those open keep theirs, and a pair
//! that does not load leaves the old one in force (and says why). `camloop tls self-signed`
//! makes a development pair with [`self_signed`]. The pair is checked to be one (the key
//! signs for the certificate) when it loads, and its certificate's end of validity is kept
//! (`camloop_tls_certificate_expiry_days`, and a warning within 30 days of it).

use anyhow::Context;
use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};
use std::time::Duration;
use tokio::net::TcpStream;
use tokio_rustls::TlsAcceptor;
use tokio_rustls::rustls;
use tokio_rustls::rustls::pki_types::pem::PemObject;
use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};

/// The listener's TLS: the files and the acceptor made from them.
pub struct Tls {
    cert: PathBuf,
    key: PathBuf,
    acceptor: RwLock<TlsAcceptor>,
    /// When the certificate in force (the chain's first) stops being valid.
    not_after: RwLock<jiff::Timestamp>,
}

impl std::fmt::Debug for Tls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tls")
            .field("cert", &self.cert)
            .field("key", &self.key)
            .finish()
    }
}

impl Tls {
    /// Loads the pair; an error names the file and what is wrong with it.
    pub fn load(cert: &Path, key: &Path) -> anyhow::Result<Arc<Self>> {
        let (acceptor, not_after) = acceptor(cert, key)?;
        Ok(Arc::new(Self {
            cert: cert.to_path_buf(),
            key: key.to_path_buf(),
            acceptor: RwLock::new(acceptor),
            not_after: RwLock::new(not_after),
        }))
    }

    /// Reads the pair again; on error the pair in force stays.
    pub fn reload(&self) -> anyhow::Result<()> {
        let (fresh, not_after) = acceptor(&self.cert, &self.key)?;
        *self.acceptor.write().unwrap_or_else(|p| p.into_inner()) = fresh;
        *self.not_after.write().unwrap_or_else(|p| p.into_inner()) = not_after;
        Ok(())
    }

    /// When the certificate in force stops being valid.
    pub fn not_after(&self) -> jiff::Timestamp {
        *self.not_after.read().unwrap_or_else(|p| p.into_inner())
    }

    /// The TLS handshake on an accepted connection, within `timeout`.
    pub(super) async fn accept(
        &self,
        stream: TcpStream,
        timeout: Duration,
    ) -> std::io::Result<tokio_rustls::server::TlsStream<TcpStream>> {
        let acceptor = self
            .acceptor
            .read()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        tokio::time::timeout(timeout, acceptor.accept(stream))
            .await
            .map_err(|_| std::io::Error::new(std::io::ErrorKind::TimedOut, "TLS handshake"))?
    }
}

/// The acceptor of the pair, and when its certificate stops being valid.
fn acceptor(cert: &Path, key: &Path) -> anyhow::Result<(TlsAcceptor, jiff::Timestamp)> {
    let certs: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(cert)
        .and_then(|i| i.collect::<Result<_, _>>())
        .with_context(|| format!("http.tls_cert {}", cert.display()))?;
    anyhow::ensure!(
        !certs.is_empty(),
        "http.tls_cert {}: no certificate in the file",
        cert.display()
    );
    let not_after =
        not_after(&certs[0]).with_context(|| format!("http.tls_cert {}", cert.display()))?;
    let key = PrivateKeyDer::from_pem_file(key)
        .with_context(|| format!("http.tls_key {}", key.display()))?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut config = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()?
        .with_no_client_auth()
        .with_single_cert(certs, key)
        .context("http.tls_cert and http.tls_key do not make a pair")?;
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok((TlsAcceptor::from(Arc::new(config)), not_after))
}

/// The end of a certificate's validity (its `notAfter`).
fn not_after(cert: &CertificateDer<'_>) -> anyhow::Result<jiff::Timestamp> {
    use x509_cert::der::Decode;
    let parsed = x509_cert::Certificate::from_der(cert.as_ref())
        .map_err(|e| anyhow::anyhow!("the certificate does not parse: {e}"))?;
    let end = parsed.tbs_certificate.validity.not_after.to_unix_duration();
    let seconds = i64::try_from(end.as_secs()).unwrap_or(i64::MAX);
    Ok(jiff::Timestamp::from_second(seconds).unwrap_or(jiff::Timestamp::MAX))
}

/// Days from `now` to `not_after` (negative once expired), to two decimals' worth.
pub fn days_left(not_after: jiff::Timestamp, now: jiff::Timestamp) -> f64 {
    not_after.duration_since(now).as_secs_f64() / 86_400.0
}

/// A self-signed development certificate for `names` (host names or addresses) and its
/// key, both PEM. Not for production: clients must be told to trust it (`curl --cacert`).
pub fn self_signed(names: &[String]) -> anyhow::Result<(String, String)> {
    let pair = rcgen::generate_simple_self_signed(names.to_vec())
        .context("making the self-signed certificate")?;
    Ok((pair.cert.pem(), pair.signing_key.serialize_pem()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_self_signed_pair_loads_and_a_broken_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let (cert, key) = self_signed(&["localhost".into()]).unwrap();
        let (c, k) = (dir.path().join("cert.pem"), dir.path().join("key.pem"));
        std::fs::write(&c, &cert).unwrap();
        std::fs::write(&k, &key).unwrap();
        let tls = Tls::load(&c, &k).unwrap();
        std::fs::write(&c, "not a certificate").unwrap();
        let e = format!("{:#}", tls.reload().unwrap_err());
        assert!(e.contains("cert.pem"), "{e}");
        // The swapped pair: key where the certificate should be.
        let e = format!("{:#}", Tls::load(&k, &k).unwrap_err());
        assert!(e.contains("tls_cert"), "{e}");
        // A key of another pair: refused as no pair.
        let (_, other_key) = self_signed(&["localhost".into()]).unwrap();
        std::fs::write(&c, &cert).unwrap();
        std::fs::write(&k, &other_key).unwrap();
        let e = format!("{:#}", Tls::load(&c, &k).unwrap_err());
        assert!(e.contains("do not make a pair"), "{e}");
    }

    #[test]
    fn the_certificate_s_end_of_validity_is_read_at_load_and_reload() {
        let dir = tempfile::tempdir().unwrap();
        let (c, k) = (dir.path().join("cert.pem"), dir.path().join("key.pem"));
        let write = |days: i64| {
            let key = rcgen::KeyPair::generate().unwrap();
            let mut params = rcgen::CertificateParams::new(vec!["localhost".into()]).unwrap();
            let end = jiff::Timestamp::now() + jiff::SignedDuration::from_hours(24 * days);
            params.not_after = rcgen::date_time_ymd(2000, 1, 1)
                + std::time::Duration::from_secs(
                    u64::try_from(end.as_second() - 946_684_800).unwrap(),
                );
            params.not_before = rcgen::date_time_ymd(2000, 1, 1);
            let cert = params.self_signed(&key).unwrap();
            std::fs::write(&c, cert.pem()).unwrap();
            std::fs::write(&k, key.serialize_pem()).unwrap();
        };
        write(10);
        let tls = Tls::load(&c, &k).unwrap();
        let left = days_left(tls.not_after(), jiff::Timestamp::now());
        // Whole seconds in the certificate: within a minute of ten days.
        assert!((left - 10.0).abs() < 1.0 / 1440.0, "{left}");
        write(-3);
        tls.reload().unwrap();
        let left = days_left(tls.not_after(), jiff::Timestamp::now());
        assert!((left + 3.0).abs() < 1.0 / 1440.0, "{left}");
    }
}
