#!/usr/bin/env python3
"""Seventh independent cross-check of drawcal: another fresh, blind set of physics OUTSIDE the catalogue,
with a tune half (tune7) and a held-back half (heldback7).

Written blind: from physics descriptions of industrial arms (dress packs, drives whose motor sits on
the turret, tool changers, motors heating the link that houses them), drawstring encoder rigs (servo
interference on analog sensor cables, viscoelastic cables, strings touching the arm, end fittings),
laser trackers and stereo cameras, from DATA_FORMAT.md, README.md, docs/CLI.md and the earlier
cross-check simulators (gen3.py ... gen6.py in full; of sim.py / gen2.py the parts imported),
README3.md and their scorer score3.py only -- WITHOUT reading src/, docs/PHYSICS.md, EVAL.md,
BENCHMARKS.md, tests/*.rs or the git history.  The tool version measured is commit 5f1c5a3 (`git
rev-parse --short HEAD` of the checkout; binary /tmp/bin/drawcal-base, the same file as the checkout's
target/release/drawcal, built after that commit; the only uncommitted change in the checkout then was
tests/api/load/run.sh, outside the tool).

None of the kinds below is a catalogue effect (joint_compliance, backlash, joint_periodic, joint_scale,
base_tilt, thermal_expansion, sensor_scale, sensor_offset, sensor_drift, cable_sag, anchor_step,
rig_step, rig_drift) nor one of gen3.py's, gen4.py's, gen5.py's or gen6.py's kinds.  Several RESEMBLE
a catalogue effect without being it (`resembles` in KINDS): naming that catalogue effect is a misname.
Each effect's part that is an exact reparametrisation of the geometric model (a constant joint offset,
link length, tool offset, rig / base pose, and for point data a uniform scale about the instrument,
which the link lengths, tool and base translation absorb together) is taken out, and so, where the
kind says so, is the part that IS a catalogue effect (a compliance proportional to the gravity torque,
a backlash of the joint's own approach direction, a string offset / scale / linear drift), so that
what is left is out of the catalogue.

The kinds (half, side, ~resembles):
  dress_pack_tension     tune7     robot  ~joint_compliance  the dress pack (hoses / cables) is clamped to
        the turret (link 1) and to the forearm; stretched beyond its slack length d0 it pulls the two
        clamps together with F = k*w*softplus((d - d0)/w) (d the clamp distance, a function of q2 and
        q3 -- q2..q4 on the 7-axis arm): an internal force between link 1 and the forearm whose torques
        z_j.((B - o_j) x F) deflect every joint between them (2 and the elbow); per joint the mean and
        the projection onto its gravity torque are taken out: driven by a PAIR of joints.
  parallelogram_backlash tune7     robot  ~backlash          the elbow's motor sits on the turret and drives
        the forearm through a rod / belt along the upper arm, so its gearbox turns with the ABSOLUTE
        forearm angle q2 + q3 (axes 2, 3 parallel): joint 3 lags by -b/2*sign(last change of q2 + q3);
        the part a backlash of joint 3 or of joint 2 (the sign of their own last moves) reproduces is
        taken out: the approach direction of a SUM of two joints.
  tool_changer_rock      heldback7 robot  ~backlash          a worn tool changer has angular play: whenever
        gravity has a component across the tool axis the tool rocks over to the limit of the play,
        theta*tanh(|g_perp|/w) about the axis z x g_perp through the changer's face (10-30 mm in front
        of the flange); the displacement's flange-frame mean (a tool offset) is taken out: saturated,
        two-axis, driven by the flange's orientation to gravity (no payload column involved).
  forearm_motor_heat     heldback7 robot  ~thermal_expansion the forearm length (ER3A d4, UR5 a3, 7-axis d5)
        grows with the heat of the elbow motor holding it: input (elbow gravity torque)^2 (I^2 R of the
        holding current), first-order lag tau 4-10 min from a cold start, mean taken out: one link,
        driven by the history of the configurations, not the ambient temperature.
  servo_emi_offset       tune7     sensor ~joint_compliance  one string's analog signal runs beside joint j's
        motor cable and picks up its PWM interference, rectified to an offset proportional to the
        motor's holding current: reading += k*(|tau_g,j| - mean): a one-string error driven by the
        robot's configuration (a gravity torque's magnitude), not by the string.
  cable_viscoelastic_creep tune7   sensor ~sensor_scale      one string's (polymer) cable creeps under the
        spring-return tension F(l) = F0*(1 + kappa*(l - mean l)/mean l): delayed strain eps = lag of F/F0
        (tau 3-10 min, from a relaxed cable), reading off by -l*eps; its part an offset, a scale or a
        linear drift reproduces is taken out: the string's own length history times its length.
  string_link_contact    heldback7 sensor ~cable_sag         in some configurations one string touches the
        forearm (a capsule of radius R around the elbow-wrist segment, R at the 15-35 % quantile of the
        string-forearm distance, clipped to 30-150 mm) and is pushed out to its surface: its path is
        longer by |C' - A| + |T - C'| - |T - A|; zero elsewhere; mean (a string offset) taken out:
        a region of the configuration space, seen on one string.
  string_hook_offsets    heldback7 sensor ~sensor_offset     the strings' end fittings on the tool are not
        concentric: string i ends at T + R_flange*delta_i (delta_i fixed in the flange frame, their
        common part -- a tool offset -- taken out); per string the reading's mean (a string offset) is
        taken out: every string's error -u_i.R_flange*delta_i turns with the flange's orientation.
  smr_vertex_offset      tune7     rig    ~                  tracker data: the SMR's cube-corner vertex is
        off its sphere's centre by v (fixed in the flange frame); the tracker reads the range to the
        vertex, so the point is off by (v.b)b, b the beam direction; its part v (a tool offset) and the
        best similarity transform of the points (a rig pose / scale) are taken out: -v_perp, driven by
        the flange's orientation relative to the beam.
  tracker_refraction_gradient tune7 rig   ~rig_drift         tracker data: the air stratifies as the room
        warms (vertical gradient proportional to T - Tmean); the beam curves and the point is off by
        c*(T - Tmean)*D^2 perpendicular to the beam in its vertical plane (D the range): temperature
        TIMES range squared (gen3's static refraction field has no time in it).
  stereo_disparity_offset heldback7 rig   ~                  camera (stereo photogrammetry) data: the two
        cameras' principal points disagree by a constant disparity offset, so depth is off by
        -z^2*dd/(f*b) along each ray; the best similarity transform (a rig pose and a uniform scale
        about the camera) taken out: a depth-quadratic warp along the rays (noise 3x larger along the
        line of sight).
  tracker_elevation_eccentricity heldback7 rig ~             tracker data: the elevation encoder's disc is
        mounted eccentric: the vertical angle is off by e*sin(el + phi) (once per revolution), the point
        moves by D*e*sin(el + phi) along the elevation direction; the best similarity transform taken
        out.

Kinematics, robots, rigs, multilateration and pose sampling are the earlier simulators' (imported from
sim.py / gen2.py / gen3.py, one definition; lsq_remove and lag from gen6.py).  Robots: ER3A and UR5
(DH), the same two written as Craig MDH (er3a_mdh, ur5_mdh: simulated on the DH chain with DH
deviations, robot.json written as gen2.dh_to_mdh of the nominal, an exact reparametrisation) and gen2's
7-axis arm7 (parallelogram_backlash: the ER3A and UR5 chains only, whose axes 2 and 3 are parallel).
Every dataset <name>/ has a twin <name>/oracle/ with the identical poses, split column, geometric
deviations, base pose and noise realisation but WITHOUT the effect; the tool is run on the twin with
`--physics off`.  truth3.json has gen3's ... gen6's fields, so score3.py scores these datasets unchanged;
`gen7.py score` computes the per-half summary itself (tune7, heldback7, overall) with score3.py's own
functions.  Conditions as gen6: 6 recordings per kind (150-200 poses, effect 3-6x the point noise,
measured as gen3), 8 effect-free recordings (4 per half), string noise 0.02 mm with 0.024 mm
resolution, tracker 0.03 mm per axis, camera 0.02/0.02/0.06 mm.

Design notes (decided on the effects' visibility and the physics, not on the tool's findings):
- magnitudes follow the ratio 3-6 to the point noise (drawn uniformly, none adjusted: every effect was
  visible at the first `visible`), so several are larger than the physics usually gives: the refraction
  gradient (0.016-0.030 mm/(K*m^2), some 35-60x what 1 K/m of stratification per K of warming bends a
  beam), the SMR's vertex offset (0.25-0.39 mm against ~0.01), the elevation encoder's eccentricity
  (180-430 arcsec), the stereo disparity offset (2-5 mm of depth at the mean depth, ~0.2-0.5 px for a
  300 mm baseline), the tool changer's play (2-10 mrad), the servo interference (0.013-0.043 mm per
  N*m of holding torque);
- the shapes of dress_pack_tension, parallelogram_backlash, cable_viscoelastic_creep and
  string_link_contact are normalised to unit RMS after the catalogue / reparametrisation parts are
  taken out and then scaled by the magnitude (`unit` says so); string_link_contact's shape is that of a
  rigid contact (penetrations of tens of mm, so the rigid path excess reaches 17-34 mm) scaled down to
  0.1-0.2 mm RMS: read it as a string grazing a soft sleeve, the shape (zero outside the contact
  region, convex inside) kept;
- shares left after the catalogue parts are taken out (truth3.json `params`): dress pack 0.48-0.64 of
  the joint-2 torque term, 0.66-0.98 of the elbow's; parallelogram backlash 0.67-0.75; viscoelastic
  creep 0.37-0.54;
- signs: physical where the physics fixes it (the pack pulls, the joint lags, the tool droops, the
  forearm grows, the cable creeps longer, a touching string is longer), random for the interference's
  polarity and the gradient's direction; vectors (SMR vertex, hooks) are random directions;
- joint-local kinds avoid joint 1 (a joint-1 quantity moving with a global driver is a rig yaw);
- places_ok were written with the kinds, before any run of the tool, and not changed after;
- `visible` at 5f1c5a3: every effect dataset with --physics off is 2.28x or more the twin's held-out
  RMS (tune7 gmean 4.16, min 2.50; heldback7 gmean 3.91, min 2.28); effect-free datasets 1.000;
- the generation is deterministic (two plans into two directories are byte-identical); `plan` takes
  ~20 s, `visible` ~7 s and `run` ~10 s on 2 shared cores (the tool takes 0.05-0.2 s a recording).

Measured once at 5f1c5a3 (binary /tmp/bin/drawcal-base), `score`:
  tune7:     located 58.3 %, misnamed 2.78 / 10 (2.50 without < 1 % gain), silent 25.0 %, wrong place
             11.1 %, ratio 2.843 (worst 6.12), false alarms 0 of 4
  heldback7: located 58.3 %, misnamed 6.39 / 10 (6.11 without < 1 % gain), silent 27.8 %, wrong place
             13.9 %, ratio 2.101 (worst 5.60), false alarms 0 of 4

Usage (from the repository root):
    python3 tests/crosscheck/gen7.py list        # one line of physics per kind
    python3 tests/crosscheck/gen7.py plan        # write every dataset and its twin
    python3 tests/crosscheck/gen7.py run [sub]   # run the tool (one process at a time, timeout)
    python3 tests/crosscheck/gen7.py score       # tune7 per dataset and per kind; heldback7 aggregate only
    python3 tests/crosscheck/gen7.py score full  # also heldback7 per dataset and per kind (unblinds it)
    python3 tests/crosscheck/gen7.py visible     # sanity: the effect datasets with --physics off against
                                                 # the twin (is the effect visible at all?); per kind for
                                                 # tune7, aggregate only for heldback7 (`visible full`)
Env: XC7_OUT (default /tmp/xcheck7/ds), XCHECK_DATA (default tests/data),
     XCHECK_TOOL (default target/release/drawcal)
"""
import json, math, os, sys, copy, time
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim import rpy_to_R  # noqa: E402
import gen2  # noqa: E402
import gen3  # noqa: E402
from gen2 import frames, axes, multilaterate, make_rig, load_robot, gravity_torques, dh_to_mdh, HOME  # noqa: E402
from gen3 import sample_poses, place  # noqa: E402
from gen6 import lsq_remove, lag, CAMERA_SIGMA  # noqa: E402

