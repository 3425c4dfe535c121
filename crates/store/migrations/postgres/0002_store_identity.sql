-- The store's identity: one row, made when this migration runs, i.e. when the database is
-- new (or is upgraded from version 1). A database replaced or emptied under camloop gets a
-- different id, which the service compares with the one it remembers in its var folder.
-- Mirrors ../sqlite/0002_store_identity.sql. gen_random_uuid() is built in from PostgreSQL 13.

CREATE TABLE store_identity (
    singleton     INTEGER PRIMARY KEY NOT NULL CHECK (singleton = 1),
    id            TEXT NOT NULL,
    created_at_ms BIGINT NOT NULL
);
INSERT INTO store_identity (singleton, id, created_at_ms)
VALUES (1, replace(gen_random_uuid()::text, '-', ''),
        (extract(epoch FROM clock_timestamp()) * 1000)::bigint);
