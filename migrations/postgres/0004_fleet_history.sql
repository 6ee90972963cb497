-- Fleet history at scale (100,000 calibrations; BENCHMARKS.md, "Fleet
-- scale"). Keep in lockstep with migrations/sqlite.
--
-- The report moves to a table of its own, as on SQLite (where a large
-- report in the summary row made every history read walk it). PostgreSQL
-- kept it out of line already (TOAST); the schemas stay the same.

CREATE TABLE calibration_reports (
    calibration_id  BIGINT PRIMARY KEY REFERENCES calibrations(id),
    report          TEXT NOT NULL
);
INSERT INTO calibration_reports (calibration_id, report) SELECT id, report FROM calibrations;
ALTER TABLE calibrations DROP COLUMN report;

-- Every column the history filters on, by robot (the site and line
-- filters reach calibrations through their robots): a page's ids and a
-- count are read from this index alone.
CREATE INDEX calibrations_history ON calibrations(robot_id, created_at)
    INCLUDE (test_rms_after_mm, model_id, id);

-- A line without its site (robots_fleet leads with the site).
CREATE INDEX robots_line ON robots(line);