OUT = os.environ.get("XC7_OUT", "/tmp/xcheck7/ds")
SRC = os.environ.get("XCHECK_DATA", "tests/data")
TOOL = os.environ.get("XCHECK_TOOL", "target/release/drawcal")
gen2.SRC = SRC
gen3.TOOL = TOOL
D2R = math.pi / 180.0
HALVES = ("tune7", "heldback7")

# ---------------------------------------------------------------- the kinds
# kind: (half, side, unit magnitude, unit, resembles (catalogue name or ""), one line of physics)
KINDS = {
    # ---- robot side
    "dress_pack_tension": ("tune7", "robot", 0.01, "deg per unit-RMS torque term",
                           "joint_compliance",
                           "the dress pack clamped to the turret and the forearm pulls them together once "
                           "stretched past its slack (soft one-sided spring of the clamp distance, a function of "
                           "q2 and q3); its torques deflect joint 2 and the elbow, each with its mean and its "
                           "gravity-torque projection taken out: driven by a PAIR of joints"),
    "parallelogram_backlash": ("tune7", "robot", 0.01, "deg per unit-RMS term",
                               "backlash",
                               "the elbow motor sits on the turret and drives the forearm through a rod / belt, so "
                               "its gear play follows the ABSOLUTE forearm angle: joint 3 lags by -b/2*sign(last "
                               "change of q2 + q3), with the part joint 3's or joint 2's own backlash reproduces "
                               "taken out"),
    "tool_changer_rock": ("heldback7", "robot", 1e-3, "rad",
                          "backlash",
                          "a worn tool changer's angular play: the tool rocks over to theta*tanh(|g_perp|/w) about "
                          "z x g_perp through the changer face whenever gravity pulls across the tool axis "
                          "(saturated, two-axis, by the flange's orientation to gravity); flange-frame mean taken out"),
    "forearm_motor_heat": ("heldback7", "robot", 0.01, "mm per unit-std heat state",
                           "thermal_expansion",
                           "the forearm (ER3A d4, UR5 a3, 7-axis d5) grows with the heat of the elbow motor "
                           "holding it: lag (tau 4-10 min, cold start) of the elbow gravity torque squared, mean "
                           "taken out: one link, driven by the configuration history, not the ambient"),
    # ---- sensor side
    "servo_emi_offset": ("tune7", "sensor", 1e-3, "mm/(N*m)",
                         "joint_compliance",
                         "one string's analog signal picks up joint j's servo PWM interference, rectified to an "
                         "offset proportional to the holding current: reading += k*(|tau_g,j| - mean) (one "
                         "string, driven by the robot's configuration)"),
    "cable_viscoelastic_creep": ("tune7", "sensor", 0.01, "mm per unit-RMS term",
                                 "sensor_scale",
                                 "one string's polymer cable creeps under the spring-return tension F(l): delayed "
                                 "strain = lag (tau 3-10 min) of F/F0, reading off by -l*eps; offset, scale and "
                                 "linear-drift parts taken out: its own length history times its length"),
    "string_link_contact": ("heldback7", "sensor", 0.01, "mm per unit-RMS term",
                            "cable_sag",
                            "in part of the configurations one string touches the forearm (capsule around the "
                            "elbow-wrist segment) and is pushed out to its surface: a longer path there, zero "
                            "elsewhere, mean taken out"),
    "string_hook_offsets": ("heldback7", "sensor", 0.1, "mm (RMS end-fitting offset)",
                            "sensor_offset",
                            "the strings' end fittings on the tool are not concentric: string i ends at "
                            "T + R_flange*delta_i (common part taken out), each reading's mean taken out: every "
                            "string's error turns with the flange's orientation"),
    # ---- rig / instrument side
    "smr_vertex_offset": ("tune7", "rig", 0.01, "mm",
                          "",
                          "tracker data: the SMR's cube-corner vertex is off its centre by v (flange frame); the "
                          "point is off by (v.b)b along the beam b; v itself (tool) and the best similarity "
                          "transform taken out: -v_perp, by the flange's orientation to the beam"),
    "tracker_refraction_gradient": ("tune7", "rig", 1e-3, "mm/(K*m^2)",
                                    "rig_drift",
                                    "tracker data: the air stratifies as the room warms; the beam curves, the point "
                                    "is off by c*(T - Tmean)*D^2 across the beam in its vertical plane: temperature "
                                    "TIMES range squared"),
    "stereo_disparity_offset": ("heldback7", "rig", 0.01, "mm at the mean depth (before the similarity removal)",
                                "",
                                "camera (stereo) data: a constant disparity offset between the cameras, depth off by "
                                "-z^2*dd/(f*b) along each ray; the best similarity transform taken out: a "
                                "depth-quadratic warp (noise 3x larger along the line of sight)"),
    "tracker_elevation_eccentricity": ("heldback7", "rig", 1e-5, "rad",
                                       "",
                                       "tracker data: the elevation encoder's disc is eccentric, vertical angle off "
                                       "by e*sin(el + phi), the point by D*e*sin(el + phi) along the elevation "
                                       "direction; the best similarity transform taken out"),
}
SEEDS_PER_KIND = 6
N_NULL = 8
ROBOT_SIDE = {k for k, v in KINDS.items() if v[1] == "robot"}
RIG_POINT_KINDS = ("smr_vertex_offset", "tracker_refraction_gradient", "stereo_disparity_offset",
                   "tracker_elevation_eccentricity")


