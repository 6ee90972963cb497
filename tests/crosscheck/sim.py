#!/usr/bin/env python3
"""Independent drawstring-calibration simulator for a blind cross-check of
drawcal's physics analysis.  Written from the physics descriptions only
(DATA_FORMAT.md convention: T_i = Rz(q+th) Tz(d) Tx(a) Rx(alpha) Ry(beta)).

usage:  python3 sim.py gen [x|y]      # write $XCHECK_OUT (default /tmp/xcheck)/<name>/{robot,rig,poses,truth}
        python3 sim.py genz           # targeted batch z (joints 5/6, ratio 3, extra nulls)
        python3 sim.py run [x|y|z]    # run the tool on each dataset (one at a time)
        python3 score.py datasets*.json   # compare findings with truth
"""
import json, math, os, sys, copy, subprocess, glob
import numpy as np

OUT = os.environ.get("XCHECK_OUT", "/tmp/xcheck")
SRC = os.environ.get("XCHECK_DATA", "tests/data")
TOOL = os.environ.get("XCHECK_TOOL", "target/release/drawcal")
D2R = math.pi / 180.0
SIGMA = 0.02
RES = 0.024


# ---------------------------------------------------------------- kinematics
def rotx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def roty(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rotz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x, y, z):
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T


def frames(joints, q_deg):
    """joints: list of dicts (mm, deg). q_deg: joint angles. returns F_0..F_n"""
    F = [np.eye(4)]
    for J, q in zip(joints, q_deg):
        T = (rotz((q + J["theta_offset_deg"]) * D2R) @ trans(0, 0, J["d_mm"]) @ trans(J["a_mm"], 0, 0)
             @ rotx(J["alpha_deg"] * D2R) @ roty(J["beta_deg"] * D2R))
        F.append(F[-1] @ T)
    return F


def tool_in_base(joints, tool, q_deg):
    F = frames(joints, q_deg)
    return (F[-1] @ np.array([*tool, 1.0]))[:3]


def rpy_to_R(rpy_deg):
    r, p, y = [v * D2R for v in rpy_deg]
    return (rotz(y) @ roty(p) @ rotx(r))[:3, :3]


def gravity_torques(joints, links, g_base, q_deg):
    """tau_j (N*m) = z_{j-1} . sum_{i>=j} (c_i - o_{j-1}) x m_i g ; lengths mm->m"""
    F = frames(joints, q_deg)
    n = len(joints)
    g = np.asarray(g_base, float)
    cs = [(F[i + 1] @ np.array([*links[i]["com_mm"], 1.0]))[:3] * 1e-3 for i in range(n)]
    ms = [links[i]["mass_kg"] for i in range(n)]
    tau = np.zeros(n)
    for j in range(n):
        z = F[j][:3, 2]
        o = F[j][:3, 3] * 1e-3
        tot = np.zeros(3)
        for i in range(j, n):
            tot += np.cross(cs[i] - o, ms[i] * g)
        tau[j] = z @ tot
    return tau


def multilaterate(anchors, dists, x0):
    x = np.array(x0, float)
    for _ in range(20):
        d = np.linalg.norm(x - anchors, axis=1)
        r = d - dists
        Jm = (x - anchors) / d[:, None]
        dx = np.linalg.lstsq(Jm, -r, rcond=None)[0]
        x += dx
        if np.linalg.norm(dx) < 1e-10:
            break
    return x


# ---------------------------------------------------------------- datasets
EFFECTS = ["joint_compliance", "joint_compliance", "joint_compliance",
           "joint_periodic", "joint_periodic", "joint_periodic",
           "backlash", "backlash", "backlash",
           "thermal_expansion", "thermal_expansion",
           "sensor_scale", "sensor_scale",
           "sensor_offset", "sensor_offset",
           "anchor_step", "anchor_step", "anchor_step",
           "cable_sag", "cable_sag"] + [None] * 10

HOME = {"er3a": [0, 0, 0, 0, 45, 0], "ur5": [0, -90, 0, -90, 0, 0]}
SRCSET = {"er3a": "er3a_compliance_j2", "ur5": "ur5_geometric"}


def load_preset(name):
    robot = json.load(open(f"{SRC}/{SRCSET[name]}/robot.json"))
    rig = json.load(open(f"{SRC}/{SRCSET[name]}/rig.json"))
    return robot, rig


FORCE = {}  # batch z: forced joint/sensor and ratio


