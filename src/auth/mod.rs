//! Who someone is: user names, password rules and hashes (argon2id), API tokens and their
//! digests, the lockout after repeated failures (`lockout`), where hashes run (`hasher`),
//! the one-time values of the sign-in form (`nonce`), and how many refusals the audit trail
//! takes (`refusals`). The HTTP side (`service::http::access`), the OPC UA users and the commands
//! (`camloop user`, `camloop token`) all use these; the store keeps only hashes.
//!
//! Passwords are hashed with argon2id (the `argon2` crate's defaults: 19 MiB, 2 passes, a
//! random 16-byte salt per hash): slow on purpose, since a person's password may be guessable.
//! API tokens are 32 random bytes from the operating system, so a fast SHA-256 is enough to
//! store them: nobody can search a 2^256 space, however fast the hash, and a fast digest
//! lets the service find a token by its digest (an index) on every request.

use crate::names::check_plain_name;
use crate::store::Role;
use argon2::password_hash::phc::PasswordHash;
use argon2::password_hash::{PasswordHasher, PasswordVerifier};
use std::fmt;

mod hasher;
mod lockout;
mod nonce;
mod refusals;

pub use hasher::{Busy, Hasher};
pub use lockout::{Attempt, Client, Counted, LOCKOUT_FAILURES, LOCKOUT_WINDOW, Lockout, Refused};
pub use nonce::{MAX_NONCES, NONCE_LIFETIME, NonceRefused, Nonces};
pub use refusals::{Admit, PER_CLIENT_PER_MINUTE, RefusalBudget, TOTAL_PER_MINUTE};

/// Shortest password accepted, characters.
pub(crate) const MIN_PASSWORD_CHARS: usize = 12;
/// API tokens start with this, so a leaked one is recognisable (secret scanners, logs).
pub(crate) const TOKEN_PREFIX: &str = "clt_";

/// A user name: the machine-name rule (1–32 letters, digits, `-`, `_`), since it appears in
/// URLs, logs and the audit trail.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(transparent)]
pub(crate) struct UserName(String);

impl UserName {
    pub fn new(name: &str) -> Result<Self, crate::names::NameError> {
        check_plain_name(name)?;
        Ok(Self(name.to_string()))
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for UserName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Why a password or a token could not be made or checked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AuthError {
    #[error("the password has {chars} characters; at least {MIN_PASSWORD_CHARS} are needed")]
    PasswordTooShort { chars: usize },
    #[error("the password is only white space")]
    PasswordBlank,
    #[error("the password is, or contains, the user name `{user}`")]
    PasswordHasUserName { user: String },
    #[error(
        "the password is too easy to guess (strength {score} of 4, at least {MIN_PASSWORD_SCORE} needed){hint}"
    )]
    PasswordWeak { score: u8, hint: String },
    #[error("the operating system's random source failed: {0}")]
    Random(String),
    #[error("password hashing failed: {0}")]
    Hash(String),
}

/// Checks the password rule: at least [`MIN_PASSWORD_CHARS`] characters.
pub(crate) fn check_password(password: &str) -> Result<(), AuthError> {
    let chars = password.chars().count();
    if chars < MIN_PASSWORD_CHARS {
        return Err(AuthError::PasswordTooShort { chars });
    }
    Ok(())
}

/// The least strength (zxcvbn's score, 0–4) a person's new password needs: 3 is "safely
/// unguessable", about 10^10 guesses, years against argon2id at 19 MiB a check.
pub(crate) const MIN_PASSWORD_SCORE: u8 = 3;

/// The password policy for a password a person chooses for `user`: the length rule, not
/// blank, not containing the user name (in any case), and a strength estimate (zxcvbn: its
/// dictionaries of common passwords, names and words are the deny-list, with repeats,
/// sequences, keyboard patterns and dates) of at least [`MIN_PASSWORD_SCORE`].
pub(crate) fn check_new_password(password: &str, user: &UserName) -> Result<(), AuthError> {
    check_password(password)?;
    if password.trim().is_empty() {
        return Err(AuthError::PasswordBlank);
    }
    if password
        .to_lowercase()
        .contains(&user.as_str().to_lowercase())
    {
        return Err(AuthError::PasswordHasUserName {
            user: user.to_string(),
        });
    }
    let estimate = zxcvbn::zxcvbn(password, &[user.as_str(), "camloop"]);
    let score = u8::from(estimate.score());
    if score < MIN_PASSWORD_SCORE {
        let hint = estimate.feedback().map_or(String::new(), |f| {
            let mut parts: Vec<String> = f.warning().map(|w| w.to_string()).into_iter().collect();
            parts.extend(f.suggestions().iter().map(|s| s.to_string()));
            match parts.is_empty() {
                true => String::new(),
                false => {
                    let said: Vec<String> = parts
                        .iter()
                        .map(|p| p.trim_end_matches('.').to_lowercase())
                        .collect();
                    format!(": {}", said.join("; "))
                }
            }
        });
        return Err(AuthError::PasswordWeak { score, hint });
    }
    Ok(())
}

