-- Pose plans (POST /plans): what was asked, its state, and the plan when
-- done. A plan runs in the process that took it, under a lease that
-- process renews (lease_until_ms, on the database's clock); a plan whose
-- lease ran out before it finished was interrupted and reads as failed.
-- Keep in lockstep with the other backend's migrations.

CREATE TABLE plans (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    model_id        INTEGER NOT NULL REFERENCES robot_models(id),
    robot_id        INTEGER REFERENCES robots(id),
    rig_id          INTEGER NOT NULL REFERENCES rigs(id),
    options         TEXT NOT NULL,
    state           TEXT NOT NULL CHECK (state IN ('queued','running','succeeded','failed')),
    error           TEXT,
    error_field     TEXT,
    result          TEXT,
    runner          TEXT,
    lease_until_ms  BIGINT,
    created_by      TEXT NOT NULL,
    created_at      TEXT NOT NULL,
    updated_at      TEXT NOT NULL,
    started_at      TEXT,
    finished_at     TEXT
);
CREATE INDEX plans_state ON plans(state, id);
