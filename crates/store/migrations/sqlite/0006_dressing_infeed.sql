-- The dresser's measured infeed (radius removed, µm) of a wheel dressing, when the dressing
-- report carries it: the loop moves the learned size correction by the size step it tells.
-- NULL for dressings reported without it and for rows written before this column.
-- Mirrors ../postgres/0006_dressing_infeed.sql.

ALTER TABLE dressings ADD COLUMN infeed_um REAL;
