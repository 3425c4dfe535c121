//! Machine names: one rule for the config, the HTTP API and the store. A name becomes a
//! folder name (`var/machines/<name>/`), a URL path segment and a database key, so it is
//! kept plain: 1–32 ASCII letters, digits, `-` or `_`.

use std::fmt;

/// Longest machine name, in characters.
pub(crate) const MAX_NAME_LEN: usize = 32;

/// Defines a name type checked by [`check_plain_name`]: constructors, serde through the
/// rule (`try_from = "String"`, so the text on the wire, in files and in the database stays
/// the bare string), and the text views. Written once for every kind of name.
macro_rules! plain_name {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(
            Clone, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
        )]
        #[serde(try_from = "String", into = "String")]
        pub struct $name(String);

        impl $name {
            /// Checks `name` against the rule.
            pub fn new(name: &str) -> Result<Self, NameError> {
                check_plain_name(name)?;
                Ok(Self(name.to_string()))
            }

            pub fn as_str(&self) -> &str {
                &self.0
            }
        }

        /// Debug as the text (`"SIM1"`), as messages showed names before they were typed.
        impl fmt::Debug for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                fmt::Debug::fmt(&self.0, f)
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.0)
            }
        }

        /// A name reads as the text it is wherever text is asked for (`&name` where a `&str`
        /// is expected), so typed records pass through the text-keyed layers without
        /// conversions.
        impl std::ops::Deref for $name {
            type Target = str;

            fn deref(&self) -> &str {
                &self.0
            }
        }

        impl PartialEq<str> for $name {
            fn eq(&self, other: &str) -> bool {
                self.0 == other
            }
        }

        impl PartialEq<&str> for $name {
            fn eq(&self, other: &&str) -> bool {
                self.0 == *other
            }
        }

        impl PartialEq<String> for $name {
            fn eq(&self, other: &String) -> bool {
                self.0 == *other
            }
        }

        impl PartialEq<$name> for String {
            fn eq(&self, other: &$name) -> bool {
                *self == other.0
            }
        }

        impl PartialEq<$name> for str {
            fn eq(&self, other: &$name) -> bool {
                self == other.0
            }
        }

        impl PartialEq<$name> for &str {
            fn eq(&self, other: &$name) -> bool {
                *self == other.0
            }
        }

        impl AsRef<str> for $name {
            fn as_ref(&self) -> &str {
                &self.0
            }
        }

        /// A name is also a folder name (`var/machines/<name>/`, a feature's state folder).
        impl AsRef<std::path::Path> for $name {
            fn as_ref(&self) -> &std::path::Path {
                self.0.as_ref()
            }
        }

        impl std::borrow::Borrow<str> for $name {
            fn borrow(&self) -> &str {
                &self.0
            }
        }

        impl From<$name> for String {
            fn from(name: $name) -> String {
                name.0
            }
        }

        impl TryFrom<String> for $name {
            type Error = NameError;
            fn try_from(name: String) -> Result<Self, NameError> {
                check_plain_name(&name)?;
                Ok(Self(name))
            }
        }

        impl TryFrom<&str> for $name {
            type Error = NameError;
            fn try_from(name: &str) -> Result<Self, NameError> {
                Self::new(name)
            }
        }

        impl std::str::FromStr for $name {
            type Err = NameError;
            fn from_str(s: &str) -> Result<Self, NameError> {
                Self::new(s)
            }
        }
    };
}

plain_name!(
    /// A machine name that passed [`MachineName::new`]; the only way to make one.
    /// Deserialising checks the rule too, so a name read from a file or a request is valid
    /// once it is a `MachineName`.
    MachineName
);

plain_name!(
    /// A lobe's or pin's name (a recipe's feature): the recipe checks it by the same rule at
    /// load, and it keys the store, the journal, MQTT topics and URL paths like a machine.
    FeatureName
);

plain_name!(
    /// A part's name in a recipe (its drawing number, `CAM-4711`), by the same rule: one
    /// recipe's kind of shaft, not one shaft. A shaft's serial is a [`crate::ids::PartId`].
    PartName
);

/// Why a name was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    #[error("name is empty")]
    Empty,
    #[error("name `{name}` has {len} characters, at most {MAX_NAME_LEN} are allowed")]
    TooLong { name: String, len: usize },
    #[error(
        "name `{name}` has `{ch}` at character {position}: only letters, digits, '-' or '_' are allowed"
    )]
    BadCharacter {
        name: String,
        ch: char,
        /// 1-based.
        position: usize,
    },
}

