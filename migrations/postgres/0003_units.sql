-- Work units (issue 14): see migrations/sqlite/0012_units.sql.
CREATE TABLE units (
    experiment_id  TEXT             NOT NULL REFERENCES experiments (id) ON DELETE CASCADE,
    scope          BIGINT           NOT NULL,
    col            BIGINT           NOT NULL,
    b              DOUBLE PRECISION,
    spec           TEXT             NOT NULL,
    rig            TEXT             NOT NULL,
    priority       BIGINT           NOT NULL,
    created_ms     BIGINT           NOT NULL,
    state          TEXT             NOT NULL CHECK (state IN ('queued', 'running', 'done', 'failed', 'cancelled')),
    attempt        BIGINT           NOT NULL DEFAULT 0,
    worker         TEXT,
    lease_until_ms BIGINT,
    lost           BIGINT           NOT NULL DEFAULT 0,
    trials         BIGINT           NOT NULL DEFAULT 0,
    error          TEXT,
    PRIMARY KEY (experiment_id, scope, col)
);
CREATE INDEX units_claimable ON units (rig, priority DESC, created_ms, experiment_id, scope, col)
    WHERE state IN ('queued', 'running');
