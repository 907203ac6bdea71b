-- Each attached rig's own agent credential (issue 45 item 4): the SHA-256
-- of the secret, in hex (the secret itself is shown once, when issued). A
-- rig with a row here is opened by that credential alone; one without is
-- opened by the server's shared agent tokens, as before (docs/rigs.md
-- "Tokens": the migration).
CREATE TABLE rig_credentials (
    rig TEXT PRIMARY KEY,
    sha256 TEXT NOT NULL UNIQUE,
    created_ms BIGINT NOT NULL
);
