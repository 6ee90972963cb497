#!/usr/bin/env python3
"""Fourth independent cross-check of drawcal: a fresh, blind set of physics OUTSIDE the catalogue.

Written on 2026-12-05 from physics descriptions (robots, drawstring encoders,
laser trackers) and from DATA_FORMAT.md, README.md, docs/CLI.md and the earlier
cross-check simulators only -- WITHOUT reading src/, docs/PHYSICS.md, EVAL.md or
tests/*.rs.  The tool version measured is commit 53cffe5 (binary
/tmp/drawcal-53cffe5).

None of the kinds below is a catalogue effect (joint_compliance, backlash,
joint_periodic, joint_scale, base_tilt, thermal_expansion, sensor_scale,
sensor_offset, sensor_drift, cable_sag, anchor_step, rig_step, rig_drift) nor one
of gen3.py's kinds.  Several are chosen to RESEMBLE a catalogue effect without
being it (see `resembles` in KINDS): naming that catalogue effect is a misname.

Kinematics, robots, rigs, multilateration and pose sampling are the earlier
simulators' (imported from sim.py / gen2.py / gen3.py, one definition).  Every
dataset <name>/ has a twin <name>/oracle/ with the identical poses, split column,
geometric deviations, base pose and noise realisation but WITHOUT the effect; the
tool is run on the twin with `--physics off`.  truth3.json has gen3's fields, so
score3.py scores these datasets unchanged.

Usage (from the repository root):
    python3 tests/crosscheck/gen4.py list    # one line of physics per kind
    python3 tests/crosscheck/gen4.py plan    # write every dataset and its twin
    python3 tests/crosscheck/gen4.py run     # run the tool (one process at a time, timeout)
    python3 tests/crosscheck/gen4.py score   # = score3.py on XC4_OUT
Env: XC4_OUT (default /tmp/xcheck4/ds), XCHECK_DATA (default tests/data),
     XCHECK_TOOL (default target/release/drawcal)
"""
import json, math, os, sys, copy, time
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim import rpy_to_R  # noqa: E402
import gen2  # noqa: E402
import gen3  # noqa: E402
from gen2 import frames, tool_in_base, multilaterate, make_rig, load_robot, HOME  # noqa: E402
from gen3 import rodrigues, sample_poses, place  # noqa: E402

OUT = os.environ.get("XC4_OUT", "/tmp/xcheck4/ds")
SRC = os.environ.get("XCHECK_DATA", "tests/data")
TOOL = os.environ.get("XCHECK_TOOL", "target/release/drawcal")
gen2.SRC = SRC
gen3.TOOL = TOOL
D2R = math.pi / 180.0
HALF = "blind4"

