-- Work units (issue 14). With PostgreSQL and several workers, an
-- experiment's run (its driver) hands the B columns of its bisection and
-- grid maps, or a whole map (a trace, the analytic engine), to whichever
-- worker claims them, and replays their stored trials. A unit is keyed by
-- its map (`scope`) and column (`col`, -1 for a whole map): planning it
-- again changes nothing. Units hold leases fenced by `attempt`, as
-- experiments do.
CREATE TABLE units (
    experiment_id  TEXT    NOT NULL REFERENCES experiments (id) ON DELETE CASCADE,
    scope          INTEGER NOT NULL,
    col            INTEGER NOT NULL,
    b              REAL,               -- the column's damping (N·s/m); NULL for a whole map
    spec           TEXT    NOT NULL,   -- the map's spec (JSON)
    rig            TEXT    NOT NULL,
    priority       INTEGER NOT NULL,   -- the experiment's
    created_ms     INTEGER NOT NULL,   -- the experiment's: the oldest experiment's units first
    state          TEXT    NOT NULL CHECK (state IN ('queued', 'running', 'done', 'failed', 'cancelled')),
    attempt        INTEGER NOT NULL DEFAULT 0,
    worker         TEXT,
    lease_until_ms INTEGER,
    lost           INTEGER NOT NULL DEFAULT 0,
    trials         INTEGER NOT NULL DEFAULT 0,
    error          TEXT,
    PRIMARY KEY (experiment_id, scope, col)
);
CREATE INDEX units_claimable ON units (rig, priority DESC, created_ms, experiment_id, scope, col)
    WHERE state IN ('queued', 'running');