/// The rule itself, for names that are not machines but live in the same places (lobes and
/// pins in URLs and folders; recipes apply the same rule).
pub fn check_plain_name(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return Err(NameError::Empty);
    }
    if let Some((i, ch)) = name
        .chars()
        .enumerate()
        .find(|(_, c)| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        return Err(NameError::BadCharacter {
            name: quote(name),
            ch,
            position: i + 1,
        });
    }
    if name.len() > MAX_NAME_LEN {
        return Err(NameError::TooLong {
            name: quote(name),
            len: name.len(),
        });
    }
    Ok(())
}

/// A part's identifier (serial number) as the gauges send it: 1–32 characters of
/// `A–Z a–z 0–9 . _ -` (the gauge codecs' rule), so a path such as `../..`, a NUL or a
/// 10 kB value is refused before it reaches the store.
pub fn valid_part_ident(part: &str) -> bool {
    (1..=MAX_NAME_LEN).contains(&part.len())
        && part
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// Most characters of a value sent by a client that an error message quotes back.
pub(crate) const MAX_QUOTED_CHARS: usize = 64;

/// `value` as an error message may quote it: at most [`MAX_QUOTED_CHARS`] characters (then
/// `…`), control characters escaped, so a 10 kB or binary value never comes back whole.
pub fn quote(value: &str) -> String {
    quote_up_to(value, MAX_QUOTED_CHARS)
}

/// [`quote`] with another length.
pub fn quote_up_to(value: &str, max_chars: usize) -> String {
    let mut out = String::new();
    for (i, c) in value.chars().enumerate() {
        if i == max_chars {
            out.push('…');
            break;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rule_accepts_plain_names_and_says_what_is_wrong_with_others() {
        for ok in ["SIM1", "line-3_grinder", "a", &"x".repeat(32)] {
            assert_eq!(MachineName::new(ok).unwrap().as_str(), ok);
        }
        assert_eq!(MachineName::new(""), Err(NameError::Empty));
        assert_eq!(
            MachineName::new(&"x".repeat(33)),
            Err(NameError::TooLong {
                name: "x".repeat(33),
                len: 33
            })
        );
        // A 10 kB name is quoted back by its first 64 characters only; NUL comes escaped.
        let long = MachineName::new(&"y".repeat(10_000))
            .unwrap_err()
            .to_string();
        assert!(long.contains(&format!("`{}…`", "y".repeat(64))), "{long}");
        assert!(long.len() < 200, "{} bytes", long.len());
        let nul = MachineName::new("a\0b").unwrap_err().to_string();
        assert!(nul.starts_with("name `a\\u{0}b` has"), "{nul}");
        assert_eq!(
            MachineName::new("bad name").unwrap_err().to_string(),
            "name `bad name` has ` ` at character 4: only letters, digits, '-' or '_' are allowed"
        );
        assert!(matches!(
            MachineName::new("Grinder/1"),
            Err(NameError::BadCharacter {
                ch: '/',
                position: 8,
                ..
            })
        ));
    }

    /// serde goes through the same rule: a bad name in JSON is refused with the rule's
    /// message, a good one round-trips unchanged.
    #[test]
    fn deserialising_checks_the_rule() {
        let ok: MachineName = serde_json::from_str("\"SIM1\"").unwrap();
        assert_eq!(ok.as_str(), "SIM1");
        assert_eq!(serde_json::to_string(&ok).unwrap(), "\"SIM1\"");
        let bad = serde_json::from_str::<MachineName>("\"../etc\"").unwrap_err();
        assert!(bad.to_string().contains("only letters, digits"), "{bad}");
    }

    /// A feature name follows the machines' rule, with the same messages, and its JSON text
    /// is the bare string.
    #[test]
    fn feature_names_follow_the_same_rule_and_round_trip_as_text() {
        assert_eq!(FeatureName::new("lobe_1-a").unwrap(), "lobe_1-a");
        assert_eq!(FeatureName::new(""), Err(NameError::Empty));
        assert_eq!(
            FeatureName::new("in 1").unwrap_err().to_string(),
            "name `in 1` has ` ` at character 3: only letters, digits, '-' or '_' are allowed"
        );
        assert!(matches!(
            "x".repeat(33).parse::<FeatureName>(),
            Err(NameError::TooLong { len: 33, .. })
        ));
        let ok: FeatureName = serde_json::from_str("\"IN1\"").unwrap();
        assert_eq!(serde_json::to_string(&ok).unwrap(), "\"IN1\"");
        let bad = serde_json::from_str::<FeatureName>("\"a/b\"").unwrap_err();
        assert!(bad.to_string().contains("`/` at character 2"), "{bad}");
    }
}
