-- What a claim reads (issue 14): the runs that may be claimed, in claim
-- order, without the finished ones (the claim's first condition is this
-- predicate).
CREATE INDEX experiments_claimable ON experiments (rig, priority DESC, created_ms, id)
    WHERE state IN ('queued', 'scheduled', 'interrupted', 'running');
