//! Program and axis name rules of the SINUMERIK control, checked before anything is rendered.

use thiserror::Error;

/// Longest program name the control accepts, characters.
pub(crate) const MAX_PROGRAM_NAME_CHARS: usize = 24;

/// Prefixes Siemens reserves for its own programs, upper case, in the order they are checked.
pub(crate) const RESERVED_PREFIXES: [&str; 7] = ["CYCLE", "CUST_", "GROUP_", "_", "S_", "E_", "F_"];

/// Longest axis name the control accepts, characters.
pub(crate) const MAX_AXIS_NAME_CHARS: usize = 8;

/// Device names Windows reserves; the control refuses them as program names, whatever the
/// case. `COM1`–`COM9` and `LPT1`–`LPT9` are checked by [`is_reserved_device_name`].
pub(crate) const RESERVED_DEVICE_NAMES: [&str; 4] = ["CON", "PRN", "AUX", "NUL"];

/// Single-letter addresses with a fixed meaning in a block (feed, G code, spindle, tool, …).
/// An axis with one of these names would be read as that address, so they are refused.
/// This is our inference from the block syntax, not a rule quoted from a manual.
const FIXED_ADDRESS_LETTERS: [char; 15] = [
    'D', 'F', 'G', 'H', 'I', 'J', 'K', 'L', 'M', 'N', 'O', 'P', 'R', 'S', 'T',
];

/// Why a program name is refused. Each variant names the one rule that failed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ProgramNameError {
    #[error("program name is empty")]
    Empty,
    #[error(
        "program name `{name}` has `{ch}` at position {position}: only letters A-Z, digits and `_` are allowed"
    )]
    BadCharacter {
        name: String,
        ch: char,
        /// 1-based character position.
        position: usize,
    },
    #[error(
        "program name `{name}` has {chars} characters: at most {MAX_PROGRAM_NAME_CHARS} are allowed"
    )]
    TooLong { name: String, chars: usize },
    #[error(
        "program name `{name}` starts with `_`: the prefix `_` is reserved by Siemens, although `_` + letter would otherwise be a valid start"
    )]
    LeadingUnderscore { name: String },
    #[error("program name `{name}` starts with `{prefix}`, a prefix reserved by Siemens")]
    ReservedPrefix { name: String, prefix: &'static str },
    #[error("program name `{name}` must start with two letters")]
    FirstTwoNotLetters { name: String },
    #[error(
        "program name `{name}` is a reserved device name (CON, PRN, AUX, NUL, COM1-COM9, LPT1-LPT9)"
    )]
    ReservedDeviceName { name: String },
}

/// Check a program name against the control's rules and return it in upper case.
///
/// Rules, checked in this order (the first failure is reported):
/// 1. not empty;
/// 2. only ASCII letters, digits and `_`;
/// 3. at most 24 characters;
/// 4. no prefix reserved by Siemens (`CYCLE`, `CUST_`, `GROUP_`, `_`, `S_`, `E_`, `F_`),
///    compared case-insensitively;
/// 5. the first two characters are letters;
/// 6. not a reserved device name (`CON`, `PRN`, `AUX`, `NUL`, `COM1`–`COM9`, `LPT1`–`LPT9`),
///    compared case-insensitively [M].
///
/// The manual allows a name to start with `_` + letter but also reserves the prefix `_`.
/// We resolve the conflict by refusing a leading `_` ([`ProgramNameError::LeadingUnderscore`]):
/// a user program must never collide with a Siemens one. Rule 4 is checked before rule 5 so
/// that `S_TABLE` is reported as a reserved prefix rather than as a bad second character.
///
/// A second conflict in the notes: `U_` is suggested for user cycles, yet rule 5 as quoted
/// refuses `U_` + anything. That S_, E_ and F_ are listed as reserved suggests the control
/// accepts letter + `_` [?]. We keep the stricter reading: a refused name costs the user a
/// rename, an accepted name the control refuses costs a failed transfer at the machine.
///
/// Names are case-insensitive on the control; the canonical upper-case form is returned and
/// used in the program text.
pub fn validate_program_name(name: &str) -> Result<String, ProgramNameError> {
    if name.is_empty() {
        return Err(ProgramNameError::Empty);
    }
    if let Some((i, ch)) = name
        .chars()
        .enumerate()
        .find(|(_, ch)| !(ch.is_ascii_alphanumeric() || *ch == '_'))
    {
        return Err(ProgramNameError::BadCharacter {
            name: name.to_owned(),
            ch,
            position: i + 1,
        });
    }
    // Only ASCII remains, so bytes == characters from here on.
    if name.len() > MAX_PROGRAM_NAME_CHARS {
        return Err(ProgramNameError::TooLong {
            name: name.to_owned(),
            chars: name.len(),
        });
    }
    let upper = name.to_ascii_uppercase();
    if upper.starts_with('_') {
        return Err(ProgramNameError::LeadingUnderscore {
            name: name.to_owned(),
        });
    }
    if let Some(prefix) = RESERVED_PREFIXES.iter().find(|p| upper.starts_with(**p)) {
        return Err(ProgramNameError::ReservedPrefix {
            name: name.to_owned(),
            prefix,
        });
    }
    let first_two_letters =
        upper.len() >= 2 && upper.bytes().take(2).all(|b| b.is_ascii_alphabetic());
    if !first_two_letters {
        return Err(ProgramNameError::FirstTwoNotLetters {
            name: name.to_owned(),
        });
    }
    if is_reserved_device_name(&upper) {
        return Err(ProgramNameError::ReservedDeviceName {
            name: name.to_owned(),
        });
    }
    Ok(upper)
}

