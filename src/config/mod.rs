//! The service configuration (`camloop run --config FILE`): one TOML file, unknown keys are
//! errors, every problem is reported at once, secrets come from the environment and are
//! redacted in Debug output.

mod auth;
mod check;
mod cluster;
mod http;
mod keys;
mod values;

pub use auth::AuthSection;
pub use camloop_mqtt::{ENV_MQTT_PASSWORD, MqttSection};
pub use camloop_opcua::{OpcUaSection, OpcUaSecurity};
pub use check::{Checked, CheckedMachine, check, configured_features, load, machine_features};
pub use cluster::ClusterSection;
pub use http::{HttpSection, network_exposure};
pub use keys::Lines;

use crate::names::{FeatureName, MachineName};
use crate::sim::GrinderConfig;
use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};

/// Environment variable that overrides `database.url`.
pub(crate) const ENV_DATABASE_URL: &str = "CAMLOOP_DATABASE_URL";
/// Environment variable holding the shared API token (deprecated: it acts as an `admin`;
/// use per-user tokens from `camloop token create`).
pub const ENV_API_TOKEN: &str = "CAMLOOP_API_TOKEN";
/// The shortest `CAMLOOP_API_TOKEN` accepted: it acts as admin, so it must be as hard to
/// guess as a random 128-bit value written in hex.
pub const MIN_API_TOKEN_CHARS: usize = 32;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    #[serde(default)]
    pub service: ServiceSection,
    #[serde(default)]
    pub database: DatabaseSection,
    #[serde(default)]
    pub http: HttpSection,
    #[serde(default)]
    pub mqtt: MqttSection,
    #[serde(default)]
    pub opcua: OpcUaSection,
    #[serde(default)]
    pub cluster: ClusterSection,
    #[serde(default)]
    pub auth: AuthSection,
    #[serde(default)]
    pub machines: Vec<MachineSection>,
    /// Folder of the config file; relative paths in the file are resolved against it.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// The deprecated shared API token (acts as `admin`), from the environment only.
    #[serde(skip)]
    pub api_token: Option<Secret>,
    /// The line of every key in the file, for problems found after parsing.
    #[serde(skip)]
    pub lines: Lines,
    /// The config file, for messages.
    #[serde(skip)]
    pub file: PathBuf,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceSection {
    /// Working folder for the database, journal and machine state (relative to the config).
    pub var_dir: PathBuf,
    /// "plain" for a terminal, "json" for log collectors.
    pub log_format: LogFormat,
}

