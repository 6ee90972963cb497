#!/usr/bin/env python3
"""Sixth independent cross-check of drawcal: another fresh, blind set of physics OUTSIDE the catalogue,
with a tune half (tune6) and a held-back half (heldback6).

Written blind: from physics descriptions of industrial arms (coupled wrists, gas-spring counterbalances,
gearbox stiffness), drawstring encoder rigs (drums, cables, shared excitation, anchors), laser trackers
and cameras, from DATA_FORMAT.md, README.md, docs/CLI.md and the earlier cross-check simulators (sim.py,
gen2.py, gen3.py, gen4.py, gen5.py) and their scorer score3.py only -- WITHOUT reading src/,
docs/PHYSICS.md, EVAL.md, BENCHMARKS.md, tests/*.rs or the git history.  The tool version measured is
commit 4c26b3c (binary /tmp/bin/drawcal-4c26b3c).

None of the kinds below is a catalogue effect (joint_compliance, backlash, joint_periodic, joint_scale,
base_tilt, thermal_expansion, sensor_scale, sensor_offset, sensor_drift, cable_sag, anchor_step,
rig_step, rig_drift) nor one of gen3.py's, gen4.py's or gen5.py's kinds.  Several RESEMBLE a catalogue
effect without being it (`resembles` in KINDS): naming that catalogue effect is a misname.  Each
effect's part that is an exact reparametrisation of the geometric model (a constant joint offset, tool
offset, rig pose) is taken out, and so, where the kind says so, is the part that IS a catalogue effect
(a compliance proportional to the gravity torque, a string offset / scale), so that what is left is
out of the catalogue.

The kinds (half, side, ~resembles):
  counterbalance_spring  tune6     robot  ~joint_compliance  joint 2 carries a gas-spring counterbalance
        between a point on link 1 and one on link 2; the gearbox deflects under the SPRING torque too,
        tau_s(q2) = -F(L)*a*b*sin(q2 + psi0)/L, L = sqrt(a^2 + b^2 - 2ab cos(q2 + psi0)), F progressive
        in L; the joint-2 error is c*tau_s with its mean and its projection onto joint 2's gravity torque
        taken out (what a compliance proportional to the gravity torque would reproduce): a function of
        q2 alone, neither a gravity torque nor a harmonic.
  tool_thermal_growth    tune6     robot  ~thermal_expansion the probe extension is heated by the process
        it carries (spindle / torch, on and off in blocks of 10-25 poses): it grows along its own axis
        (flange frame) by A*theta(t), theta a first-order lag (tau 3-8 min) of the duty; not the
        ambient temperature, and the shift turns with the flange (not a rig move).
  wrist_coupling_ratio   heldback6 robot  ~joint_scale       coupled wrist (axis 5 driven through axis 4's
        hollow shaft): the controller's coupling factor is off, so joint 5's real angle is off by
        c*(q4 - mean q4): an angle proportional to ANOTHER joint's angle (linear, not periodic; gen3's
        cross_coupling is a sine of the other joint).
  compliance_thermal     heldback6 robot  ~joint_compliance  joint 2/3's gearbox stiffness changes with the
        temperature (bearing preload / lubricant): deflection c*tau_g*(T - Tmean), with the part
        proportional to tau_g alone (an ordinary compliance) and the mean taken out: torque TIMES
        temperature.
  drum_exit_walk         tune6     sensor ~sensor_scale      one string's cable leaves a plain drum with no
        fixed guide: its exit point walks along the drum axis d by w*(l - l_ref) (w = groove pitch /
        circumference), so the reading is off by -w*(l - l_ref)*(d . u), u the string direction; the
        part linear in l (offset + scale, what a straight-pull bench calibration absorbs) is taken out:
        length TIMES direction.
  shared_reference_drift tune6     sensor ~sensor_drift      potentiometric drawstring sensors share one
        excitation reference: its warm-up (tau = session*0.1-0.3) plus a slow wander scales EVERY
        string's reading by (1 + k*v(t)); mean taken out (the sensors' calibration): a common,
        length-proportional drift in time, not an offset of one string, not the ambient temperature.
  anchor_thermal_shift   heldback6 sensor ~anchor_step       one anchor's exit point sits on a long bracket
        that expands with the temperature: it moves by k*(T - Tmean) along a fixed direction d, the
        reading is off by -(d . u)*k*(T - Tmean): a smooth, temperature-driven anchor move (not a step).
  cable_kink_bump        heldback6 sensor ~sensor_offset     one string's cable has a flattened / kinked
        section 60-150 mm long; while it runs over the exit guide the cable rides higher in the groove:
        a raised-cosine bump of the reading confined to a window of that string's length (centre at the
        30-70 % quantile of its lengths), mean taken out.
  rig_thermal_tilt       tune6     rig    ~thermal_expansion the string frame / tracker tripod stands on legs
        of different materials: it tilts about a horizontal axis through its feet by c*(T - Tmean): a
        rigid rig rotation about a far pivot driven by temperature (the robot does not change).
  tracker_transit_tilt   tune6     rig    ~                  tracker data: the trunnion (transit) axis is
        not perpendicular to the vertical axis by i; the horizontal angle is off by i*tan(elevation), so
        the point moves tangentially by i*(z - z_head): a shear of the workspace about the tracker.
  camera_radial_distortion heldback6 rig  ~                  camera (photogrammetry) data: residual radial
        lens distortion, the lateral position off by k*rho^2*(x_c, y_c) in the camera frame, rho the
        normalised image radius; noise 3x larger along the line of sight.
  tracker_range_warmup   heldback6 rig    ~rig_drift         tracker data: the ADM's zero settles after
        power-on, every range off by A*(1 - exp(-t/tau)) (tau = session*0.1-0.3, mean taken out) along
        the beam: a radial drift about the instrument, not a rig translation.

Kinematics, robots, rigs, multilateration and pose sampling are the earlier simulators' (imported from
sim.py / gen2.py / gen3.py, one definition).  Robots: ER3A and UR5 (DH), the same two written as Craig
MDH (er3a_mdh, ur5_mdh: simulated on the DH chain with DH deviations, robot.json written as
gen2.dh_to_mdh of the nominal, an exact reparametrisation) and gen2's 7-axis arm7.  Every dataset <name>/
has a twin <name>/oracle/ with the identical poses, split column, geometric deviations, base pose and
noise realisation but WITHOUT the effect; the tool is run on the twin with `--physics off`.  truth3.json
has gen3's / gen4's / gen5's fields, so score3.py scores these datasets unchanged; `gen6.py score`
computes the per-half summary itself (tune6, heldback6, overall) with score3.py's own functions.

Design notes (decided on the effects' visibility and the physics, not on the tool's findings):
- magnitudes follow the ratio 3-6 to the point noise (drawn uniformly, none adjusted: every effect was
  visible at the first `visible`), so several are larger than the physics usually gives: the probe's
  thermal growth (0.8-1.6 mm for a full duty swing), the anchor bracket (0.17-0.44 mm/K against ~0.01),
  the rig's thermal tilt (0.7-1.1e-4 rad/K against ~2e-5), the tracker's transit tilt (100-230 arcsec),
  the ADM warm-up (0.7-1.2 mm), the cable kink (0.6-1.4 mm peak), the gearbox stiffness' temperature
  coefficient (~25 %/K);
- wrist_coupling_ratio is simulated on the ER3A only (a coupled wrist); counterbalance_spring always on
  joint 2 (where counterbalances sit); joint-local kinds avoid joint 1 (a joint-1 zero moving with a
  global driver is a rig yaw);
- places_ok of a direction-dependent one-string error (drum_exit_walk) are the string and `workspace` at
  that string, as gen3's eyelet_friction and gen4's anchor_post_flex;
- `visible` at 4c26b3c: every effect dataset with --physics off is 2.19x or more the twin's held-out RMS
  (tune6 gmean 3.95, min 2.32; heldback6 gmean 3.89, min 2.19); effect-free datasets 1.000;
- the generation is deterministic (two plans into two directories are byte-identical).

Usage (from the repository root):
    python3 tests/crosscheck/gen6.py list        # one line of physics per kind
    python3 tests/crosscheck/gen6.py plan        # write every dataset and its twin
    python3 tests/crosscheck/gen6.py run [sub]   # run the tool (one process at a time, timeout)
    python3 tests/crosscheck/gen6.py score       # tune6 per dataset and per kind; heldback6 aggregate only
    python3 tests/crosscheck/gen6.py score full  # also heldback6 per dataset and per kind (unblinds it)
    python3 tests/crosscheck/gen6.py visible     # sanity: the effect datasets with --physics off against
                                                 # the twin (is the effect visible at all?); per kind for
                                                 # tune6, aggregate only for heldback6 (`visible full`)
Env: XC6_OUT (default /tmp/xcheck6/ds), XCHECK_DATA (default tests/data),
     XCHECK_TOOL (default target/release/drawcal)
"""
import json, math, os, sys, copy, time
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim import rpy_to_R  # noqa: E402
import gen2  # noqa: E402
import gen3  # noqa: E402
from gen2 import frames, tool_in_base, multilaterate, make_rig, load_robot, gravity_torques, dh_to_mdh  # noqa: E402
from gen3 import rodrigues, sample_poses, place  # noqa: E402

