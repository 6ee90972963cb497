#!/usr/bin/env python3
"""Third independent cross-check of drawcal: physics OUTSIDE the catalogue.

Written from DATA_FORMAT.md, README.md, docs/CLI.md and the physics
descriptions of the brief only (not from src/, PHYSICS.md's methods or
EVAL.md).  Kinematics, robots, rigs and the multilateration are the first
two simulators' (imported from sim.py / gen2.py, one definition).

Every dataset <name>/ has a twin <name>/oracle/ with the identical poses,
split column, geometric deviations, base pose and noise realisation but
WITHOUT the out-of-catalogue effect; the tool is run on the twin with
`--physics off` and its held-out RMS approximates what a fit of the true
effect would reach.

Usage (from the repository root, after cargo build --release):
    python3 tests/crosscheck/gen3.py list    # one line of physics per kind
    python3 tests/crosscheck/gen3.py plan    # write every dataset and its twin
    python3 tests/crosscheck/gen3.py run     # run the tool (one process at a time, timeout)
    python3 tests/crosscheck/gen3.py score   # = python3 tests/crosscheck/score3.py
Env: XC3_OUT (default /tmp/xcheck3/ds), XCHECK_DATA (default tests/data),
     XCHECK_TOOL (default target/release/drawcal)
"""
import json, math, os, sys, copy, subprocess, time
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim import rotx, roty, rotz, trans, rpy_to_R  # noqa: E402
import gen2  # noqa: E402
from gen2 import link_T, frames, tool_in_base, multilaterate, make_rig, load_robot, HOME  # noqa: E402

OUT = os.environ.get("XC3_OUT", "/tmp/xcheck3/ds")
SRC = os.environ.get("XCHECK_DATA", "tests/data")
TOOL = os.environ.get("XCHECK_TOOL", "target/release/drawcal")
gen2.SRC = SRC
D2R = math.pi / 180.0

# ---------------------------------------------------------------- the kinds
# kind: (half, side, unit magnitude, unit, one line of physics)
KINDS = {
    "cross_coupling": ("tune", "robot", 0.01, "deg",
                       "joint b's real angle is off by k*sin(q_a + phi), driven by ANOTHER joint a (cable/harness or "
                       "coupled-drive torque): pairs (2->3), (3->2), (4->5)"),
    "nonint_harmonic": ("tune", "robot", 0.01, "deg",
                        "joint j's angle error k*sin(h*q_j + phi) with a NON-integer h (1.5, 2.5, 3.3, 4.7: an "
                        "intermediate gear stage turning h times per joint revolution)"),
    "base_tilt": ("tune", "robot", 1e-6, "rad/(N*m)",
                  "compliant mount: the whole robot tilts about a horizontal axis through the base origin by "
                  "c * (horizontal gravity moment of the whole arm about the base), a function of the whole configuration"),
    "rig_osc": ("tune", "point", 0.01, "mm",
                "the rig / tracker frame oscillates in translation, A*sin(2*pi*t/P + phi) along a fixed direction "
                "(HVAC / building cycle, P = session/2..4, ~8-16 min)"),
    "drum_pitch": ("tune", "sensor", 0.01, "mm",
                   "one string's reading has a periodic error in its own length, k*sin(2*pi*l/p + phi), p = 30-80 mm "
                   "(spool/drum winding pitch)"),
    "workspace_field": ("tune", "point", 0.01, "mm",
                        "tracker data only: a smooth distortion field over the workspace; either a vertical error "
                        "k*((z-z0)/500mm)^2 (refraction in stratified air) or a tangential error D*k*sin(16*az+phi) "
                        "(azimuth encoder graduation error, 16x per turn; D = horizontal range, az = azimuth from the tracker)"),
    "local_bump": ("heldback", "robot", 0.01, "deg",
                   "joint j's angle error confined to a 25-40 deg window of its range (raised-cosine bump, a worn "
                   "gear-tooth region), zero elsewhere, not periodic"),
    "axis_wobble": ("heldback", "robot", 0.001, "deg",
                    "joint j's axis tilts as the joint turns: tilt w about the horizontal direction "
                    "(cos(2q+phi), sin(2q+phi), 0) of the stationary frame (oval bearing race, 2x per revolution)"),
    "link_thermal": ("heldback", "robot", 1e-5, "1/K",
                     "ONE link only (ER3A a2 / d4 / d1, UR5 a2 / a3) grows with the ambient temperature, "
                     "dL = kappa*L*(T - T0); temperature = warm-up + a 1-1.5 K HVAC swing"),
    "settling": ("heldback", "robot", 1e-3, "-",
                 "motion-driven: T is off by c*(T_k - T_{k-1}), along the Cartesian move that led to the pose and "
                 "proportional to its length (unsettled overshoot, c>0, or lag, c<0)"),
    "eyelet_friction": ("heldback", "sensor", 0.01, "mm/rad",
                        "one string's reading is off by rho*(theta - mean theta), theta = angle between the string and "
                        "its eyelet's axis (wrap over a rounded eyelet; the eyelet points at the workspace centre)"),
    "string_zero_osc": ("heldback", "sensor", 0.01, "mm",
                        "one string's zero oscillates in time, A*sin(2*pi*t/P + phi), P = session/2..5 (sensor "
                        "electronics / spool temperature cycling)"),
}
TUNE = [k for k, v in KINDS.items() if v[0] == "tune"]
HELD = [k for k, v in KINDS.items() if v[0] == "heldback"]
SEEDS_PER_KIND = 7


