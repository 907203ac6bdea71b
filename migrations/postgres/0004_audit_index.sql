-- See migrations/sqlite/0013_audit_index.sql.
CREATE INDEX agent_audit_rig ON agent_audit (rig, id);