OUT = os.environ.get("XC6_OUT", "/tmp/xcheck6/ds")
SRC = os.environ.get("XCHECK_DATA", "tests/data")
TOOL = os.environ.get("XCHECK_TOOL", "target/release/drawcal")
gen2.SRC = SRC
gen3.TOOL = TOOL
D2R = math.pi / 180.0
HALVES = ("tune6", "heldback6")

# ---------------------------------------------------------------- the kinds
# kind: (half, side, unit magnitude, unit, resembles (catalogue name or ""), one line of physics)
KINDS = {
    # ---- robot side
    "counterbalance_spring": ("tune6", "robot", 0.01, "deg per unit-RMS spring term",
                              "joint_compliance",
                              "joint 2's gearbox deflects under a gas-spring counterbalance's torque tau_s(q2) "
                              "(spring between link 1 and link 2, progressive force); error c*tau_s with its mean and "
                              "its projection onto joint 2's gravity torque taken out: a function of q2 alone"),
    "tool_thermal_growth": ("tune6", "robot", 0.01, "mm",
                            "thermal_expansion",
                            "the probe extension, heated by the process it carries (on/off in blocks of 10-25 "
                            "poses), grows along its own axis in the FLANGE frame by A*theta(t), theta a first-order "
                            "lag (tau 3-8 min) of the duty, mean taken out: not the ambient temperature, not a rig move"),
    "wrist_coupling_ratio": ("heldback6", "robot", 1e-3, "deg/deg",
                             "joint_scale",
                             "coupled wrist: axis 5 is driven through axis 4's hollow shaft and the controller's "
                             "coupling factor is off, joint 5's real angle is off by c*(q4 - mean q4) (linear in "
                             "ANOTHER joint's angle, not periodic)"),
    "compliance_thermal": ("heldback6", "robot", 1e-5, "deg/(N*m*K)",
                           "joint_compliance",
                           "joint 2/3's gearbox stiffness changes with temperature (bearing preload / lubricant): "
                           "deflection c*tau_g*(T - Tmean) with the part proportional to tau_g alone and the mean "
                           "taken out (torque TIMES temperature)"),
    # ---- sensor side
    "drum_exit_walk": ("tune6", "sensor", 1e-3, "mm/mm",
                       "sensor_scale",
                       "one string's exit point walks along its drum's axis d by w*(l - l_ref) (no fixed guide): "
                       "reading off by -w*(l - l_ref)*(d . u), u the string direction, its part linear in l "
                       "(offset + scale) taken out: length TIMES direction"),
    "shared_reference_drift": ("tune6", "sensor", 1e-5, "1 (relative)",
                               "sensor_drift",
                               "all strings' potentiometers share one excitation reference whose warm-up (tau = "
                               "session*0.1-0.3) plus a slow wander scales EVERY reading by (1 + k*v(t)), mean taken "
                               "out: a common length-proportional drift in time (not one string, not the ambient)"),
    "anchor_thermal_shift": ("heldback6", "sensor", 1e-3, "mm/K",
                             "anchor_step",
                             "one anchor's exit point, on a long bracket, moves by k*(T - Tmean) along a fixed "
                             "direction d: that string's reading off by -(d . u)*k*(T - Tmean) (smooth, temperature "
                             "driven, not a step)"),
    "cable_kink_bump": ("heldback6", "sensor", 0.01, "mm",
                        "sensor_offset",
                        "one string's cable has a kinked / flattened section 60-150 mm long that rides higher in "
                        "the exit guide's groove: a raised-cosine bump of the reading over a window of that "
                        "string's length (centre at its 30-70 % quantile), mean taken out"),
    # ---- rig / instrument side
    "rig_thermal_tilt": ("tune6", "rig", 1e-6, "rad/K",
                         "thermal_expansion",
                         "the string frame / tracker tripod stands on legs of different materials: it tilts about "
                         "a horizontal axis through its feet by c*(T - Tmean), a rigid rig rotation about a far "
                         "pivot driven by temperature (the robot does not change)"),
    "tracker_transit_tilt": ("tune6", "rig", 1e-5, "rad",
                             "",
                             "tracker data: the trunnion axis is tilted by i from perpendicular to the vertical "
                             "axis; horizontal angle off by i*tan(elevation), the point moves tangentially by "
                             "i*(z - z_head): a shear of the workspace about the tracker"),
    "camera_radial_distortion": ("heldback6", "rig", 1e-3, "1",
                                 "",
                                 "camera (photogrammetry) data: residual radial lens distortion, lateral position "
                                 "off by k*rho^2*(x_c, y_c) in the camera frame, rho the normalised image radius "
                                 "(noise 3x larger along the line of sight)"),
    "tracker_range_warmup": ("heldback6", "rig", 0.01, "mm",
                             "rig_drift",
                             "tracker data: the ADM's zero settles after power-on, every range off by "
                             "A*(1 - exp(-t/tau)) (tau = session*0.1-0.3, mean taken out) along the beam: a radial "
                             "drift about the instrument, not a translation"),
}
SEEDS_PER_KIND = 6
N_NULL = 8
ROBOT_SIDE = {k for k, v in KINDS.items() if v[1] == "robot"}
RIG_POINT_KINDS = ("rig_thermal_tilt", "tracker_transit_tilt", "camera_radial_distortion", "tracker_range_warmup")
CAMERA_SIGMA = (0.02, 0.02, 0.06)   # camera frame: lateral, lateral, along the line of sight


