-- Compact history (version 4). Mirrors ../sqlite/0004_compact_history.sql (which explains
-- the columns): the tables are rebuilt the same way so that both backends keep the same
-- tables and columns; ids are kept and the identities continue after the highest.

-- Index names are global in PostgreSQL: the old tables' implicit ones are renamed first.
ALTER TABLE measurement_data RENAME TO measurement_data_v1;
ALTER INDEX measurement_data_pkey RENAME TO measurement_data_v1_pkey;
CREATE TABLE measurement_data (
    measurement_id   BIGINT PRIMARY KEY REFERENCES measurements(id),
    codec            BIGINT NOT NULL CHECK (codec IN (0, 1)),
    raw_revolutions  BYTEA,
    averaged_profile BYTEA NOT NULL,
    analysis_json    TEXT,
    analysis_packed  BYTEA,
    CHECK ((codec = 0 AND analysis_json IS NOT NULL) OR (codec = 1 AND analysis_packed IS NOT NULL))
);
INSERT INTO measurement_data (measurement_id, codec, raw_revolutions, averaged_profile, analysis_json)
    SELECT measurement_id, 0, raw_revolutions, averaged_profile, analysis_json FROM measurement_data_v1;
DROP TABLE measurement_data_v1;

ALTER TABLE table_version_status RENAME TO table_version_status_v1;
ALTER TABLE table_versions RENAME TO table_versions_v1;
ALTER INDEX table_version_status_by_version RENAME TO table_version_status_by_version_v1;
ALTER INDEX table_version_status_pkey RENAME TO table_version_status_v1_pkey;
ALTER INDEX table_versions_pkey RENAME TO table_versions_v1_pkey;
ALTER INDEX table_versions_machine_lobe_version_key RENAME TO table_versions_v1_machine_lobe_version_key;
ALTER SEQUENCE table_version_status_id_seq RENAME TO table_version_status_v1_id_seq;
ALTER SEQUENCE table_versions_id_seq RENAME TO table_versions_v1_id_seq;
CREATE TABLE table_versions (
    id                   BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    machine              TEXT NOT NULL REFERENCES machines(name),
    lobe                 TEXT NOT NULL,
    version              BIGINT NOT NULL,
    parent_version       BIGINT,
    table_number         BIGINT NOT NULL,
    program_text         TEXT,
    sha256               TEXT NOT NULL,
    learning_params_json TEXT,
    reason               TEXT NOT NULL,
    created_at_ms        BIGINT NOT NULL,
    codec                BIGINT NOT NULL CHECK (codec IN (0, 1)),
    base_id              BIGINT REFERENCES table_versions(id),
    chain_depth          BIGINT NOT NULL,
    program_packed       BYTEA,
    learning_packed      BYTEA,
    UNIQUE (machine, lobe, version),
    CHECK ((codec = 0 AND program_text IS NOT NULL AND learning_params_json IS NOT NULL)
        OR (codec = 1 AND program_packed IS NOT NULL AND learning_packed IS NOT NULL))
);
INSERT INTO table_versions (id, machine, lobe, version, parent_version, table_number,
        program_text, sha256, learning_params_json, reason, created_at_ms, codec, chain_depth)
    OVERRIDING SYSTEM VALUE
    SELECT id, machine, lobe, version, parent_version, table_number, program_text, sha256,
        learning_params_json, reason, created_at_ms, 0, 0 FROM table_versions_v1;
SELECT setval(pg_get_serial_sequence('table_versions', 'id'), COALESCE(MAX(id), 0) + 1, false)
    FROM table_versions;
CREATE TABLE table_version_status (
    id               BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    table_version_id BIGINT NOT NULL REFERENCES table_versions(id),
    status           TEXT NOT NULL CHECK (status IN ('waiting', 'pushed', 'refused')),
    why              TEXT NOT NULL,
    at_ms            BIGINT NOT NULL
);
INSERT INTO table_version_status (id, table_version_id, status, why, at_ms)
    OVERRIDING SYSTEM VALUE
    SELECT id, table_version_id, status, why, at_ms FROM table_version_status_v1;
SELECT setval(pg_get_serial_sequence('table_version_status', 'id'), COALESCE(MAX(id), 0) + 1, false)
    FROM table_version_status;
DROP TABLE table_version_status_v1;
DROP TABLE table_versions_v1;
CREATE INDEX table_version_status_by_version ON table_version_status (table_version_id, id);
CREATE INDEX table_versions_by_lobe ON table_versions (machine, lobe, id);

ALTER TABLE learning_states RENAME TO learning_states_v1;
ALTER INDEX learning_states_by_lobe RENAME TO learning_states_by_lobe_v1;
ALTER INDEX learning_states_pkey RENAME TO learning_states_v1_pkey;
ALTER SEQUENCE learning_states_id_seq RENAME TO learning_states_v1_id_seq;
CREATE TABLE learning_states (
    id             BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    machine        TEXT NOT NULL REFERENCES machines(name),
    lobe           TEXT NOT NULL,
    state_json     TEXT,
    saved_at_ms    BIGINT NOT NULL,
    codec          BIGINT NOT NULL CHECK (codec IN (0, 1)),
    base_id        BIGINT REFERENCES learning_states(id),
    chain_depth    BIGINT NOT NULL,
    state_packed   BYTEA,
    state_sha256   TEXT,
    meaning_sha256 TEXT,
    CHECK ((codec = 0 AND state_json IS NOT NULL) OR (codec = 1 AND state_packed IS NOT NULL))
);
INSERT INTO learning_states (id, machine, lobe, state_json, saved_at_ms, codec, chain_depth)
    OVERRIDING SYSTEM VALUE
    SELECT id, machine, lobe, state_json, saved_at_ms, 0, 0 FROM learning_states_v1;
SELECT setval(pg_get_serial_sequence('learning_states', 'id'), COALESCE(MAX(id), 0) + 1, false)
    FROM learning_states;
DROP TABLE learning_states_v1;
CREATE INDEX learning_states_by_lobe ON learning_states (machine, lobe, id DESC);

-- The rows still to pack, so that the check at every start reads an index, not the blobs.
CREATE INDEX measurement_data_plain ON measurement_data (measurement_id) WHERE codec = 0;
CREATE INDEX table_versions_plain ON table_versions (id) WHERE codec = 0;
CREATE INDEX learning_states_plain ON learning_states (id) WHERE codec = 0;