# ---------------------------------------------------------------- the kinds
# kind: (side, unit magnitude, unit, resembles (catalogue name or ""), one line of physics)
KINDS = {
    # ---- robot side
    "link_bending": ("robot", 1e-5, "1/(N*m^2) (=1/EI)", "joint_compliance",
                     "the upper arm (link 2, joint-2 axis to joint-3 axis) bends as an Euler-Bernoulli cantilever "
                     "under the gravity of the outboard links (tip force + tip moment) and its own weight; the elbow "
                     "is displaced AND rotated, a coupled function of q2, q3 (and the wrist), not a joint rotation"),
    "payload_tool_droop": ("robot", 1e-3, "rad/(N*m)", "joint_compliance",
                           "a compliant tool adapter / quick-changer: the tool tilts about the flange by c * (gravity "
                           "moment of the payload at T about the flange), so T droops by c*m*|r|^2*g_perp; payload_kg "
                           "changes in blocks of 10-20 poses (0 / 1.5 / 3 kg)"),
    "harness_windup": ("robot", 0.01, "deg", "joint_scale",
                       "joint 1 or 4: the dress pack twisted towards either end of travel pulls the joint back "
                       "towards neutral, error -k*sign(x)*((|x|-x0)/(1-x0))^2 for |x|>x0, 0 inside "
                       "(x = angle over the sampled half-range, x0 = 0.4-0.6)"),
    "joint_hysteresis": ("robot", 0.01, "deg", "backlash",
                         "joint 1/2/3 stops short of its target by b*tanh(dq/w), dq = its own last move, w ~ the "
                         "median move (friction / elasto-plastic wind-up: graded with the move size, not a "
                         "two-level approach-side play)"),
    "joint_zero_step": ("robot", 0.01, "deg", "rig_step",
                        "joint 1/2/3's zero jumps by delta at one instant (re-homing / encoder count lost after a "
                        "stop) at 30-70 % of the session: a joint-local step in time, the rig does not move"),
    # ---- sensor side (one string)
    "string_hysteresis": ("sensor", 0.01, "mm", "backlash",
                          "one string's reading depends on its own direction of travel, h*tanh(dl/2mm), dl = the "
                          "change of its length since the previous pose (spool friction / cable stretch: "
                          "pulled-out vs retracted)"),
    "string_linearity": ("sensor", 0.01, "mm", "sensor_scale",
                         "one string's potentiometer linearity error, a slow wave over the full scale: "
                         "k*sin(2*pi*l/p + phi), p = FS/1.5, FS/2 or FS/3 (667-1333 mm; not a drum pitch, not a scale)"),
    "string_sawtooth": ("sensor", 0.01, "mm", "sensor_drift",
                        "one string's zero creeps linearly and resets periodically (auto-zero of the electronics / "
                        "thermostat cycling of the spool): A*(frac(t/P + ph) - 0.5), P = session/2.5..5"),
    # ---- rig / instrument side
    "anchor_post_flex": ("sensor", 0.01, "mm", "cable_sag",
                         "one anchor's post is a cantilever bent by the HORIZONTAL pull of its string: the exit "
                         "point moves towards T, reading off by -c*(|u_h|^2 - mean), u_h = horizontal part of the "
                         "unit string direction (depends on the string's elevation, not on its span)"),
    "rig_thermal": ("point", 1e-5, "1/K", "thermal_expansion",
                    "the string frame (aluminium) expands with the ambient temperature about its anchor centroid, "
                    "A' = c + (1 + alpha*(T - Tmean))*(A - c); the ROBOT does not change (strings only)"),
    "rig_creep_exp": ("point", 0.01, "mm", "rig_drift",
                      "the rig / tracker settles after set-up: translation A*(1 - exp(-t/tau)) along a fixed "
                      "direction, tau = session*0.08..0.2 (exponential settling, not a linear creep)"),
    "rig_knock_recover": ("point", 0.01, "mm", "rig_step",
                          "the rig / tracker is knocked at t0 (30-70 % of the session) and springs back: translation "
                          "A*exp(-(t-t0)/tau) for t >= t0, tau = session*0.05..0.15 (step-and-recover, not a step)"),
}
SEEDS_PER_KIND = 6
N_NULL = 8
ROBOT_SIDE = {k for k, v in KINDS.items() if v[0] == "robot"}


def bend_link2(robot, F, pb, m):
    """Euler-Bernoulli cantilever for link 2 (F[1] origin -> F[2] origin) under the outboard links' weight
    (tip force and moment at F[2] origin) and its own distributed weight; m = 1/EI in 1/(N*m^2).
    Returns T after the elbow is displaced by delta and rotated by theta."""
    g = np.asarray(robot.get("gravity_in_base", [0, 0, -9.81]), float)
    o1, o2 = F[1][:3, 3] * 1e-3, F[2][:3, 3] * 1e-3
    Lv = o2 - o1
    L = float(np.linalg.norm(Lv))
    e = Lv / L
    links = robot["links"]
    Ft, Mt = np.zeros(3), np.zeros(3)
    for i in range(2, len(links)):
        c = (F[i + 1] @ np.array([*links[i]["com_mm"], 1.0]))[:3] * 1e-3
        Ft += links[i]["mass_kg"] * g
        Mt += np.cross(c - o2, links[i]["mass_kg"] * g)
    w = links[1]["mass_kg"] * g / L
    perp = lambda v: v - (v @ e) * e
    Fp, Mp, wp = perp(Ft), perp(Mt), perp(w)
    delta = m * (Fp * L ** 3 / 3 + np.cross(Mp, e) * L ** 2 / 2 + wp * L ** 4 / 8)
    theta = m * (np.cross(e, Fp) * L ** 2 / 2 + Mp * L + np.cross(e, wp) * L ** 3 / 6)
    p = pb * 1e-3
    return (o2 + delta + rodrigues(theta) @ (p - o2)) * 1e3