def make_dataset(idx, effect, robot_name, seed, batch="x"):
    """batch x: periodic/backlash on joints 1-4; batch y: any joint 1-6"""
    rng = np.random.default_rng(seed)
    robot, rig = load_preset(robot_name)
    nom = robot["joints"]
    n = len(nom)
    # ---- true geometry
    true_j = copy.deepcopy(nom)
    devs = []
    for i, J in enumerate(true_j):
        dv = {"joint": i + 1,
              "a_mm": rng.normal(0, 0.5), "d_mm": rng.normal(0, 0.5),
              "alpha_deg": rng.normal(0, 0.1), "theta_offset_deg": rng.normal(0, 0.1),
              "beta_deg": 0.0}
        parallel_next = i < n - 1 and abs(math.sin(nom[i]["alpha_deg"] * D2R)) < 1e-9
        if parallel_next:
            dv["beta_deg"] = rng.normal(0, 0.1)
        for k in ["a_mm", "d_mm", "alpha_deg", "theta_offset_deg", "beta_deg"]:
            J[k] = nom[i][k] + dv[k]
        devs.append(dv)
    tool_true = (np.array(robot["tool_point_mm"]) + rng.normal(0, 0.6, 3)).tolist()
    bg = rig["base_in_rig"]
    base_xyz = np.array(bg["xyz_mm"]) + rng.normal(0, 2.0, 3)
    base_rpy = np.array(bg["rpy_deg"]) + rng.normal(0, 0.4, 3)
    Rb = rpy_to_R(base_rpy)
    anchors = np.array(rig["anchors_mm"], float)
    r = rig["r_mm"]

    def to_rig(p):
        return Rb @ p + base_xyz

    # ---- poses
    N = int(rng.integers(120, 201))
    qs = []
    while len(qs) < N:
        q = np.array([rng.uniform(J["q_min_deg"], J["q_max_deg"]) for J in nom])
        T = to_rig(tool_in_base(true_j, tool_true, q))
        L = np.linalg.norm(T - anchors, axis=1) - r
        if T[2] > 150 and np.all(L > 100) and np.all(L < 1900):
            qs.append(q)
    # nearest-neighbour tour from home
    home = np.array(HOME[robot_name], float)
    left = list(range(N))
    order = []
    cur = home
    while left:
        dd = [np.linalg.norm(qs[k] - cur) for k in left]
        k = left.pop(int(np.argmin(dd)))
        order.append(k)
        cur = qs[k]
    Q = np.array([qs[k] for k in order])
    # times and temperature
    t = np.zeros(N)
    prev, tt = home, 0.0
    for k in range(N):
        tt += np.max(np.abs(Q[k] - prev)) / 30.0 + rng.uniform(3, 6)
        t[k] = tt
        prev = Q[k]
    rise = rng.uniform(4, 8)
    tau_t = rng.uniform(0.25, 0.5) * t[-1]
    temp_true = 20.0 + rise * (1 - np.exp(-t / tau_t))
    temp_rec = temp_true + rng.normal(0, 0.03, N)
    split = np.where(rng.random(N) < 0.3, "test", "train")
    # direction each joint last moved
    dirs = np.zeros((N, n))
    last = np.ones(n)
    prev = home
    for k in range(N):
        dq = Q[k] - prev
        last = np.where(np.abs(dq) > 1e-9, np.sign(dq), last)
        dirs[k] = last
        prev = Q[k]

    # ---- effect definitions (unit magnitude, scaled later)
    eff = {"effect": effect}
    joint = None
    sensor = None
    if effect == "joint_compliance":
        joint = int(rng.choice([2, 3]))
    elif effect in ("joint_periodic", "backlash"):
        joint = int(rng.integers(1, 5 if batch == "x" else 7))
    elif effect in ("sensor_scale", "sensor_offset", "anchor_step"):
        sensor = int(rng.integers(1, len(anchors) + 1))
    joint = FORCE.get("joint", joint)
    phi = rng.uniform(0, 360)
    step_dir = rng.normal(size=3)
    step_dir /= np.linalg.norm(step_dir)
    t_step = rng.uniform(0.35, 0.65) * t[-1]
    off_sign = rng.choice([-1, 1])

    def robot_points(mag):
        """true T in rig frame for every pose with the effect at magnitude mag"""
        P = np.zeros((N, 3))
        for k in range(N):
            q = Q[k].copy()
            jj = true_j
            if effect == "joint_compliance":
                tau = gravity_torques(nom, robot["links"], robot["gravity_in_base"], Q[k])
                q[joint - 1] += mag * tau[joint - 1]  # mag in deg/(N*m)
            elif effect == "joint_periodic":
                q[joint - 1] += mag * math.sin((Q[k, joint - 1] + phi) * D2R)
            elif effect == "backlash":
                q[joint - 1] += mag * dirs[k, joint - 1]
            elif effect == "thermal_expansion":
                dT = temp_true[k] - temp_true[0]
                jj = copy.deepcopy(true_j)
                for i in range(n):
                    jj[i]["a_mm"] += mag * dT * nom[i]["a_mm"]
                    jj[i]["d_mm"] += mag * dT * nom[i]["d_mm"]
            P[k] = to_rig(tool_in_base(jj, tool_true, q))
        return P

    def readings(P, mag):
        Lr = np.zeros((N, len(anchors)))
        for k in range(N):
            A = anchors.copy()
            if effect == "anchor_step" and t[k] > t_step:
                A[sensor - 1] += mag * step_dir
            D = np.linalg.norm(P[k] - A, axis=1)
            l = D - r
            if effect == "cable_sag":
                h = np.linalg.norm((P[k] - A)[:, :2], axis=1)
                l = l + mag * h ** 2 * D  # mag = (w/F)^2/24  [1/mm^2]
            if effect == "sensor_scale":
                l[sensor - 1] *= (1 + mag)
            if effect == "sensor_offset":
                l[sensor - 1] += mag
            Lr[k] = l
        return Lr

    P0 = robot_points(0.0)
    L0 = readings(P0, 0.0)
    M0 = np.array([multilaterate(anchors, L0[k] + r, P0[k]) for k in range(N)])
    # point noise
    Ln = L0 + rng.normal(0, SIGMA, L0.shape)
    Ln = np.round(Ln / RES) * RES
    Mn = np.array([multilaterate(anchors, Ln[k] + r, P0[k]) for k in range(N)])
    point_noise = float(np.sqrt(np.mean(np.sum((Mn - M0) ** 2, axis=1))))

    robot_side = effect in ("joint_compliance", "joint_periodic", "backlash", "thermal_expansion")
    unit_mag = {"joint_compliance": 1e-3, "joint_periodic": 0.01, "backlash": 0.01,
                "thermal_expansion": 1e-5, "sensor_scale": 1e-4, "sensor_offset": 0.1,
                "anchor_step": 0.3, "cable_sag": 1e-10}

    def eff_rms(mag):
        if robot_side:
            P = robot_points(mag)
            return float(np.sqrt(np.mean(np.sum((P - P0) ** 2, axis=1))))
        Lm = readings(P0, mag)
        M = np.array([multilaterate(anchors, Lm[k] + r, P0[k]) for k in range(N)])
        return float(np.sqrt(np.mean(np.sum((M - M0) ** 2, axis=1))))

    mag = 0.0
    ratio = 0.0
    if effect is not None:
        u = unit_mag[effect]
        ru = eff_rms(u)
        ratio = rng.uniform(3, 10)
        ratio = FORCE.get("ratio", ratio)
        mag = u * ratio * point_noise / ru
        if effect == "sensor_offset":
            mag *= off_sign
        if effect == "sensor_scale":
            mag *= off_sign
        erms = eff_rms(mag)
    else:
        erms = 0.0
    P = robot_points(mag)
    L = readings(P, mag)
    L = L + rng.normal(0, SIGMA, L.shape)
    L = np.round(L / RES) * RES

    name = f"{batch}{idx:02d}_{robot_name}_{effect or 'none'}"
    d = f"{OUT}/{name}"
    os.makedirs(d, exist_ok=True)
    json.dump(robot, open(f"{d}/robot.json", "w"), indent=1)
    json.dump(rig, open(f"{d}/rig.json", "w"), indent=1)
    m = len(anchors)
    with open(f"{d}/poses.csv", "w") as f:
        f.write("pose," + ",".join(f"q{i+1}_deg" for i in range(n)) + "," +
                ",".join(f"l{i+1}_mm" for i in range(m)) + ",time_s,temp_c,split\n")
        for k in range(N):
            f.write(f"{k+1}," + ",".join(f"{v:.6f}" for v in Q[k]) + "," +
                    ",".join(f"{v:.6f}" for v in L[k]) + f",{t[k]:.3f},{temp_rec[k]:.4f},{split[k]}\n")
    units = {"joint_compliance": "deg/(N*m)", "joint_periodic": "deg", "backlash": "deg",
             "thermal_expansion": "1/K", "sensor_scale": "-", "sensor_offset": "mm",
             "anchor_step": "mm", "cable_sag": "1/mm^2 ((w/F)^2/24)"}
    truth = {"name": name, "seed": seed, "robot": robot_name, "n_poses": N,
             "effect": effect, "joint": joint, "sensor": sensor, "magnitude": mag,
             "unit": units.get(effect), "effect_rms_mm": erms, "point_noise_mm": point_noise,
             "ratio": erms / point_noise if point_noise else None,
             "extra": {"phi_deg": phi if effect == "joint_periodic" else None,
                       "t_step_s": t_step if effect == "anchor_step" else None,
                       "step_dir": step_dir.tolist() if effect == "anchor_step" else None,
                       "temp_rise_c": rise, "session_s": t[-1]},
             "deviations": devs, "tool_point_mm": tool_true,
             "base_in_rig": {"xyz_mm": base_xyz.tolist(), "rpy_deg": base_rpy.tolist()}}
    json.dump(truth, open(f"{d}/truth_xcheck.json", "w"), indent=1)
    return name, truth


