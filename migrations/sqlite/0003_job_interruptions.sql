-- A job's interruptions (its worker died or lost the lease before it
-- finished) are counted apart from its attempts (runs that failed by
-- themselves), so that restarts do not use up a job's attempts. Keep in
-- lockstep with the other backend's migrations.

ALTER TABLE jobs ADD COLUMN interruptions BIGINT NOT NULL DEFAULT 0;

-- Unfinished jobs' attempts counted claims until now: start them afresh.
UPDATE jobs SET attempts = 0 WHERE state IN ('queued', 'running');
