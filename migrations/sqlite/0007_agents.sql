-- Attached rigs (docs/rigs.md): each agent session gets an epoch from a
-- per-rig counter that only grows (across restarts); results that arrive
-- under an epoch other than the one their trial was sent with, and every
-- message refused, are kept here for audit, never stored as trials.
CREATE TABLE rig_epochs (
    rig   TEXT PRIMARY KEY,
    epoch INTEGER NOT NULL
);

CREATE TABLE agent_audit (
    id      INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms   INTEGER NOT NULL,
    rig     TEXT    NOT NULL,
    epoch   INTEGER,               -- the epoch the message carried, if any
    trial   TEXT,                  -- the trial it named, if any
    reason  TEXT    NOT NULL,      -- why it was refused, in words
    message TEXT    NOT NULL       -- the message as received (at most 64 KiB)
);

-- Attached rigs registered through the API, and why a rig is quarantined
-- (its queue paused) when it is.
CREATE TABLE attached_rigs (
    id          TEXT PRIMARY KEY,
    description TEXT    NOT NULL,
    created_ms  INTEGER NOT NULL,
    quarantine  TEXT
);
