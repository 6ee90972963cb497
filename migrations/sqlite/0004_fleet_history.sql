-- Fleet history at scale (100,000 calibrations; BENCHMARKS.md, "Fleet
-- scale"). Keep in lockstep with migrations/postgres.
--
-- The report moves to a table of its own. SQLite reads a row's columns in
-- order through the row's overflow pages: with a 30-130 KB report stored
-- before `created_at`, every history row read walked its whole report, and
-- every scan of the table read a page per row. The summary rows are now a
-- few hundred bytes. (PostgreSQL kept the report out of line already.)

CREATE TABLE calibration_reports (
    calibration_id  INTEGER PRIMARY KEY REFERENCES calibrations(id),
    report          TEXT NOT NULL
);
INSERT INTO calibration_reports (calibration_id, report) SELECT id, report FROM calibrations;
ALTER TABLE calibrations DROP COLUMN report;

-- Every column the history filters on, by robot (the site and line
-- filters reach calibrations through their robots): a page's ids and a
-- count are read from this index alone. The row id is in every index.
CREATE INDEX calibrations_history ON calibrations(robot_id, created_at, test_rms_after_mm, model_id);

-- A line without its site (robots_fleet leads with the site).
CREATE INDEX robots_line ON robots(line);