/// `CON`, `PRN`, `AUX`, `NUL`, `COM1`–`COM9` or `LPT1`–`LPT9`; `upper` in upper case.
fn is_reserved_device_name(upper: &str) -> bool {
    if RESERVED_DEVICE_NAMES.contains(&upper) {
        return true;
    }
    match (upper.get(..3), upper.get(3..)) {
        (Some("COM" | "LPT"), Some(digit)) => {
            digit.len() == 1 && digit.bytes().all(|b| (b'1'..=b'9').contains(&b))
        }
        _ => false,
    }
}

/// Why an axis name is refused. `role` is "following" or "leading".
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AxisNameError {
    #[error("{role} axis name is empty")]
    Empty { role: &'static str },
    #[error("{role} axis name `{name}` must start with a letter")]
    BadStart { role: &'static str, name: String },
    #[error(
        "{role} axis name `{name}` has `{ch}` at position {position}: only letters A-Z and digits are allowed"
    )]
    BadCharacter {
        role: &'static str,
        name: String,
        ch: char,
        /// 1-based character position.
        position: usize,
    },
    #[error(
        "{role} axis name `{name}` is a fixed address letter (feed, G code, spindle, …) and cannot name an axis"
    )]
    FixedAddress { role: &'static str, name: String },
    #[error(
        "{role} axis name `{name}` has {chars} characters: at most {MAX_AXIS_NAME_CHARS} are allowed"
    )]
    TooLong {
        role: &'static str,
        name: String,
        chars: usize,
    },
}

/// Check an axis name (ASCII letters and digits, starting with a letter, not one of the
/// fixed single-letter addresses D F G H I J K L M N O P R S T, at most
/// [`MAX_AXIS_NAME_CHARS`] characters [M]) and return it in upper case.
pub fn validate_axis_name(role: &'static str, name: &str) -> Result<String, AxisNameError> {
    let Some(first) = name.chars().next() else {
        return Err(AxisNameError::Empty { role });
    };
    if !first.is_ascii_alphabetic() {
        return Err(AxisNameError::BadStart {
            role,
            name: name.to_owned(),
        });
    }
    if let Some((i, ch)) = name
        .chars()
        .enumerate()
        .find(|(_, ch)| !ch.is_ascii_alphanumeric())
    {
        return Err(AxisNameError::BadCharacter {
            role,
            name: name.to_owned(),
            ch,
            position: i + 1,
        });
    }
    // Only ASCII remains, so bytes == characters from here on.
    if name.len() > MAX_AXIS_NAME_CHARS {
        return Err(AxisNameError::TooLong {
            role,
            name: name.to_owned(),
            chars: name.len(),
        });
    }
    let upper = name.to_ascii_uppercase();
    let mut chars = upper.chars();
    if let (Some(only), None) = (chars.next(), chars.next())
        && FIXED_ADDRESS_LETTERS.contains(&only)
    {
        return Err(AxisNameError::FixedAddress {
            role,
            name: name.to_owned(),
        });
    }
    Ok(upper)
}
