//! The audit trail's key and its signed head, both kept outside the database.
//!
//! - Every row appended since version 7 carries `chain = 'hmac-sha256'`: its `row_sha256`
//!   is the HMAC-SHA256, under the site's [`AuditKey`], of its id, the row before's digest
//!   and its fields. Someone who can write the database but not read the key cannot make a
//!   row, or re-chain rows after changing one, that the key verifies.
//! - The head ([`AuditHead`]: rows, the newest id and its digest, under the same key) is
//!   written by each writer to a file beside the key. Removing the newest rows leaves a
//!   chain that holds link by link; the head, which the database writer cannot rewrite,
//!   shows that it is shorter than it was.

use hmac::{Hmac, Mac};
use std::fmt;

type HmacSha256 = Hmac<sha2::Sha256>;

/// The first line of a head file: what it is and its version.
const HEAD_MAGIC: &str = "camloop-audit-head v1";

/// A secret of 32 bytes; its `Debug` shows nothing of it.
#[derive(Clone, PartialEq, Eq)]
pub struct AuditKey([u8; 32]);

impl fmt::Debug for AuditKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("AuditKey(…)")
    }
}

/// What was wrong with a key or a head file's text.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AuditKeyError {
    #[error("the audit key must be 64 hexadecimal digits, not {chars} characters")]
    KeyText { chars: usize },
    #[error("the audit head is not `{HEAD_MAGIC}` with rows, last_id, last and mac: {0}")]
    HeadText(String),
    #[error(
        "the audit head's signature does not match this key: the file was changed or made with another key"
    )]
    HeadSignature,
}

impl AuditKey {
    pub fn from_bytes(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    /// A key from its text: 64 hex digits (surrounding white space ignored).
    pub fn from_hex(text: &str) -> Result<Self, AuditKeyError> {
        let t = text.trim();
        let bad = || AuditKeyError::KeyText {
            chars: t.chars().count(),
        };
        if t.len() != 64 || !t.is_ascii() {
            return Err(bad());
        }
        let mut bytes = [0u8; 32];
        for (i, b) in bytes.iter_mut().enumerate() {
            *b = u8::from_str_radix(&t[2 * i..2 * i + 2], 16).map_err(|_| bad())?;
        }
        Ok(Self(bytes))
    }

    pub fn to_hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// The HMAC-SHA256 of `data` under this key, as lowercase hex.
    pub(crate) fn mac(&self, data: &[u8]) -> String {
        let mut m = HmacSha256::new_from_slice(&self.0).expect("HMAC takes a key of any length");
        m.update(data);
        m.finalize()
            .into_bytes()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    }
}

/// The trail as one writer left it: how many rows, the newest id and its digest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AuditHead {
    pub rows: u64,
    pub last_id: i64,
    pub last_digest: String,
}

impl AuditHead {
    fn body(&self) -> String {
        format!(
            "{HEAD_MAGIC} rows={} last_id={} last={}",
            self.rows, self.last_id, self.last_digest
        )
    }

    /// The head as a file holds it: one line, signed with `key`.
    pub fn signed_text(&self, key: &AuditKey) -> String {
        let body = self.body();
        let mac = key.mac(body.as_bytes());
        format!("{body} mac={mac}\n")
    }

    /// A head read back from [`AuditHead::signed_text`], refused unless `key` signed it.
    pub fn parse_signed(text: &str, key: &AuditKey) -> Result<Self, AuditKeyError> {
        let bad = |why: &str| AuditKeyError::HeadText(why.to_string());
        let line = text.trim();
        let rest = line
            .strip_prefix(HEAD_MAGIC)
            .ok_or_else(|| bad("no header"))?;
        let field = |name: &str| {
            rest.split_whitespace()
                .find_map(|f| f.strip_prefix(name)?.strip_prefix('='))
                .ok_or_else(|| bad(name))
        };
        let head = AuditHead {
            rows: field("rows")?.parse().map_err(|_| bad("rows"))?,
            last_id: field("last_id")?.parse().map_err(|_| bad("last_id"))?,
            last_digest: field("last")?.to_string(),
        };
        let mac = field("mac")?;
        let expected = key.mac(head.body().as_bytes());
        // Both are hex digests of fixed length; compared whole, a byte at a time, so the
        // time taken does not tell where they differ.
        let same = mac.len() == expected.len()
            && mac
                .bytes()
                .zip(expected.bytes())
                .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                == 0;
        if !same {
            return Err(AuditKeyError::HeadSignature);
        }
        Ok(head)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hmac_matches_rfc_4231_case_2() {
        // RFC 4231, test case 2: key "Jefe", data "what do ya want for nothing?". The key
        // is short, so it is padded with zeros to the block, as HMAC does with any key.
        let mut m = HmacSha256::new_from_slice(b"Jefe").unwrap();
        m.update(b"what do ya want for nothing?");
        let hex: String = m
            .finalize()
            .into_bytes()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(
            hex,
            "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"
        );
    }

    #[test]
    fn a_head_reads_back_only_under_its_key_and_unchanged() {
        let key = AuditKey::from_bytes([7; 32]);
        let other = AuditKey::from_bytes([8; 32]);
        assert_eq!(AuditKey::from_hex(&key.to_hex()).unwrap(), key);
        let head = AuditHead {
            rows: 12,
            last_id: 14,
            last_digest: "ab".repeat(32),
        };
        let text = head.signed_text(&key);
        assert_eq!(AuditHead::parse_signed(&text, &key).unwrap(), head);
        assert_eq!(
            AuditHead::parse_signed(&text, &other),
            Err(AuditKeyError::HeadSignature)
        );
        let shorter = text.replace("rows=12", "rows=11");
        assert_eq!(
            AuditHead::parse_signed(&shorter, &key),
            Err(AuditKeyError::HeadSignature)
        );
        assert!(AuditKey::from_hex("12ab").is_err());
    }
}
