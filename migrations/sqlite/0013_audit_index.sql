-- The audit is read a page at a time per rig, newest first, and trimmed
-- per rig to its retention (docs/rigs.md, "The audit"): both by (rig, id).
CREATE INDEX agent_audit_rig ON agent_audit (rig, id);
