-- Tunes: every evaluation (parameters, objectives, elapsed time) stored as
-- it finishes, so a resumed tune takes them from here instead of redoing
-- them; and the best so far, shown while running.
CREATE TABLE evaluations (
    experiment_id TEXT    NOT NULL REFERENCES experiments (id) ON DELETE CASCADE,
    key           TEXT    NOT NULL,   -- accuracy + exact parameter values
    seq           INTEGER NOT NULL,   -- order stored
    record        TEXT    NOT NULL,   -- the Evaluation JSON
    PRIMARY KEY (experiment_id, key)
);

ALTER TABLE experiments ADD COLUMN best TEXT;