def elbow_joint(rbase):
    """1-based index of the elbow joint (the forearm is the body after it)"""
    return 4 if rbase == "arm7" else 3


def forearm_points(F, joints, e):
    """(a point on the elbow axis, the wrist point) of the forearm, both fixed in the body after joint e,
    from the frames F (DH: frame e-1's origin is on joint e's axis; the wrist point is d_{e+1} along z_e)"""
    oa = F[e - 1][:3, 3].copy()
    ob = (F[e] @ np.array([0.0, 0.0, joints[e]["d_mm"], 1.0]))[:3]
    return oa, ob


def remove_similarity(disp, X):
    """disp (N x 3) minus its least-squares part t + w x X + s*X (a rig / base pose change and a uniform
    scale about the instrument: an exact reparametrisation of the geometric model for point data)"""
    N = len(X)
    Xc = X / 1000.0
    A = np.zeros((3 * N, 7))
    for k in range(N):
        x, y, z = Xc[k]
        A[3 * k:3 * k + 3, 0:3] = np.eye(3)
        A[3 * k:3 * k + 3, 3:6] = np.array([[0, z, -y], [-z, 0, x], [y, -x, 0]])   # w x X
        A[3 * k:3 * k + 3, 6] = Xc[k]
    b = disp.reshape(-1)
    c = np.linalg.lstsq(A, b, rcond=None)[0]
    return (b - A @ c).reshape(N, 3)


