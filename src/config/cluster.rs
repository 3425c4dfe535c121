//! The `[cluster]` section: several `camloop run` instances sharing the machines of one
//! config through one PostgreSQL (off by default: one instance owns every machine).

use super::{ConfigProblem, Lines};
use serde::Deserialize;
use std::path::PathBuf;

#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClusterSection {
    /// Share the machines with the other instances of this config.
    pub enabled: bool,
    /// This instance's name, unique in the plant (1-64 letters, digits, '-', '_', '.');
    /// empty: the host name.
    pub instance: String,
    /// How long a machine's lease lasts without renewal, ms. An instance that dies loses
    /// its machines this long after its last renewal; the others take them at their next
    /// look (every quarter lease).
    pub lease_ms: u64,
    /// Folder every instance reaches (a network mount), holding each machine's journal and
    /// delivery state, so whichever instance owns a machine resumes where the last one
    /// stopped. Relative to the config file.
    pub state_dir: PathBuf,
}

impl Default for ClusterSection {
    fn default() -> Self {
        Self {
            enabled: false,
            instance: String::new(),
            lease_ms: 6000,
            state_dir: PathBuf::new(),
        }
    }
}

impl ClusterSection {
    /// The instance name: the configured one, else the host name.
    pub(crate) fn instance_name(&self) -> String {
        if !self.instance.is_empty() {
            return self.instance.clone();
        }
        std::fs::read_to_string("/etc/hostname")
            .ok()
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "camloop".into())
    }

    pub(super) fn problems(&self, lines: &Lines, database_url: &str) -> Vec<ConfigProblem> {
        if !self.enabled {
            return Vec::new();
        }
        let mut p = Vec::new();
        let mut bad = |key: &str, why: String| {
            p.push(ConfigProblem::at(
                lines.of(&format!("cluster.{key}")),
                format!("cluster.{key}: {why}"),
            ));
        };
        let name_ok = |n: &str| {
            (1..=64).contains(&n.len())
                && n.chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        };
        if !self.instance.is_empty() && !name_ok(&self.instance) {
            bad(
                "instance",
                format!(
                    "`{}` must be 1-64 letters, digits, '-', '_' or '.'",
                    self.instance
                ),
            );
        }
        if !(1000..=600_000).contains(&self.lease_ms) {
            bad(
                "lease_ms",
                format!("{} must be 1000 to 600000 ms", self.lease_ms),
            );
        }
        if self.state_dir.as_os_str().is_empty() {
            bad(
                "state_dir",
                "required: a folder every instance reaches (each machine's journal and delivery state)".into(),
            );
        }
        if !database_url.starts_with("postgres://") && !database_url.starts_with("postgresql://") {
            bad(
                "enabled",
                "several instances coordinate through PostgreSQL: database.url (or CAMLOOP_DATABASE_URL) must be postgres://…".into(),
            );
        }
        p
    }
}
