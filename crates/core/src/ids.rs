//! The loop's ids: a part's id as the gauge gave it, and a table version. They live in the
//! core (not the loop crate) because the core's measurement and the store's records carry
//! them too, and the store may not depend on the loop; the loop crate re-exports them.

use crate::names::valid_part_ident;
use std::fmt;
use std::num::NonZeroU64;

/// A table version of one feature: 1, 2, … in the order the share took them. Never 0: "no
/// version" is `Option<TableVersion>`, not a number that means nothing.
///
/// On every wire and in every column it is the plain integer (serde through `u64`), so the
/// files and the database read as they did when versions were bare integers.
#[derive(
    Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(try_from = "u64", into = "u64")]
pub struct TableVersion(NonZeroU64);

/// Why a number is not a table version.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("table version {0} out of range (versions count from 1)")]
pub struct VersionOutOfRange(pub i128);

impl TableVersion {
    /// The first version a feature's share takes.
    pub const FIRST: Self = Self(NonZeroU64::MIN);

    /// `n` as a version; `None` for 0.
    pub fn new(n: u64) -> Option<Self> {
        NonZeroU64::new(n).map(Self)
    }

    /// A version read from a signed column or an API path: refused when it is 0, negative,
    /// or beyond what a signed column can hold.
    pub fn from_i64(n: i64) -> Result<Self, VersionOutOfRange> {
        u64::try_from(n)
            .ok()
            .and_then(Self::new)
            .ok_or(VersionOutOfRange(i128::from(n)))
    }

    pub fn get(self) -> u64 {
        self.0.get()
    }

    /// The version as a signed column holds it. A feature would need 2^63 parts to pass
    /// that range, so the conversion saturates rather than fail.
    pub fn to_i64(self) -> i64 {
        i64::try_from(self.0.get()).unwrap_or(i64::MAX)
    }

    /// The version after this one.
    pub fn next(self) -> Self {
        Self(self.0.saturating_add(1))
    }
}

impl TryFrom<u64> for TableVersion {
    type Error = VersionOutOfRange;

    fn try_from(n: u64) -> Result<Self, Self::Error> {
        Self::new(n).ok_or(VersionOutOfRange(i128::from(n)))
    }
}

impl From<TableVersion> for u64 {
    fn from(v: TableVersion) -> u64 {
        v.get()
    }
}

impl fmt::Debug for TableVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "v{}", self.0)
    }
}

/// The bare number, as messages and file names have always written it (`v{}` is the
/// caller's).
impl fmt::Display for TableVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

/// `Option<TableVersion>` as records written before the type kept it: `null` or 0 read as
/// none, any other number as that version. `with = "ids::lenient_version"` writes `null` for
/// none (the form of optional fields); [`zero_for_none`] writes 0 (the form of fields that
/// always held a number).
pub mod lenient_version {
    use super::TableVersion;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(v: &Option<TableVersion>, s: S) -> Result<S::Ok, S::Error> {
        v.map(TableVersion::get).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<TableVersion>, D::Error> {
        Ok(Option::<u64>::deserialize(d)?.and_then(TableVersion::new))
    }

    /// The same, written as 0 for none.
    pub mod zero_for_none {
        use super::TableVersion;
        use serde::{Deserializer, Serializer};

        pub fn serialize<S: Serializer>(v: &Option<TableVersion>, s: S) -> Result<S::Ok, S::Error> {
            s.serialize_u64(v.map_or(0, TableVersion::get))
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(
            d: D,
        ) -> Result<Option<TableVersion>, D::Error> {
            super::deserialize(d)
        }
    }
}

/// A part's id (serial number) as the gauge sent it, checked by the gauges' rule
/// ([`valid_part_ident`]): 1–32 characters of `A–Z a–z 0–9 . _ -`.
#[derive(Clone, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct PartId(String);

/// Why a text is not a part id.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("part id {} is not 1–32 characters of A–Z a–z 0–9 . _ -", crate::names::quote(.0))]
pub struct BadPartId(pub String);

impl PartId {
    pub fn new(part: &str) -> Result<Self, BadPartId> {
        if valid_part_ident(part) {
            Ok(Self(part.to_string()))
        } else {
            Err(BadPartId(part.to_string()))
        }
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// A master part's run (a gauge study), never a production part.
    pub fn is_master(&self) -> bool {
        crate::measure::is_master_part(&self.0)
    }
}

impl TryFrom<String> for PartId {
    type Error = BadPartId;

    fn try_from(part: String) -> Result<Self, Self::Error> {
        if valid_part_ident(&part) {
            Ok(Self(part))
        } else {
            Err(BadPartId(part))
        }
    }
}

impl From<PartId> for String {
    fn from(p: PartId) -> String {
        p.0
    }
}

impl fmt::Debug for PartId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl fmt::Display for PartId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::ops::Deref for PartId {
    type Target = str;

    fn deref(&self) -> &str {
        &self.0
    }
}

impl PartialEq<str> for PartId {
    fn eq(&self, other: &str) -> bool {
        self.0 == other
    }
}

impl PartialEq<&str> for PartId {
    fn eq(&self, other: &&str) -> bool {
        self.0 == *other
    }
}

impl PartialEq<String> for PartId {
    fn eq(&self, other: &String) -> bool {
        self.0 == *other
    }
}

impl AsRef<str> for PartId {
    fn as_ref(&self) -> &str {
        &self.0
    }
}

impl std::borrow::Borrow<str> for PartId {
    fn borrow(&self) -> &str {
        &self.0
    }
}

impl std::str::FromStr for PartId {
    type Err = BadPartId;

    fn from_str(s: &str) -> Result<Self, BadPartId> {
        Self::new(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_version_is_never_zero_nor_negative() {
        assert_eq!(TableVersion::new(0), None);
        assert_eq!(TableVersion::from_i64(0), Err(VersionOutOfRange(0)));
        assert_eq!(TableVersion::from_i64(-3), Err(VersionOutOfRange(-3)));
        assert_eq!(TableVersion::from_i64(7).map(TableVersion::get), Ok(7));
        assert_eq!(TableVersion::FIRST.next().get(), 2);
        assert_eq!(
            TableVersion::new(u64::MAX).map(TableVersion::to_i64),
            Some(i64::MAX)
        );
    }

    #[test]
    fn ids_read_and_write_as_their_bare_values() {
        let v: TableVersion = serde_json::from_str("12").unwrap();
        assert_eq!(serde_json::to_string(&v).unwrap(), "12");
        assert!(serde_json::from_str::<TableVersion>("0").is_err());
        let p: PartId = serde_json::from_str("\"S-17.a\"").unwrap();
        assert_eq!(serde_json::to_string(&p).unwrap(), "\"S-17.a\"");
        assert!(serde_json::from_str::<PartId>("\"../..\"").is_err());
        assert!(PartId::new("MASTER-1").unwrap().is_master());
    }
}
