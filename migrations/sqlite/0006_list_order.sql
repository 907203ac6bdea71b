-- Paging the list newest first by (created_ms, id) without sorting every row.
CREATE INDEX experiments_created ON experiments (created_ms DESC, id DESC);
