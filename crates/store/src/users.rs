//! Users and their API tokens. Passwords are kept as argon2id hashes and tokens as SHA-256
//! digests (see `crate::auth`); neither can be read back. A user is disabled, never
//! deleted, so the audit trail's names keep meaning someone.

use jiff::Timestamp;

use super::unix_ms::{instant, instant_opt};
use super::{Role, Store, StoreError, with_read, with_write};

/// Row id of a user.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct UserId(pub i64);

/// Row id of an API token.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TokenId(pub i64);

/// A user as stored.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct User {
    pub id: UserId,
    pub name: String,
    pub role: Role,
    /// argon2id, PHC string.
    pub password_hash: String,
    pub created_at: Timestamp,
    pub disabled_at: Option<Timestamp>,
}

/// A token to keep: its digest, whose it is, its role ceiling and when it runs out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NewToken {
    pub user: UserId,
    pub label: String,
    pub sha256: camloop_core::digest::Sha256,
    pub role: Role,
    pub created_at: Timestamp,
    pub expires_at: Timestamp,
}

/// A token with its user, as the service checks it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TokenGrant {
    pub id: TokenId,
    pub user: String,
    pub user_role: Role,
    /// The token's ceiling.
    pub role: Role,
    pub expires_at: Timestamp,
    pub revoked_at: Option<Timestamp>,
    pub user_disabled_at: Option<Timestamp>,
}

/// A token as listed (no digest).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TokenInfo {
    pub id: TokenId,
    pub user: String,
    pub label: String,
    pub role: Role,
    pub created_at: Timestamp,
    pub expires_at: Timestamp,
    pub revoked_at: Option<Timestamp>,
}

const USER_COLUMNS: &str =
    "SELECT id, name, role, password_hash, created_at_ms, disabled_at_ms FROM users";

/// A token with its user as read: id, user, user role, token role, expires, revoked,
/// user disabled.
type GrantRow = (i64, String, String, String, i64, Option<i64>, Option<i64>);

/// A token as listed: id, user, label, role, created, expires, revoked.
type TokenRow = (i64, String, String, String, i64, i64, Option<i64>);

/// A user's row as read: id, name, role, password hash, created, disabled.
type UserRow = (i64, String, String, String, i64, Option<i64>);

fn user_from(row: UserRow) -> Result<User, StoreError> {
    let (id, name, role, password_hash, created_at_ms, disabled_at_ms) = row;
    Ok(User {
        id: UserId(id),
        name,
        role: Role::parse(&role)?,
        password_hash,
        created_at: instant(created_at_ms, "created_at_ms")?,
        disabled_at: instant_opt(disabled_at_ms, "disabled_at_ms")?,
    })
}

/// One INSERT … RETURNING id through the writer: the id of the new row.
macro_rules! inserted_id {
    ($store:expr, $op:expr, $sql:expr $(, $bind:expr)* $(,)?) => {
        with_write!($store, pool => {
            let id: i64 = sqlx::query_scalar($sql)
                $(.bind($bind))*
                .fetch_one(pool)
                .await
                .map_err($store.db_error($op))?;
            Ok::<i64, StoreError>(id)
        })
    };
}

/// One UPDATE through the writer: whether it changed the row (every change of a user or a
/// token answers "was there such a one, not changed already").
macro_rules! changed_one {
    ($store:expr, $op:expr, $sql:expr $(, $bind:expr)* $(,)?) => {
        with_write!($store, pool => {
            let done = sqlx::query($sql)
                $(.bind($bind))*
                .execute(pool)
                .await
                .map_err($store.db_error($op))?;
            Ok(done.rows_affected() == 1)
        })
    };
}

impl Store {
    /// Adds a user; a name taken already is a [`StoreError::Conflict`].
    pub async fn add_user(
        &self,
        name: &str,
        role: Role,
        password_hash: &str,
        at: Timestamp,
    ) -> Result<UserId, StoreError> {
        const OP: &str = "adding a user";
        if self.user(name).await?.is_some() {
            return Err(StoreError::Conflict {
                what: format!("user {name} exists already"),
                detail: super::Detail(String::new()),
            });
        }
        inserted_id!(
            self,
            OP,
            "INSERT INTO users (name, role, password_hash, created_at_ms, changed_at_ms) \
             VALUES ($1, $2, $3, $4, $4) RETURNING id",
            name,
            role.as_str(),
            password_hash,
            at.as_millisecond(),
        )
        .map(UserId)
    }

    /// The user called `name`, disabled or not.
    pub async fn user(&self, name: &str) -> Result<Option<User>, StoreError> {
        const OP: &str = "reading a user";
        // Through the readers: the access layer asks on every session's request, and must
        // never wait for (or hold) the connection the machine loops write through.
        with_read!(self, pool => {
            let row: Option<UserRow> =
                sqlx::query_as(&format!("{USER_COLUMNS} WHERE name = $1"))
                    .bind(name)
                    .fetch_optional(pool)
                    .await
                    .map_err(self.db_error(OP))?;
            row.map(user_from).transpose()
        })
    }

