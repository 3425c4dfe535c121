//! SHA-256 digests as lower-case hex: the identity of measurements, programs and recipes in
//! the manifest, the store and the API.

use std::fmt;

use sha2::Digest as _;

/// A SHA-256 digest. Its text (Display, serde, the database columns, the manifest) is 64
/// lower-case hex digits, the only text it parses from, so a digest read from a file or a
/// row is checked once, where it is read.
#[derive(
    Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(try_from = "String", into = "String")]
pub struct Sha256([u8; 32]);

/// Why a text is not a [`Sha256`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{text}` is not a SHA-256: 64 lower-case hex digits expected")]
pub struct Sha256Error {
    /// The refused text, quoted as error messages quote client values.
    text: String,
}

impl Sha256 {
    /// The digest of `bytes`.
    pub fn of(bytes: &[u8]) -> Self {
        Self::from_hasher(sha2::Sha256::new_with_prefix(bytes))
    }

    /// The digest a hasher fed piecewise has reached.
    pub fn from_hasher(hasher: sha2::Sha256) -> Self {
        Self(hasher.finalize().into())
    }

    pub fn as_bytes(&self) -> &[u8; 32] {
        &self.0
    }
}

impl fmt::Display for Sha256 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut buf = [0u8; 64];
        let hex = base16ct::lower::encode_str(&self.0, &mut buf).map_err(|_| fmt::Error)?;
        f.write_str(hex)
    }
}

/// Debug as the quoted hex text, as the digest showed when it was a `String`.
impl fmt::Debug for Sha256 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "\"{self}\"")
    }
}

impl std::str::FromStr for Sha256 {
    type Err = Sha256Error;
    fn from_str(text: &str) -> Result<Self, Sha256Error> {
        let refused = || Sha256Error {
            text: crate::names::quote(text),
        };
        let mut bytes = [0u8; 32];
        // `lower::decode` takes lower case only; the length check makes a short text an
        // error rather than a shorter digest.
        if text.len() != 64 {
            return Err(refused());
        }
        base16ct::lower::decode(text, &mut bytes).map_err(|_| refused())?;
        Ok(Self(bytes))
    }
}

impl TryFrom<String> for Sha256 {
    type Error = Sha256Error;
    fn try_from(text: String) -> Result<Self, Sha256Error> {
        text.parse()
    }
}

impl From<Sha256> for String {
    fn from(sha: Sha256) -> String {
        sha.to_string()
    }
}

impl PartialEq<str> for Sha256 {
    fn eq(&self, other: &str) -> bool {
        other.parse::<Sha256>().is_ok_and(|o| o == *self)
    }
}

impl PartialEq<String> for Sha256 {
    fn eq(&self, other: &String) -> bool {
        *self == **other
    }
}

impl PartialEq<Sha256> for String {
    fn eq(&self, other: &Sha256) -> bool {
        *other == **self
    }
}

impl PartialEq<&str> for Sha256 {
    fn eq(&self, other: &&str) -> bool {
        *self == **other
    }
}

/// SHA-256 of `bytes`, lower-case hex (64 characters), for digests kept as text (token
/// hashes, the audit chain).
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::of(bytes).to_string()
}

/// Bytes as lower-case hex, two characters each.
pub fn lower_hex(bytes: &[u8]) -> String {
    base16ct::lower::encode_string(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Known answers from FIPS 180-2 (empty string and "abc").
    #[test]
    fn sha256_hex_matches_published_vectors() {
        assert_eq!(
            sha256_hex(b""),
            "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
        );
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(lower_hex(&[0x00, 0x0f, 0xa5]), "000fa5");
    }

    /// The typed digest parses exactly its own text, says why anything else is refused, and
    /// its JSON is the bare hex string.
    #[test]
    fn sha256_parses_its_hex_text_only_and_round_trips_through_serde() {
        const ABC: &str = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";
        let abc: Sha256 = ABC.parse().unwrap();
        assert_eq!(abc, Sha256::of(b"abc"));
        assert_eq!(abc.to_string(), ABC);
        assert_eq!(abc.as_bytes()[0], 0xba);
        assert_eq!(abc, ABC);
        let json = serde_json::to_string(&abc).unwrap();
        assert_eq!(json, format!("\"{ABC}\""));
        assert_eq!(serde_json::from_str::<Sha256>(&json).unwrap(), abc);
        for bad in [
            ABC.to_uppercase(),
            ABC[..63].to_string(),
            format!("{ABC}0"),
            format!("{}g", &ABC[..63]),
            String::new(),
        ] {
            let e = bad.parse::<Sha256>().unwrap_err().to_string();
            assert!(
                e.ends_with("is not a SHA-256: 64 lower-case hex digits expected"),
                "{e}"
            );
            assert!(serde_json::from_str::<Sha256>(&format!("\"{bad}\"")).is_err());
        }
        assert_eq!(
            "xyz".parse::<Sha256>().unwrap_err().to_string(),
            "`xyz` is not a SHA-256: 64 lower-case hex digits expected"
        );
    }
}
