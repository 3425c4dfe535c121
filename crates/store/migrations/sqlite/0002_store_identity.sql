-- The store's identity: one row, made when this migration runs, i.e. when the database is
-- new (or is upgraded from version 1). A database replaced or emptied under camloop gets a
-- different id, which the service compares with the one it remembers in its var folder.
-- Mirrors ../postgres/0002_store_identity.sql.

CREATE TABLE store_identity (
    singleton     INTEGER PRIMARY KEY NOT NULL CHECK (singleton = 1),
    id            TEXT NOT NULL,
    created_at_ms INTEGER NOT NULL
);
INSERT INTO store_identity (singleton, id, created_at_ms)
VALUES (1, lower(hex(randomblob(16))),
        CAST(ROUND((julianday('now') - 2440587.5) * 86400000.0) AS INTEGER));
