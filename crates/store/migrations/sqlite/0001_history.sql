-- camloop history store, SQLite. Mirrors ../postgres/0001_history.sql column for column.
-- Times are unix milliseconds (INTEGER). Lifts in blobs are i32 little-endian, 0.1 µm units.
-- History is appended: the only UPDATE is measurement_data.raw_revolutions -> NULL (retention).

CREATE TABLE machines (
    name          TEXT PRIMARY KEY NOT NULL,
    first_seen_ms INTEGER NOT NULL
);

CREATE TABLE recipe_snapshots (
    id            INTEGER PRIMARY KEY AUTOINCREMENT,
    machine       TEXT NOT NULL REFERENCES machines(name),
    part          TEXT NOT NULL,
    lobe          TEXT NOT NULL,
    kind          TEXT NOT NULL CHECK (kind IN ('lobe', 'pin')),
    recipe_json   TEXT NOT NULL,
    sha256        TEXT NOT NULL,
    created_at_ms INTEGER NOT NULL
);
CREATE INDEX recipe_snapshots_by_lobe ON recipe_snapshots (machine, part, lobe, id);

CREATE TABLE measurements (
    id                   INTEGER PRIMARY KEY AUTOINCREMENT,
    machine              TEXT NOT NULL REFERENCES machines(name),
    part                 TEXT NOT NULL,
    lobe                 TEXT NOT NULL,
    received_at_ms       INTEGER NOT NULL,
    verdict              TEXT NOT NULL CHECK (verdict IN ('pass', 'fail')),
    max_profile_error_um REAL NOT NULL,
    base_radius_error_um REAL NOT NULL,
    phase_error_deg      REAL NOT NULL,
    revolutions_used     INTEGER NOT NULL,
    points_per_rev       INTEGER NOT NULL,
    origin               TEXT NOT NULL,
    sha256               TEXT NOT NULL UNIQUE,
    recipe_snapshot_id   INTEGER REFERENCES recipe_snapshots(id)
);
-- Covering index for the history list of one lobe: a page of 1,000 is read from adjacent
-- index pages instead of 1,000 table pages spread over the file (SQLite has no INCLUDE,
-- so the summary columns follow the sort key).
CREATE INDEX measurements_by_lobe ON measurements (machine, lobe, received_at_ms DESC, id DESC,
    verdict, part, max_profile_error_um, base_radius_error_um, phase_error_deg, revolutions_used, points_per_rev, origin, sha256, recipe_snapshot_id);
CREATE INDEX measurements_by_machine ON measurements (machine, received_at_ms DESC, id DESC);
CREATE INDEX measurements_by_time ON measurements (received_at_ms);

CREATE TABLE measurement_data (
    measurement_id   INTEGER PRIMARY KEY REFERENCES measurements(id),
    raw_revolutions  BLOB,
    averaged_profile BLOB NOT NULL,
    analysis_json    TEXT NOT NULL
);

CREATE TABLE table_versions (
    id                   INTEGER PRIMARY KEY AUTOINCREMENT,
    machine              TEXT NOT NULL REFERENCES machines(name),
    lobe                 TEXT NOT NULL,
    version              INTEGER NOT NULL,
    parent_version       INTEGER,
    table_number         INTEGER NOT NULL,
    program_text         TEXT NOT NULL,
    sha256               TEXT NOT NULL,
    learning_params_json TEXT NOT NULL,
    reason               TEXT NOT NULL,
    created_at_ms        INTEGER NOT NULL,
    UNIQUE (machine, lobe, version)
);

CREATE TABLE table_version_status (
    id               INTEGER PRIMARY KEY AUTOINCREMENT,
    table_version_id INTEGER NOT NULL REFERENCES table_versions(id),
    status           TEXT NOT NULL CHECK (status IN ('waiting', 'pushed', 'refused')),
    why              TEXT NOT NULL,
    at_ms            INTEGER NOT NULL
);
CREATE INDEX table_version_status_by_version ON table_version_status (table_version_id, id);

CREATE TABLE dressings (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    machine        TEXT NOT NULL REFERENCES machines(name),
    at_ms          INTEGER NOT NULL,
    old_radius_mm  REAL NOT NULL,
    new_radius_mm  REAL NOT NULL,
    source         TEXT NOT NULL
);
CREATE INDEX dressings_by_machine ON dressings (machine, at_ms);

CREATE TABLE events (
    id      INTEGER PRIMARY KEY AUTOINCREMENT,
    machine TEXT NOT NULL REFERENCES machines(name),
    at_ms   INTEGER NOT NULL,
    level   TEXT NOT NULL CHECK (level IN ('info', 'warn', 'error')),
    kind    TEXT NOT NULL,
    message TEXT NOT NULL
);
CREATE INDEX events_by_machine ON events (machine, at_ms DESC, id DESC);
CREATE INDEX events_by_time ON events (at_ms DESC, id DESC);

CREATE TABLE learning_states (
    id         INTEGER PRIMARY KEY AUTOINCREMENT,
    machine    TEXT NOT NULL REFERENCES machines(name),
    lobe       TEXT NOT NULL,
    state_json TEXT NOT NULL,
    saved_at_ms INTEGER NOT NULL
);
CREATE INDEX learning_states_by_lobe ON learning_states (machine, lobe, id DESC);
