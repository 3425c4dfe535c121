//! The `[auth]` section: who may read without signing in, how long a dashboard session
//! lasts, and where the first start writes the `admin` password.

use serde::Deserialize;
use std::path::PathBuf;

#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AuthSection {
    /// Anyone who reaches the listener may read (role `viewer`) without signing in.
    /// Unset: allowed when `http.listen` is a loopback address, refused otherwise.
    pub anonymous_read: Option<bool>,
    /// A dashboard session ends this long after sign-in, minutes.
    pub session_minutes: u32,
    /// Where the first start writes the `admin` user's random password (mode 0600),
    /// relative to the config file; empty: `<var_dir>/admin-password`.
    pub admin_password_file: PathBuf,
}

impl Default for AuthSection {
    fn default() -> Self {
        Self {
            anonymous_read: None,
            session_minutes: 8 * 60,
            admin_password_file: PathBuf::new(),
        }
    }
}

impl AuthSection {
    /// Whether anonymous clients read as `viewer` on a listener at `listen`.
    pub fn anonymous_read(&self, listen: std::net::SocketAddr) -> bool {
        self.anonymous_read
            .unwrap_or_else(|| listen.ip().is_loopback())
    }
}