def lsq_remove(e, cols):
    """e minus its least-squares projection onto span(cols) (each a length-N array)"""
    A = np.column_stack(cols)
    c = np.linalg.lstsq(A, e, rcond=None)[0]
    return e - A @ c


def lag(u, dt, tau):
    """first-order lag of the input u sampled at the poses (the state starts at 0)"""
    out = np.zeros(len(u))
    h = 0.0
    for k in range(len(u)):
        a = 1.0 - math.exp(-dt[k] / tau)
        h = h + (u[k] - h) * a
        out[k] = h
    return out


# ---------------------------------------------------------------- one dataset and its twin
def make_dataset(spec):
    rng = np.random.default_rng(spec["seed"])
    kind = spec["kind"]
    rname = spec["robot"]
    rbase = rname.replace("_mdh", "")
    robot = load_robot(rbase)                      # simulated on the DH chain
    robot_file = dh_to_mdh(robot) if rname.endswith("_mdh") else robot   # what the tool reads
    rigkind = spec["rig"]
    camera = rigkind == "camera"
    points = rigkind in ("points", "camera")
    rig = make_rig("points" if points else rigkind, rbase)
    if camera:
        rig["instrument"] = ("camera (simulated photogrammetry): x_mm,y_mm,z_mm = T in the camera system's frame, "
                             "noise 3x larger along the line of sight")
    nom = robot["joints"]
    n = len(nom)
    sigma = spec["sigma"]
    res = 0.024 if not points else 0.0
    # ---- true geometry (as gen2 / gen3 / gen4 / gen5, DH)
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
    Q, home = sample_poses(rng, robot, rbase, true_j, tool_true, to_rig, anchors, r, points, planar, nrm, c0, side, N)
    # ---- clock and temperature (as gen3 / gen4 / gen5: warm-up plus an HVAC swing)
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
    # ---- payload in blocks of 10-20 poses (as gen4 / gen5; written only where cols ask, no kind uses it)
    payload = np.zeros(N)
    levels = [0.0, 1.5, 3.0]
    k, b = 0, 0
    perm = list(rng.permutation(3))
    while k < N:
        ln = int(rng.integers(10, 21))
        payload[k:k + ln] = levels[perm[b % 3]]
        k += ln
        b += 1
    dt = np.diff(np.concatenate([[0.0], t]))

    # ---- the effect's parameters (drawn whatever the kind: every kind consumes the same rng stream)
    P = dict(spec.get("params", {}))
    P.setdefault("sign", float(rng.choice([-1.0, 1.0])))
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    P.setdefault("dir", d.tolist())
    P.setdefault("tau_frac", float(rng.uniform(0.1, 0.3)))
    P.setdefault("tool_tau_s", float(rng.uniform(180, 480)))
    P.setdefault("q_frac", float(rng.uniform(0.3, 0.7)))
    P.setdefault("kink_width_mm", float(rng.uniform(60, 150)))
    P.setdefault("axis_az_deg", float(rng.uniform(0, 360)))
    P.setdefault("spring_dpsi_deg", float(rng.uniform(-20, 20)))
    P.setdefault("spring_kappa", float(rng.uniform(0.3, 0.8)))
    P.setdefault("spring_a_b_mm", [float(rng.uniform(120, 180)), float(rng.uniform(300, 420))])
    walk = rng.normal(size=N + 30)
    duty_blocks = rng.integers(10, 26, size=N)
    duty_first = int(rng.integers(0, 2))
    j = P.get("joint")
    sg = P.get("sensor")
    g_rig = Rb @ np.array([0, 0, -1.0])   # gravity direction in the rig frame
    T_mean = float(temp_true.mean())
    if kind in ("compliance_thermal", "anchor_thermal_shift", "rig_thermal_tilt"):
        P["temp_mean_c"] = T_mean

    if kind == "counterbalance_spring":
        # joint 2's gravity torque over q2 (other joints at home) ~ A*sin(q2 + phi_g): the spring is set to
        # oppose it, near its dead centre where the arm is upright
        qs = np.linspace(-180, 180, 361)
        tg = np.array([gravity_torques(robot, np.r_[home[:1], qq, home[2:]])[1] for qq in qs])
        cs = np.linalg.lstsq(np.column_stack([np.sin(qs * D2R), np.cos(qs * D2R)]), tg, rcond=None)[0]
        phi_g = math.atan2(cs[1], cs[0])
        psi0 = phi_g + P["spring_dpsi_deg"] * D2R
        a_, b_ = P["spring_a_b_mm"]
        x = Q[:, 1] * D2R + psi0
        L = np.sqrt(a_ ** 2 + b_ ** 2 - 2 * a_ * b_ * np.cos(x))
        F = 1.0 + P["spring_kappa"] * (L - L.mean()) / L.mean()
        tau_s = -F * a_ * b_ * np.sin(x) / L
        tg2 = np.array([gravity_torques(robot, Q[k])[1] for k in range(N)])
        e = lsq_remove(tau_s, [np.ones(N), tg2])
        spring = e / np.sqrt(np.mean(e ** 2))
        P["psi0_deg"] = psi0 / D2R
        P["share_left_after_gravity_projection"] = float(np.sqrt(np.mean(e ** 2)) / np.std(tau_s))
    if kind == "tool_thermal_growth":
        duty = np.zeros(N)
        k, bi, on = 0, 0, duty_first
        while k < N:
            duty[k:k + duty_blocks[bi]] = on
            k += duty_blocks[bi]
            bi += 1
            on = 1 - on
        theta = lag(duty, dt, P["tool_tau_s"])
        growth = theta - theta.mean()
        tv = np.array(tool_true)
        tool_axis = tv / np.linalg.norm(tv)
        P["tool_axis_flange"] = tool_axis.tolist()
        P["duty_frac_on"] = float(duty.mean())
    if kind == "wrist_coupling_ratio":
        q4c = Q[:, 3] - Q[:, 3].mean()
    if kind == "compliance_thermal":
        tgj = np.array([gravity_torques(robot, Q[k])[j - 1] for k in range(N)])
        e = lsq_remove(tgj * (temp_true - T_mean), [np.ones(N), tgj])
        ct = e   # deg per unit c (tau in N*m, T in K)
        P["share_left_after_compliance_projection"] = float(np.std(e) / np.std(tgj * (temp_true - T_mean)))
    if kind in ("shared_reference_drift", "tracker_range_warmup"):
        tau = P["tau_frac"] * t[-1]
        warm = 1.0 - np.exp(-t / tau)
        P["tau_s"] = float(tau)
    if kind == "shared_reference_drift":
        wv = np.cumsum(walk)
        wv = np.convolve(wv, np.ones(31) / 31, mode="valid")[:N]
        wv = (wv - wv.mean()) / (wv.std() + 1e-12)
        v = (warm - warm.mean()) / warm.std() + 0.5 * wv
        vref = v - v.mean()
    if kind == "tracker_range_warmup":
        rangeoff = warm - warm.mean()
    if kind == "rig_thermal_tilt":
        a0 = np.array([math.cos(P["axis_az_deg"] * D2R), math.sin(P["axis_az_deg"] * D2R), 0.0])
        ax = a0 - (a0 @ g_rig) * g_rig
        ax /= np.linalg.norm(ax)
        if points:
            hinge = np.array([0.0, 0.0, -1300.0])   # the tripod's feet below the tracker head
        else:
            hinge = np.array([c0[0], c0[1], base_xyz[2] - 600.0])   # the frame's feet on the floor
        P["axis_rig"] = ax.tolist()
        P["hinge_mm"] = hinge.tolist()

    def robot_points(m):
        Pts = np.zeros((N, 3))
        for k in range(N):
            q = Q[k].copy()
            tool = tool_true
            if m != 0 and kind == "counterbalance_spring":
                q[1] += m * spring[k]
            elif m != 0 and kind == "wrist_coupling_ratio":
                q[4] += m * q4c[k]
            elif m != 0 and kind == "compliance_thermal":
                q[j - 1] += m * ct[k]
            elif m != 0 and kind == "tool_thermal_growth":
                tool = (np.array(tool_true) + m * growth[k] * tool_axis).tolist()
            F_ = frames(true_j, q, "dh")
            pb = (F_[-1] @ np.array([*tool, 1.0]))[:3]
            Pts[k] = to_rig(pb)
        return Pts

    P0 = robot_points(0.0)
    L0 = None
    if not points:
        L0 = np.linalg.norm(P0[:, None, :] - anchors[None, :, :], axis=2) - r
        U0 = (P0[:, None, :] - anchors[None, :, :]) / (L0 + r)[:, :, None]
    if kind == "drum_exit_walk":
        um = U0[:, sg - 1].mean(0)
        um /= np.linalg.norm(um)
        dd = d - (d @ um) * um
        dd /= np.linalg.norm(dd)
        lref = float(L0[:, sg - 1].mean())
        ew = -(L0[:, sg - 1] - lref) * (U0[:, sg - 1] @ dd)
        walk_e = lsq_remove(ew, [np.ones(N), L0[:, sg - 1]])
        P["drum_axis_rig"] = dd.tolist()
        P["l_ref_mm"] = lref
    if kind == "cable_kink_bump":
        lc = float(np.quantile(L0[:, sg - 1], P["q_frac"]))
        x = (L0[:, sg - 1] - lc) / (0.5 * P["kink_width_mm"])
        bump = np.where(np.abs(x) < 1, 0.5 * (1 + np.cos(math.pi * np.clip(x, -1, 1))), 0.0)
        P["l_centre_mm"] = lc
        P["poses_in_window"] = int(np.sum(np.abs(x) < 1))
        bump = bump - bump.mean()
    if camera:
        zc = P0.mean(0) / np.linalg.norm(P0.mean(0))
        xc = np.cross([0, 0, 1.0], zc)
        xc /= np.linalg.norm(xc)
        yc = np.cross(zc, xc)
        Rc = np.column_stack([xc, yc, zc])   # camera frame -> rig frame
        P["camera_axis_rig"] = zc.tolist()

    def rig_view(X, m):
        """the true points X as the (moved / distorted) rig or instrument sees them"""
        if m == 0 or kind not in RIG_POINT_KINDS:
            return X
        if kind == "rig_thermal_tilt":
            hg = np.array(P["hinge_mm"])
            ax_ = np.array(P["axis_rig"])
            return np.array([hg + rodrigues(-m * (temp_true[k] - T_mean) * ax_) @ (X[k] - hg) for k in range(N)])
        if kind == "tracker_transit_tilt":
            rh = np.linalg.norm(X[:, :2], axis=1)
            th = np.column_stack([-X[:, 1] / rh, X[:, 0] / rh, np.zeros(N)])
            return X + (m * X[:, 2])[:, None] * th
        if kind == "camera_radial_distortion":
            Xc = X @ Rc
            rho2 = (Xc[:, 0] ** 2 + Xc[:, 1] ** 2) / Xc[:, 2] ** 2
            ec = np.column_stack([Xc[:, 0] * rho2, Xc[:, 1] * rho2, np.zeros(N)]) * m
            return X + ec @ Rc.T
        if kind == "tracker_range_warmup":
            D = np.linalg.norm(X, axis=1)
            return X + (m * rangeoff / D)[:, None] * X
        return X

    def measure(Pts, m):
        """noise-free readings (strings) or points (tracker / camera) of the true points Pts with the effect at m"""
        X = rig_view(Pts, m)
        if points:
            return X
        A = anchors
        if m != 0 and kind == "anchor_thermal_shift":
            Lm = np.linalg.norm(X[:, None, :] - anchors[None, :, :], axis=2) - r
            As = anchors[sg - 1][None, :] + (m * (temp_true - T_mean))[:, None] * d[None, :]
            Lm[:, sg - 1] = np.linalg.norm(X - As, axis=1) - r
            return Lm
        L = np.linalg.norm(X[:, None, :] - A[None, :, :], axis=2) - r
        if m != 0 and KINDS.get(kind, ("", ""))[1] == "sensor":
            s_ = (sg or 1) - 1
            if kind == "drum_exit_walk":
                L[:, s_] += m * walk_e
            elif kind == "cable_kink_bump":
                L[:, s_] += m * bump
            elif kind == "shared_reference_drift":
                L = L * (1 + m * vref)[:, None]
        return L

    def located(X, guess):
        if points:
            return X
        return np.array([multilaterate(anchors, X[k] + r, guess[k]) for k in range(N)])

    M0 = located(measure(P0, 0.0), P0)
    if camera:
        noise = (noise / sigma * np.array(CAMERA_SIGMA)[None, :]) @ Rc.T   # camera frame -> rig frame
        point_noise = float(np.linalg.norm(CAMERA_SIGMA))
    elif points:
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
        # signs: physical where the physics fixes it (a heated probe grows, a warming-up reference / ADM
        # settles one way -- its sign is the part's, random), random elsewhere
        if kind not in ("tool_thermal_growth",):
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
        json.dump(robot_file, open(f"{folder}/robot.json", "w"), indent=1)
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
             "ratio": erms / point_noise, "scaling": "as gen3 / gen4 / gen5: RMS over the poses of the noise-free "
             "displacement of the located point (strings: multilaterated with the nominal anchors from the "
             "readings; tracker / camera: the measured point) with the effect against without it; the effect's "
             "session mean (and, where the kind says so, its catalogue part) is taken out",
             "robot": rname, "robot_convention_written": robot_file.get("convention", "dh"),
             "deviations_convention": "dh (simulated on the DH chain)",
             "rig": spec["rig"], "n_poses": N, "cols": spec["cols"], "sigma": sigma,
             "session_s": float(t[-1]), "temp_rise_c": float(rise), "temp_swing_c": float(swing),
             "deviations": devs, "tool_point_mm": tool_true, **rng_info,
             "base_in_rig": {"xyz_mm": base_xyz.tolist(), "rpy_deg": base_rpy.tolist()}}
    json.dump(truth, open(f"{dname}/truth3.json", "w"), indent=1)
    return truth


