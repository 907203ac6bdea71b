-- Leases (issue 14): a running experiment is held by one worker process
-- until `lease_until_ms`; its heartbeats extend the lease. `attempt` counts
-- the claims: it fences every write of a run (a worker whose lease was
-- taken over changes nothing). An expired lease is claimed again, up to a
-- limit of attempts; then the experiment fails saying why.
ALTER TABLE experiments ADD COLUMN attempt INTEGER NOT NULL DEFAULT 0;
ALTER TABLE experiments ADD COLUMN worker TEXT;
ALTER TABLE experiments ADD COLUMN lease_until_ms INTEGER;
ALTER TABLE experiments ADD COLUMN lost INTEGER NOT NULL DEFAULT 0;  -- leases that expired

-- Worker processes (`zwidth worker`, and `zwidth serve` running its own):
-- what they run, seen at their last heartbeat.
CREATE TABLE workers (
    id               TEXT PRIMARY KEY,   -- host:pid:random
    rigs             TEXT NOT NULL,      -- the rig list it serves, as given
    started_ms       INTEGER NOT NULL,
    seen_ms          INTEGER NOT NULL,
    running          TEXT,               -- the experiment it runs, if any
    trials_per_s     REAL NOT NULL DEFAULT 0
);