def seg_seg(p0, p1, q0, q1):
    """closest points of the segments p0-p1 and q0-q1: (s, t, point on p, point on q)"""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c, b = d1 @ r, d1 @ d2
    den = a * e - b * b
    s = np.clip((b * f - c * e) / den, 0.0, 1.0) if den > 1e-12 else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, np.clip(-c / a, 0.0, 1.0)
    elif t > 1.0:
        t, s = 1.0, np.clip((b - c) / a, 0.0, 1.0)
    return s, t, p0 + s * d1, q0 + t * d2


def sign_state(x, x0, thr=0.05):
    """the flank a play rests on: the sign of the last change of x larger than thr (the first from x0)"""
    out = np.zeros(len(x))
    prev, st = x0, 1.0
    for k in range(len(x)):
        dx = x[k] - prev
        if abs(dx) > thr:
            st = math.copysign(1.0, dx)
        out[k] = st
        prev = x[k]
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
        rig["instrument"] = ("camera (simulated stereo photogrammetry): x_mm,y_mm,z_mm = T in the camera system's "
                             "frame, noise 3x larger along the line of sight")
    nom = robot["joints"]
    n = len(nom)
    sigma = spec["sigma"]
    res = 0.024 if not points else 0.0
    # ---- true geometry (as gen2 ... gen6, DH)
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
    # ---- clock and temperature (as gen3 ... gen6: warm-up plus an HVAC swing)
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
    # ---- payload in blocks of 10-20 poses (as gen4 ... gen6; written only where cols ask, no kind uses it)
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
    P.setdefault("phase_deg", float(rng.uniform(0, 360)))
    P.setdefault("pack_slack_quantile", float(rng.uniform(0.35, 0.6)))
    P.setdefault("pack_clamp_up_back_mm", [float(rng.uniform(250, 400)), float(rng.uniform(80, 200))])
    P.setdefault("creep_tau_s", float(rng.uniform(180, 600)))
    P.setdefault("creep_kappa", float(rng.uniform(0.3, 0.8)))
    P.setdefault("heat_tau_s", float(rng.uniform(240, 600)))
    P.setdefault("rock_w", float(rng.uniform(0.1, 0.2)))
    P.setdefault("rock_pivot_mm", float(rng.uniform(10, 30)))
    P.setdefault("contact_quantile", float(rng.uniform(0.15, 0.35)))
    hook_dirs = rng.normal(size=(6, 3))
    g_unit = np.asarray(robot.get("gravity_in_base", [0, 0, -9.81]), float)
    g_unit = g_unit / np.linalg.norm(g_unit)
    j = P.get("joint")
    sg = P.get("sensor")
    e_j = elbow_joint(rbase)
    T_mean = float(temp_true.mean())
    if kind == "tracker_refraction_gradient":
        P["temp_mean_c"] = T_mean
    # nominal and true frames at the commanded joints (the physics is computed on the nominal geometry, as
    # the gravity torques; the flange's orientation for the instruments on the true one)
    Fnom = [frames(nom, Q[k], "dh") for k in range(N)]
    Rf_rig = np.array([Rb @ frames(true_j, Q[k], "dh")[-1][:3, :3] for k in range(N)])
    tg_all = np.array([gravity_torques(robot, Q[k]) for k in range(N)])

    if kind == "dress_pack_tension":
        Fh = frames(nom, home, "dh")
        o1h = Fh[1][:3, 3]
        _, obh = forearm_points(Fh, nom, e_j)
        fwd = obh - o1h
        fwd = fwd - (fwd @ g_unit) * g_unit
        if np.linalg.norm(fwd) < 1e-6:
            fwd = Fh[1][:3, 0] - (Fh[1][:3, 0] @ g_unit) * g_unit
        fwd /= np.linalg.norm(fwd)
        up, back = P["pack_clamp_up_back_mm"]
        A_home = o1h - up * g_unit - back * fwd
        A_loc = np.linalg.inv(Fh[1]) @ np.array([*A_home, 1.0])
        Acl = np.array([(Fnom[k][1] @ A_loc)[:3] for k in range(N)])
        Bcl = np.array([0.5 * sum(forearm_points(Fnom[k], nom, e_j)) for k in range(N)])
        dist = np.linalg.norm(Acl - Bcl, axis=1)
        d0 = float(np.quantile(dist, P["pack_slack_quantile"]))
        w = 0.15 * float(dist.std())
        x = (dist - d0) / w
        Fm = w * np.where(x > 30, x, np.log1p(np.exp(np.minimum(x, 30))))
        Fv = (Fm / dist)[:, None] * (Acl - Bcl)
        pack = {}
        AXk = [axes(nom, Q[k], "dh") for k in range(N)]
        for jj in range(2, e_j + 1):
            tau = np.array([AXk[k][jj - 1][1] @ np.cross(Bcl[k] - AXk[k][jj - 1][0], Fv[k]) for k in range(N)])
            pack[jj] = lsq_remove(tau, [np.ones(N), tg_all[:, jj - 1]])
            P[f"share_left_after_gravity_projection_j{jj}"] = float(np.std(pack[jj]) / (np.std(tau) + 1e-12))
        sc = math.sqrt(np.mean(sum(v ** 2 for v in pack.values())))
        for jj in pack:
            pack[jj] = pack[jj] / sc
        P["clamp_distance_mm"] = [float(dist.min()), float(d0), float(dist.max())]
        P["poses_stretched"] = int(np.sum(dist > d0))
    if kind == "parallelogram_backlash":
        s23 = sign_state(Q[:, 1] + Q[:, 2], home[1] + home[2])
        s3 = sign_state(Q[:, 2], home[2])
        s2 = sign_state(Q[:, 1], home[1])
        e = lsq_remove(-s23, [np.ones(N), s3, s2])
        P["share_left_after_backlash_projection"] = float(np.std(e) / np.std(s23))
        para = e / math.sqrt(np.mean(e ** 2))
    if kind == "tool_changer_rock":
        Tf = np.array(tool_true) - np.array([0.0, 0.0, P["rock_pivot_mm"]])
        ez = np.array([0.0, 0.0, 1.0])
        dfl = np.zeros((N, 3))
        for k in range(N):
            gf = Fnom[k][-1][:3, :3].T @ g_unit
            gp = gf - gf[2] * ez
            ngp = np.linalg.norm(gp)
            if ngp < 1e-12:
                continue
            om = np.cross(ez, gp / ngp) * math.tanh(ngp / P["rock_w"])
            dfl[k] = np.cross(om, Tf)
        dfl -= dfl.mean(0)
        P["flange_displacement_rms_per_rad_mm"] = float(np.sqrt(np.mean(np.sum(dfl ** 2, 1))))
    if kind == "forearm_motor_heat":
        u = tg_all[:, e_j - 1] ** 2
        H = lag(u, dt, P["heat_tau_s"])
        growth = (H - H.mean()) / (H.std() + 1e-12)
        link_j, link_key = {"er3a": (4, "d_mm"), "ur5": (3, "a_mm"), "arm7": (5, "d_mm")}[rbase]
        link_sign = 1.0 if nom[link_j - 1][link_key] >= 0 else -1.0
        P["link"] = {"joint": link_j, "key": link_key}
    if kind == "servo_emi_offset":
        at = np.abs(tg_all[:, j - 1])
        emi = at - at.mean()
        P["abs_torque_range_nm"] = [float(at.min()), float(at.max())]

    def robot_points(m):
        Pts = np.zeros((N, 3))
        for k in range(N):
            q = Q[k].copy()
            tool = tool_true
            jj = true_j
            if m != 0 and kind == "dress_pack_tension":
                for ji, v in pack.items():
                    q[ji - 1] += m * v[k]
            elif m != 0 and kind == "parallelogram_backlash":
                q[2] += m * para[k]
            elif m != 0 and kind == "tool_changer_rock":
                tool = (np.array(tool_true) + m * dfl[k]).tolist()
            elif m != 0 and kind == "forearm_motor_heat":
                jj = copy.deepcopy(true_j)
                jj[link_j - 1][link_key] += link_sign * m * growth[k]
            F_ = frames(jj, q, "dh")
            pb = (F_[-1] @ np.array([*tool, 1.0]))[:3]
            Pts[k] = to_rig(pb)
        return Pts

    P0 = robot_points(0.0)
    L0 = None
    if not points:
        L0 = np.linalg.norm(P0[:, None, :] - anchors[None, :, :], axis=2) - r
    if kind == "cable_viscoelastic_creep":
        ls = L0[:, sg - 1]
        Fl = 1.0 + P["creep_kappa"] * (ls - ls.mean()) / ls.mean()
        eps = lag(Fl, dt, P["creep_tau_s"])
        e = lsq_remove(-ls * eps, [np.ones(N), ls, t])
        P["share_left_after_offset_scale_drift"] = float(np.std(e) / np.std(ls * eps))
        creep = e / math.sqrt(np.mean(e ** 2))
    if kind == "string_link_contact":
        A = anchors[sg - 1]
        dist = np.zeros(N)
        geo = []
        for k in range(N):
            F_ = frames(true_j, Q[k], "dh")
            oa, ob = forearm_points(F_, true_j, e_j)
            oa, ob = to_rig(oa), to_rig(ob)
            T = P0[k]
            u = (T - A) / np.linalg.norm(T - A)
            s_, t_, cs, cf = seg_seg(A, T - 80.0 * u, oa, ob)
            dist[k] = np.linalg.norm(cs - cf)
            geo.append((cs, cf))
        Rl = float(np.clip(np.quantile(dist, P["contact_quantile"]), 30.0, 150.0))
        extra = np.zeros(N)
        for k in range(N):
            if dist[k] < Rl:
                cs, cf = geo[k]
                nv = (cs - cf) / max(dist[k], 1e-9)
                Cp = cs + (Rl - dist[k]) * nv
                T = P0[k]
                extra[k] = np.linalg.norm(Cp - A) + np.linalg.norm(T - Cp) - np.linalg.norm(T - A)
        P["capsule_radius_mm"] = Rl
        P["poses_in_contact"] = int(np.sum(dist < Rl))
        P["raw_extra_max_mm"] = float(extra.max())
        e = extra - extra.mean()
        contact = e / math.sqrt(np.mean(e ** 2))
    if kind == "string_hook_offsets":
        Dh = hook_dirs[:m_an] - hook_dirs[:m_an].mean(0)
        Dh /= math.sqrt(np.mean(np.sum(Dh ** 2, 1)))
        P["hook_dirs_flange"] = Dh.tolist()
    if camera:
        zc = P0.mean(0) / np.linalg.norm(P0.mean(0))
        xc = np.cross([0, 0, 1.0], zc)
        xc /= np.linalg.norm(xc)
        yc = np.cross(zc, xc)
        Rc = np.column_stack([xc, yc, zc])   # camera frame -> rig frame
        P["camera_axis_rig"] = zc.tolist()
    if kind == "smr_vertex_offset":
        v = np.array(P["dir"])
        Bm = P0 / np.linalg.norm(P0, axis=1)[:, None]
        vr = np.einsum("kij,j->ki", Rf_rig, v)
        disp = np.sum(vr * Bm, 1)[:, None] * Bm - vr
        field = remove_similarity(disp, P0)
        P["vertex_dir_flange"] = v.tolist()
    if kind == "tracker_refraction_gradient":
        D = np.linalg.norm(P0, axis=1)
        Bm = P0 / D[:, None]
        nz = np.array([0, 0, 1.0])[None, :] - Bm[:, 2:3] * Bm
        nz /= np.linalg.norm(nz, axis=1)[:, None]
        field = ((temp_true - T_mean) * (D / 1000.0) ** 2)[:, None] * nz
        P["range_m"] = [float(D.min() / 1000), float(D.max() / 1000)]
    if kind == "stereo_disparity_offset":
        zcam = P0 @ Rc[:, 2]
        zbar = float(zcam.mean())
        dz = (zcam / zbar) ** 2           # depth error per unit (mm at the mean depth)
        disp = (dz / zcam)[:, None] * P0  # along the ray from the camera
        field = remove_similarity(disp, P0)
        P["depth_range_mm"] = [float(zcam.min()), float(zcam.max())]
    if kind == "tracker_elevation_eccentricity":
        D = np.linalg.norm(P0, axis=1)
        rho = np.linalg.norm(P0[:, :2], axis=1)
        el = np.arctan2(P0[:, 2], rho)
        az = np.arctan2(P0[:, 1], P0[:, 0])
        eel = np.column_stack([-np.sin(el) * np.cos(az), -np.sin(el) * np.sin(az), np.cos(el)])
        disp = (D * np.sin(el + P["phase_deg"] * D2R))[:, None] * eel
        field = remove_similarity(disp, P0)
        P["elevation_deg"] = [float(el.min() / D2R), float(el.max() / D2R)]

    def rig_view(X, m):
        """the true points X as the instrument sees them"""
        if m == 0 or kind not in RIG_POINT_KINDS:
            return X
        return X + m * field

    def measure(Pts, m):
        """noise-free readings (strings) or points (tracker / camera) of the true points Pts with the effect at m"""
        X = rig_view(Pts, m)
        if points:
            return X
        L = np.linalg.norm(X[:, None, :] - anchors[None, :, :], axis=2) - r
        if m != 0 and kind == "string_hook_offsets":
            Xh = X[:, None, :] + m * np.einsum("kij,sj->ksi", Rf_rig, Dh)
            Lh = np.linalg.norm(Xh - anchors[None, :, :], axis=2) - r
            E = Lh - L
            return L + (E - E.mean(0))
        if m != 0 and KINDS.get(kind, ("", ""))[1] == "sensor":
            s_ = sg - 1
            if kind == "servo_emi_offset":
                L[:, s_] += m * emi
            elif kind == "cable_viscoelastic_creep":
                L[:, s_] += m * creep
            elif kind == "string_link_contact":
                L[:, s_] += m * contact
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
        # signs: physical where the physics fixes it (the pack pulls, the joint lags, the tool droops, the
        # forearm grows, the cable creeps, a touching string is longer); random for the interference's
        # polarity and the gradient's direction; vectors are random directions already
        if kind in ("servo_emi_offset", "tracker_refraction_gradient"):
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
             "ratio": erms / point_noise, "scaling": "as gen3 ... gen6: RMS over the poses of the noise-free "
             "displacement of the located point (strings: multilaterated with the nominal anchors from the "
             "readings; tracker / camera: the measured point) with the effect against without it; the effect's "
             "reparametrisation part (and, where the kind says so, its catalogue part) is taken out",
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
    R = np.random.default_rng(7070707)
    specs = []
    ROB = ["er3a", "ur5", "er3a_mdh", "ur5_mdh", "arm7", "er3a"]
    RIGS_ROBOT = ["std4", "s3tilt", "std4", "points", "s5np", "std4"]
    RIGS_STR = ["std4", "s5np", "std4", "s3tilt", "std4", "s5np"]
    NSTR = {"std4": 4, "s3tilt": 3, "s5np": 5}

    def add(kind, half, i, robot, rig, params, places, drivers, cols):
        idx = len(specs)
        tag = params.get("joint") or params.get("sensor") or ""
        specs.append({"name": f"{idx:03d}_{kind}{tag}_{robot}_{rig}", "kind": kind, "half": half,
                      "robot": robot, "rig": rig, "n": int(R.integers(150, 201)), "seed": 1400000 + idx,
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
            e = elbow_joint(rb.replace("_mdh", ""))
            if kind == "dress_pack_tension":
                prm = {"joint": 2, "elbow_joint": e}
                places = [place("joint", 2), place("joint", e), place("configuration")]
                drivers = [f"q2 and q{e} (the clamp distance between turret and forearm), beside the gravity torques"]
            elif kind == "parallelogram_backlash":
                rb = ["er3a", "ur5", "er3a_mdh", "ur5_mdh", "er3a", "ur5"][i]   # axes 2 and 3 parallel
                prm = {"joint": 3, "source_joint": 2}
                places = [place("motion", 3), place("motion", 2)]
                drivers = ["the direction of the last change of q2 + q3 (on joint 3)"]
            elif kind == "tool_changer_rock":
                wj = [6, 5] if rb == "arm7" else [5, 4]
                places = [place("configuration"), place("joint", wj[0]), place("joint", wj[1])]
                drivers = ["the flange's orientation to gravity (wrist and q2 + q3)"]
            elif kind == "forearm_motor_heat":
                cols = with_time(i)
                places = [place("time"), place("order"), place("motion")]
                drivers = ["the lagged history of the elbow's holding torque (squared)"]
            elif KINDS[kind][1] == "sensor":
                rig = RIGS_STR[i]
                if kind == "string_hook_offsets":
                    places = [place("configuration"), place("string")]
                    drivers = ["the flange's orientation against every string's direction"]
                else:
                    s = int(R.integers(1, NSTR[rig] + 1))
                    prm = {"sensor": s}
                    if kind == "servo_emi_offset":
                        jj = [2, e, 2, 2, e, 2][i]
                        prm = {"sensor": s, "joint": jj}
                        places = [place("string", sensor=s), place("joint", jj), place("configuration")]
                        drivers = [f"|gravity torque of joint {jj}| (on string {s})"]
                    elif kind == "cable_viscoelastic_creep":
                        cols = with_time(i)
                        places = [place("string", sensor=s), place("time", sensor=s), place("order", sensor=s),
                                  place("motion", sensor=s)]
                        drivers = [f"string {s}'s lagged length history times its length"]
                    elif kind == "string_link_contact":
                        places = [place("string", sensor=s), place("workspace", sensor=s), place("configuration")]
                        drivers = [f"configurations where string {s} touches the forearm"]
            elif kind in ("smr_vertex_offset", "tracker_refraction_gradient", "tracker_elevation_eccentricity"):
                rig = "points"
                if kind == "smr_vertex_offset":
                    places, drivers = [place("configuration"), place("workspace")], \
                        ["the flange's orientation relative to the beam"]
                elif kind == "tracker_refraction_gradient":
                    cols = with_temp(i)
                    places = [place("temperature"), place("time"), place("order"), place("workspace")]
                    drivers = ["temperature times the range squared (vertical, across the beam)"]
                else:
                    places, drivers = [place("workspace")], ["the elevation angle from the tracker"]
            elif kind == "stereo_disparity_offset":
                rig = "camera"
                places, drivers = [place("workspace")], ["the depth from the camera (quadratic, along the rays)"]
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
    means the effect is invisible to the geometric fit. Per kind for tune7, aggregate only for heldback7
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
    json.dump(rows, open(f"{OUT}/visible7.json", "w"), indent=1)
    for h in HALVES:
        rr = [r for r in rows if r[2] == h]
        for k in dict.fromkeys(r[1] for r in rr):
            vals = [r[3] for r in rr if r[1] == k]
            if h == "tune7" or detail or k == "none":
                print(f"{h:9s} {k:30s} off/oracle gmean {score3.gmean(vals):6.3f} min {min(vals):6.3f} "
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
    json.dump(rows, open(f"{OUT}/scores7.json", "w"), indent=1)
    shown = [r for r in rows if full or r["half"] == "tune7"]
    print(f"{'dataset':52s} {'eff/noise':>9s} {'tool':>7s} {'oracle':>7s} {'ratio':>6s} {'category':12s} findings")
    for r in shown:
        f = lambda x: "   -   " if x is None else f"{x:7.4f}"
        print(f"{r['name']:52s} {r['ratio_eff']:9.2f} {f(r.get('tool_rms'))} {f(r.get('oracle_rms'))} "
              f"{'' if r.get('ratio') is None else format(r['ratio'], '6.3f'):>6s} {r['cat']:12s} "
              f"{'; '.join(r.get('findings', []))}")
    print()
    print("(located: an unexplained finding at the right place, or the right name for a kind since taken into the catalogue)")
    print(f"{'kind':30s} {'half':9s} {'n':>2s} {'located':>7s} {'wrongpl':>7s} {'silent':>6s} {'named':>5s} "
          f"{'named>=1%':>9s} {'ratio':>6s}")
    for h in HALVES:
        if h == "heldback7" and not full:
            print(f"(heldback7: per-kind lines withheld; `score full` shows them)")
            continue
        rh = [r for r in rows if r["half"] == h]
        for k in dict.fromkeys(r["kind"] for r in rh):
            rr = [r for r in rh if r["kind"] == k]
            print(f"{k:30s} {h:9s} {len(rr):2d} {sum(r['cat'] in ('located', 'named_right') for r in rr):7d} "
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
    json.dump(sums, open(f"{OUT}/summary7.json", "w"), indent=1)
    return sums


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "list"
    if cmd == "list":
        for k, v in KINDS.items():
            print(f"{k:31s} {v[0]:9s} {v[1]:6s} ~{v[4]:17s} {v[5]}")
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
