-- Scheduling: an experiment may wait for a start time, and the whole queue
-- may be paused (a one-row settings table).
ALTER TABLE experiments ADD COLUMN not_before_ms INTEGER;

CREATE TABLE queue_control (
    id     INTEGER PRIMARY KEY CHECK (id = 1),
    paused INTEGER NOT NULL DEFAULT 0
);
INSERT INTO queue_control (id, paused) VALUES (1, 0);