impl Default for ServiceSection {
    fn default() -> Self {
        Self {
            var_dir: PathBuf::from("../var"),
            log_format: LogFormat::Plain,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    Plain,
    Json,
}

#[derive(Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatabaseSection {
    /// `sqlite://…` (the embedded default) or `postgres://…`; CAMLOOP_DATABASE_URL overrides.
    pub url: String,
    /// Days raw revolutions are kept; summaries are kept forever. 0: keep raw forever.
    pub raw_retention_days: u32,
}

impl Default for DatabaseSection {
    fn default() -> Self {
        Self {
            url: "sqlite://../var/camloop.db?mode=rwc".into(),
            raw_retention_days: 90,
        }
    }
}

impl fmt::Debug for DatabaseSection {
    /// The URL may carry a password: show only its scheme.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let scheme = self.url.split("://").next().unwrap_or("?");
        f.debug_struct("DatabaseSection")
            .field("url", &format!("{scheme}://…"))
            .field("raw_retention_days", &self.raw_retention_days)
            .finish()
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineSection {
    /// Machine name: letters, digits, '-' and '_' (it names folders and URLs). Checked as the
    /// file is read: a bad name is a problem on its line, and its entry is not checked further.
    pub name: MachineName,
    /// Part recipe (relative to the config file).
    pub recipe: PathBuf,
    /// Grind only this lobe or pin of the recipe (default: every feature, in recipe order).
    #[serde(default)]
    pub lobe: Option<FeatureName>,
    /// Grind only these lobes or pins, in recipe order (default: every feature).
    #[serde(default)]
    pub features: Option<Vec<FeatureName>>,
    /// The grinding C speed on this machine, rpm, instead of the recipe's
    /// `axis_limits.c_speed_rpm` (the main program, the guards and the simulator use it).
    #[serde(default)]
    pub c_speed_rpm: Option<f64>,
    /// The controller's file share (a mounted folder), relative to the config file.
    pub share: PathBuf,
    pub gauge: GaugeSection,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum GaugeSection {
    /// The simulated grinder and gauge; frames go through the real CAN codec in memory.
    Sim {
        /// Time between parts, ms.
        #[serde(default = "default_part_interval_ms")]
        part_interval_ms: u64,
        #[serde(default)]
        seed: u64,
        /// Simulator settings (defaults: about 16 µm uncompensated on the demo lobe). Boxed:
        /// the other gauges' settings are far smaller.
        #[serde(default)]
        grinder: Box<GrinderConfig>,
    },
    /// A SocketCAN interface read through the DBC.
    Can { interface: String, dbc: PathBuf },
    /// A serial line speaking camloop's line protocol.
    Serial { port: String, baud: u32 },
    /// A folder the gauge PC drops measurement files into.
    Drop {
        folder: PathBuf,
        #[serde(default = "default_poll_ms")]
        poll_ms: u64,
        /// A file is taken once its size and time have not changed for this long, ms.
        #[serde(default = "default_stable_ms")]
        stable_ms: u64,
        /// A bigger file is rejected unread, bytes.
        #[serde(default = "default_max_file_bytes")]
        max_file_bytes: u64,
    },
}

fn default_part_interval_ms() -> u64 {
    1000
}

fn default_poll_ms() -> u64 {
    500
}

fn default_stable_ms() -> u64 {
    10_000
}

fn default_max_file_bytes() -> u64 {
    16 * 1024 * 1024
}

/// A secret that never shows in Debug output or logs.
#[derive(Clone, PartialEq, Eq)]
pub struct Secret(String);

impl Secret {
    pub fn new(secret: impl Into<String>) -> Self {
        Self(secret.into())
    }

    pub(crate) fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Secret(…)")
    }
}

/// One problem in the configuration: the line of the config file it is on (when known) and
/// what is wrong. Problems found in files the config names (recipes, DBC files) carry the
/// line of the key that names them, and the other file's name and line in the message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigProblem {
    pub line: Option<usize>,
    pub message: String,
}

impl ConfigProblem {
    fn at(line: Option<usize>, message: impl Into<String>) -> Self {
        Self {
            line,
            message: message.into(),
        }
    }
}

impl fmt::Display for ConfigProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "line {l}: {}", self.message),
            None => f.write_str(&self.message),
        }
    }
}

/// Every problem found, one per entry, each naming the line and the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {}", join(.problems))]
pub struct ConfigError {
    pub file: String,
    pub problems: Vec<ConfigProblem>,
}

fn join(problems: &[ConfigProblem]) -> String {
    let texts: Vec<String> = problems.iter().map(ToString::to_string).collect();
    texts.join("; ")
}

