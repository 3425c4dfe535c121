-- Version 7: the audit trail keyed and held to its next id.
-- `chain` says how a row's `row_sha256` was made: 'sha256' (the rows before this version:
-- SHA-256 of the row before's digest and the fields) or 'hmac-sha256' (HMAC-SHA256 under a
-- key kept outside the database, over the id, the row before's digest and the fields).
-- The trigger refuses any id but the next one: `INSERT OR REPLACE` deletes the row it
-- replaces without firing the DELETE trigger, and an insert under an old id would do the
-- same; both are refused before the row is touched.
-- Mirrors ../postgres/0007_audit_keyed.sql.

ALTER TABLE audit ADD COLUMN chain TEXT NOT NULL DEFAULT 'sha256';

CREATE TRIGGER audit_next_id BEFORE INSERT ON audit
WHEN NEW.id IS NULL OR NEW.id <> (SELECT COALESCE(MAX(id), 0) + 1 FROM audit)
BEGIN
    SELECT RAISE(ABORT, 'the audit trail takes only the next id');
END;
