#!/usr/bin/env python3
"""Fifth independent cross-check of drawcal: another fresh, blind set of physics OUTSIDE the catalogue,
with a tune half (tune5) and a held-back half (heldback5).

Written blind: from physics descriptions of industrial arms, drawstring encoder rigs and laser
trackers, from DATA_FORMAT.md, README.md, docs/CLI.md and the earlier cross-check simulators
(sim.py, gen2.py, gen3.py, gen4.py) and their scorer score3.py only -- WITHOUT reading src/,
docs/PHYSICS.md, EVAL.md, BENCHMARKS.md, tests/*.rs or the git history.  The tool version measured
is commit 927c580 (binary /tmp/bin/drawcal-927c580).

None of the kinds below is a catalogue effect (joint_compliance, backlash, joint_periodic,
joint_scale, base_tilt, thermal_expansion, sensor_scale, sensor_offset, sensor_drift, cable_sag,
anchor_step, rig_step, rig_drift) nor one of gen3.py's or gen4.py's kinds.  Most are chosen to
RESEMBLE a catalogue effect without being it (`resembles` in KINDS): naming that catalogue effect
is a misname.  Every effect is written with its session mean taken out where a constant part would
be an exact reparametrisation of the geometric model (a constant joint offset, tool offset, rig
pose), so the scaled RMS is the part an analysis can see.

Kinematics, robots, rigs, multilateration and pose sampling are the earlier simulators' (imported
from sim.py / gen2.py / gen3.py, one definition).  Every dataset <name>/ has a twin <name>/oracle/
with the identical poses, split column, geometric deviations, base pose and noise realisation but
WITHOUT the effect; the tool is run on the twin with `--physics off`.  truth3.json has gen3's /
gen4's fields, so score3.py scores these datasets unchanged; score3.py groups its summary by the
halves `tune` / `heldback`, so `gen5.py score` computes the per-half summary itself (tune5,
heldback5, overall) with score3.py's own functions.

Design notes (decided on the effects' visibility, not on the tool's findings):
- joint-local zero drifts (motor_heat_zero, joint_zero_thermal) use joints 2 and 3 only: joint 1's
  zero moving in time is exactly a rig yaw about joint 1's axis, which no analysis can tell apart;
- frame_tension_sway is a smooth field the geometric fit half absorbs (`visible`: 1.3-2.2x the twin
  at ratios 3-6), so its ratio is drawn in 4.5-6;
- magnitudes follow the ratio 3-6 to the point noise, so some are larger than the physics usually
  gives: tracker_air_temp (4-7e-5/K against ~1e-6/K for air), drum_thermal_scale (1-2.4e-4/K against
  2.3e-5/K for aluminium), tracker_adm_cyclic (0.2-0.4 mm against 0.01-0.03 mm);
- `visible` at 927c580: every effect dataset with --physics off is 1.58x or more the twin's held-out
  RMS (tune5 gmean 3.68, heldback5 gmean 4.11); effect-free datasets 1.000.

Usage (from the repository root):
    python3 tests/crosscheck/gen5.py list        # one line of physics per kind
    python3 tests/crosscheck/gen5.py plan        # write every dataset and its twin
    python3 tests/crosscheck/gen5.py run [sub]   # run the tool (one process at a time, timeout)
    python3 tests/crosscheck/gen5.py score       # tune5 per dataset and per kind; heldback5 aggregate only
    python3 tests/crosscheck/gen5.py score full  # also heldback5 per dataset and per kind (unblinds it)
    python3 tests/crosscheck/gen5.py visible     # sanity: the effect datasets with --physics off against
                                                 # the twin (is the effect visible at all?); aggregate per half
Env: XC5_OUT (default /tmp/xcheck5/ds), XCHECK_DATA (default tests/data),
     XCHECK_TOOL (default target/release/drawcal)
"""
import json, math, os, sys, copy, time
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim import rpy_to_R  # noqa: E402
import gen2  # noqa: E402
import gen3  # noqa: E402
from gen2 import frames, tool_in_base, multilaterate, make_rig, load_robot, gravity_torques  # noqa: E402
from gen3 import rodrigues, sample_poses, place, gravity_moment_base  # noqa: E402

