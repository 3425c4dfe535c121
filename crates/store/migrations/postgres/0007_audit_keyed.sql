-- Version 7: the audit trail keyed and held to its next id.
-- `chain` says how a row's `row_sha256` was made: 'sha256' (the rows before this version)
-- or 'hmac-sha256' (HMAC-SHA256 under a key kept outside the database). The triggers refuse
-- any id but the next one and TRUNCATE (which fires no row trigger). A table owner can
-- still drop triggers: on a site, the tables belong to an owner role and the service's
-- role may only SELECT and INSERT on `audit` (see the hardening chapter).
-- Mirrors ../sqlite/0007_audit_keyed.sql.

ALTER TABLE audit ADD COLUMN chain TEXT NOT NULL DEFAULT 'sha256';

CREATE FUNCTION audit_next_id() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    IF NEW.id IS DISTINCT FROM (SELECT COALESCE(MAX(id), 0) + 1 FROM audit) THEN
        RAISE EXCEPTION 'the audit trail takes only the next id';
    END IF;
    RETURN NEW;
END;
$$;

CREATE TRIGGER audit_next_id BEFORE INSERT ON audit
    FOR EACH ROW EXECUTE FUNCTION audit_next_id();

CREATE TRIGGER audit_no_truncate BEFORE TRUNCATE ON audit
    FOR EACH STATEMENT EXECUTE FUNCTION audit_append_only();