def tool_droop(robot, F, pb, m, payload):
    """compliant tool adapter: rotation c*M about the flange origin, M = payload gravity moment"""
    if payload == 0 or m == 0:
        return pb
    g = np.asarray(robot.get("gravity_in_base", [0, 0, -9.81]), float)
    fo = F[-1][:3, 3] * 1e-3
    r = pb * 1e-3 - fo
    M = np.cross(r, payload * g)
    return (fo + rodrigues(m * M) @ r) * 1e3


# ---------------------------------------------------------------- one dataset and its twin
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
    # ---- true geometry (as gen2 / gen3)
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
    # ---- clock and temperature (as gen3: warm-up plus an HVAC swing)
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
    # ---- payload in blocks of 10-20 poses (drawn whatever the kind; written only where cols ask)
    payload = np.zeros(N)
    levels = [0.0, 1.5, 3.0]
    k, b = 0, 0
    perm = list(rng.permutation(3))
    while k < N:
        ln = int(rng.integers(10, 21))
        payload[k:k + ln] = levels[perm[b % 3]]
        k += ln
        b += 1
    dQ = np.diff(np.vstack([np.asarray(home, float)[None, :], Q]), axis=0)   # each joint's move into the pose

    # ---- the effect's parameters (drawn whatever the kind: every kind consumes the same rng stream)
    P = dict(spec.get("params", {}))
    P.setdefault("phi", float(rng.uniform(0, 360)))
    d = rng.normal(size=3)
    P.setdefault("dir", (d / np.linalg.norm(d)).tolist())
    P.setdefault("sign", float(rng.choice([-1.0, 1.0])))
    P.setdefault("step_frac", float(rng.uniform(0.3, 0.7)))
    P.setdefault("x0", float(rng.uniform(0.4, 0.6)))
    P.setdefault("w_factor", float(rng.uniform(0.7, 1.3)))
    P.setdefault("lin_cycles", float(rng.choice([1.5, 2.0, 3.0])))
    P.setdefault("saw_cycles", float(rng.uniform(2.5, 5.0)))
    P.setdefault("saw_phase", float(rng.uniform(0, 1)))
    P.setdefault("tau_frac", float(rng.uniform(0.08, 0.2) if kind == "rig_creep_exp" else rng.uniform(0.05, 0.15)))
    j = P.get("joint")
    if kind == "joint_zero_step":
        P["k0"] = int(np.searchsorted(t, P["step_frac"] * t[-1]))
        P["t0_s"] = float(t[P["k0"]])
    if kind == "rig_knock_recover":
        P["t0_s"] = float(P["step_frac"] * t[-1])
    if kind in ("rig_creep_exp", "rig_knock_recover"):
        P["tau_s"] = float(P["tau_frac"] * t[-1])
    if kind == "joint_hysteresis":
        P["w_deg"] = float(P["w_factor"] * np.median(np.abs(dQ[:, j - 1])))
    if kind == "harness_windup":
        lo, hi = max(nom[j - 1]["q_min_deg"], -180.0), min(nom[j - 1]["q_max_deg"], 180.0)
        P["mid_deg"], P["half_deg"] = (lo + hi) / 2, (hi - lo) / 2
    if kind == "string_sawtooth":
        P["period_s"] = float(t[-1] / P["saw_cycles"])
    if kind == "string_linearity":
        P["period_mm"] = float(rig.get("sensor", {}).get("range_mm", 2000.0) / P["lin_cycles"])
    g_rig = Rb @ np.array([0, 0, -1.0])   # gravity direction in the rig frame

    def robot_points(m):
        Pts = np.zeros((N, 3))
        for k in range(N):
            q = Q[k].copy()
            if m != 0 and kind == "harness_windup":
                x = (Q[k, j - 1] - P["mid_deg"]) / P["half_deg"]
                ex = max(abs(x) - P["x0"], 0.0) / (1 - P["x0"])
                q[j - 1] -= m * math.copysign(ex * ex, x)
            elif m != 0 and kind == "joint_hysteresis":
                q[j - 1] -= m * math.tanh(dQ[k, j - 1] / P["w_deg"])
            elif m != 0 and kind == "joint_zero_step" and k >= P["k0"]:
                q[j - 1] += m
            F = frames(true_j, q, "dh")
            pb = (F[-1] @ np.array([*tool_true, 1.0]))[:3]
            if m != 0 and kind == "link_bending":
                pb = bend_link2(robot, F, pb, m)
            elif m != 0 and kind == "payload_tool_droop":
                pb = tool_droop(robot, F, pb, m, payload[k])
            Pts[k] = to_rig(pb)
        return Pts

    def rig_shift(m):
        """translation of the rig / tracker frame at each pose (its readings see T - u)"""
        if m == 0 or kind not in ("rig_creep_exp", "rig_knock_recover"):
            return np.zeros((N, 3))
        if kind == "rig_creep_exp":
            s = 1 - np.exp(-t / P["tau_s"])
        else:
            s = np.where(t >= P["t0_s"], np.exp(-(t - P["t0_s"]) / P["tau_s"]), 0.0)
        return m * s[:, None] * np.array(P["dir"])[None, :]

    P0 = robot_points(0.0)
    L0 = None
    if not points:
        L0 = np.linalg.norm(P0[:, None, :] - anchors[None, :, :], axis=2) - r
        L_home = np.linalg.norm(to_rig(tool_in_base(true_j, tool_true, home, "dh")) - anchors, axis=1) - r
        dL = np.diff(np.vstack([L_home[None, :], L0]), axis=0)   # each string's change into the pose
    if kind == "anchor_post_flex":
        s_ = P["sensor"] - 1
        u = (P0 - anchors[s_]) / np.linalg.norm(P0 - anchors[s_], axis=1)[:, None]
        P["uh2_mean"] = float(np.mean(1 - (u @ g_rig) ** 2))
    if kind == "rig_thermal":
        P["temp_mean_c"] = float(temp_true.mean())

    def measure(Pts, m):
        """noise-free readings (strings) or points (tracker) of the true points Pts with the effect at m"""
        X = Pts - rig_shift(m)
        if points:
            return X
        if m != 0 and kind == "rig_thermal":
            c = anchors.mean(0)
            L = np.zeros((N, m_an))
            for k in range(N):
                Ak = c + (1 + m * (temp_true[k] - P["temp_mean_c"])) * (anchors - c)
                L[k] = np.linalg.norm(X[k] - Ak, axis=1) - r
        else:
            L = np.linalg.norm(X[:, None, :] - anchors[None, :, :], axis=2) - r
        if m != 0 and kind in ("string_hysteresis", "string_linearity", "string_sawtooth", "anchor_post_flex"):
            s_ = P["sensor"] - 1
            if kind == "string_hysteresis":
                L[:, s_] += m * np.tanh(dL[:, s_] / 2.0)
            elif kind == "string_linearity":
                L[:, s_] += m * np.sin(2 * math.pi * L[:, s_] / P["period_mm"] + P["phi"] * D2R)
            elif kind == "string_sawtooth":
                L[:, s_] += m * (np.mod(t / P["period_s"] + P["saw_phase"], 1.0) - 0.5)
            else:
                u = (X - anchors[s_]) / np.linalg.norm(X - anchors[s_], axis=1)[:, None]
                L[:, s_] -= m * ((1 - (u @ g_rig) ** 2) - P["uh2_mean"])
        return L

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

    robot_kind = kind in ROBOT_SIDE

    def eff_rms(m):
        Pm = robot_points(m) if robot_kind else P0
        Mm = located(measure(Pm, m), Pm)
        return float(np.sqrt(np.mean(np.sum((Mm - M0) ** 2, axis=1))))

    mag, erms = 0.0, 0.0
    if kind != "none":
        u_ = KINDS[kind][1]
        ru = eff_rms(u_)
        mag = u_ * spec["ratio"] * point_noise / ru
        if kind in ("joint_zero_step", "string_hysteresis", "string_sawtooth"):
            mag *= P["sign"]
        erms = eff_rms(mag)

    rng_info = {}
    if not points:
        Lm = measure(robot_points(mag) if robot_kind else P0, mag)
        rng_info = {"l_min_mm": float(Lm.min()), "l_max_mm": float(Lm.max())}

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
                for c in cols:
                    row.append({"time_s": f"{t[k]:.3f}", "temp_c": f"{temp_rec[k]:.4f}",
                                "payload_kg": f"{payload[k]:.2f}"}[c])
                row.append(split[k])
                f.write(",".join(row) + "\n")

    dname = f"{OUT}/{spec['name']}"
    write(dname, mag)
    write(f"{dname}/oracle", 0.0)
    truth = {"name": spec["name"], "kind": kind, "half": spec["half"],
             "side": KINDS[kind][0] if kind != "none" else None,
             "resembles": KINDS[kind][3] if kind != "none" else None,
             "physics": KINDS[kind][4] if kind != "none" else "effect-free",
             "drivers": spec.get("drivers", []), "places_ok": spec.get("places_ok", []),
             "magnitude": mag, "unit": KINDS[kind][2] if kind != "none" else None,
             "params": P, "effect_rms_mm": erms, "point_noise_mm": point_noise,
             "ratio": erms / point_noise, "scaling": "as gen3: RMS over the poses of the noise-free displacement of "
             "the located point (strings: multilaterated with the nominal anchors from the readings; tracker: the "
             "measured point) with the effect against without it",
             "robot": rname, "rig": spec["rig"], "n_poses": N, "cols": spec["cols"], "sigma": sigma,
             "session_s": float(t[-1]), "temp_rise_c": float(rise), "temp_swing_c": float(swing),
             "deviations": devs, "tool_point_mm": tool_true, **rng_info,
             "base_in_rig": {"xyz_mm": base_xyz.tolist(), "rpy_deg": base_rpy.tolist()}}
    json.dump(truth, open(f"{dname}/truth3.json", "w"), indent=1)
    return truth