def rodrigues(rv):
    a = float(np.linalg.norm(rv))
    if a < 1e-15:
        return np.eye(3)
    k = rv / a
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * K @ K


def fk_wobble(joints, tool, q, j, tilt_deg, phi):
    """DH chain with joint j's axis tilted by tilt_deg about the horizontal direction
    (cos(2q_j+phi), sin(2q_j+phi), 0) of the stationary frame F_{j-1}"""
    T = np.eye(4)
    for i, (J, qi) in enumerate(zip(joints, q)):
        if i == j - 1:
            ang = 2 * qi * D2R + phi * D2R
            W = np.eye(4)
            W[:3, :3] = rodrigues(np.array([math.cos(ang), math.sin(ang), 0.0]) * tilt_deg * D2R)
            T = T @ W
        T = T @ link_T(J, qi, "dh")
    return (T @ np.array([*tool, 1.0]))[:3]


def gravity_moment_base(robot, q):
    """gravity moment (N*m) of all links about the base origin, base frame (nominal geometry)"""
    F = frames(robot["joints"], q, "dh")
    g = np.asarray(robot.get("gravity_in_base", [0, 0, -9.81]), float)
    M = np.zeros(3)
    for i, L in enumerate(robot["links"]):
        c = (F[i + 1] @ np.array([*L["com_mm"], 1.0]))[:3] * 1e-3
        M += np.cross(c, L["mass_kg"] * g)
    return M


# ---------------------------------------------------------------- one dataset and its twin
def sample_poses(rng, robot, rbase, true_j, tool_true, to_rig, anchors, r, points, planar, nrm, c0, side, N):
    nom = robot["joints"]
    lim = [(max(J["q_min_deg"], -180.0), min(J["q_max_deg"], 180.0)) for J in nom]  # UR5 used within +-180
    qs = []
    tries = 0
    while len(qs) < N:
        tries += 1
        if tries > 400000:
            raise RuntimeError("cannot sample poses")
        q = np.array([rng.uniform(a, b) for a, b in lim])
        pb = tool_in_base(true_j, tool_true, q, "dh")
        if points:
            if pb[2] < -150:
                continue
            qs.append(q)
            continue
        T = to_rig(pb)
        L = np.linalg.norm(T - anchors, axis=1) - r
        if not (np.all(L > 150) and np.all(L < 1900)):
            continue
        if planar and side * (nrm @ (T - c0)) < 150:
            continue
        G = (T - anchors) / np.linalg.norm(T - anchors, axis=1)[:, None]
        if np.sqrt(np.trace(np.linalg.inv(G.T @ G))) > 6:
            continue
        qs.append(q)
    home = np.array(HOME[rbase], float)
    QS = np.array(qs)
    left = list(range(N))
    order = []
    cur = home
    while left:
        dd = np.linalg.norm(QS[left] - cur, axis=1)
        k = left.pop(int(np.argmin(dd)))
        order.append(k)
        cur = QS[k]
    return QS[order], home


