-- Who may do what, and who did what: users (argon2id password hashes), their API tokens
-- (SHA-256 of the token: the token itself is shown once and never stored), and the audit
-- trail, every row chained to the one before by `prev_sha256` (see src/store/audit.rs).
-- The audit trail is appended only: the trigger refuses UPDATE and DELETE, and
-- `camloop audit verify` finds a row changed behind its back.
-- Mirrors ../sqlite/0005_access.sql.

CREATE TABLE users (
    id             BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    name           TEXT NOT NULL UNIQUE,
    role           TEXT NOT NULL,
    password_hash  TEXT NOT NULL,
    created_at_ms  BIGINT NOT NULL,
    changed_at_ms  BIGINT NOT NULL,
    disabled_at_ms BIGINT
);

CREATE TABLE api_tokens (
    id            BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    user_id       BIGINT NOT NULL REFERENCES users(id),
    label         TEXT NOT NULL,
    token_sha256  TEXT NOT NULL UNIQUE,
    role          TEXT NOT NULL,
    created_at_ms BIGINT NOT NULL,
    expires_at_ms BIGINT NOT NULL,
    revoked_at_ms BIGINT
);

CREATE TABLE audit (
    id          BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    at_ms       BIGINT NOT NULL,
    actor       TEXT NOT NULL,
    role        TEXT NOT NULL,
    client      TEXT NOT NULL,
    action      TEXT NOT NULL,
    machine     TEXT,
    feature     TEXT,
    version     BIGINT,
    before_json TEXT,
    after_json  TEXT,
    result      TEXT NOT NULL,
    reason      TEXT NOT NULL,
    prev_sha256 TEXT NOT NULL,
    row_sha256  TEXT NOT NULL
);

CREATE INDEX audit_by_time ON audit (at_ms);

CREATE FUNCTION audit_append_only() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    RAISE EXCEPTION 'the audit trail is append-only';
END;
$$;

CREATE TRIGGER audit_no_change BEFORE UPDATE OR DELETE ON audit
    FOR EACH ROW EXECUTE FUNCTION audit_append_only();