impl Config {
    /// Parses the text of `file`, applies the environment (`env` looks a variable up), and
    /// checks everything that needs no other file, reporting every problem at once. The
    /// service checks the files the config names, and its listener, with [`check`] or
    /// [`load`].
    pub fn parse(
        text: &str,
        file: &Path,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<Self, ConfigError> {
        match Self::read(text, file, env) {
            (Some(config), problems) if problems.is_empty() => Ok(config),
            (_, problems) => Err(ConfigError {
                file: file.display().to_string(),
                problems,
            }),
        }
    }

    /// Parses as far as possible: the config (when its structure could be read) and every
    /// problem found.
    pub(crate) fn read(
        text: &str,
        file: &Path,
        env: impl Fn(&str) -> Option<String>,
    ) -> (Option<Self>, Vec<ConfigProblem>) {
        let read = keys::read::<Config>(text);
        let mut problems = read.problems;
        let Some(mut config) = read.value else {
            return (None, problems);
        };
        config.lines = read.lines;
        config.file = file.to_path_buf();
        config.base_dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
        if let Some(url) = env(ENV_DATABASE_URL) {
            config.database.url = url;
        }
        config.api_token = env(ENV_API_TOKEN).filter(|t| !t.is_empty()).map(Secret);
        config.mqtt.password = env(ENV_MQTT_PASSWORD)
            .filter(|t| !t.is_empty())
            .map(camloop_mqtt::Password::new);
        let machines_dropped = read.dropped.iter().any(|k| k == "machines");
        problems.extend(config.problems(machines_dropped));
        problems.sort_by_key(|p| p.line.unwrap_or(usize::MAX));
        (Some(config), problems)
    }

    /// The line of `path` (`http.listen`, `machines[0].name`) in the file.
    pub fn line(&self, path: &str) -> Option<usize> {
        self.lines.of(path)
    }

    /// Whether the file sets exactly the key at `path` (`machines[0].gauge.grinder.c_speed_rpm`).
    pub fn sets(&self, path: &str) -> bool {
        self.lines.has(path)
    }

    fn problems(&self, machines_dropped: bool) -> Vec<ConfigProblem> {
        let mut p = Vec::new();
        if self.machines.is_empty() && !machines_dropped {
            p.push(ConfigProblem::at(
                None,
                "at least one [[machines]] is needed",
            ));
        }
        let url = &self.database.url;
        if !(url.starts_with("sqlite:")
            || url.starts_with("postgres://")
            || url.starts_with("postgresql://"))
        {
            p.push(ConfigProblem::at(
                self.line("database.url"),
                "database.url: must start with sqlite: or postgres://",
            ));
        }
        if let Some(token) = &self.api_token {
            let chars = token.expose().chars().count();
            if chars < MIN_API_TOKEN_CHARS {
                p.push(ConfigProblem::at(
                    None,
                    format!(
                        "{ENV_API_TOKEN} has {chars} characters; at least {MIN_API_TOKEN_CHARS} are needed, since it acts as admin (better: per-user tokens, `camloop token create`)"
                    ),
                ));
            }
        }
        p.extend(self.http.problems(&self.lines));
        p.extend(
            self.mqtt
                .problems()
                .into_iter()
                .map(|problem| ConfigProblem::at(self.lines.of(&problem.key), problem.message)),
        );
        p.extend(
            self.opcua
                .problems()
                .into_iter()
                .map(|problem| ConfigProblem::at(self.lines.of(&problem.key), problem.message)),
        );
        p.extend(self.cluster.problems(&self.lines, url));
        let mut names = std::collections::HashMap::new();
        for (i, m) in self.machines.iter().enumerate() {
            let at = |key: &str| self.line(&format!("machines[{i}]{key}"));
            let label = format!("machines.{}", m.name);
            if let Some(first) = names.insert(m.name.clone(), i) {
                let first_line = self.line(&format!("machines[{first}].name"));
                let first_at = first_line.map(|l| format!(" (first at line {l})"));
                p.push(ConfigProblem::at(
                    at(".name"),
                    format!(
                        "{label}: duplicate machine name{}",
                        first_at.unwrap_or_default()
                    ),
                ));
            }
            p.extend(m.gauge.problems(&label, |key| at(&format!(".gauge{key}"))));
        }
        p
    }

    /// A path from the file, resolved against the config file's folder.
    pub fn resolve(&self, path: &Path) -> PathBuf {
        if path.is_absolute() {
            path.to_path_buf()
        } else {
            self.base_dir.join(path)
        }
    }

    /// The database URL with a relative SQLite path resolved against the config's folder.
    pub fn database_url(&self) -> String {
        let url = &self.database.url;
        match url.strip_prefix("sqlite://") {
            Some(rest) if !rest.starts_with('/') && !rest.starts_with(":memory:") => {
                format!("sqlite://{}", self.base_dir.join(rest).display())
            }
            _ => url.clone(),
        }
    }

    pub fn var_dir(&self) -> PathBuf {
        self.resolve(&self.service.var_dir)
    }

    /// Where the first start writes the `admin` password.
    pub(crate) fn admin_password_file(&self) -> PathBuf {
        match self.auth.admin_password_file.as_os_str().is_empty() {
            true => self.var_dir().join("admin-password"),
            false => self.resolve(&self.auth.admin_password_file),
        }
    }

    /// The `[mqtt]` settings as this instance uses them: in a cluster the client id is
    /// `<client_id>-<instance>`, since a broker disconnects a client whose id another takes.
    pub(crate) fn mqtt_settings(&self) -> MqttSection {
        let mut settings = self.mqtt.clone();
        settings.tls_ca = settings.tls_ca.map(|p| self.resolve(&p));
        if self.cluster.enabled {
            let instance = self.cluster.instance_name();
            settings.client_id = format!("{}-{instance}", settings.client_id);
        }
        settings
    }

    /// Where each machine's journal and delivery state live: `<var>/machines`, or with a
    /// cluster the shared `<cluster.state_dir>/machines` every instance reaches.
    pub(crate) fn machines_dir(&self) -> PathBuf {
        match self.cluster.enabled {
            true => self.resolve(&self.cluster.state_dir).join("machines"),
            false => self.var_dir().join("machines"),
        }
    }
}

#[cfg(test)]
mod tests;
