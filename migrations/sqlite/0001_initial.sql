-- drawcal service schema, SQLite flavour. Keep in lockstep with
-- migrations/postgres (same versions, same tables and columns).

CREATE TABLE robot_models (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    name        TEXT NOT NULL,
    dof         INTEGER NOT NULL,
    robot_json  TEXT NOT NULL,
    created_at  TEXT NOT NULL
);

CREATE TABLE robots (
    id                     INTEGER PRIMARY KEY AUTOINCREMENT,
    serial_number          TEXT NOT NULL UNIQUE,
    model_id               INTEGER NOT NULL REFERENCES robot_models(id),
    site                   TEXT,
    line                   TEXT,
    cell                   TEXT,
    active_calibration_id  INTEGER,
    created_at             TEXT NOT NULL,
    updated_at             TEXT NOT NULL
);
CREATE INDEX robots_fleet ON robots(site, line);

CREATE TABLE rigs (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    name        TEXT NOT NULL,
    n_strings   INTEGER NOT NULL,
    rig_json    TEXT NOT NULL,
    created_at  TEXT NOT NULL
);

CREATE TABLE sessions (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    robot_id    INTEGER NOT NULL REFERENCES robots(id),
    rig_id      INTEGER NOT NULL REFERENCES rigs(id),
    name        TEXT,
    n_poses     INTEGER NOT NULL DEFAULT 0,
    n_batches   INTEGER NOT NULL DEFAULT 0,
    columns     TEXT,
    created_at  TEXT NOT NULL,
    updated_at  TEXT NOT NULL
);

CREATE TABLE pose_batches (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    session_id  INTEGER NOT NULL REFERENCES sessions(id),
    seq         INTEGER NOT NULL,
    n_rows      INTEGER NOT NULL,
    body        TEXT NOT NULL,
    created_at  TEXT NOT NULL,
    UNIQUE (session_id, seq)
);

CREATE TABLE jobs (
    id                INTEGER PRIMARY KEY AUTOINCREMENT,
    session_id        INTEGER NOT NULL REFERENCES sessions(id),
    robot_id          INTEGER NOT NULL REFERENCES robots(id),
    kind              TEXT NOT NULL DEFAULT 'identify',
    options           TEXT NOT NULL,
    state             TEXT NOT NULL CHECK (state IN ('queued','running','succeeded','failed','cancelled')),
    stage             TEXT,
    progress          REAL NOT NULL DEFAULT 0,
    attempts          INTEGER NOT NULL DEFAULT 0,
    max_attempts      INTEGER NOT NULL DEFAULT 3,
    locked_by         TEXT,
    locked_until_ms   INTEGER,
    cancel_requested  BOOLEAN NOT NULL DEFAULT FALSE,
    error             TEXT,
    calibration_id    INTEGER,
    created_at        TEXT NOT NULL,
    updated_at        TEXT NOT NULL,
    started_at        TEXT,
    finished_at       TEXT
);
CREATE INDEX jobs_runnable ON jobs(state, id);

CREATE TABLE calibrations (
    id                  INTEGER PRIMARY KEY AUTOINCREMENT,
    robot_id            INTEGER NOT NULL REFERENCES robots(id),
    model_id            INTEGER NOT NULL REFERENCES robot_models(id),
    session_id          INTEGER NOT NULL REFERENCES sessions(id),
    job_id              INTEGER NOT NULL UNIQUE REFERENCES jobs(id),
    version             INTEGER NOT NULL,
    method              TEXT NOT NULL,
    n_poses             INTEGER NOT NULL,
    n_test              INTEGER NOT NULL,
    test_rms_before_mm  REAL,
    test_rms_after_mm   REAL,
    train_rms_after_mm  REAL,
    effects             TEXT NOT NULL,
    report              TEXT NOT NULL,
    created_at          TEXT NOT NULL,
    UNIQUE (robot_id, version)
);
CREATE INDEX calibrations_created ON calibrations(created_at);

CREATE TABLE activations (
    id                       INTEGER PRIMARY KEY AUTOINCREMENT,
    robot_id                 INTEGER NOT NULL REFERENCES robots(id),
    action                   TEXT NOT NULL CHECK (action IN ('activate','rollback')),
    calibration_id           INTEGER REFERENCES calibrations(id),
    previous_calibration_id  INTEGER REFERENCES calibrations(id),
    actor                    TEXT NOT NULL,
    reason                   TEXT NOT NULL,
    created_at               TEXT NOT NULL
);
CREATE INDEX activations_robot ON activations(robot_id, id);