def gen(batch="x"):
    rng = np.random.default_rng(20240601 if batch == "x" else 777)
    effs = list(EFFECTS)
    rng.shuffle(effs)
    names = []
    for i, e in enumerate(effs):
        rn = ["er3a", "ur5"][i % 2]
        name, tr = make_dataset(i, e, rn, (5000 if batch == "x" else 9000) + i, batch)
        print(name, f"N={tr['n_poses']} mag={tr['magnitude']:.4g} rms={tr['effect_rms_mm']:.3f} "
              f"noise={tr['point_noise_mm']:.4f} ratio={tr['ratio']:.1f}", flush=True)
        names.append(name)
    json.dump(names, open(f"{OUT}/datasets{'' if batch == 'x' else '_' + batch}.json", "w"))


ZSPEC = [  # (effect, robot, joint, ratio): joints 5/6, low ratio, compliance j2 on er3a
    ("backlash", "er3a", 5, 5), ("backlash", "er3a", 6, 5), ("backlash", "ur5", 5, 5), ("backlash", "ur5", 6, 5),
    ("joint_periodic", "er3a", 5, 5), ("joint_periodic", "er3a", 6, 5), ("joint_periodic", "ur5", 5, 5),
    ("joint_periodic", "ur5", 6, 5), ("joint_periodic", "er3a", 2, 3), ("joint_periodic", "ur5", 1, 3),
    ("joint_compliance", "er3a", 2, 3), ("joint_compliance", "ur5", 2, 3), ("backlash", "er3a", 2, 3),
    ("backlash", "ur5", 4, 3), ("thermal_expansion", "er3a", None, 3), ("cable_sag", "ur5", None, 3),
    ("anchor_step", "er3a", None, 3), ("sensor_scale", "ur5", None, 3), ("sensor_offset", "er3a", None, 3),
] + [(None, ["er3a", "ur5"][i % 2], None, None) for i in range(11)]


