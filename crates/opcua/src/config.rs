//! The `[opcua]` section: the OPC UA server inside `camloop run` (off by default). The
//! service's config file holds it; its checks name the key, and the service adds the line.

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
    pub fn host(&self) -> String {
        self.host_name
            .clone()
            .unwrap_or_else(|| self.listen.ip().to_string())
    }

    /// Every problem of an enabled section at once (none when it is off).
    pub fn problems(&self) -> Vec<SectionProblem> {
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
                p.push(SectionProblem::new(
                    "opcua.host_name",
                    format!("opcua.host_name: `{h}` is not a host name"),
                ));
            }
        }
        p.extend(self.certificate_problems());
        if self.listen.port() == 0 {
            p.push(SectionProblem::new(
                "opcua.listen",
                "opcua.listen: the port must not be 0 (clients find the endpoint by its URL)"
                    .to_string(),
            ));
        }
        p
    }

    fn certificate_problems(&self) -> Vec<SectionProblem> {
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
                p.push(SectionProblem::new(
                    format!("opcua.{key}"),
                    format!("opcua.{key}: `{value}` must be at most 64 characters without , = + \" \\ < > ; #"),
                ));
            }
        }
        let c = &self.certificate_country;
        if !(c.is_empty() || (c.len() == 2 && c.chars().all(|x| x.is_ascii_uppercase()))) {
            p.push(SectionProblem::new(
                "opcua.certificate_country",
                format!("opcua.certificate_country: `{c}` is not a two-letter country code (ISO 3166, e.g. DE)"),
            ));
        }
        if !(1..=3650).contains(&self.certificate_days) {
            p.push(SectionProblem::new(
                "opcua.certificate_days",
                format!(
                    "opcua.certificate_days: {} is not between 1 and 3650",
                    self.certificate_days
                ),
            ));
        }
        p
    }
}

/// One problem in the section: its key (`opcua.<key>`) and what is wrong, key first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SectionProblem {
    /// The full key, `opcua.listen` say, for the caller to find its line.
    pub key: String,
    pub message: String,
}

impl SectionProblem {
    fn new(key: impl Into<String>, message: String) -> Self {
        Self {
            key: key.into(),
            message,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each problem names its full key first (the service finds its line by it), all at
    /// once, and none while the section is off.
    #[test]
    fn every_problem_names_its_key_and_an_off_section_has_none() {
        let bad = OpcUaSection {
            enabled: true,
            listen: SocketAddr::from(([127, 0, 0, 1], 0)),
            host_name: Some("a b".into()),
            certificate_organization: "A, B".into(),
            certificate_country: "Germany".into(),
            certificate_days: 0,
            ..OpcUaSection::default()
        };
        let keys: Vec<String> = bad.problems().into_iter().map(|p| p.key).collect();
        assert_eq!(
            keys,
            [
                "opcua.host_name",
                "opcua.certificate_organization",
                "opcua.certificate_country",
                "opcua.certificate_days",
                "opcua.listen",
            ]
        );
        for p in bad.problems() {
            assert!(p.message.starts_with(&format!("{}: ", p.key)), "{p:?}");
        }
        let off = OpcUaSection {
            enabled: false,
            ..bad
        };
        assert_eq!(off.problems(), []);
        assert_eq!(OpcUaSection::default().host(), "127.0.0.1");
    }
}
