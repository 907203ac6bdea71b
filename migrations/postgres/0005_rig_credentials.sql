-- See migrations/sqlite/0014_rig_credentials.sql.
CREATE TABLE rig_credentials (
    rig TEXT PRIMARY KEY,
    sha256 TEXT NOT NULL UNIQUE,
    created_ms BIGINT NOT NULL
);