OUT = os.environ.get("XC5_OUT", "/tmp/xcheck5/ds")
SRC = os.environ.get("XCHECK_DATA", "tests/data")
TOOL = os.environ.get("XCHECK_TOOL", "target/release/drawcal")
gen2.SRC = SRC
gen3.TOOL = TOOL
D2R = math.pi / 180.0
HALVES = ("tune5", "heldback5")

# ---------------------------------------------------------------- the kinds
# kind: (half, side, unit magnitude, unit, resembles (catalogue name or ""), one line of physics)
KINDS = {
    # ---- robot side
    "motor_heat_zero": ("tune5", "robot", 0.01, "deg",
                        "thermal_expansion",
                        "joint 2/3's zero drifts with its OWN motor/gearbox heating: offset k*H, H a first-order "
                        "lag (tau = session*0.2..0.5) of the joint's cumulative travel, H_k = H_{k-1}*exp(-dt/tau) + "
                        "|dq_k| (not the ambient temperature, not a length)"),
    "gravity_preload_play": ("tune5", "robot", 0.01, "deg",
                             "backlash",
                             "joint 2/3's gear play is taken up by gravity: the joint rests on the flank its gravity "
                             "torque pushes it to, error b*tanh(tau_g/w), w = 0.1*std(tau_g) (two levels chosen by "
                             "the SIGN of the gravity torque, a function of the configuration, not the approach side)"),
    "tool_reseat": ("heldback5", "robot", 0.01, "mm",
                    "rig_step",
                    "the probe / SMR nest is re-seated at t0 (30-70 % of the session): T jumps by delta in the "
                    "FLANGE frame, so its shift in the rig frame turns with the flange orientation (not a rig move)"),
    "joint_zero_thermal": ("heldback5", "robot", 0.01, "deg/K",
                           "thermal_expansion",
                           "joint 2/3's zero (absolute encoder / gearbox mount) drifts with the ambient "
                           "temperature, k*(T - Tmean): an angle, no link grows"),
    # ---- sensor side (one string)
    "drum_layer_change": ("tune5", "sensor", 1e-3, "mm/mm",
                          "sensor_scale",
                          "one string's cable changes winding (layer change / end of the helical groove) at a length "
                          "l_th (35-65 % quantile of its lengths): the reading's slope changes there, error "
                          "k*(max(0, l - l_th) - mean): a kink, not a scale"),
    "string_count_slip": ("tune5", "sensor", 0.01, "mm",
                          "sensor_drift",
                          "one string's incremental encoder loses a fixed number of counts whenever the string "
                          "retracts fast by more than a threshold (60-80 % quantile of its retractions) in one move: "
                          "a staircase driven by that string's own motion history"),
    "drum_thermal_scale": ("heldback5", "sensor", 1e-5, "1/K",
                           "sensor_scale",
                           "one string's drum (aluminium) expands with the temperature: reading = l*(1 - "
                           "alpha*(T - Tmean)), a temperature-times-length error of that string only"),
    "string_crosstalk": ("heldback5", "sensor", 1e-3, "mm/mm",
                         "sensor_scale",
                         "one string's channel picks up a fraction of ANOTHER string's signal (shared ADC reference "
                         "/ ground): reading_s += k*(l_o - mean l_o)"),
    # ---- rig / instrument side
    "frame_tension_sway": ("tune5", "rig", 0.01, "mm",
                           "",
                           "the string frame sits on compliant legs and is pulled by the strings' spring tensions: it "
                           "translates by C*(sum_i u_i - mean), u_i = unit vector from anchor i to T (legs 3x "
                           "stiffer vertically): a rig displacement driven by where T is"),
    "tracker_air_temp": ("tune5", "rig", 1e-5, "1/K",
                         "thermal_expansion",
                         "tracker data: the air temperature used for the refractive index was entered once; every "
                         "range is off by -k*(T - Tmean)*D about the tracker head (a scale about the instrument, "
                         "driven by temperature; the robot does not change)"),
    "platform_tilt": ("heldback5", "rig", 1e-6, "rad/(N*m)",
                      "base_tilt",
                      "the rig frame / tracker tripod stands on the same raised floor plate as the robot pedestal; "
                      "the plate bends under the arm's horizontal gravity moment and the RIG tilts about its own "
                      "feet, c*(M_h - mean): relative motion = a base tilt plus a translation about a far pivot"),
    "tracker_adm_cyclic": ("heldback5", "rig", 0.01, "mm",
                           "",
                           "tracker data: the absolute distance meter's cyclic (phase) nonlinearity, a range error "
                           "k*sin(2*pi*D/p + phi) along the beam, p = 300-600 mm (half a modulation wavelength)"),
}
SEEDS_PER_KIND = 6
N_NULL = 8
ROBOT_SIDE = {k for k, v in KINDS.items() if v[1] == "robot"}
RIG_POINT_KINDS = ("frame_tension_sway", "tracker_air_temp", "platform_tilt", "tracker_adm_cyclic")


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
    # ---- true geometry (as gen2 / gen3 / gen4)
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
    # ---- clock and temperature (as gen3 / gen4: warm-up plus an HVAC swing)
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
    # ---- payload in blocks of 10-20 poses (as gen4; written only where cols ask, no kind uses it)
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
    dt = np.diff(np.concatenate([[0.0], t]))

    # ---- the effect's parameters (drawn whatever the kind: every kind consumes the same rng stream)
    P = dict(spec.get("params", {}))
    P.setdefault("phi", float(rng.uniform(0, 360)))
    d = rng.normal(size=3)
    P.setdefault("dir", (d / np.linalg.norm(d)).tolist())
    P.setdefault("sign", float(rng.choice([-1.0, 1.0])))
    P.setdefault("step_frac", float(rng.uniform(0.3, 0.7)))
    P.setdefault("tau_frac", float(rng.uniform(0.2, 0.5)))
    P.setdefault("q_frac", float(rng.uniform(0.35, 0.65)))
    P.setdefault("slip_q", float(rng.uniform(0.6, 0.8)))
    P.setdefault("adm_period_mm", float(rng.uniform(300, 600)))
    j = P.get("joint")
    sg = P.get("sensor")
    g_rig = Rb @ np.array([0, 0, -1.0])   # gravity direction in the rig frame
    T_mean = float(temp_true.mean())
    if kind in ("joint_zero_thermal", "drum_thermal_scale", "tracker_air_temp"):
        P["temp_mean_c"] = T_mean
    if kind == "motor_heat_zero":
        tau = P["tau_frac"] * t[-1]
        H = np.zeros(N)
        h = 0.0
        for k in range(N):
            h = h * math.exp(-dt[k] / tau) + abs(dQ[k, j - 1])
            H[k] = h
        H /= H.mean()
        P["tau_s"] = float(tau)
        heat = H - H.mean()
    if kind == "gravity_preload_play":
        tg = np.array([gravity_torques(robot, Q[k])[j - 1] for k in range(N)])
        w = 0.1 * float(np.std(tg))
        play = np.tanh(tg / w)
        P["w_nm"] = w
        P["frac_positive_torque"] = float(np.mean(tg > 0))
        play = play - play.mean()
    if kind == "tool_reseat":
        k0 = int(np.searchsorted(t, P["step_frac"] * t[-1]))
        P["k0"], P["t0_s"] = k0, float(t[k0])
        stepv = (np.arange(N) >= k0).astype(float)
        stepv -= stepv.mean()   # the mean tool point is the identified one
    if kind == "platform_tilt":
        Mh = np.zeros((N, 3))
        for k in range(N):
            M = Rb @ gravity_moment_base(robot, Q[k])
            Mh[k] = M - (M @ g_rig) * g_rig
        Mh -= Mh.mean(0)
        if points:
            hinge = np.array([0.0, 0.0, -1300.0])   # the tripod's feet below the tracker head
        else:
            hinge = np.array([c0[0], c0[1], base_xyz[2] - 600.0])   # the frame's feet on the plate
        P["hinge_mm"] = hinge.tolist()

    def robot_points(m):
        Pts = np.zeros((N, 3))
        for k in range(N):
            q = Q[k].copy()
            tool = tool_true
            if m != 0 and kind == "motor_heat_zero":
                q[j - 1] += m * heat[k]
            elif m != 0 and kind == "gravity_preload_play":
                q[j - 1] += m * play[k]
            elif m != 0 and kind == "joint_zero_thermal":
                q[j - 1] += m * (temp_true[k] - T_mean)
            elif m != 0 and kind == "tool_reseat":
                tool = (np.array(tool_true) + m * stepv[k] * np.array(P["dir"])).tolist()
            F = frames(true_j, q, "dh")
            pb = (F[-1] @ np.array([*tool, 1.0]))[:3]
            Pts[k] = to_rig(pb)
        return Pts

    P0 = robot_points(0.0)
    L0 = None
    if not points:
        L0 = np.linalg.norm(P0[:, None, :] - anchors[None, :, :], axis=2) - r
        L_home = np.linalg.norm(to_rig(tool_in_base(true_j, tool_true, home, "dh")) - anchors, axis=1) - r
        dL = np.diff(np.vstack([L_home[None, :], L0]), axis=0)   # each string's change into the pose
    if kind == "drum_layer_change":
        P["l_th_mm"] = float(np.quantile(L0[:, sg - 1], P["q_frac"]))
        P["kink_mean_mm"] = float(np.mean(np.maximum(0, L0[:, sg - 1] - P["l_th_mm"])))
    if kind == "string_count_slip":
        retr = -dL[:, sg - 1]
        P["slip_thr_mm"] = float(np.quantile(retr[retr > 0], P["slip_q"]))
        cnt = np.cumsum(retr > P["slip_thr_mm"]).astype(float)
        P["n_slips"] = int(cnt[-1])
        slips = cnt - cnt.mean()
    if kind == "string_crosstalk":
        P["lo_mean_mm"] = float(L0[:, P["source"] - 1].mean())
    if kind == "frame_tension_sway":
        U = (P0[:, None, :] - anchors[None, :, :]) / np.linalg.norm(P0[:, None, :] - anchors[None, :, :], axis=2)[:, :, None]
        P["S_mean"] = U.sum(1).mean(0).tolist()
        P["leg_compliance_xyz"] = [1.0, 1.0, 0.3]

    def rig_view(X, m):
        """the true points X as the (moved / distorted) rig or tracker sees them"""
        if m == 0 or kind not in RIG_POINT_KINDS:
            return X
        if kind == "frame_tension_sway":
            U = (X[:, None, :] - anchors[None, :, :]) / np.linalg.norm(X[:, None, :] - anchors[None, :, :], axis=2)[:, :, None]
            u = m * (U.sum(1) - np.array(P["S_mean"])) * np.array(P["leg_compliance_xyz"])[None, :]
            return X - u
        if kind == "platform_tilt":
            hg = np.array(P["hinge_mm"])
            return np.array([hg + rodrigues(-m * Mh[k]) @ (X[k] - hg) for k in range(N)])
        if kind == "tracker_air_temp":
            return X * (1 - m * (temp_true - T_mean))[:, None]
        if kind == "tracker_adm_cyclic":
            D = np.linalg.norm(X, axis=1)
            e = m * np.sin(2 * math.pi * D / P["adm_period_mm"] + P["phi"] * D2R)
            return X + (e / D)[:, None] * X
        return X

    def measure(Pts, m):
        """noise-free readings (strings) or points (tracker) of the true points Pts with the effect at m"""
        X = rig_view(Pts, m)
        if points:
            return X
        L = np.linalg.norm(X[:, None, :] - anchors[None, :, :], axis=2) - r
        if m != 0 and KINDS.get(kind, ("", ""))[1] == "sensor":
            s_ = sg - 1
            if kind == "drum_layer_change":
                L[:, s_] += m * (np.maximum(0, L[:, s_] - P["l_th_mm"]) - P["kink_mean_mm"])
            elif kind == "string_count_slip":
                L[:, s_] += m * slips
            elif kind == "drum_thermal_scale":
                L[:, s_] -= m * (temp_true - T_mean) * L[:, s_]
            elif kind == "string_crosstalk":
                o_ = P["source"] - 1
                L[:, s_] += m * (L[:, o_] - P["lo_mean_mm"])
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
        u_ = KINDS[kind][2]
        ru = eff_rms(u_)
        mag = u_ * spec["ratio"] * point_noise / ru
        # signs: physical where the physics fixes it (a warm drum under-reads, warm air shortens the
        # tracker's ranges, the rig tilts with the moment's sense), random elsewhere
        if kind not in ("drum_thermal_scale", "tracker_air_temp", "platform_tilt", "frame_tension_sway",
                        "tool_reseat"):
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
             "side": KINDS[kind][1] if kind != "none" else None,
             "resembles": KINDS[kind][4] if kind != "none" else None,
             "physics": KINDS[kind][5] if kind != "none" else "effect-free",
             "drivers": spec.get("drivers", []), "places_ok": spec.get("places_ok", []),
             "magnitude": mag, "unit": KINDS[kind][3] if kind != "none" else None,
             "params": P, "effect_rms_mm": erms, "point_noise_mm": point_noise,
             "ratio": erms / point_noise, "scaling": "as gen3 / gen4: RMS over the poses of the noise-free "
             "displacement of the located point (strings: multilaterated with the nominal anchors from the "
             "readings; tracker: the measured point) with the effect against without it; the effect's session "
             "mean is taken out where a constant part is a reparametrisation of the geometric model",
             "robot": rname, "rig": spec["rig"], "n_poses": N, "cols": spec["cols"], "sigma": sigma,
             "session_s": float(t[-1]), "temp_rise_c": float(rise), "temp_swing_c": float(swing),
             "deviations": devs, "tool_point_mm": tool_true, **rng_info,
             "base_in_rig": {"xyz_mm": base_xyz.tolist(), "rpy_deg": base_rpy.tolist()}}
    json.dump(truth, open(f"{dname}/truth3.json", "w"), indent=1)
    return truth


