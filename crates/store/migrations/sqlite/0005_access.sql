-- Who may do what, and who did what: users (argon2id password hashes), their API tokens
-- (SHA-256 of the token: the token itself is shown once and never stored), and the audit
-- trail, every row chained to the one before by `prev_sha256` (see src/store/audit.rs).
-- The audit trail is appended only: the triggers refuse UPDATE and DELETE, and
-- `camloop audit verify` finds a row changed behind their back.
-- Mirrors ../postgres/0005_access.sql.

CREATE TABLE users (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    name           TEXT NOT NULL UNIQUE,
    role           TEXT NOT NULL,
    password_hash  TEXT NOT NULL,
    created_at_ms  INTEGER NOT NULL,
    changed_at_ms  INTEGER NOT NULL,
    disabled_at_ms INTEGER
);

CREATE TABLE api_tokens (
    id            INTEGER PRIMARY KEY AUTOINCREMENT,
    user_id       INTEGER NOT NULL REFERENCES users(id),
    label         TEXT NOT NULL,
    token_sha256  TEXT NOT NULL UNIQUE,
    role          TEXT NOT NULL,
    created_at_ms INTEGER NOT NULL,
    expires_at_ms INTEGER NOT NULL,
    revoked_at_ms INTEGER
);

CREATE TABLE audit (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms       INTEGER NOT NULL,
    actor       TEXT NOT NULL,
    role        TEXT NOT NULL,
    client      TEXT NOT NULL,
    action      TEXT NOT NULL,
    machine     TEXT,
    feature     TEXT,
    version     INTEGER,
    before_json TEXT,
    after_json  TEXT,
    result      TEXT NOT NULL,
    reason      TEXT NOT NULL,
    prev_sha256 TEXT NOT NULL,
    row_sha256  TEXT NOT NULL
);

CREATE INDEX audit_by_time ON audit (at_ms);

CREATE TRIGGER audit_no_update BEFORE UPDATE ON audit
BEGIN
    SELECT RAISE(ABORT, 'the audit trail is append-only');
END;

CREATE TRIGGER audit_no_delete BEFORE DELETE ON audit
BEGIN
    SELECT RAISE(ABORT, 'the audit trail is append-only');
END;