def make_dataset(spec):
    rng = np.random.default_rng(spec["seed"])
    kind = spec["kind"]
    rname = spec["robot"]
    robot = load_robot(rname)
    rig = make_rig(spec["rig"], rname)
    points = spec["rig"] == "points"
    nom = robot["joints"]
    n = len(nom)
    sigma = spec["sigma"]
    res = 0.024 if not points else 0.0
    # ---- true geometry (as gen2)
    true_j = copy.deepcopy(nom)
    devs = []
    for i, J in enumerate(true_j):
        dv = {"joint": i + 1, "a_mm": rng.normal(0, 0.5), "d_mm": rng.normal(0, 0.5),
              "alpha_deg": rng.normal(0, 0.1), "theta_offset_deg": rng.normal(0, 0.1), "beta_deg": 0.0}
        if i < n - 1 and abs(math.sin(nom[i]["alpha_deg"] * D2R)) < 1e-9:
            dv["beta_deg"] = rng.normal(0, 0.1)
        for k in ["a_mm", "d_mm", "alpha_deg", "theta_offset_deg", "beta_deg"]:
            J[k] = nom[i][k] + dv[k]
        devs.append(dv)
    tool_true = (np.array(robot["tool_point_mm"]) + rng.normal(0, 0.6, 3)).tolist()
    bg = rig["base_in_rig"]
    base_xyz = np.array(bg["xyz_mm"]) + rng.normal(0, 2.0, 3)
    base_rpy = np.array(bg["rpy_deg"]) + rng.normal(0, 0.4, 3)
    Rb = rpy_to_R(base_rpy)
    anchors = np.array(rig["anchors_mm"], float) if not points else np.zeros((0, 3))
    r = rig.get("r_mm", 0.0)
    planar, nrm, c0, side = False, None, None, 0
    if len(anchors) >= 3:
        c0 = anchors.mean(0)
        sv = np.linalg.svd(anchors - c0)
        nrm = sv[2][-1]
        planar = sv[1][-1] < 1.0
        side = np.sign(nrm @ (Rb @ np.array([0, 0, 600.0]) + base_xyz - c0)) if planar else 0

    def to_rig(p):
        return Rb @ p + base_xyz

    N = spec["n"]
    Q, home = sample_poses(rng, robot, rname, true_j, tool_true, to_rig, anchors, r, points, planar, nrm, c0, side, N)
    # ---- clock and temperature: warm-up plus an HVAC swing (so temperature is not a function of time alone)
    t = np.zeros(N)
    prev, tt = home, 0.0
    for k in range(N):
        tt += np.max(np.abs(Q[k] - prev)) / 30.0 + rng.uniform(6, 12)
        t[k] = tt
        prev = Q[k]
    rise = rng.uniform(3, 6)
    tau_t = rng.uniform(0.25, 0.5) * t[-1]
    swing = rng.uniform(1.0, 1.5)
    per_T = t[-1] / rng.uniform(1.5, 3.0)
    ph_T = rng.uniform(0, 2 * math.pi)
    temp_true = 20.0 + rise * (1 - np.exp(-t / tau_t)) + swing * np.sin(2 * math.pi * t / per_T + ph_T)
    temp_rec = temp_true + rng.normal(0, 0.03, N)
    split = np.where(rng.random(N) < 0.3, "test", "train")
    m_an = len(anchors)
    noise = rng.normal(0, sigma, (N, m_an) if not points else (N, 3))

    # ---- the effect's parameters (drawn whatever the kind, so every kind consumes the same rng stream)
    P = dict(spec.get("params", {}))
    P.setdefault("phi", float(rng.uniform(0, 360)))
    d = rng.normal(size=3)
    P.setdefault("dir", (d / np.linalg.norm(d)).tolist())
    P.setdefault("period_s", float(t[-1] / rng.uniform(2.0, 4.0)))
    P.setdefault("sign", float(rng.choice([-1.0, 1.0])))
    P.setdefault("pitch_mm", float(rng.uniform(30, 80)))
    P.setdefault("width_deg", float(rng.uniform(25, 40)))
    P.setdefault("q0_quantile", float(rng.uniform(0.25, 0.75)))
    if kind == "string_zero_osc":
        P["period_s"] = float(t[-1] / rng.uniform(2.0, 5.0))
    if kind == "local_bump":
        P["q0_deg"] = float(np.quantile(Q[:, P["joint"] - 1], P["q0_quantile"]))

    robot_kind = KINDS[kind][1] == "robot" if kind != "none" else False

    def robot_points(m):
        Pts = np.zeros((N, 3))
        for k in range(N):
            q = Q[k].copy()
            jj = true_j
            pb = None
            if m != 0 and kind == "cross_coupling":
                q[P["joint"] - 1] += m * math.sin((Q[k, P["source_joint"] - 1] + P["phi"]) * D2R)
            elif m != 0 and kind == "nonint_harmonic":
                q[P["joint"] - 1] += m * math.sin((P["harmonic"] * Q[k, P["joint"] - 1] + P["phi"]) * D2R)
            elif m != 0 and kind == "local_bump":
                x = (Q[k, P["joint"] - 1] - P["q0_deg"]) / (P["width_deg"] / 2)
                if abs(x) < 1:
                    q[P["joint"] - 1] += m * P["sign"] * 0.5 * (1 + math.cos(math.pi * x))
            elif m != 0 and kind == "link_thermal":
                jj = copy.deepcopy(true_j)
                key = P["length"]
                jj[P["joint"] - 1][key] += m * nom[P["joint"] - 1][key] * (temp_true[k] - temp_true[0])
            if m != 0 and kind == "axis_wobble":
                pb = fk_wobble(jj, tool_true, q, P["joint"], m, P["phi"])
            else:
                pb = tool_in_base(jj, tool_true, q, "dh")
            if m != 0 and kind == "base_tilt":
                M = gravity_moment_base(robot, Q[k])
                pb = rodrigues(m * np.array([M[0], M[1], 0.0])) @ pb
            Pts[k] = to_rig(pb)
        if m != 0 and kind == "settling":
            prevp = np.vstack([to_rig(tool_in_base(true_j, tool_true, home, "dh"))[None, :], Pts[:-1]])
            Pts = Pts + m * (Pts - prevp)
        return Pts

    def rig_shift(m):
        """translation of the rig / tracker frame at each pose (its readings see T - u)"""
        if m == 0 or kind != "rig_osc":
            return np.zeros((N, 3))
        s = np.sin(2 * math.pi * t / P["period_s"] + P["phi"] * D2R)
        return m * s[:, None] * np.array(P["dir"])[None, :]

    if kind == "eyelet_friction":
        s = P["sensor"] - 1
        # eyelet axis: from the anchor towards the workspace centre (the effect-free points)
        P0_ = robot_points(0.0)
        ax = P0_.mean(0) - anchors[s]
        ax /= np.linalg.norm(ax)
        u = (P0_ - anchors[s]) / np.linalg.norm(P0_ - anchors[s], axis=1)[:, None]
        theta = np.arccos(np.clip(u @ ax, -1, 1))
        P["theta_mean_deg"] = float(theta.mean() / D2R)
        P["eyelet_axis"] = ax.tolist()

    def measure(Pts, m):
        """noise-free readings (strings) or points (tracker) of the true points Pts with the effect at m"""
        X = Pts - rig_shift(m)
        if points:
            X = X.copy()
            if m != 0 and kind == "workspace_field":
                if P["variant"] == "z2":
                    X[:, 2] += m * ((X[:, 2] - P["z0_mm"]) / 500.0) ** 2
                else:
                    D = np.linalg.norm(X[:, :2], axis=1)
                    az = np.arctan2(X[:, 1], X[:, 0])
                    dang = m * np.sin(16 * az + P["phi"] * D2R) / 1000.0  # m: mm of tangential error per metre of range
                    tang = np.stack([-np.sin(az), np.cos(az), np.zeros(N)], 1)
                    X += (D * dang)[:, None] * tang
            return X
        L = np.linalg.norm(X[:, None, :] - anchors[None, :, :], axis=2) - r
        if m != 0 and kind in ("drum_pitch", "eyelet_friction", "string_zero_osc"):
            s = P["sensor"] - 1
            if kind == "drum_pitch":
                L[:, s] += m * np.sin(2 * math.pi * L[:, s] / P["pitch_mm"] + P["phi"] * D2R)
            elif kind == "eyelet_friction":
                u = (X - anchors[s]) / np.linalg.norm(X - anchors[s], axis=1)[:, None]
                th = np.arccos(np.clip(u @ np.array(P["eyelet_axis"]), -1, 1))
                L[:, s] += m * (th - P["theta_mean_deg"] * D2R)
            else:
                L[:, s] += m * np.sin(2 * math.pi * t / P["period_s"] + P["phi"] * D2R)
        return L

    P0 = robot_points(0.0)
    if kind == "workspace_field" and P.get("variant") == "z2":
        P["z0_mm"] = float(P0[:, 2].mean())

    def located(X, guess):
        if points:
            return X
        return np.array([multilaterate(anchors, X[k] + r, guess[k]) for k in range(N)])

    M0 = located(measure(P0, 0.0), P0)
    if points:
        point_noise = float(sigma * math.sqrt(3))
    else:
        Ln = measure(P0, 0.0) + noise
        Ln = np.round(Ln / res) * res
        point_noise = float(np.sqrt(np.mean(np.sum((located(Ln, P0) - M0) ** 2, axis=1))))

    def eff_rms(m):
        Pm = robot_points(m) if robot_kind else P0
        Mm = located(measure(Pm, m), Pm)
        return float(np.sqrt(np.mean(np.sum((Mm - M0) ** 2, axis=1))))

    mag, erms = 0.0, 0.0
    if kind != "none":
        u = KINDS[kind][2]
        ru = eff_rms(u)
        mag = u * spec["ratio"] * point_noise / ru
        if kind not in ("base_tilt", "link_thermal", "local_bump"):   # the bump carries its sign itself
            mag *= P["sign"]
        erms = eff_rms(mag)

    def write(folder, m):
        os.makedirs(folder, exist_ok=True)
        Pm = robot_points(m) if robot_kind else P0
        X = measure(Pm, m) + noise
        if not points:
            X = np.round(X / res) * res
        json.dump(robot, open(f"{folder}/robot.json", "w"), indent=1)
        json.dump(rig, open(f"{folder}/rig.json", "w"), indent=1)
        meas = ["x_mm", "y_mm", "z_mm"] if points else [f"l{i+1}_mm" for i in range(m_an)]
        cols = spec["cols"]
        with open(f"{folder}/poses.csv", "w") as f:
            f.write(",".join(["pose"] + [f"q{i+1}_deg" for i in range(n)] + meas + cols + ["split"]) + "\n")
            for k in range(N):
                row = [str(k + 1)] + [f"{v:.6f}" for v in Q[k]] + [f"{v:.6f}" for v in X[k]]
                if "time_s" in cols:
                    row.append(f"{t[k]:.3f}")
                if "temp_c" in cols:
                    row.append(f"{temp_rec[k]:.4f}")
                row.append(split[k])
                f.write(",".join(row) + "\n")

    d = f"{OUT}/{spec['name']}"
    write(d, mag)
    write(f"{d}/oracle", 0.0)
    truth = {"name": spec["name"], "kind": kind, "half": spec["half"],
             "side": KINDS[kind][1] if kind != "none" else None,
             "physics": KINDS[kind][4] if kind != "none" else "effect-free",
             "drivers": spec.get("drivers", []), "places_ok": spec.get("places_ok", []),
             "magnitude": mag, "unit": KINDS[kind][3] if kind != "none" else None,
             "params": P, "effect_rms_mm": erms, "point_noise_mm": point_noise,
             "ratio": erms / point_noise, "scaling": "RMS over the poses of the noise-free displacement of the "
             "located point (strings: multilaterated from the readings; tracker: the measured point) with the effect "
             "against without it; robot side = displacement of T",
             "robot": rname, "rig": spec["rig"], "n_poses": N, "cols": spec["cols"], "sigma": sigma,
             "session_s": float(t[-1]), "temp_rise_c": float(rise), "temp_swing_c": float(swing),
             "deviations": devs, "tool_point_mm": tool_true,
             "base_in_rig": {"xyz_mm": base_xyz.tolist(), "rpy_deg": base_rpy.tolist()}}
    json.dump(truth, open(f"{d}/truth3.json", "w"), indent=1)
    return truth


