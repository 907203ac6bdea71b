-- Rigs: each experiment runs on one rig (default the first configured), and
-- a rig may have a recurring window outside which it starts nothing new.
-- Progress: the fraction of the work done, for the ETA.
ALTER TABLE experiments ADD COLUMN rig TEXT NOT NULL DEFAULT 'sim';
ALTER TABLE experiments ADD COLUMN progress REAL NOT NULL DEFAULT 0;

CREATE INDEX experiments_rig_queue ON experiments (rig, state, priority DESC, created_ms);

CREATE TABLE rig_windows (
    rig    TEXT PRIMARY KEY,
    window TEXT NOT NULL      -- the Window JSON: {"start":"22:00","end":"06:00","tz":"Europe/Berlin"}
);
