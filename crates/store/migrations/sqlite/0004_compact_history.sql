-- Compact history (version 4). The bulky columns get packed forms (see src/store/pack.rs):
-- lifts delta-coded against the averaged profile and compressed, reports, table programs and
-- learning states compressed, programs and states against the previous row of the same
-- (machine, lobe) as dictionary (`base_id`, at most `chain_depth` 15 rows deep).
-- `codec` says which form a row has: 0 the version-1 columns, 1 packed. This migration only
-- reshapes the tables (the version-1 text columns become nullable); camloop then packs the
-- codec-0 rows in place at start, a batch per transaction, and reads either form.
-- Learning states are kept when they change meaningfully (`meaning_sha256` differs from the
-- newest row's), otherwise the newest row is replaced: the history keeps every meaningful
-- state plus the latest.
-- Tables are rebuilt because SQLite cannot drop a NOT NULL; ids are kept.
-- Mirrors ../postgres/0004_compact_history.sql.

ALTER TABLE measurement_data RENAME TO measurement_data_v1;
CREATE TABLE measurement_data (
    measurement_id   INTEGER PRIMARY KEY REFERENCES measurements(id),
    codec            INTEGER NOT NULL CHECK (codec IN (0, 1)),
    raw_revolutions  BLOB,
    averaged_profile BLOB NOT NULL,
    analysis_json    TEXT,
    analysis_packed  BLOB,
    CHECK ((codec = 0 AND analysis_json IS NOT NULL) OR (codec = 1 AND analysis_packed IS NOT NULL))
);
INSERT INTO measurement_data (measurement_id, codec, raw_revolutions, averaged_profile, analysis_json)
    SELECT measurement_id, 0, raw_revolutions, averaged_profile, analysis_json FROM measurement_data_v1;
DROP TABLE measurement_data_v1;

-- The status rows reference table_versions: both are rebuilt, children dropped first.
ALTER TABLE table_version_status RENAME TO table_version_status_v1;
ALTER TABLE table_versions RENAME TO table_versions_v1;
CREATE TABLE table_versions (
    id                   INTEGER PRIMARY KEY AUTOINCREMENT,
    machine              TEXT NOT NULL REFERENCES machines(name),
    lobe                 TEXT NOT NULL,
    version              INTEGER NOT NULL,
    parent_version       INTEGER,
    table_number         INTEGER NOT NULL,
    program_text         TEXT,
    sha256               TEXT NOT NULL,
    learning_params_json TEXT,
    reason               TEXT NOT NULL,
    created_at_ms        INTEGER NOT NULL,
    codec                INTEGER NOT NULL CHECK (codec IN (0, 1)),
    base_id              INTEGER REFERENCES table_versions(id),
    chain_depth          INTEGER NOT NULL,
    program_packed       BLOB,
    learning_packed      BLOB,
    UNIQUE (machine, lobe, version),
    CHECK ((codec = 0 AND program_text IS NOT NULL AND learning_params_json IS NOT NULL)
        OR (codec = 1 AND program_packed IS NOT NULL AND learning_packed IS NOT NULL))
);
INSERT INTO table_versions (id, machine, lobe, version, parent_version, table_number,
        program_text, sha256, learning_params_json, reason, created_at_ms, codec, chain_depth)
    SELECT id, machine, lobe, version, parent_version, table_number, program_text, sha256,
        learning_params_json, reason, created_at_ms, 0, 0 FROM table_versions_v1;
CREATE TABLE table_version_status (
    id               INTEGER PRIMARY KEY AUTOINCREMENT,
    table_version_id INTEGER NOT NULL REFERENCES table_versions(id),
    status           TEXT NOT NULL CHECK (status IN ('waiting', 'pushed', 'refused')),
    why              TEXT NOT NULL,
    at_ms            INTEGER NOT NULL
);
INSERT INTO table_version_status (id, table_version_id, status, why, at_ms)
    SELECT id, table_version_id, status, why, at_ms FROM table_version_status_v1;
DROP TABLE table_version_status_v1;
DROP TABLE table_versions_v1;
CREATE INDEX table_version_status_by_version ON table_version_status (table_version_id, id);
CREATE INDEX table_versions_by_lobe ON table_versions (machine, lobe, id);

ALTER TABLE learning_states RENAME TO learning_states_v1;
CREATE TABLE learning_states (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    machine        TEXT NOT NULL REFERENCES machines(name),
    lobe           TEXT NOT NULL,
    state_json     TEXT,
    saved_at_ms    INTEGER NOT NULL,
    codec          INTEGER NOT NULL CHECK (codec IN (0, 1)),
    base_id        INTEGER REFERENCES learning_states(id),
    chain_depth    INTEGER NOT NULL,
    state_packed   BLOB,
    state_sha256   TEXT,
    meaning_sha256 TEXT,
    CHECK ((codec = 0 AND state_json IS NOT NULL) OR (codec = 1 AND state_packed IS NOT NULL))
);
INSERT INTO learning_states (id, machine, lobe, state_json, saved_at_ms, codec, chain_depth)
    SELECT id, machine, lobe, state_json, saved_at_ms, 0, 0 FROM learning_states_v1;
DROP TABLE learning_states_v1;
CREATE INDEX learning_states_by_lobe ON learning_states (machine, lobe, id DESC);

-- The rows still to pack, so that the check at every start reads an index, not the blobs.
CREATE INDEX measurement_data_plain ON measurement_data (measurement_id) WHERE codec = 0;
CREATE INDEX table_versions_plain ON table_versions (id) WHERE codec = 0;
CREATE INDEX learning_states_plain ON learning_states (id) WHERE codec = 0;