# ---------------------------------------------------------------- the plan
def place(driver, joint=None, sensor=None):
    return {"driver": driver, "joint": joint, "sensor": sensor}


def plan():
    R = np.random.default_rng(3030303)
    specs = []
    ROB = ["er3a", "ur5"]
    RIGS_ROBOT = ["std4", "s3tilt", "s5np", "points", "std4"]
    RIGS_SENS = ["std4", "s3tilt", "s5np", "std4", "s5np"]
    NSTR = {"std4": 4, "s3tilt": 3, "s5np": 5}

    def add(kind, half, i, robot, rig, params, places, drivers, cols):
        idx = len(specs)
        tag = params.get("joint") or params.get("sensor") or ""
        specs.append({"name": f"{idx:03d}_{half}_{kind}{tag}_{robot}_{rig}", "kind": kind, "half": half,
                      "robot": robot, "rig": rig, "n": int(R.integers(150, 201)), "seed": 600000 + idx,
                      "sigma": 0.02 if rig != "points" else 0.03, "ratio": float(R.uniform(3, 6)),
                      "params": params, "places_ok": places, "drivers": drivers, "cols": cols})

    def rand_cols():
        return [["time_s", "temp_c"], ["time_s"], [], ["time_s", "temp_c"]][int(R.integers(0, 4))]

    for kind in KINDS:
        half = KINDS[kind][0]
        for i in range(SEEDS_PER_KIND):
            rb = ROB[i % 2]
            rig = RIGS_ROBOT[i % 5]
            cols = rand_cols()
            if kind == "cross_coupling":
                a, b = [(2, 3), (3, 2), (4, 5), (2, 3), (3, 2)][i % 5]
                prm = {"source_joint": a, "joint": b}
                places, drivers = [place("joint", a), place("joint", b)], [f"joint {a} angle"]
            elif kind == "nonint_harmonic":
                j = [1, 2, 3, 1, 2, 3, 1][i % 7]
                prm = {"joint": j, "harmonic": [1.5, 2.5, 4.7, 3.3, 1.5, 2.5, 3.3][i % 7]}
                places, drivers = [place("joint", j)], [f"joint {j} angle"]
            elif kind == "base_tilt":
                prm = {}
                places = [place("joint", 2), place("joint", 3), place("workspace")]
                drivers = ["configuration (horizontal gravity moment about the base: q1, q2, q3 mostly)"]
            elif kind == "rig_osc":
                rig = ["points", "std4", "s5np", "s3tilt", "points"][i % 5]
                cols = ["time_s", "temp_c"] if i % 2 == 0 else ["time_s"]
                prm = {}
                places, drivers = [place("time"), place("order")], ["time"]
            elif kind in ("drum_pitch", "eyelet_friction", "string_zero_osc"):
                rig = RIGS_SENS[i % 5]
                s = int(R.integers(1, NSTR[rig] + 1))
                prm = {"sensor": s}
                if kind == "drum_pitch":
                    places, drivers = [place("string", sensor=s)], [f"string {s} length"]
                elif kind == "eyelet_friction":
                    places = [place("string", sensor=s), place("workspace", sensor=s)]
                    drivers = [f"string {s} direction (position of T relative to anchor {s})"]
                else:
                    cols = ["time_s", "temp_c"] if i % 2 == 0 else ["time_s"]
                    places, drivers = [place("time", sensor=s), place("order", sensor=s)], ["time"]
            elif kind == "workspace_field":
                rig = "points"
                prm = {"variant": ["z2", "azimuth16"][i % 2]}
                places, drivers = [place("workspace")], ["workspace position"]
            elif kind == "local_bump":
                j = [2, 3, 1, 2, 3, 1, 2][i % 7]
                prm = {"joint": j}
                places, drivers = [place("joint", j)], [f"joint {j} angle"]
            elif kind == "axis_wobble":
                j = [1, 2, 3, 2, 1, 3, 2][i % 7]
                prm = {"joint": j}
                places, drivers = [place("joint", j)], [f"joint {j} angle"]
            elif kind == "link_thermal":
                cols = ["time_s", "temp_c"] if i % 2 == 0 else ["temp_c"]
                if rb == "er3a":
                    j, key = [(2, "a_mm"), (4, "d_mm"), (1, "d_mm")][i // 2 % 3]
                else:
                    j = [2, 3][i // 2 % 2]
                    key = "a_mm"
                prm = {"joint": j, "length": key}
                places, drivers = [place("temperature")], ["temperature"]
            elif kind == "settling":
                prm = {}
                places, drivers = [place("motion")], ["the move that led to the pose (previous pose)"]
            add(kind, half, i, rb, rig, prm, places, drivers, cols)
    # effect-free: same conditions, half and half
    n_null = len(specs)
    for i in range(n_null):
        rig = ["std4", "s3tilt", "s5np", "points", "std4", "s5np"][i % 6]
        add("none", ["tune", "heldback"][i % 2], i, ROB[(i // 2) % 2], rig, {}, [], [], rand_cols())
    return specs


def run_tool(folder, physics, out, timeout=240):
    t0 = time.time()
    with open(f"{folder}/{out}.log", "w") as log:
        try:
            p = subprocess.run(["timeout", str(timeout), TOOL, "identify", "--robot", f"{folder}/robot.json",
                                "--rig", f"{folder}/rig.json", "--poses", f"{folder}/poses.csv",
                                "--physics", physics, "--out", f"{folder}/{out}.json"],
                               stdout=log, stderr=subprocess.STDOUT)
            rc = p.returncode
        except Exception:
            rc = -999
    return rc, time.time() - t0


def run(only=None):
    specs = json.load(open(f"{OUT}/plan.json"))
    for s in specs:
        if only and only not in s["name"]:
            continue
        d = f"{OUT}/{s['name']}"
        if not os.path.exists(f"{d}/truth3.json"):
            continue
        rc1, t1 = run_tool(d, "on", "report")
        rc2, t2 = run_tool(f"{d}/oracle", "off", "report")
        json.dump({"rc": rc1, "secs": t1, "oracle_rc": rc2, "oracle_secs": t2}, open(f"{d}/run.json", "w"))
        print(s["name"], f"rc={rc1} {t1:.1f}s oracle rc={rc2} {t2:.1f}s", flush=True)


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "list"
    if cmd == "list":
        for k, v in KINDS.items():
            print(f"{k:16s} {v[0]:8s} {v[1]:6s} {v[4]}")
    elif cmd == "plan":
        specs = plan()
        os.makedirs(OUT, exist_ok=True)
        json.dump(specs, open(f"{OUT}/plan.json", "w"), indent=1)
        only = sys.argv[2] if len(sys.argv) > 2 else None
        for s in specs:
            if only and only not in s["name"]:
                continue
            if os.path.exists(f"{OUT}/{s['name']}/truth3.json"):
                continue
            t0 = time.time()
            tr = make_dataset(s)
            print(s["name"], f"N={tr['n_poses']} noise={tr['point_noise_mm']:.4f} mag={tr['magnitude']:.4g} "
                  f"{tr['unit']} rms={tr['effect_rms_mm']:.3f} ratio={tr['ratio']:.2f} {time.time()-t0:.1f}s",
                  flush=True)
    elif cmd == "run":
        run(sys.argv[2] if len(sys.argv) > 2 else None)
    elif cmd == "score":
        import score3
        score3.main(OUT)
    else:
        print(__doc__)