/// The argon2id hash of `password` (a PHC string with its salt and parameters), after
/// checking the length rule (a person's new password goes through [`check_new_password`]
/// first).
pub fn hash_password(password: &str) -> Result<String, AuthError> {
    check_password(password)?;
    argon2::Argon2::default()
        .hash_password(password.as_bytes())
        .map(|h| h.to_string())
        .map_err(|e| AuthError::Hash(e.to_string()))
}

/// Whether `password` matches the stored hash. A hash that does not parse matches nothing.
pub fn verify_password(password: &str, hash: &str) -> bool {
    let Ok(parsed) = PasswordHash::new(hash) else {
        return false;
    };
    argon2::Argon2::default()
        .verify_password(password.as_bytes(), &parsed)
        .is_ok()
}

/// The most argon2 memory a stored hash may ask a check for: 64 MiB (camloop's own take
/// 19 MiB). A hash asking for more matches nothing, so a row written into the database by
/// hand cannot make each sign-in allocate gigabytes.
const MAX_CHECK_BLOCKS: usize = 64 * 1024;

/// [`verify_password`] with the hash's memory in `blocks` (grown to the hash's cost once,
/// then reused) instead of allocated and freed for every check: the hasher's threads each
/// keep one, so argon2's memory is a fixed 19 MiB per core that a burst of sign-ins never
/// adds to. The result is compared in constant time.
pub(crate) fn verify_password_in(
    password: &str,
    hash: &str,
    blocks: &mut Vec<argon2::Block>,
) -> bool {
    let Ok(parsed) = PasswordHash::new(hash) else {
        return false;
    };
    let Ok(algorithm) = argon2::Algorithm::try_from(parsed.algorithm.as_str()) else {
        return false;
    };
    let Ok(params) = argon2::Params::try_from(&parsed) else {
        return false;
    };
    let version = match parsed.version.map(argon2::Version::try_from) {
        None => argon2::Version::default(),
        Some(Ok(v)) => v,
        Some(Err(_)) => return false,
    };
    let (Some(salt), Some(expected)) = (&parsed.salt, &parsed.hash) else {
        return false;
    };
    let count = params.block_count();
    if count > MAX_CHECK_BLOCKS {
        return false;
    }
    if blocks.len() < count {
        blocks.resize(count, argon2::Block::default());
    }
    let mut out = vec![0u8; expected.len()];
    let argon = argon2::Argon2::new(algorithm, version, params);
    if argon
        .hash_password_into_with_memory(password.as_bytes(), salt, &mut out, &mut blocks[..count])
        .is_err()
    {
        return false;
    }
    out.len() == expected.len()
        && out
            .iter()
            .zip(expected.as_bytes())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
}

/// `n` random bytes from the operating system, as lowercase hex.
pub(crate) fn random_hex(n: usize) -> Result<String, AuthError> {
    let mut bytes = vec![0u8; n];
    getrandom::fill(&mut bytes).map_err(|e| AuthError::Random(e.to_string()))?;
    Ok(crate::digest::lower_hex(&bytes))
}

/// A new API token: the prefix and 32 random bytes (hex). Shown once; only its
/// [`token_digest`] is kept.
pub fn new_token() -> Result<String, AuthError> {
    Ok(format!("{TOKEN_PREFIX}{}", random_hex(32)?))
}

/// What the store keeps of a token or a session key: its SHA-256.
pub fn token_digest(token: &str) -> crate::digest::Sha256 {
    crate::digest::Sha256::of(token.as_bytes())
}

/// A random password for the first `admin`: 24 characters from a 64-letter alphabet
/// (144 bits).
pub(crate) fn random_password() -> Result<String, AuthError> {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHJKLMNPQRSTUVWXYZabcdefghijkmnopqrstuvwxyz23456789-_.+=%@";
    let mut bytes = [0u8; 24];
    getrandom::fill(&mut bytes).map_err(|e| AuthError::Random(e.to_string()))?;
    Ok(bytes
        .iter()
        .map(|b| char::from(ALPHABET[usize::from(b % 64)]))
        .collect())
}

