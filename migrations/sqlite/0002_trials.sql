-- Every finished trial of an experiment, written as it finishes (in small
-- batches), so that a killed run resumes without redoing any of them.
-- `scope` tells the maps of one experiment apart (a compare has one per estimator).
CREATE TABLE trials (
    experiment_id TEXT    NOT NULL REFERENCES experiments (id) ON DELETE CASCADE,
    scope         INTEGER NOT NULL,
    k             REAL    NOT NULL,
    b             REAL    NOT NULL,
    point         TEXT    NOT NULL,   -- the Point JSON
    PRIMARY KEY (experiment_id, scope, k, b)
);
