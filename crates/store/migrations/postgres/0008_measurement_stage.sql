-- The stage of the part a measurement was taken at: `final` for the finished part (every
-- row written before this column), `in_process` for the measurement before the finish pass
-- with stock still on. Whatever judges finished parts (capability, control charts, Q-DAS
-- export, the dashboard's latest result) reads `final` rows only.
-- Mirrors ../sqlite/0008_measurement_stage.sql.

ALTER TABLE measurements ADD COLUMN stage TEXT NOT NULL DEFAULT 'final'
    CHECK (stage IN ('final', 'in_process'));
