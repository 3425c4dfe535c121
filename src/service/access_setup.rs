//! Access at start: the settings the listener uses, and the first `admin`.
//!
//! On a database with no user, the service makes `admin` with a random password and writes
//! the password once to a file only its owner can read (mode 0600), printing the file's path
//! and never the password. The operator signs in with it, then changes it
//! (`camloop user passwd admin`) and deletes the file.

use crate::audit_seal::AuditSeal;
use crate::config::Config;
use crate::service::http::AuthState;
use crate::store::{AuditEntry, AuditResult, Role, Store};
use anyhow::Context;
use std::io::Write as _;
use std::path::Path;
use tracing::{info, warn};

/// Makes the var folder, or narrows it and what is directly in it, to the service's account
/// only (0700, 0600): it holds the database (password hashes, history), the audit key, the
/// MQTT queue, the OPC UA key, the machines' journals and the demo's share.
pub(crate) fn private_var_dir(config: &Config) -> anyhow::Result<()> {
    let var = config.var_dir();
    crate::private_fs::create_dir_all(&var)
        .and_then(|()| crate::private_fs::restrict_with_children(&var))
        .with_context(|| format!("var folder {}", var.display()))
}

/// The folder of the audit trail's key and head: beside the first admin's password.
pub(crate) fn seal_dir(config: &Config) -> std::path::PathBuf {
    let file = config.admin_password_file();
    file.parent()
        .map_or_else(|| config.var_dir(), Path::to_path_buf)
}

/// The listener's access settings from the configuration (the audit key made on the first
/// start).
pub(crate) fn access_settings(config: &Config) -> anyhow::Result<AuthState> {
    let anonymous_read = config.auth.anonymous_read(config.http.listen);
    let mut auth = AuthState::new(config.api_token.clone(), anonymous_read);
    auth.audit_seal = std::sync::Arc::new(AuditSeal::open_or_create(&seal_dir(config))?);
    auth.session = jiff::SignedDuration::from_mins(i64::from(config.auth.session_minutes.max(1)));
    // Under TLS the session cookie is `Secure`: a browser never sends it in clear.
    auth.secure_cookie = config.http.tls();
    if config.api_token.is_some() {
        warn!(
            "CAMLOOP_API_TOKEN is deprecated: it acts as an admin; make per-user tokens with `camloop token create`"
        );
    }
    Ok(auth)
}

/// Makes the first `admin` when the store has no user; returns the password file written.
pub(crate) async fn ensure_admin(
    store: &Store,
    config: &Config,
) -> anyhow::Result<Option<std::path::PathBuf>> {
    if !store.users().await?.is_empty() {
        return Ok(None);
    }
    let password = crate::auth::random_password()?;
    let hash = tokio::task::spawn_blocking({
        let p = password.clone();
        move || crate::auth::hash_password(&p)
    })
    .await
    .context("hashing the first admin's password")??;
    let file = config.admin_password_file();
    write_secret_file(&file, &format!("{password}\n")).with_context(|| {
        format!(
            "cannot write the first admin's password to {}",
            file.display()
        )
    })?;
    let now = crate::clock::now();
    match store.add_user("admin", Role::Admin, &hash, now).await {
        Ok(_) => {}
        // Instances sharing one database start together: another one made the admin
        // between our look and our insert. Its password is in its own file; ours is void.
        Err(crate::store::StoreError::Conflict { .. }) => {
            let _ = std::fs::remove_file(&file);
            info!("first start: another instance created user `admin` at the same moment");
            return Ok(None);
        }
        Err(e) => return Err(e.into()),
    }
    let entry = AuditEntry {
        at: now,
        actor: "camloop".into(),
        role: Role::Admin,
        client: "local".into(),
        action: "user.add".into(),
        machine: None,
        feature: None,
        version: None,
        before: None,
        after: Some(r#"{"user":"admin","role":"admin"}"#.into()),
        result: AuditResult::Ok,
        reason: format!("first start: password written to {}", file.display()),
    };
    AuditSeal::open_or_create(&seal_dir(config))?
        .append(store, &entry)
        .await?;
    info!(file = %file.display(), "first start: user `admin` created; its password is in this file (readable only by this account): sign in, change it with `camloop user passwd admin`, then delete the file");
    println!(
        "camloop: first start: the password of user `admin` is in {}",
        file.display()
    );
    Ok(Some(file))
}

/// Writes `text` to a new file readable and writable only by its owner (mode 0600 from the
/// moment it exists), replacing any file there.
pub(crate) fn write_secret_file(path: &Path, text: &str) -> std::io::Result<()> {
    if let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
    {
        crate::private_fs::create_dir_all(dir)?;
    }
    let _ = std::fs::remove_file(path);
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    let mut file = options.open(path)?;
    file.write_all(text.as_bytes())?;
    file.sync_all()
}
