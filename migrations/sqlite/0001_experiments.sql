-- Experiments: one row per submitted map or compare, its state and result.
CREATE TABLE experiments (
    id              TEXT PRIMARY KEY,               -- uuid v7
    kind            TEXT NOT NULL,                  -- 'map' | 'compare'
    spec            TEXT NOT NULL,                  -- the ExperimentSpec JSON, as validated
    state           TEXT NOT NULL CHECK (state IN ('queued', 'scheduled', 'running', 'succeeded', 'failed', 'cancelled', 'interrupted')),
    priority        INTEGER NOT NULL DEFAULT 0,
    created_ms      INTEGER NOT NULL,               -- unix time, ms
    started_ms      INTEGER,
    finished_ms     INTEGER,
    trials_done     INTEGER NOT NULL DEFAULT 0,
    result          TEXT,                           -- result JSON when succeeded
    error           TEXT,                           -- message when failed
    idempotency_key TEXT UNIQUE
);

CREATE INDEX experiments_queue ON experiments (state, priority DESC, created_ms);