/// The role someone acts with: the lower of the user's role and the token's ceiling.
pub(crate) fn effective_role(user: Role, ceiling: Role) -> Role {
    user.min(ceiling)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passwords_need_twelve_characters_and_verify_only_themselves() {
        assert_eq!(
            hash_password("eleven-char"),
            Err(AuthError::PasswordTooShort { chars: 11 })
        );
        let hash = hash_password("twelve-chars").unwrap();
        assert!(hash.starts_with("$argon2id$"), "{hash}");
        assert!(verify_password("twelve-chars", &hash));
        assert!(!verify_password("twelve-charS", &hash));
        assert!(!verify_password("twelve-chars", "not a hash"));
        // A fresh salt each time: the same password never gives the same text.
        assert_ne!(hash, hash_password("twelve-chars").unwrap());
    }

    #[test]
    fn easy_passwords_are_refused_with_the_reason() {
        let ann = UserName::new("ann-marie").unwrap();
        let refused = |p: &str| check_new_password(p, &ann).unwrap_err();
        assert_eq!(refused("            "), AuthError::PasswordBlank);
        assert_eq!(
            refused("Ann-Marie-1234"),
            AuthError::PasswordHasUserName {
                user: "ann-marie".into()
            }
        );
        for easy in [
            "passwordpassword",
            "123456789012",
            "qwertyuiopasdf",
            "aaaaaaaaaaaa",
        ] {
            let e = refused(easy);
            assert!(
                matches!(e, AuthError::PasswordWeak { score, .. } if score < 3),
                "{easy}: {e:?}"
            );
            assert!(
                e.to_string()
                    .starts_with("the password is too easy to guess"),
                "{e}"
            );
        }
        let e = refused("passwordpassword").to_string();
        assert!(e.contains("strength") && !e.ends_with('.'), "{e}");
        // The user name as the whole password, in another case.
        let eng = UserName::new("engineer-one").unwrap();
        assert!(matches!(
            check_new_password("ENGINEER-ONE", &eng),
            Err(AuthError::PasswordHasUserName { .. })
        ));
        // Long, unrelated words pass; so does the first admin's random password.
        for good in [
            "a-password-of-the-right-length",
            "another-long-secret",
            "a-long-enough-secret",
        ] {
            assert_eq!(check_new_password(good, &ann), Ok(()), "{good}");
        }
        assert_eq!(
            check_new_password(&random_password().unwrap(), &ann),
            Ok(())
        );
    }

    #[test]
    fn a_check_in_reused_memory_agrees_with_the_crate_s_own() {
        let hash = hash_password("twelve-chars").unwrap();
        let mut blocks = Vec::new();
        for (password, hash) in [
            ("twelve-chars", hash.as_str()),
            ("twelve-charS", hash.as_str()),
            ("twelve-chars", "not a hash"),
            (
                "anything-at-all",
                "$argon2id$v=19$m=19456,t=2,p=1$c29tZXNhbHRzb21lc2FsdA$QUwJiZ3Eg4pcXfI7u8T/HWl3eo6L6VeKvzZp4RkZ+6Q",
            ),
        ] {
            assert_eq!(
                verify_password_in(password, hash, &mut blocks),
                verify_password(password, hash),
                "{password} {hash}"
            );
        }
        assert!(verify_password_in("twelve-chars", &hash, &mut blocks));
        // 19 MiB of 1 KiB blocks, kept for the next check.
        assert_eq!(blocks.len(), 19 * 1024);
        let capacity = blocks.capacity();
        assert!(!verify_password_in("wrong-password", &hash, &mut blocks));
        assert_eq!(blocks.capacity(), capacity, "the same memory, not more");
        // A hash asking for 1 GiB matches nothing and takes nothing.
        let greedy = "$argon2id$v=19$m=1048576,t=2,p=1$c29tZXNhbHRzb21lc2FsdA$QUwJiZ3Eg4pcXfI7u8T/HWl3eo6L6VeKvzZp4RkZ+6Q";
        assert!(!verify_password_in("anything-at-all", greedy, &mut blocks));
        assert_eq!(blocks.capacity(), capacity);
    }

    #[test]
    fn tokens_are_random_and_kept_as_digests() {
        let (a, b) = (new_token().unwrap(), new_token().unwrap());
        assert_ne!(a, b);
        assert_eq!(a.len(), TOKEN_PREFIX.len() + 64);
        assert_eq!(token_digest(&a).to_string().len(), 64);
        assert_ne!(token_digest(&a), a);
        let p = random_password().unwrap();
        assert_eq!(p.chars().count(), 24);
        assert!(check_password(&p).is_ok());
    }

    #[test]
    fn the_effective_role_is_the_lower_of_user_and_token() {
        assert_eq!(effective_role(Role::Admin, Role::Viewer), Role::Viewer);
        assert_eq!(effective_role(Role::Operator, Role::Admin), Role::Operator);
        assert!(Role::Viewer < Role::Operator && Role::Engineer < Role::Admin);
    }
}
