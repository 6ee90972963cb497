#!/usr/bin/env python3
"""Replicas on one PostgreSQL sharing a queue, one killed mid-run
(BENCHMARKS.md, "Fleet scale").

    tests/api/load/replicas.py [--jobs 1000] [--replicas 4] [--robots 20]
                               [--kill-at 0.3] [--bin target/release/drawcal]

Creates a fresh PostgreSQL database (drawcal_replicas on $PG_URL, default
postgres://postgres@127.0.0.1:5432), starts REPLICAS `drawcal serve`
processes on it (one worker each, the default lease of 15 s): the first
alone, through which it uploads ROBOTS sessions of
tests/data/er3a_paper_like (50 poses) and queues JOBS identifications over
HTTP (its worker starts on them meanwhile), then the others. When KILL_AT
of the jobs have succeeded it SIGKILLs a replica that is running a job at
that moment. When every job has ended it checks, from the database and
the replicas' logs, that every job ran to completion exactly once:

- every job succeeded, with one calibration, its own (calibrations.job_id
  is unique; each job's calibration_id names a calibration of that job);
- each robot's versions are 1..n without gap or repeat;
- the jobs the killed replica held were taken over (interruptions = 1,
  attempts = 0) and completed by another replica;
- in the logs, each job was claimed once, and twice only if the killed
  replica held it; "job succeeded" once per job.

Exits 1 if any check fails. Needs only the Python standard library, psql,
and the release binary (cargo build --release).
"""

import argparse
import http.client
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor

ROOT = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
DATA = os.path.join(ROOT, "tests", "data", "er3a_paper_like")
KEY = "dck_replicas_admin_key_0123456789abcdef01234567"


def psql(url, sql):
    out = subprocess.run(
        ["psql", "-qtAX", "-F", "\t", url, "-c", sql],
        check=True, capture_output=True, text=True,
    ).stdout
    return [line.split("\t") for line in out.splitlines() if line]


