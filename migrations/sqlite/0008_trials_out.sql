-- The trial out on each attached rig and the epoch it was sent under,
-- written before it is sent and removed once its result is committed: a
-- restarted server takes the agent's result for it (listed in `hello`, or
-- sent when the agent finishes) instead of running it again.
CREATE TABLE rig_trials_out (
    rig     TEXT PRIMARY KEY,
    trial   TEXT    NOT NULL,
    epoch   INTEGER NOT NULL,
    sent_ms INTEGER NOT NULL
);
