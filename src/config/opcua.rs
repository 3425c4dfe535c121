//! The `[opcua]` section: the OPC UA server inside `camloop run` (off by default).

use super::{ConfigProblem, Lines};
use serde::Deserialize;
use std::net::SocketAddr;
use std::path::PathBuf;

/// Which message security the endpoint offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
pub enum OpcUaSecurity {
    /// Basic256Sha256 with SignAndEncrypt: the default, and the only secure choice offered.
    #[serde(rename = "Basic256Sha256")]
    Basic256Sha256,
    /// Basic256Sha256 SignAndEncrypt plus an unsecured `None` endpoint (warned at start).
    #[serde(rename = "Basic256Sha256+None")]
    Basic256Sha256AndNone,
}

#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OpcUaSection {
    /// Serve OPC UA at all.
    pub enabled: bool,
    /// Address and TCP port of the endpoint (`opc.tcp://<host>:<port>/`).
    pub listen: SocketAddr,
    /// The host name written in the endpoint URL and the server certificate; default: the
    /// listen address.
    pub host_name: Option<String>,
    pub security: OpcUaSecurity,
    /// Trust client certificates not yet in `<pki>/trusted` (warned at start). Off: a new
    /// client's certificate lands in `<pki>/rejected` until an operator moves it.
    pub accept_unknown_clients: bool,
    /// Clients that give no user may browse, read and subscribe (never write).
    pub anonymous_read: bool,
    /// The certificate store (own certificate, trusted and rejected clients); default:
    /// `<var>/opcua/pki`.
    pub pki_dir: Option<PathBuf>,
    /// The subject of the server certificate made on the first start (an existing one is
    /// kept): organisation (`O`), unit (`OU`), country (`C`, two letters) and state or
    /// region (`ST`); empty parts are left out. The common name is `camloop`.
    pub certificate_organization: String,
    pub certificate_organizational_unit: String,
    pub certificate_country: String,
    pub certificate_state: String,
    /// Days the certificate made on the first start is valid.
    pub certificate_days: u32,
}

impl Default for OpcUaSection {
    fn default() -> Self {
        Self {
            enabled: false,
            listen: SocketAddr::from(([127, 0, 0, 1], 4840)),
            host_name: None,
            security: OpcUaSecurity::Basic256Sha256,
            accept_unknown_clients: false,
            anonymous_read: false,
            pki_dir: None,
            certificate_organization: "camloop".into(),
            certificate_organizational_unit: String::new(),
            certificate_country: String::new(),
            certificate_state: String::new(),
            certificate_days: 365,
        }
    }
}

impl OpcUaSection {
    /// The host name clients see in the endpoint URL.
    pub(crate) fn host(&self) -> String {
        self.host_name
            .clone()
            .unwrap_or_else(|| self.listen.ip().to_string())
    }

    pub(super) fn problems(&self, lines: &Lines) -> Vec<ConfigProblem> {
        let mut p = Vec::new();
        if !self.enabled {
            return p;
        }
        if let Some(h) = &self.host_name {
            let ok = !h.is_empty()
                && h.len() <= 253
                && h.chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | ':'));
            if !ok {
                p.push(ConfigProblem::at(
                    lines.of("opcua.host_name"),
                    format!("opcua.host_name: `{h}` is not a host name"),
                ));
            }
        }
        p.extend(self.certificate_problems(lines));
        if self.listen.port() == 0 {
            p.push(ConfigProblem::at(
                lines.of("opcua.listen"),
                "opcua.listen: the port must not be 0 (clients find the endpoint by its URL)"
                    .to_string(),
            ));
        }
        p
    }

    fn certificate_problems(&self, lines: &Lines) -> Vec<ConfigProblem> {
        let mut p = Vec::new();
        let parts = [
            ("certificate_organization", &self.certificate_organization),
            (
                "certificate_organizational_unit",
                &self.certificate_organizational_unit,
            ),
            ("certificate_state", &self.certificate_state),
        ];
        for (key, value) in parts {
            // The stack writes the subject as `O=…,C=…` text: a separator would split it.
            let ok = value.len() <= 64
                && !value.chars().any(|c| {
                    c.is_control()
                        || matches!(c, ',' | '=' | '+' | '"' | '\\' | '<' | '>' | ';' | '#')
                });
            if !ok {
                p.push(ConfigProblem::at(
                    lines.of(&format!("opcua.{key}")),
                    format!("opcua.{key}: `{value}` must be at most 64 characters without , = + \" \\ < > ; #"),
                ));
            }
        }
        let c = &self.certificate_country;
        if !(c.is_empty() || (c.len() == 2 && c.chars().all(|x| x.is_ascii_uppercase()))) {
            p.push(ConfigProblem::at(
                lines.of("opcua.certificate_country"),
                format!("opcua.certificate_country: `{c}` is not a two-letter country code (ISO 3166, e.g. DE)"),
            ));
        }
        if !(1..=3650).contains(&self.certificate_days) {
            p.push(ConfigProblem::at(
                lines.of("opcua.certificate_days"),
                format!(
                    "opcua.certificate_days: {} is not between 1 and 3650",
                    self.certificate_days
                ),
            ));
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use crate::config::{Config, OpcUaSecurity};

    use std::path::Path;

    fn parse(text: &str) -> Result<Config, crate::config::ConfigError> {
        Config::parse(text, Path::new("c.toml"), |_| None)
    }

    #[test]
    fn off_by_default_secure_by_default_and_none_only_when_named() {
        let section = |text: &str| toml::from_str::<super::OpcUaSection>(text);
        let c = section("").unwrap();
        assert!(!c.enabled);
        assert_eq!(c.security, OpcUaSecurity::Basic256Sha256);
        assert!(!c.accept_unknown_clients && !c.anonymous_read);
        let c = section("enabled = true\nsecurity = \"Basic256Sha256+None\"\n").unwrap();
        assert_eq!(c.security, OpcUaSecurity::Basic256Sha256AndNone);
        let e = section("enabled = true\nsecurity = \"None\"\n").unwrap_err();
        assert!(e.to_string().contains("unknown variant `None`"), "{e}");
        // In a whole config the line is named.
        let e = parse("[opcua]\nenabled = true\nsecurity = \"None\"\n").unwrap_err();
        assert!(e.to_string().contains("line 3"), "{e}");
    }

    #[test]
    fn a_port_of_zero_and_a_bad_host_name_are_refused_with_their_lines() {
        let e = parse("[opcua]\nenabled = true\nlisten = \"127.0.0.1:0\"\nhost_name = \"a b\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3: opcua.listen"), "{e}");
        assert!(e.contains("line 4: opcua.host_name"), "{e}");
    }

    #[test]
    fn the_certificate_subject_is_checked_with_its_lines() {
        let e = parse(
            "[opcua]\nenabled = true\ncertificate_organization = \"A, B\"\ncertificate_country = \"Germany\"\ncertificate_days = 0\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("line 3: opcua.certificate_organization"), "{e}");
        assert!(e.contains("line 4: opcua.certificate_country"), "{e}");
        assert!(e.contains("line 5: opcua.certificate_days"), "{e}");
        // A good subject: the only problem left is the missing machines.
        let e = parse(
            "[opcua]\nenabled = true\ncertificate_organization = \"Werk Süd\"\ncertificate_country = \"DE\"\n",
        )
        .unwrap_err()
        .to_string();
        assert!(!e.contains("opcua."), "{e}");
    }
}
