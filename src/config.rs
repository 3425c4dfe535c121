//! The service configuration (`camloop run --config FILE`): one TOML file, unknown keys are
//! errors, every problem is reported at once, secrets come from the environment and are
//! redacted in Debug output.

use crate::sim::GrinderConfig;
use serde::Deserialize;
use std::fmt;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

/// Environment variable that overrides `database.url`.
pub const ENV_DATABASE_URL: &str = "CAMLOOP_DATABASE_URL";
/// Environment variable holding the API token for write requests.
pub const ENV_API_TOKEN: &str = "CAMLOOP_API_TOKEN";

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    #[serde(default)]
    pub service: ServiceSection,
    #[serde(default)]
    pub database: DatabaseSection,
    #[serde(default)]
    pub http: HttpSection,
    pub machines: Vec<MachineSection>,
    /// Folder of the config file; relative paths in the file are resolved against it.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// The API token, from the environment only.
    #[serde(skip)]
    pub api_token: Option<Secret>,
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
#[serde(default, deny_unknown_fields)]
pub struct HttpSection {
    /// Address the API listens on; localhost unless you mean otherwise.
    pub listen: SocketAddr,
}

impl Default for HttpSection {
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineSection {
    /// Machine name: letters, digits, '-' and '_' (it names folders and URLs).
    pub name: String,
    /// Part recipe (relative to the config file).
    pub recipe: PathBuf,
    /// The lobe or pin of the recipe this machine grinds.
    pub lobe: String,
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
        /// Simulator settings (defaults: about 16 µm uncompensated on the demo lobe).
        #[serde(default)]
        grinder: GrinderConfig,
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
    },
}

fn default_part_interval_ms() -> u64 {
    1000
}

fn default_poll_ms() -> u64 {
    500
}

/// A secret that never shows in Debug output or logs.
#[derive(Clone, PartialEq, Eq)]
pub struct Secret(String);

impl Secret {
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Secret(…)")
    }
}

/// Every problem found, one per entry, each naming the file and the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {}", .problems.join("; "))]
pub struct ConfigError {
    pub file: String,
    pub problems: Vec<String>,
}

impl Config {
    /// Parses the text of `file`, applies the environment (`env` looks a variable up), and
    /// checks everything, reporting every problem at once.
    pub fn parse(
        text: &str,
        file: &Path,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<Self, ConfigError> {
        let error = |problems: Vec<String>| ConfigError {
            file: file.display().to_string(),
            problems,
        };
        let mut config: Config = toml::from_str(text).map_err(|e| {
            let line = e
                .span()
                .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
            let at = line.map(|l| format!("line {l}: ")).unwrap_or_default();
            error(vec![format!("{at}{}", e.message().trim_end())])
        })?;
        config.base_dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
        if let Some(url) = env(ENV_DATABASE_URL) {
            config.database.url = url;
        }
        config.api_token = env(ENV_API_TOKEN).filter(|t| !t.is_empty()).map(Secret);
        let problems = config.problems();
        if problems.is_empty() {
            Ok(config)
        } else {
            Err(error(problems))
        }
    }

    fn problems(&self) -> Vec<String> {
        let mut p = Vec::new();
        if self.machines.is_empty() {
            p.push("at least one [[machines]] is needed".to_string());
        }
        let url = &self.database.url;
        if !(url.starts_with("sqlite:")
            || url.starts_with("postgres://")
            || url.starts_with("postgresql://"))
        {
            p.push("database.url: must start with sqlite: or postgres://".to_string());
        }
        let mut names = std::collections::HashSet::new();
        for m in &self.machines {
            let at = format!("machines.{}", m.name);
            if !(1..=32).contains(&m.name.len())
                || !m
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
            {
                p.push(format!(
                    "{at}: name must be 1–32 letters, digits, '-' or '_'"
                ));
            }
            if !names.insert(m.name.clone()) {
                p.push(format!("{at}: duplicate machine name"));
            }
            if let GaugeSection::Sim {
                part_interval_ms: 0,
                ..
            } = m.gauge
            {
                p.push(format!("{at}.gauge.part_interval_ms: must be > 0"));
            }
            if let GaugeSection::Sim { grinder, .. } = &m.gauge {
                p.extend(
                    grinder
                        .problems()
                        .into_iter()
                        .map(|e| format!("{at}.gauge.grinder: {e}")),
                );
            }
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
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
[[machines]]
name = "SIM1"
recipe = "parts/demo-camshaft.toml"
lobe = "IN1"
share = "../var/share/SIM1"
[machines.gauge]
kind = "sim"
"#;

    #[test]
    fn environment_overrides_the_url_and_supplies_the_token_which_never_shows() {
        let env = |k: &str| match k {
            ENV_DATABASE_URL => Some("postgres://camloop:hunter2@db/camloop".to_string()),
            ENV_API_TOKEN => Some("s3cret".to_string()),
            _ => None,
        };
        let c = Config::parse(MINIMAL, Path::new("config/camloop.toml"), env).unwrap();
        assert_eq!(c.database.url, "postgres://camloop:hunter2@db/camloop");
        assert_eq!(c.api_token.as_ref().map(Secret::expose), Some("s3cret"));
        let shown = format!("{c:?}");
        assert!(
            !shown.contains("hunter2") && !shown.contains("s3cret"),
            "{shown}"
        );
    }

    #[test]
    fn relative_paths_resolve_against_the_config_folder() {
        let c = Config::parse(MINIMAL, Path::new("config/camloop.toml"), |_| None).unwrap();
        assert_eq!(
            c.database_url(),
            "sqlite://config/../var/camloop.db?mode=rwc"
        );
        assert_eq!(
            c.resolve(Path::new("parts/x.toml")),
            PathBuf::from("config/parts/x.toml")
        );
    }

    #[test]
    fn every_problem_is_reported_at_once() {
        let text = r#"
[database]
url = "mysql://x"
[[machines]]
name = "bad name"
recipe = "r.toml"
lobe = "IN1"
share = "s"
[machines.gauge]
kind = "sim"
part_interval_ms = 0
[[machines]]
name = "bad name"
recipe = "r.toml"
lobe = "IN1"
share = "s"
[machines.gauge]
kind = "drop"
folder = "in"
"#;
        let e = Config::parse(text, Path::new("c.toml"), |_| None)
            .unwrap_err()
            .to_string();
        for expected in [
            "database.url",
            "name must be",
            "duplicate machine name",
            "part_interval_ms: must be > 0",
        ] {
            assert!(e.contains(expected), "`{expected}` missing from `{e}`");
        }
        let e = Config::parse("colour = 1\n", Path::new("c.toml"), |_| None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("c.toml: line 1: unknown field `colour`"),
            "{e}"
        );
    }
}