# ---------------------------------------------------------------- the plan
def plan():
    R = np.random.default_rng(4040404)
    specs = []
    ROB = ["er3a", "ur5"]
    RIGS_ROBOT = ["std4", "s3tilt", "s5np", "points", "points", "std4"]
    RIGS_STR = ["std4", "s3tilt", "s5np", "s5np", "s3tilt", "std4"]
    NSTR = {"std4": 4, "s3tilt": 3, "s5np": 5}

    def add(kind, i, robot, rig, params, places, drivers, cols):
        idx = len(specs)
        tag = params.get("joint") or params.get("sensor") or ""
        specs.append({"name": f"{idx:03d}_{kind}{tag}_{robot}_{rig}", "kind": kind, "half": HALF,
                      "robot": robot, "rig": rig, "n": int(R.integers(150, 201)), "seed": 700000 + idx,
                      "sigma": 0.02 if rig != "points" else 0.03, "ratio": float(R.uniform(3, 6)),
                      "params": params, "places_ok": places, "drivers": drivers, "cols": cols})

    def rand_cols():
        return [["time_s", "temp_c"], ["time_s"], [], ["time_s", "temp_c", "payload_kg"]][int(R.integers(0, 4))]

    def with_time(i):
        return ["time_s", "temp_c"] if i % 2 == 0 else ["time_s"]

    for kind in KINDS:
        for i in range(SEEDS_PER_KIND):
            rb = ROB[i % 2]
            rig = RIGS_ROBOT[i]
            cols = rand_cols()
            prm = {}
            if kind == "link_bending":
                places, drivers = [place("joint", 2), place("joint", 3), place("workspace")], \
                    ["configuration (gravity load on the upper arm: q2, q3 and the wrist)"]
            elif kind == "payload_tool_droop":
                cols = [["payload_kg"], ["time_s", "temp_c", "payload_kg"], ["time_s", "payload_kg"]][i % 3]
                places, drivers = [place("payload")], ["payload_kg (times the tool axis' angle to gravity)"]
            elif kind == "harness_windup":
                j = [1, 4][i // 2 % 2] if i < 4 else [1, 4][i % 2]
                prm = {"joint": j}
                places, drivers = [place("joint", j)], [f"joint {j} angle (ends of travel)"]
            elif kind == "joint_hysteresis":
                j = [1, 2, 3, 2, 3, 1][i]
                prm = {"joint": j}
                places, drivers = [place("motion", j)], [f"joint {j}'s last move"]
            elif kind == "joint_zero_step":
                j = [2, 3, 1, 1, 2, 3][i]
                prm = {"joint": j}
                cols = with_time(i)
                places, drivers = [place("time", j), place("order", j)], [f"time (a step of joint {j}'s zero)"]
            elif kind in ("string_hysteresis", "string_linearity", "string_sawtooth", "anchor_post_flex"):
                rig = RIGS_STR[i]
                s = int(R.integers(1, NSTR[rig] + 1))
                prm = {"sensor": s}
                if kind == "string_hysteresis":
                    places, drivers = [place("string", sensor=s), place("motion", sensor=s)], \
                        [f"string {s}'s direction of travel"]
                elif kind == "string_linearity":
                    places, drivers = [place("string", sensor=s)], [f"string {s} length"]
                elif kind == "string_sawtooth":
                    cols = with_time(i)
                    places, drivers = [place("time", sensor=s), place("order", sensor=s)], ["time"]
                else:
                    places, drivers = [place("string", sensor=s), place("workspace", sensor=s)], \
                        [f"string {s}'s elevation angle (position of T relative to anchor {s})"]
            elif kind == "rig_thermal":
                rig = RIGS_STR[i]
                cols = ["time_s", "temp_c"] if i % 2 == 0 else ["temp_c"]
                places, drivers = [place("temperature")], ["temperature"]
            elif kind in ("rig_creep_exp", "rig_knock_recover"):
                rig = ["points", "std4", "s5np", "s3tilt", "std4", "points"][i]
                cols = with_time(i)
                places, drivers = [place("time"), place("order")], ["time"]
            add(kind, i, rb, rig, prm, places, drivers, cols)
    for i in range(N_NULL):
        rig = ["std4", "s3tilt", "s5np", "points", "std4", "s5np", "s3tilt", "points"][i]
        cols = [["time_s", "temp_c"], ["time_s", "temp_c", "payload_kg"], ["time_s"], [],
                ["payload_kg"], ["time_s", "temp_c"], ["time_s", "temp_c", "payload_kg"], ["time_s"]][i]
        add("none", i, ROB[i % 2], rig, {}, [], [], cols)
    return specs


def run(only=None):
    specs = json.load(open(f"{OUT}/plan.json"))
    for s in specs:
        if only and only not in s["name"]:
            continue
        d = f"{OUT}/{s['name']}"
        if not os.path.exists(f"{d}/truth3.json"):
            continue
        rc1, t1 = gen3.run_tool(d, "on", "report")
        rc2, t2 = gen3.run_tool(f"{d}/oracle", "off", "report")
        json.dump({"rc": rc1, "secs": t1, "oracle_rc": rc2, "oracle_secs": t2}, open(f"{d}/run.json", "w"))
        print(s["name"], f"rc={rc1} {t1:.1f}s oracle rc={rc2} {t2:.1f}s", flush=True)


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "list"
    if cmd == "list":
        for k, v in KINDS.items():
            print(f"{k:19s} {v[0]:6s} ~{v[3]:17s} {v[4]}")
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
            lr = f" l=[{tr['l_min_mm']:.0f},{tr['l_max_mm']:.0f}]" if "l_min_mm" in tr else ""
            print(s["name"], f"N={tr['n_poses']} noise={tr['point_noise_mm']:.4f} mag={tr['magnitude']:.4g} "
                  f"{tr['unit']} rms={tr['effect_rms_mm']:.3f} ratio={tr['ratio']:.2f}{lr} {time.time()-t0:.1f}s",
                  flush=True)
    elif cmd == "run":
        run(sys.argv[2] if len(sys.argv) > 2 else None)
    elif cmd == "score":
        import score3
        score3.main(OUT)
    else:
        print(__doc__)