# ---------------------------------------------------------------- the plan
def plan():
    R = np.random.default_rng(5050505)
    specs = []
    ROB = ["er3a", "ur5"]
    RIGS_ROBOT = ["std4", "s3tilt", "s5np", "points", "points", "std4"]
    RIGS_STR = ["std4", "s3tilt", "s5np", "s5np", "s3tilt", "std4"]
    NSTR = {"std4": 4, "s3tilt": 3, "s5np": 5}

    def add(kind, half, i, robot, rig, params, places, drivers, cols):
        idx = len(specs)
        tag = params.get("joint") or params.get("sensor") or ""
        specs.append({"name": f"{idx:03d}_{kind}{tag}_{robot}_{rig}", "kind": kind, "half": half,
                      "robot": robot, "rig": rig, "n": int(R.integers(150, 201)), "seed": 900000 + idx,
                      "sigma": 0.02 if rig != "points" else 0.03, "ratio": float(R.uniform(3, 6)),
                      "params": params, "places_ok": places, "drivers": drivers, "cols": cols})

    def rand_cols():
        return [["time_s", "temp_c"], ["time_s"], [], ["time_s", "temp_c", "payload_kg"]][int(R.integers(0, 4))]

    def with_time(i):
        return ["time_s", "temp_c"] if i % 2 == 0 else ["time_s"]

    def with_temp(i):
        return [["time_s", "temp_c"], ["temp_c"], ["time_s", "temp_c", "payload_kg"]][i % 3]

    for kind in KINDS:
        half = KINDS[kind][0]
        for i in range(SEEDS_PER_KIND):
            rb = ROB[i % 2]
            rig = RIGS_ROBOT[i]
            cols = rand_cols()
            prm = {}
            if kind == "motor_heat_zero":
                j = [2, 3, 3, 2, 2, 3][i]   # not joint 1: its zero moving in time IS a rig yaw about its axis
                prm = {"joint": j}
                cols = with_time(i)
                places = [place("motion", j), place("time", j), place("order", j)]
                drivers = [f"joint {j}'s own travel history (a lag of its cumulative motion; time / order as a proxy)"]
            elif kind == "gravity_preload_play":
                j = [2, 3, 2, 3, 2, 3][i]
                prm = {"joint": j}
                places = [place("joint", j), place("joint", 5 - j), place("workspace"), place("configuration")]
                drivers = [f"the sign of joint {j}'s gravity torque (configuration: q2, q3, the wrist)"]
            elif kind == "tool_reseat":
                cols = with_time(i)
                places, drivers = [place("time"), place("order")], ["time (a step of the tool point in the flange frame)"]
            elif kind == "joint_zero_thermal":
                j = [3, 2, 2, 3, 3, 2][i]   # not joint 1 (as motor_heat_zero)
                prm = {"joint": j}
                cols = with_temp(i)
                places, drivers = [place("temperature", j)], [f"temperature (joint {j}'s zero)"]
            elif KINDS[kind][1] == "sensor":
                rig = RIGS_STR[i]
                s = int(R.integers(1, NSTR[rig] + 1))
                prm = {"sensor": s}
                if kind == "drum_layer_change":
                    places, drivers = [place("string", sensor=s)], [f"string {s} length (a kink at l_th)"]
                elif kind == "string_count_slip":
                    cols = with_time(i)
                    places = [place("motion", sensor=s), place("time", sensor=s), place("order", sensor=s)]
                    drivers = [f"string {s}'s retraction history (a staircase in time / order)"]
                elif kind == "drum_thermal_scale":
                    cols = with_temp(i)
                    places, drivers = [place("temperature", sensor=s)], [f"temperature times string {s}'s length"]
                elif kind == "string_crosstalk":
                    o = int(R.integers(1, NSTR[rig]))
                    o = o if o < s else o + 1
                    prm["source"] = o
                    places = [place("string", sensor=s), place("string", sensor=o)]
                    drivers = [f"string {o}'s length, read on string {s}"]
            elif kind == "frame_tension_sway":
                rig = RIGS_STR[i]
                places, drivers = [place("workspace")], ["where T is (the resultant of the string tensions)"]
            elif kind == "platform_tilt":
                rig = ["points", "std4", "s5np", "s3tilt", "std4", "points"][i]
                places = [place("joint", 2), place("joint", 3), place("workspace"), place("configuration")]
                drivers = ["configuration (horizontal gravity moment of the arm: q1, q2, q3 mostly)"]
            elif kind == "tracker_air_temp":
                rig = "points"
                cols = with_temp(i)
                places, drivers = [place("temperature")], ["temperature (times the range from the tracker)"]
            elif kind == "tracker_adm_cyclic":
                rig = "points"
                places, drivers = [place("workspace")], ["range from the tracker (where T is)"]
            add(kind, half, i, rb, rig, prm, places, drivers, cols)
            if kind == "frame_tension_sway":
                # the geometric fit absorbs about half of this smooth field (measured with `visible`: the
                # effect with --physics off only 1.3-2.2x the twin at 3-6); keep it in the upper half of 3-6
                specs[-1]["ratio"] = 4.5 + 0.5 * (specs[-1]["ratio"] - 3.0)
    for i in range(N_NULL):
        rig = ["std4", "s3tilt", "s5np", "points", "std4", "s5np", "s3tilt", "points"][i]
        cols = [["time_s", "temp_c"], ["time_s", "temp_c", "payload_kg"], ["time_s"], ["temp_c"],
                ["payload_kg"], ["time_s", "temp_c"], ["time_s", "temp_c", "payload_kg"], ["time_s", "temp_c"]][i]
        add("none", HALVES[i % 2], i, ROB[(i // 2) % 2], rig, {}, [], [], cols)
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


def visible(only=None, detail=False):
    """sanity check: the effect dataset with --physics off (report_off.json) against the twin; a ratio near 1
    means the effect is invisible to the geometric fit. Per kind for tune5, aggregate only for heldback5
    unless detail."""
    specs = json.load(open(f"{OUT}/plan.json"))
    rows = []
    for s in specs:
        if only and only not in s["name"]:
            continue
        d = f"{OUT}/{s['name']}"
        if not os.path.exists(f"{d}/oracle/report.json"):
            continue
        if not os.path.exists(f"{d}/report_off.json"):
            gen3.run_tool(d, "off", "report_off")
        try:
            off = json.load(open(f"{d}/report_off.json"))["stats"]["test"]["after"]["rms_mm"]
            orc = json.load(open(f"{d}/oracle/report.json"))["stats"]["test"]["after"]["rms_mm"]
        except Exception:
            continue
        rows.append((s["name"], s["kind"], s["half"], off / orc))
    import score3
    for h in HALVES:
        rr = [r for r in rows if r[2] == h]
        for k in dict.fromkeys(r[1] for r in rr):
            vals = [r[3] for r in rr if r[1] == k]
            if h == "tune5" or detail:
                print(f"{h:9s} {k:22s} off/oracle gmean {score3.gmean(vals):6.3f} min {min(vals):6.3f} "
                      f"max {max(vals):6.3f}  " + " ".join(f"{v:.2f}" for v in vals))
        eff = [r[3] for r in rr if r[1] != "none"]
        nul = [r[3] for r in rr if r[1] == "none"]
        if eff:
            print(f"{h:9s} ALL EFFECTS off/oracle gmean {score3.gmean(eff):6.3f} min {min(eff):6.3f}; "
                  f"{sum(v < 1.3 for v in eff)} of {len(eff)} below 1.3; effect-free gmean {score3.gmean(nul):.3f}")


def score(full=False):
    import score3
    specs = json.load(open(f"{OUT}/plan.json"))
    rows = [score3.score_one(f"{OUT}/{s['name']}") for s in specs if os.path.exists(f"{OUT}/{s['name']}/run.json")]
    json.dump(rows, open(f"{OUT}/scores5.json", "w"), indent=1)
    shown = [r for r in rows if full or r["half"] == "tune5"]
    print(f"{'dataset':44s} {'eff/noise':>9s} {'tool':>7s} {'oracle':>7s} {'ratio':>6s} {'category':12s} findings")
    for r in shown:
        f = lambda x: "   -   " if x is None else f"{x:7.4f}"
        print(f"{r['name']:44s} {r['ratio_eff']:9.2f} {f(r.get('tool_rms'))} {f(r.get('oracle_rms'))} "
              f"{'' if r.get('ratio') is None else format(r['ratio'], '6.3f'):>6s} {r['cat']:12s} "
              f"{'; '.join(r.get('findings', []))}")
    print()
    print("(located: an unexplained finding at the right place, or the right name for a kind since taken into the catalogue)")
    print(f"{'kind':22s} {'half':9s} {'n':>2s} {'located':>7s} {'wrongpl':>7s} {'silent':>6s} {'named':>5s} "
          f"{'named>=1%':>9s} {'ratio':>6s}")
    for h in HALVES:
        if h == "heldback5" and not full:
            print(f"(heldback5: per-kind lines withheld; `score full` shows them)")
            continue
        rh = [r for r in rows if r["half"] == h]
        for k in dict.fromkeys(r["kind"] for r in rh):
            rr = [r for r in rh if r["kind"] == k]
            print(f"{k:22s} {h:9s} {len(rr):2d} {sum(r['cat'] in ('located', 'named_right') for r in rr):7d} "
                  f"{sum(r['cat'] == 'wrong_place' for r in rr):7d} {sum(r['cat'] == 'silent' for r in rr):6d} "
                  f"{sum(r.get('named', 0) for r in rr):5d} {sum(r.get('named_ge1pct', 0) for r in rr):9d} "
                  f"{score3.gmean([r.get('ratio') for r in rr]):6.3f}"
                  + (f"   false alarms {sum(r['cat'] == 'FALSE_ALARM' for r in rr)}" if k == "none" else ""))
    print()
    sums = [score3.summarize([r for r in rows if r["half"] == h], h) for h in HALVES]
    sums.append(score3.summarize(rows, "overall"))
    for s in sums:
        print(score3.fmt_summary(s))
    srcs = sorted({s for r in rows for s in r.get("place_src", [])})
    print(f"\nplaces read from: {', '.join(srcs) or '(no unexplained finding)'}")
    json.dump(sums, open(f"{OUT}/summary5.json", "w"), indent=1)
    return sums


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "list"
    if cmd == "list":
        for k, v in KINDS.items():
            print(f"{k:21s} {v[0]:9s} {v[1]:6s} ~{v[4]:17s} {v[5]}")
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
    elif cmd == "visible":
        visible(sys.argv[2] if len(sys.argv) > 2 and sys.argv[2] != "full" else None, "full" in sys.argv[2:])
    elif cmd == "score":
        score(full=len(sys.argv) > 2 and sys.argv[2] == "full")
    else:
        print(__doc__)
