//! Two small words the store, the loop and the adapters share: whether a part passed
//! ([`Verdict`]) and how serious an event is ([`EventLevel`]). They live in the core (not the
//! store) so the loop crate's plant events can carry them without depending on the store.
//! Each is spelt one way everywhere: its name in lower case, in the database, in serde and
//! in `as_str`.

use std::fmt;
use std::str::FromStr;

/// A text that names no variant of `field`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: unknown value `{text}`")]
pub struct UnknownValue {
    pub field: &'static str,
    pub text: String,
}

macro_rules! level_enum {
    ($(#[$m:meta])* $name:ident, $field:literal { $($variant:ident = $text:literal),+ $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
        #[serde(rename_all = "lowercase")]
        pub enum $name { $($variant),+ }

        impl $name {
            /// The field's name in errors.
            pub const FIELD: &'static str = $field;

            /// The text stored in the database and used in APIs.
            pub fn as_str(self) -> &'static str {
                match self { $($name::$variant => $text),+ }
            }

            /// Parses the stored text.
            pub fn parse(text: &str) -> Result<Self, UnknownValue> {
                match text {
                    $($text => Ok($name::$variant),)+
                    _ => Err(UnknownValue { field: $field, text: text.to_string() }),
                }
            }
        }

        impl FromStr for $name {
            type Err = UnknownValue;

            fn from_str(text: &str) -> Result<Self, UnknownValue> {
                Self::parse(text)
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}

level_enum!(
    /// Whether a measured lobe or pin was within tolerance.
    Verdict, "verdict" { Pass = "pass", Fail = "fail" }
);

level_enum!(
    /// Severity of an event; `Error` means an operator must act.
    EventLevel, "event level" { Info = "info", Warn = "warn", Error = "error" }
);

#[cfg(test)]
mod tests {
    use super::*;

    /// serde, `as_str` and `parse` spell each variant alike, and an unknown text names its
    /// field.
    #[test]
    fn one_spelling_everywhere() {
        for v in [Verdict::Pass, Verdict::Fail] {
            let json = serde_json::to_string(&v).unwrap();
            assert_eq!(json, format!("\"{}\"", v.as_str()));
            assert_eq!(Verdict::parse(v.as_str()), Ok(v));
        }
        for l in [EventLevel::Info, EventLevel::Warn, EventLevel::Error] {
            let json = serde_json::to_string(&l).unwrap();
            assert_eq!(json, format!("\"{}\"", l.as_str()));
            assert_eq!(l.as_str().parse::<EventLevel>(), Ok(l));
        }
        assert_eq!(
            Verdict::parse("Pass").unwrap_err().to_string(),
            "verdict: unknown value `Pass`"
        );
    }
}