    /// Every user, by name.
    pub async fn users(&self) -> Result<Vec<User>, StoreError> {
        const OP: &str = "listing users";
        with_read!(self, pool => {
            let rows: Vec<UserRow> = sqlx::query_as(&format!("{USER_COLUMNS} ORDER BY name"))
                .fetch_all(pool)
                .await
                .map_err(self.db_error(OP))?;
            rows.into_iter().map(user_from).collect()
        })
    }

    /// Sets a user's password hash; false when there is no such user.
    pub async fn set_password(
        &self,
        name: &str,
        password_hash: &str,
        at: Timestamp,
    ) -> Result<bool, StoreError> {
        changed_one!(
            self,
            "changing a password",
            "UPDATE users SET password_hash = $1, changed_at_ms = $2 WHERE name = $3",
            password_hash,
            at.as_millisecond(),
            name,
        )
    }

    /// Disables a user (its tokens and sessions stop working); false when there is no such
    /// user or it was disabled already.
    pub async fn disable_user(&self, name: &str, at: Timestamp) -> Result<bool, StoreError> {
        changed_one!(
            self,
            "disabling a user",
            "UPDATE users SET disabled_at_ms = $1, changed_at_ms = $1 \
             WHERE name = $2 AND disabled_at_ms IS NULL",
            at.as_millisecond(),
            name,
        )
    }

    /// Keeps a new token's digest.
    pub async fn add_token(&self, t: &NewToken) -> Result<TokenId, StoreError> {
        inserted_id!(
            self,
            "adding a token",
            "INSERT INTO api_tokens (user_id, label, token_sha256, role, created_at_ms, \
             expires_at_ms) VALUES ($1, $2, $3, $4, $5, $6) RETURNING id",
            t.user.0,
            &t.label,
            t.sha256.to_string(),
            t.role.as_str(),
            t.created_at.as_millisecond(),
            t.expires_at.as_millisecond(),
        )
        .map(TokenId)
    }

    /// The token whose digest is `sha256`, with its user.
    pub async fn token_grant(
        &self,
        sha256: &camloop_core::digest::Sha256,
    ) -> Result<Option<TokenGrant>, StoreError> {
        const OP: &str = "checking a token";
        with_read!(self, pool => {
            let row: Option<GrantRow> =
                sqlx::query_as(
                    "SELECT t.id, u.name, u.role, t.role, t.expires_at_ms, t.revoked_at_ms, \
                     u.disabled_at_ms FROM api_tokens t JOIN users u ON u.id = t.user_id \
                     WHERE t.token_sha256 = $1",
                )
                .bind(sha256.to_string())
                .fetch_optional(pool)
                .await
                .map_err(self.db_error(OP))?;
            row.map(|(id, user, user_role, role, expires, revoked, disabled)| {
                Ok(TokenGrant {
                    id: TokenId(id),
                    user,
                    user_role: Role::parse(&user_role)?,
                    role: Role::parse(&role)?,
                    expires_at: instant(expires, "expires_at_ms")?,
                    revoked_at: instant_opt(revoked, "revoked_at_ms")?,
                    user_disabled_at: instant_opt(disabled, "disabled_at_ms")?,
                })
            })
            .transpose()
        })
    }

    /// Revokes a token; false when there is no such token or it was revoked already.
    pub async fn revoke_token(&self, id: TokenId, at: Timestamp) -> Result<bool, StoreError> {
        changed_one!(
            self,
            "revoking a token",
            "UPDATE api_tokens SET revoked_at_ms = $1 WHERE id = $2 AND revoked_at_ms IS NULL",
            at.as_millisecond(),
            id.0,
        )
    }

    /// Every token (no digests), oldest first.
    pub async fn tokens(&self) -> Result<Vec<TokenInfo>, StoreError> {
        const OP: &str = "listing tokens";
        with_read!(self, pool => {
            let rows: Vec<TokenRow> = sqlx::query_as(
                "SELECT t.id, u.name, t.label, t.role, t.created_at_ms, t.expires_at_ms, \
                 t.revoked_at_ms FROM api_tokens t JOIN users u ON u.id = t.user_id ORDER BY t.id",
            )
            .fetch_all(pool)
            .await
            .map_err(self.db_error(OP))?;
            rows.into_iter()
                .map(|(id, user, label, role, created, expires, revoked)| {
                    Ok(TokenInfo {
                        id: TokenId(id),
                        user,
                        label,
                        role: Role::parse(&role)?,
                        created_at: instant(created, "created_at_ms")?,
                        expires_at: instant(expires, "expires_at_ms")?,
                        revoked_at: instant_opt(revoked, "revoked_at_ms")?,
                    })
                })
                .collect()
        })
    }
}