class Client:
    def __init__(self, port):
        self.port = port
        self.conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)

    def call(self, method, path, body=None, ctype="application/json"):
        headers = {"authorization": f"Bearer {KEY}"}
        if body is not None:
            headers["content-type"] = ctype
            if not isinstance(body, (bytes, str)):
                body = json.dumps(body)
        self.conn.request(method, path, body=body, headers=headers)
        r = self.conn.getresponse()
        text = r.read()
        if r.status >= 300:
            raise RuntimeError(f"{method} {path}: {r.status} {text[:300]!r}")
        return json.loads(text)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--jobs", type=int, default=1000)
    ap.add_argument("--replicas", type=int, default=4)
    ap.add_argument("--robots", type=int, default=20)
    ap.add_argument("--kill-at", type=float, default=0.3)
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "drawcal"))
    ap.add_argument("--port", type=int, default=18200)
    a = ap.parse_args()

    pg = os.environ.get("PG_URL", "postgres://postgres@127.0.0.1:5432")
    db = f"{pg}/drawcal_replicas"
    psql(f"{pg}/postgres", "DROP DATABASE IF EXISTS drawcal_replicas WITH (FORCE)")
    psql(f"{pg}/postgres", "CREATE DATABASE drawcal_replicas")
    work = tempfile.mkdtemp(prefix="drawcal-replicas-")
    print(f"date {time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}, load average "
          f"{open('/proc/loadavg').read().split()[:3]}, logs in {work}")

    procs = {}

    def start(i):
        port = a.port + i
        env = dict(os.environ, DRAWCAL_ADMIN_KEY=KEY, DATABASE_URL=db,
                   RUST_LOG="info", DRAWCAL_LOG_FORMAT="json")
        log = open(os.path.join(work, f"replica{i}.log"), "w")
        p = subprocess.Popen(
            [a.bin, "serve", "--listen", f"127.0.0.1:{port}", "--workers", "1",
             "--max-jobs-per-minute", "1000000", "--max-queued-jobs", "1000000"],
            env=env, stdout=log, stderr=subprocess.STDOUT)
        procs[i] = (p, port)
        for _ in range(300):
            try:
                c = http.client.HTTPConnection("127.0.0.1", port, timeout=2)
                c.request("GET", "/ready")
                if c.getresponse().status == 200:
                    return
            except OSError:
                pass
            if p.poll() is not None:
                sys.exit(f"replica {i} exited: see {log.name}")
            time.sleep(0.1)
        sys.exit(f"replica {i} not ready")

    try:
        # The first replica migrates the database and takes the admin key;
        # the jobs are queued through it, then the others start.
        start(0)

        c0 = Client(procs[0][1])
        model = c0.call("POST", "/models", open(os.path.join(DATA, "robot.json")).read())["id"]
        rig = c0.call("POST", "/rigs", open(os.path.join(DATA, "rig.json")).read())["id"]
        poses = open(os.path.join(DATA, "poses.csv")).read()
        sessions = []
        for r in range(a.robots):
            robot = c0.call("POST", "/robots", {"serial_number": f"REP-{r:03d}", "model_id": model,
                                                "site": f"site-{r % 4}"})["id"]
            s = c0.call("POST", "/sessions", {"robot_id": robot, "rig_id": rig})["id"]
            c0.call("POST", f"/sessions/{s}/poses", poses, ctype="text/csv")
            sessions.append(s)

        # Queue every job over HTTP (8 connections, round-robin over the
        # sessions); replica 0's worker starts on them meanwhile.
        def enqueue(k):
            c = Client(procs[0][1])
            for j in range(k, a.jobs, 8):
                c.call("POST", f"/sessions/{sessions[j % len(sessions)]}/jobs", {})
        t0 = time.time()
        with ThreadPoolExecutor(8) as ex:
            list(ex.map(enqueue, range(8)))
        t_queued = time.time()
        started = int(psql(db, "SELECT COUNT(*) FROM jobs WHERE state <> 'queued'")[0][0])
        print(f"{a.jobs} jobs queued over HTTP in {t_queued - t0:.1f} s "
              f"(replica 0 had started {started} of them meanwhile)")
        for i in range(1, a.replicas):
            start(i)
        t_up = time.time()
        pids = {i: p.pid for i, (p, _) in procs.items()}
        print(f"{a.replicas} replicas up ({t_up - t_queued:.1f} s), pids {pids}")

        # Kill, mid-run, a replica that is running a job right now.
        killed, held = None, []
        while killed is None:
            done = int(psql(db, "SELECT COUNT(*) FROM jobs WHERE state = 'succeeded'")[0][0])
            if done == a.jobs:
                sys.exit("every job ended before a replica could be killed running one: "
                         "more jobs, or a lower --kill-at")
            if done >= a.kill_at * a.jobs:
                running = psql(db, "SELECT id, locked_by FROM jobs WHERE state = 'running'")
                for i in range(a.replicas):
                    mine = [int(jid) for jid, by in running if f"-{pids[i]}-" in by]
                    if mine:
                        procs[i][0].send_signal(signal.SIGKILL)
                        procs[i][0].wait()
                        killed, held = i, mine
                        break
            time.sleep(0.02)
        t_kill = time.time()
        print(f"SIGKILL replica {killed} (pid {pids[killed]}) at {done} succeeded, "
              f"{t_kill - t_up:.1f} s after all replicas were up; it was running job(s) {held}")

        # Wait for every job to end.
        while True:
            left = int(psql(db, "SELECT COUNT(*) FROM jobs WHERE state IN ('queued', 'running')")[0][0])
            if left == 0:
                break
            if time.time() - t0 > 1800:
                sys.exit("jobs still unfinished after 30 min")
            time.sleep(0.2)
        t_end = time.time()
    finally:
        for p, _ in procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p, _ in procs.values():
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()

    # ---- the evidence, from the database --------------------------------
    failures = []

    def check(ok, what):
        print(("ok   " if ok else "FAIL ") + what)
        if not ok:
            failures.append(what)

    states = dict((s, int(n)) for s, n in psql(db, "SELECT state, COUNT(*) FROM jobs GROUP BY state"))
    check(states == {"succeeded": a.jobs}, f"job states {states}")
    n_cal, n_jobs_cal = map(int, psql(db, "SELECT COUNT(*), COUNT(DISTINCT job_id) FROM calibrations")[0])
    check(n_cal == a.jobs and n_jobs_cal == a.jobs,
          f"{n_cal} calibrations, of {n_jobs_cal} distinct jobs")
    mismatched = int(psql(db, "SELECT COUNT(*) FROM jobs j LEFT JOIN calibrations c ON c.id = j.calibration_id "
                              "WHERE c.job_id IS DISTINCT FROM j.id")[0][0])
    check(mismatched == 0, f"jobs whose calibration_id is not a calibration of that job: {mismatched}")
    gaps = psql(db, "SELECT robot_id, COUNT(*), COUNT(DISTINCT version), MIN(version), MAX(version) "
                    "FROM calibrations GROUP BY robot_id "
                    "HAVING COUNT(*) <> COUNT(DISTINCT version) OR MIN(version) <> 1 OR MAX(version) <> COUNT(*)")
    check(not gaps, f"every robot's versions are 1..n without gap or repeat (robots off: {gaps})")
    counts = Counter(int(n) for _, n in psql(db, "SELECT robot_id, COUNT(*) FROM calibrations GROUP BY robot_id"))
    print(f"     calibrations per robot: {dict(counts)}")
    odd = psql(db, "SELECT id, attempts, interruptions FROM jobs WHERE attempts <> 0 OR interruptions <> 0 ORDER BY id")
    taken_over = sorted(int(i) for i, _, _ in odd)
    check(taken_over == sorted(held) and all(at == "0" and it == "1" for _, at, it in odd),
          f"jobs with attempts or interruptions: {odd} (the killed replica held {held}: interruptions 1, attempts 0)")
    span = psql(db, "SELECT MIN(started_at), MAX(finished_at) FROM jobs")[0]

    # ---- and from the replicas' logs --------------------------------------
    claims, successes = defaultdict(list), defaultdict(list)
    for i in procs:
        for line in open(os.path.join(work, f"replica{i}.log")):
            try:
                e = json.loads(line)
            except ValueError:
                continue
            msg = e.get("fields", {}).get("message")
            job = (e.get("span") or {}).get("job_id")
            if job is None:
                continue
            if msg == "job claimed":
                claims[int(job)].append(i)
            elif msg == "job succeeded":
                successes[int(job)].append(i)
    twice = {j: r for j, r in claims.items() if len(r) > 1}
    check(set(claims) == set(range(1, a.jobs + 1)) and sorted(twice) == sorted(held)
          and all(len(r) == 2 and r[0] == killed for r in twice.values()),
          f"logs: every job claimed once, twice only the killed replica's {held}: {twice}")
    check(len(successes) == a.jobs and all(len(r) == 1 for r in successes.values())
          and all(successes[j][0] != killed for j in held),
          f"logs: 'job succeeded' once per job ({sum(map(len, successes.values()))} lines, "
          f"{len(successes)} jobs); the killed replica's jobs by another")
    per_replica = Counter(r[0] for r in successes.values())
    print(f"     jobs completed per replica: {dict(sorted(per_replica.items()))} (replica {killed} killed)")

    wall = t_end - t0
    left_at_up = a.jobs - started
    print(f"RESULT: {a.jobs} jobs in {wall:.1f} s from the first enqueue to the last finish "
          f"({a.jobs / wall:.1f} jobs/s); the {left_at_up} still queued when all {a.replicas} replicas were up "
          f"took {t_end - t_up:.1f} s ({left_at_up / (t_end - t_up):.1f} jobs/s, one replica SIGKILLed "
          f"{t_kill - t_up:.1f} s in, its job taken over after the 15 s lease); the database's first start "
          f"to last finish: {span[0]} .. {span[1]}; load average now {open('/proc/loadavg').read().split()[:3]}")
    if failures:
        print(f"{len(failures)} check(s) FAILED")
        sys.exit(1)
    print("every job exactly once: all checks passed")


if __name__ == "__main__":
    main()
