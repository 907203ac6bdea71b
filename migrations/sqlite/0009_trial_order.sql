-- Each stored trial's place in its map (issue 14): `col` is the position of
-- its B in the map's B list, `idx` its order among that column's trials.
-- Trials are listed by (scope, col, idx): the search's own order, whatever
-- the thread count or the interruptions. Trials stored before this have
-- 0, 0 and keep their insertion order among themselves.
ALTER TABLE trials ADD COLUMN col INTEGER NOT NULL DEFAULT 0;
ALTER TABLE trials ADD COLUMN idx INTEGER NOT NULL DEFAULT 0;
CREATE INDEX trials_order ON trials (experiment_id, scope, col, idx);