# ---------------------------------------------------------------- the plan
def plan():
    R = np.random.default_rng(6060606)
    specs = []
    ROB = ["er3a", "ur5", "er3a_mdh", "ur5_mdh", "arm7", "er3a"]
    RIGS_ROBOT = ["std4", "s3tilt", "std4", "points", "s5np", "std4"]
    RIGS_STR = ["std4", "s5np", "std4", "s3tilt", "std4", "s5np"]
    NSTR = {"std4": 4, "s3tilt": 3, "s5np": 5}

    def add(kind, half, i, robot, rig, params, places, drivers, cols):
        idx = len(specs)
        tag = params.get("joint") or params.get("sensor") or ""
        specs.append({"name": f"{idx:03d}_{kind}{tag}_{robot}_{rig}", "kind": kind, "half": half,
                      "robot": robot, "rig": rig, "n": int(R.integers(150, 201)), "seed": 1200000 + idx,
                      "sigma": 0.02 if rig not in ("points", "camera") else 0.03, "ratio": float(R.uniform(3, 6)),
                      "params": params, "places_ok": places, "drivers": drivers, "cols": cols})

    def rand_cols():
        return [["time_s", "temp_c"], ["time_s"], [], ["time_s", "temp_c", "payload_kg"]][int(R.integers(0, 4))]

    def with_time(i):
        return [["time_s", "temp_c"], ["time_s"], ["time_s", "temp_c", "payload_kg"]][i % 3]

    def with_temp(i):
        return [["time_s", "temp_c"], ["temp_c"], ["time_s", "temp_c", "payload_kg"]][i % 3]

    for kind in KINDS:
        half = KINDS[kind][0]
        for i in range(SEEDS_PER_KIND):
            rb = ROB[i]
            rig = RIGS_ROBOT[i]
            cols = rand_cols()
            prm = {}
            if kind == "counterbalance_spring":
                prm = {"joint": 2}
                places = [place("joint", 2), place("configuration")]
                drivers = ["joint 2's angle (the spring's torque), beside its gravity torque"]
            elif kind == "tool_thermal_growth":
                cols = with_time(i)
                places, drivers = [place("time"), place("order")], ["time (the process duty's heat, lagged)"]
            elif kind == "wrist_coupling_ratio":
                rb = ["er3a", "er3a_mdh", "er3a", "er3a_mdh", "er3a", "er3a"][i]   # a coupled wrist: the ER3A
                prm = {"joint": 5, "source_joint": 4}
                places, drivers = [place("joint", 4), place("joint", 5)], ["joint 4's angle, on joint 5"]
            elif kind == "compliance_thermal":
                j = [2, 3, 2, 2, 3, 2][i]
                prm = {"joint": j}
                cols = with_temp(i)
                places = [place("joint", j), place("temperature", j)]
                drivers = [f"joint {j}'s gravity torque times the temperature"]
            elif KINDS[kind][1] == "sensor":
                rig = RIGS_STR[i]
                if kind == "shared_reference_drift":
                    cols = with_time(i)
                    places, drivers = [place("time"), place("order")], ["time (all strings, proportional to length)"]
                else:
                    s = int(R.integers(1, NSTR[rig] + 1))
                    prm = {"sensor": s}
                    if kind == "drum_exit_walk":
                        # as gen3's eyelet_friction / gen4's anchor_post_flex: a direction-dependent error of
                        # one string is at that string and at where T is (seen from that string)
                        places = [place("string", sensor=s), place("workspace", sensor=s)]
                        drivers = [f"string {s}'s length times its direction"]
                    elif kind == "anchor_thermal_shift":
                        cols = with_temp(i)
                        places = [place("temperature", sensor=s), place("string", sensor=s)]
                        drivers = [f"temperature (anchor {s} moves)"]
                    elif kind == "cable_kink_bump":
                        places, drivers = [place("string", sensor=s)], [f"string {s}'s length (a window)"]
            elif kind == "rig_thermal_tilt":
                rig = ["std4", "s3tilt", "std4", "points", "s5np", "points"][i]
                cols = with_temp(i)
                places, drivers = [place("temperature")], ["temperature (a rig rotation about its feet)"]
            elif kind in ("tracker_transit_tilt", "tracker_range_warmup"):
                rig = "points"
                if kind == "tracker_range_warmup":
                    cols = with_time(i)
                    places, drivers = [place("time"), place("order")], ["time (a range offset along the beam)"]
                else:
                    places, drivers = [place("workspace")], ["where T is (height times the tangential direction)"]
            elif kind == "camera_radial_distortion":
                rig = "camera"
                places, drivers = [place("workspace")], ["where T is in the camera's image (radius cubed)"]
            add(kind, half, i, rb, rig, prm, places, drivers, cols)
    for i in range(N_NULL):
        rig = ["std4", "s3tilt", "s5np", "points", "std4", "camera", "std4", "points"][i]
        cols = [["time_s", "temp_c"], ["time_s", "temp_c", "payload_kg"], ["time_s"], ["temp_c"],
                ["payload_kg"], ["time_s", "temp_c"], ["time_s", "temp_c", "payload_kg"], ["time_s", "temp_c"]][i]
        add("none", HALVES[i % 2], i, ["er3a", "ur5", "er3a_mdh", "ur5_mdh", "arm7", "er3a", "ur5", "arm7"][i],
            rig, {}, [], [], cols)
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
    means the effect is invisible to the geometric fit. Per kind for tune6, aggregate only for heldback6
    unless detail."""
    import score3
    specs = json.load(open(f"{OUT}/plan.json"))
    rows = []
    for s in specs:
        if only and only not in s["name"]:
            continue
        d = f"{OUT}/{s['name']}"
        if not os.path.exists(f"{d}/oracle/report.json"):
            rc, _ = gen3.run_tool(f"{d}/oracle", "off", "report")
        if not os.path.exists(f"{d}/report_off.json"):
            gen3.run_tool(d, "off", "report_off")
        try:
            off = json.load(open(f"{d}/report_off.json"))["stats"]["test"]["after"]["rms_mm"]
            orc = json.load(open(f"{d}/oracle/report.json"))["stats"]["test"]["after"]["rms_mm"]
        except Exception:
            continue
        rows.append((s["name"], s["kind"], s["half"], off / orc))
    json.dump(rows, open(f"{OUT}/visible6.json", "w"), indent=1)
    for h in HALVES:
        rr = [r for r in rows if r[2] == h]
        for k in dict.fromkeys(r[1] for r in rr):
            vals = [r[3] for r in rr if r[1] == k]
            if h == "tune6" or detail or k == "none":
                print(f"{h:9s} {k:24s} off/oracle gmean {score3.gmean(vals):6.3f} min {min(vals):6.3f} "
                      f"max {max(vals):6.3f}  " + " ".join(f"{v:.2f}" for v in vals))
        eff = [r[3] for r in rr if r[1] != "none"]
        nul = [r[3] for r in rr if r[1] == "none"]
        if eff:
            print(f"{h:9s} ALL EFFECTS off/oracle gmean {score3.gmean(eff):6.3f} min {min(eff):6.3f}; "
                  f"{sum(v < 1.5 for v in eff)} of {len(eff)} below 1.5; effect-free gmean {score3.gmean(nul):.3f}")


def score(full=False):
    import score3
    specs = json.load(open(f"{OUT}/plan.json"))
    rows = [score3.score_one(f"{OUT}/{s['name']}") for s in specs if os.path.exists(f"{OUT}/{s['name']}/run.json")]
    json.dump(rows, open(f"{OUT}/scores6.json", "w"), indent=1)
    shown = [r for r in rows if full or r["half"] == "tune6"]
    print(f"{'dataset':48s} {'eff/noise':>9s} {'tool':>7s} {'oracle':>7s} {'ratio':>6s} {'category':12s} findings")
    for r in shown:
        f = lambda x: "   -   " if x is None else f"{x:7.4f}"
        print(f"{r['name']:48s} {r['ratio_eff']:9.2f} {f(r.get('tool_rms'))} {f(r.get('oracle_rms'))} "
              f"{'' if r.get('ratio') is None else format(r['ratio'], '6.3f'):>6s} {r['cat']:12s} "
              f"{'; '.join(r.get('findings', []))}")
    print()
    print("(located: an unexplained finding at the right place, or the right name for a kind since taken into the catalogue)")
    print(f"{'kind':24s} {'half':9s} {'n':>2s} {'located':>7s} {'wrongpl':>7s} {'silent':>6s} {'named':>5s} "
          f"{'named>=1%':>9s} {'ratio':>6s}")
    for h in HALVES:
        if h == "heldback6" and not full:
            print(f"(heldback6: per-kind lines withheld; `score full` shows them)")
            continue
        rh = [r for r in rows if r["half"] == h]
        for k in dict.fromkeys(r["kind"] for r in rh):
            rr = [r for r in rh if r["kind"] == k]
            print(f"{k:24s} {h:9s} {len(rr):2d} {sum(r['cat'] in ('located', 'named_right') for r in rr):7d} "
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
    json.dump(sums, open(f"{OUT}/summary6.json", "w"), indent=1)
    return sums


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "list"
    if cmd == "list":
        for k, v in KINDS.items():
            print(f"{k:25s} {v[0]:9s} {v[1]:6s} ~{v[4]:17s} {v[5]}")
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