def genz():
    names = []
    for i, (e, rn, j, ratio) in enumerate(ZSPEC):
        FORCE.clear()
        if j is not None:
            FORCE["joint"] = j
        if ratio is not None:
            FORCE["ratio"] = ratio
        name, tr = make_dataset(i, e, rn, 13000 + i, "z")
        print(name, f"j={tr['joint']} s={tr['sensor']} N={tr['n_poses']} mag={tr['magnitude']:.4g} "
              f"rms={tr['effect_rms_mm']:.3f} ratio={tr['ratio']:.1f}", flush=True)
        names.append(name)
    FORCE.clear()
    json.dump(names, open(f"{OUT}/datasets_z.json", "w"))


def run(batch="x"):
    for name in json.load(open(f"{OUT}/datasets{'' if batch == 'x' else '_' + batch}.json")):
        d = f"{OUT}/{name}"
        with open(f"{d}/tool.log", "w") as log:
            subprocess.run([TOOL, "identify", "--robot", f"{d}/robot.json", "--rig", f"{d}/rig.json",
                            "--poses", f"{d}/poses.csv", "--out", f"{d}/report.json"],
                           stdout=log, stderr=subprocess.STDOUT)
        print(name, "done", flush=True)


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "gen"
    if cmd == "gen":
        gen(*sys.argv[2:3])
    elif cmd == "genz":
        genz()
    elif cmd == "run":
        run(*sys.argv[2:3])
    elif cmd == "one":
        i = int(sys.argv[2]); e = None if sys.argv[3] == "none" else sys.argv[3]
        print(make_dataset(i, e, sys.argv[4], int(sys.argv[5]))[1]["ratio"])
