#!/usr/bin/env python3
"""Eighth independent cross-check of drawcal: another fresh, blind set of physics OUTSIDE the catalogue,
with a tune half (tune8) and a held-back half (heldback8).

Written blind: from physics descriptions of industrial arms (harmonic-drive flexspline creep, torsion of a
hollow upper-arm casting, process hoses over a flipping wrist, transient thermal gradients in a link),
drawstring encoder rigs (spring-return drums that overrun on fast retractions, stranded cables that twist,
tie rings that slip round the tool, capstan friction at the exit eyelet, string frames that twist under
the strings' pull), laser trackers (beam breaks re-initialised by the ADM, a cell's strip-curtain film in
the line of sight) and stereo
cameras (a knocked camera), from DATA_FORMAT.md, README.md, docs/CLI.md and the earlier cross-check
simulators (gen3.py ... gen7.py in full; of sim.py / gen2.py the parts imported), README3.md and their
scorer score3.py only -- WITHOUT reading src/, docs/PHYSICS.md, EVAL.md, BENCHMARKS.md, tests/*.rs or the
git history.  The tool version measured is commit c401eca (`git -C /work/main rev-parse --short HEAD`;
binary /tmp/bin/drawcal-base, run as given; the checkout then also had uncommitted changes under src/,
not read here; the developer confirms the binary was built from c401eca before those changes began).

None of the kinds below is a catalogue effect (joint_compliance, backlash, joint_periodic, joint_scale,
base_tilt, thermal_expansion, sensor_scale, sensor_offset, sensor_drift, cable_sag, anchor_step,
rig_step, rig_drift) nor one of gen3.py's ... gen7.py's kinds.  Several RESEMBLE a catalogue effect
without being it (`resembles` in KINDS): naming that catalogue effect -- or any other -- is a misname.
Each effect's part that is an exact reparametrisation of the geometric model (a constant joint offset, a
constant link twist, a base / rig translation or pose, a tool offset, a string offset, and for point data
the best similarity transform: a rig pose and a uniform scale about the instrument) is taken out, and so,
where the kind says so, is the part that IS a catalogue effect (a compliance proportional to the gravity
torque, a string scale / offset / linear drift, a step of a string along its own direction = an anchor
step, a similarity step = a rig step), so that what is left is out of the catalogue.

The kinds (half, side, ~resembles, driver):
  harmonic_creep_dwell   tune8     robot  ~joint_compliance  joint 2's or the elbow's flexspline creeps
        under its gravity torque (standard linear solid): the delayed deflection x relaxes towards the new
        torque during the DWELL before each reading, x_k = tau_k + (x_{k-1} - tau_k)*exp(-dwell_k/tau_c),
        tau_c 4-12 s; the part proportional to tau_g (an ordinary compliance) and the mean taken out: what
        is left is the unrelaxed torque change of the last move, times exp(-dwell/tau_c) -- driven by the
        move that led to the pose and the dwell (the dwell is time_s's step less the move).
  upper_arm_torsion      tune8     robot  ~joint_compliance  the upper arm (joint-2 axis to elbow axis) twists
        about its OWN long axis under the component of the outboard gravity moment along it (the links' and
        a 2-4 kg process tool's whose centre of mass sits 80-150 mm off the flange axis, not in robot.json: a
        lateral offset times the cosine of the arm's elevation, a PRODUCT of q2/q3 and the wrist); the
        displacement of T is phi*(e x (T - elbow)); its least-squares part made of a base
        translation, a constant twist and a compliance of every joint 2..n (J_j*tau_g,j) is taken out in
        displacement space (not on arm7, whose joint 3 turns about that axis: there it IS joint 3's
        compliance).
  string_retract_slack   tune8     sensor ~backlash          one string's spring-return drum overruns on a
        retraction: the cable winds loosely, the drum turns less than the cable wound, the reading is long
        by kappa*r*exp(-dwell/tau_s) (r the retraction into the pose, tau_s 5-15 s while the spring tightens
        the wrap); zero after an extension; offset and scale taken out: the string's own last move and the
        dwell.
  cable_twist            tune8     sensor ~sensor_drift      one string's stranded cable is tied to the tool
        with a fixed eye (no swivel): the flange's rotation ABOUT THE STRING's direction, integrated along
        the joint-space path of every move (phi = integral of omega.u), twists it and the lay shortens it,
        reading += kappa*phi; offset, scale and a linear drift taken out: one string, driven by the wrist's
        accumulated roll about it (path-dependent, mostly joint n).
  tracker_beam_break     tune8     rig    ~rig_step          tracker data: on the longest moves (T travels
        more than the 80-90 % quantile of the moves) the beam breaks and the tracker re-acquires through
        its ADM, whose zero differs from the interferometer's by a new random offset each time: the range
        (along the beam) carries a piecewise-constant offset that changes only at those moves; the best
        similarity transform taken out: abrupt events triggered by the length of the move.
  frame_tension_twist    tune8     rig    ~cable_sag         the four-corner string frame is soft in twist: the
        strings' spring tensions F_i = F0*(1 + kappa*(l_i - mean)/mean) pulling the corners towards T load
        its twist mode (corners A, D against B, C along the frame normal n) with sum_i s_i F_i (u_i.n); the
        corners move by w*s_i*n, string i reads -w*s_i*(n.u_i); mean twist and per-string offsets taken out:
        a deformation of the anchor pattern driven by where T is (std4 and s5np's four corners).
  wrist_flip_hose        heldback8 robot  ~backlash          a process hose dressed over the wrist swings from
        one side to the other when the wrist flips (q5 through zero; q6 on arm7) and its stiffness loads the
        forearm roll: joint 4 (arm7: 5) deflects by d*tanh(q5/w), w 3-8 deg; the mean and the projection
        onto joint 4's gravity torque taken out: the arm's configuration (wrist flip) sets another joint's
        error.
  upper_arm_thermal_bow  heldback8 robot  ~thermal_expansion the upper arm's two faces follow the room at
        different rates: its transient gradient (T - lag(T), tau 10-25 min, from equilibrium at the start)
        bows it OUT of the arm's plane, tilting the elbow axis (the tip moves by theta*L/2 along the joint
        axis and turns by theta); the mean (a constant tilt: a reparametrisation) taken out: the
        temperature HISTORY (a bow, no length grows; neither a uniform growth nor a joint offset).
  hook_ring_slip         heldback8 sensor ~anchor_step       one string is tied to a ring round the tool stem;
        at t0 (30-70 % of the session) a snag slides the ring round the stem: the string's end moves by delta
        FIXED IN THE FLANGE frame, so the reading steps by -u.R_flange*delta, a step that turns with the
        flange; its parts an offset, an offset step and a step along the string's direction (an anchor step)
        reproduce taken out.
  eyelet_capstan_friction heldback8 sensor ~backlash         one string slides through its exit eyelet over a
        wrap angle theta (string vs eyelet axis): capstan friction makes the free span's tension
        F0*exp(+-mu*theta) by the direction the string last moved (out: +, in: -), which stretches it by
        that times its length: reading -eps*l*exp(s*mu*theta); offset, scale, a pure direction-of-travel
        term and a pure angle term taken out: travel direction TIMES angle TIMES length.
  tracker_curtain_film   heldback8 rig    ~                  tracker data: a transparent strip curtain (PET / PVC
        film) of the cell hangs between the tracker and the robot and covers PART of the field of view (a
        vertical rectangle whose edges cut the lines of sight); a beam through it reads long by the plate's
        optical path excess t*(n_g - cos(theta_i - theta_r))/cos(theta_r) (~ t*(n_g - 1) at normal
        incidence) and is shifted sideways by the plate's lateral offset t*sin(theta_i - theta_r)/cos(theta_r);
        the best similarity transform taken out: a region of the workspace with sharp edges (the lines of
        sight through the film).
  stereo_camera_knock    heldback8 rig    ~rig_step          camera (stereo) data: at t0 (30-70 % of the
        session) one camera of the pair is knocked and yaws: a disparity offset appears, depth off by
        -z^2*dd/(f*b) along each ray from then on; the best similarity transform of the whole session AND
        that of the part after t0 (a rig step with scale) taken out: a depth-quadratic warp that switches on.

Kinematics, robots, rigs, multilateration and pose sampling are the earlier simulators' (imported from
sim.py / gen2.py / gen3.py, one definition; lsq_remove and lag from gen6.py, remove_similarity, sign_state
and elbow_joint from gen7.py).  Robots: ER3A and UR5 (DH), the same two written as Craig MDH (er3a_mdh,
ur5_mdh: simulated on the DH chain with DH deviations, robot.json written as gen2.dh_to_mdh of the
nominal, an exact reparametrisation) and gen2's 7-axis arm7.  The clock is gen3's (6-12 s dwell per pose
plus the move at 30 deg/s of the slowest joint; the same random stream), so the dwell is time_s's step
less the move.  Every dataset <name>/ has a twin <name>/oracle/ with the identical poses, split column,
geometric deviations, base pose and noise realisation but WITHOUT the effect; the tool is run on the twin
with `--physics off` (its held-out RMS stands for what a fit of the true effect would reach).
truth3.json has gen3's ... gen7's fields, so score3.py scores these datasets unchanged; `gen8.py score`
computes the per-half summary itself (tune8, heldback8, overall) with score3.py's own functions: located
right = an `unexplained` finding at one of the kind's true places (places_ok: driver, and joint / sensor
where named), misnamed = every catalogue-named finding (none of these kinds justifies any catalogue name),
ratio = tool held-out RMS / the twin's.  Conditions as gen6 / gen7: 6 recordings per kind (150-200 poses,
effect 3-6x the point noise, measured as gen3: RMS of the noise-free displacement of the located point),
8 effect-free recordings (4 per half), string noise 0.02 mm with 0.024 mm resolution, tracker 0.03 mm per
axis, camera 0.02/0.02/0.06 mm.

Design notes (decided on the physics and the effects' visibility, not on the tool's findings):
- the shapes are normalised to unit RMS after the reparametrisation / catalogue parts are taken out and
  then scaled by the magnitude drawn for the ratio 3-6 (drawn uniformly, none adjusted; `unit` says so);
  the physical scale implied is in truth3.json `params` (`implied_...`, `film_thickness_mm`);
- magnitudes against the physics: the curtain film comes out 0.86-1.06 mm thick (a real PVC strip is
  1-3 mm: physical); the ADM re-initialisation offsets are ~0.2-0.3 mm RMS against ~0.01-0.02 for a
  real tracker; the upper arm's torsional compliance 0.6-4.6e-4 rad/(N*m) (3-30x a stiff casting's); the
  out-of-plane bow 0.3-0.7 mrad per K of transient (5-10x an aluminium arm's); the flexspline creep
  0.001-0.04 deg/(N*m) (up to several times a small arm's whole joint compliance); the cable's
  twist-length coupling and the capstan's stretch (a polymer-coated cable's) of the order physics gives;
- while writing, a warm-air plume (refraction) was tried for the tracker's region kind and dropped before
  any run of the tool: at 3-6x the noise it needed a core 300-600 K warm; the transparent film replaced it.
  The out-of-plane bow first had its temperature- and time-linear parts taken out too (88 % of it, so
  60x the physical bow was needed); a bow linear in temperature is no catalogue effect (thermal_expansion
  is a uniform growth of lengths), so only its mean is taken out;
- shares left after the catalogue parts are taken out are in `params` (`share_left...`): creep 0.12-0.38
  of the lagged torque, torsion 0.96-0.99, slack 0.76-0.91, cable twist 0.44-0.99, capstan 0.10-0.18,
  the camera knock 0.09-0.15 (most of a disparity offset is a similarity transform), the ring slip
  0.89-0.99, the hose 0.99, the ADM offsets 0.91-1.0, the film 0.57-0.75;
- signs: physical where the physics fixes it (the creep and the torsion follow the load, a loose wrap
  reads long, the capstan stretches the pulled cable, a film lengthens the optical path), random
  elsewhere (the hose's side, the bow's sense, the frame's twist response, the camera's yaw, the twist's
  lay, the ring's slide; the ADM offsets are random per segment);
- places_ok were written with the kinds, before any run of the tool, and not changed after (e.g. the
  creep's `motion` place names its joint: a `motion` finding without a joint is a wrong place);
- joint-local kinds avoid joint 1 (a joint-1 quantity moving with a global driver is a rig yaw);
  upper_arm_torsion avoids arm7 (its joint 3 turns about the upper arm: the torsion IS its compliance);
- `visible` at c401eca: every effect dataset with --physics off is 1.33x or more the twin's held-out RMS
  (tune8 gmean 4.56, min 2.71; heldback8 gmean 3.87, min 1.33, one of 36 below 1.5); effect-free 1.000;
- checked from the written files: each effect dataset against its twin (identical joints, split, noise)
  shows the stated effect RMS (3.1-5.9x the point noise); effect-free datasets equal their twins;
- the generation is deterministic (two plans into two directories are byte-identical); `plan` takes
  ~30 s, `run` ~15 s on 2 shared cores.

Measured once at c401eca (binary /tmp/bin/drawcal-base), `score`:
  tune8:     located 72.2 %, misnamed 0.83 / 10 (0.56 without < 1 % gain), silent 5.6 %, wrong place
             19.4 %, ratio 3.264 (worst 6.79), false alarms 0 of 4
  heldback8: located 41.7 %, misnamed 1.67 / 10 (1.67 without < 1 % gain), silent 30.6 %, wrong place
             22.2 %, ratio 3.444 (worst 7.41), false alarms 0 of 4

Usage (from the repository root):
    python3 tests/crosscheck/gen8.py list        # one line of physics per kind
    python3 tests/crosscheck/gen8.py plan        # write every dataset and its twin
    python3 tests/crosscheck/gen8.py run [sub]   # run the tool (one process at a time, timeout)
    python3 tests/crosscheck/gen8.py score       # tune8 per dataset and per kind; heldback8 aggregate only
    python3 tests/crosscheck/gen8.py score full  # also heldback8 per dataset and per kind (unblinds it)
    python3 tests/crosscheck/gen8.py visible     # sanity: the effect datasets with --physics off against
                                                 # the twin; per kind for tune8, aggregate only for
                                                 # heldback8 (`visible full`)
Env: XC8_OUT (default /tmp/xcheck8/ds), XCHECK_DATA (default tests/data),
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
from gen7 import remove_similarity, sign_state, elbow_joint  # noqa: E402

OUT = os.environ.get("XC8_OUT", "/tmp/xcheck8/ds")
SRC = os.environ.get("XCHECK_DATA", "tests/data")
TOOL = os.environ.get("XCHECK_TOOL", "target/release/drawcal")
gen2.SRC = SRC
gen3.TOOL = TOOL
D2R = math.pi / 180.0
HALVES = ("tune8", "heldback8")

# ---------------------------------------------------------------- the kinds
# kind: (half, side, unit magnitude, unit, resembles (catalogue name or ""), one line of physics)
KINDS = {
    # ---- tune8
    "harmonic_creep_dwell": ("tune8", "robot", 0.01, "deg per unit-RMS term", "joint_compliance",
                             "joint 2's / the elbow's flexspline creeps under its gravity torque, relaxing towards "
                             "the new torque during the dwell before each reading (tau 4-12 s); the compliance part "
                             "and the mean taken out: the last move's torque change times exp(-dwell/tau)"),
    "upper_arm_torsion": ("tune8", "robot", 0.01, "mm per unit-RMS field", "joint_compliance",
                          "the upper arm twists about its own long axis under the outboard gravity moment's "
                          "component along it (lateral COM offset x cos(elevation): a product of joints); base "
                          "translation, constant twist and every joint's compliance taken out in displacement space"),
    "string_retract_slack": ("tune8", "sensor", 0.01, "mm per unit-RMS term", "backlash",
                             "one string's drum overruns on a retraction and winds loosely: reading long by "
                             "kappa*retraction*exp(-dwell/tau_s) (tau_s 5-15 s), zero after an extension; offset and "
                             "scale taken out"),
    "cable_twist": ("tune8", "sensor", 0.01, "mm per unit-RMS term", "sensor_drift",
                    "one string's stranded cable, tied to the tool without a swivel, is twisted by the flange's "
                    "rotation about the string (integrated along each move's joint path); the lay shortens it, "
                    "reading += kappa*phi; offset, scale and linear drift taken out"),
    "tracker_beam_break": ("tune8", "rig", 0.01, "mm per unit-RMS field", "rig_step",
                           "tracker data: the longest moves break the beam and the ADM re-initialises the range "
                           "with a new random zero: a piecewise-constant range offset along the beam changing only "
                           "at those moves; best similarity transform taken out"),
    "frame_tension_twist": ("tune8", "rig", 0.01, "mm of corner twist per unit std", "cable_sag",
                            "the four-corner string frame twists under the strings' spring tensions (corners A, D "
                            "against B, C along the normal, load sum s_i F_i (u_i.n)): string i reads "
                            "-w*s_i*(n.u_i); mean twist and per-string offsets taken out: where T is"),
    # ---- heldback8
    "wrist_flip_hose": ("heldback8", "robot", 0.01, "deg per unit-RMS term", "backlash",
                        "a process hose over the wrist swings sides when the wrist flips (q5 through zero; arm7 "
                        "q6): joint 4 (arm7 5) deflects by d*tanh(q5/w), w 3-8 deg; mean and gravity-torque "
                        "projection taken out"),
    "upper_arm_thermal_bow": ("heldback8", "robot", 1e-4, "rad per unit-std driver", "thermal_expansion",
                              "the upper arm's transient thermal gradient (T - lag(T), tau 10-25 min) bows it out "
                              "of the arm's plane, tilting the elbow axis; mean taken out"),
    "hook_ring_slip": ("heldback8", "sensor", 0.01, "mm per unit-RMS term", "anchor_step",
                       "one string's tie ring slides round the tool stem at t0: its end moves by delta fixed in the "
                       "flange frame, reading steps by -u.R_flange*delta; offset, offset step and anchor-step "
                       "(step along u) parts taken out"),
    "eyelet_capstan_friction": ("heldback8", "sensor", 0.01, "mm per unit-RMS term", "backlash",
                                "one string's capstan friction at its eyelet: free-span tension F0*exp(+-mu*theta) "
                                "by the direction of its last move, stretching it: reading -eps*l*exp(s*mu*theta); "
                                "offset, scale, direction and angle terms taken out"),
    "tracker_curtain_film": ("heldback8", "rig", 0.01, "mm per unit-RMS field", "",
                             "tracker data: a transparent strip-curtain film covers part of the field of view: beams "
                             "through it read long by ~t*(n_g - 1)/cos(theta) and shift sideways; best similarity "
                             "transform taken out: a region of the workspace with sharp edges"),
    "stereo_camera_knock": ("heldback8", "rig", 0.01, "mm per unit-RMS field", "rig_step",
                            "camera (stereo) data: one camera is knocked at t0 and yaws: a disparity offset appears, "
                            "depth off by -z^2*dd/(f*b) along each ray from then on; similarity transforms of the "
                            "whole session and of the part after t0 taken out"),
}
SEEDS_PER_KIND = 6
N_NULL = 8
ROBOT_SIDE = {k for k, v in KINDS.items() if v[1] == "robot"}
RIG_POINT_KINDS = ("tracker_beam_break", "tracker_curtain_film", "stereo_camera_knock")
FLIP = {"er3a": (5, 4), "ur5": (5, 4), "arm7": (6, 5)}   # (flipping joint, deflected joint), 1-based


def lsq_remove_disp(disp, cols):
    """disp (N x 3) minus its least-squares part in span(cols), each column an N x 3 field"""
    A = np.column_stack([c.reshape(-1) for c in cols])
    b = disp.reshape(-1)
    c = np.linalg.lstsq(A, b, rcond=None)[0]
    return (b - A @ c).reshape(disp.shape)


def similarity_cols(X):
    """the 7 fields t + w x X + s*X (X in mm, scaled to m for conditioning) as N x 3 columns"""
    N = len(X)
    Xc = X / 1000.0
    cols = []
    for i in range(3):
        c = np.zeros((N, 3))
        c[:, i] = 1.0
        cols.append(c)
    for i in range(3):
        w = np.zeros(3)
        w[i] = 1.0
        cols.append(np.cross(w[None, :], Xc))
    cols.append(Xc.copy())
    return cols


def rot_log(R):
    """rotation vector of the rotation matrix R"""
    c = max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))
    a = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if a < 1e-9:
        return 0.5 * v
    return v * (a / (2.0 * math.sin(a)))


def rodrigues_small(axis, ang):
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K


def unit_rms(e):
    return e / math.sqrt(np.mean(e ** 2))


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
    # ---- true geometry (as gen2 ... gen7, DH)
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
    # ---- clock (as gen3 ... gen7, the same stream: the move at 30 deg/s of the slowest joint, then a 6-12 s
    # dwell before the reading) and temperature (warm-up plus an HVAC swing)
    t = np.zeros(N)
    dwell = np.zeros(N)
    prev, tt = home, 0.0
    for k in range(N):
        mv = np.max(np.abs(Q[k] - prev)) / 30.0
        dwell[k] = rng.uniform(6, 12)
        tt += mv + dwell[k]
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
    # ---- payload in blocks of 10-20 poses (as gen4 ... gen7; written only where cols ask, no kind uses it)
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
    P.setdefault("creep_tau_s", float(rng.uniform(4, 12)))
    P.setdefault("slack_tau_s", float(rng.uniform(5, 15)))
    P.setdefault("break_quantile", float(rng.uniform(0.8, 0.9)))
    P.setdefault("twist_kappa", float(rng.uniform(0.3, 0.7)))
    P.setdefault("flip_w_deg", float(rng.uniform(3, 8)))
    P.setdefault("bow_tau_s", float(rng.uniform(600, 1500)))
    P.setdefault("event_frac", float(rng.uniform(0.3, 0.7)))
    P.setdefault("capstan_mu", float(rng.uniform(0.15, 0.35)))
    P.setdefault("curtain_frac", float(rng.uniform(0.4, 0.75)))         # where between tracker and robot
    P.setdefault("curtain_edge_quantiles", [float(rng.uniform(0.2, 0.5)), float(rng.uniform(0.25, 0.6))])
    P.setdefault("curtain_group_index", float(rng.uniform(1.55, 1.65)))
    P.setdefault("tool_mass_kg", float(rng.uniform(2.0, 4.0)))
    P.setdefault("tool_com_lateral_mm", float(rng.uniform(80, 150)))
    adm_offsets = rng.normal(size=N + 1)
    j = P.get("joint")
    sg = P.get("sensor")
    e_j = elbow_joint(rbase)
    T_mean = float(temp_true.mean())
    # nominal frames at the commanded joints (the loads are computed on the nominal geometry, as the gravity
    # torques); true frames for where T is and for the flange's orientation
    Fnom = [frames(nom, Q[k], "dh") for k in range(N)]
    Ftrue = [frames(true_j, Q[k], "dh") for k in range(N)]
    pb0 = np.array([(Ftrue[k][-1] @ np.array([*tool_true, 1.0]))[:3] for k in range(N)])   # T, base frame
    Rf_rig = np.array([Rb @ Ftrue[k][-1][:3, :3] for k in range(N)])
    tg_all = np.array([gravity_torques(robot, Q[k]) for k in range(N)])
    AXn = [axes(nom, Q[k], "dh") for k in range(N)]

    def compliance_cols():
        """displacement of T (base frame) by a compliance of each joint 2..n: tau_g,j * z_j x (T - o_j)"""
        cols = []
        for jj in range(2, n + 1):
            cols.append(np.array([tg_all[k, jj - 1] * np.cross(AXn[k][jj - 1][1], pb0[k] - AXn[k][jj - 1][0])
                                  for k in range(N)]))
        return cols

    def const_cols():
        out = []
        for i in range(3):
            c = np.zeros((N, 3))
            c[:, i] = 1.0
            out.append(c)
        return out

    # ---- robot-side shapes
    if kind == "harmonic_creep_dwell":
        tg = tg_all[:, j - 1]
        x = float(gravity_torques(robot, home)[j - 1])   # at rest at home: relaxed
        xs = np.zeros(N)
        for k in range(N):
            x = tg[k] + (x - tg[k]) * math.exp(-dwell[k] / P["creep_tau_s"])
            xs[k] = x
        e = lsq_remove(xs, [np.ones(N), tg])
        P["share_left_after_compliance_projection"] = float(np.std(e) / np.std(xs))
        creep_raw_rms = math.sqrt(np.mean(e ** 2))   # N*m
        creep = unit_rms(e)
    if kind == "upper_arm_torsion":
        g = np.asarray(robot.get("gravity_in_base", [0, 0, -9.81]), float)
        links = robot["links"]
        ta = np.array(tool_true) / np.linalg.norm(tool_true)
        dl = d - (d @ ta) * ta
        tool_com = 0.5 * np.array(tool_true) + P["tool_com_lateral_mm"] * dl / np.linalg.norm(dl)
        P["tool_com_flange_mm"] = tool_com.tolist()
        tors = np.zeros(N)
        field = np.zeros((N, 3))
        twist_col = np.zeros((N, 3))
        for k in range(N):
            F_ = Fnom[k]
            o1, oe = F_[1][:3, 3], F_[e_j - 1][:3, 3]
            eu = (oe - o1) / np.linalg.norm(oe - o1)
            M = np.zeros(3)
            for i in range(e_j - 1, n):   # the bodies after the elbow joint
                c = (F_[i + 1] @ np.array([*links[i]["com_mm"], 1.0]))[:3]
                M += np.cross((c - oe) * 1e-3, links[i]["mass_kg"] * g)
            c = (F_[-1] @ np.array([*tool_com, 1.0]))[:3]   # the process tool (not in robot.json)
            M += np.cross((c - oe) * 1e-3, P["tool_mass_kg"] * g)
            tors[k] = eu @ M
            field[k] = tors[k] * np.cross(eu, pb0[k] - oe)
            twist_col[k] = np.cross(eu, pb0[k] - oe)
        resid = lsq_remove_disp(field, const_cols() + [twist_col] + compliance_cols())
        P["share_left_after_compliance_and_reparam"] = float(np.sqrt(np.mean(resid ** 2)) /
                                                             np.sqrt(np.mean((field - field.mean(0)) ** 2)))
        P["torsion_moment_range_nm"] = [float(tors.min()), float(tors.max())]
        tors_raw_rms = math.sqrt(np.mean(np.sum(resid ** 2, 1)))   # mm per (rad/(N*m))
        tors_field = resid / math.sqrt(np.mean(np.sum(resid ** 2, 1)))
    if kind == "wrist_flip_hose":
        fj, dj = FLIP[rbase]
        raw = np.tanh(Q[:, fj - 1] / P["flip_w_deg"])
        e = lsq_remove(raw, [np.ones(N), tg_all[:, dj - 1]])
        P["flip_joint"], P["deflected_joint"] = fj, dj
        P["share_left_after_gravity_projection"] = float(np.std(e) / np.std(raw))
        P["frac_flipped_positive"] = float(np.mean(Q[:, fj - 1] > 0))
        flip = unit_rms(e)
    if kind == "upper_arm_thermal_bow":
        dT = temp_true - temp_true[0]
        u = dT - lag(dT, dt, P["bow_tau_s"])
        e = u - u.mean()
        P["gradient_driver_range_K"] = [float(u.min()), float(u.max())]
        bow_raw_std = float(np.std(e))   # K
        ud = e / np.std(e)
        bow_field = np.zeros((N, 3))
        for k in range(N):
            F_ = Fnom[k]
            o1, oe = F_[1][:3, 3], F_[e_j - 1][:3, 3]
            Lua = np.linalg.norm(oe - o1)
            eu = (oe - o1) / Lua
            z2 = AXn[k][1][1]
            ax = np.cross(eu, z2)
            ax /= np.linalg.norm(ax)
            bow_field[k] = ud[k] * (0.5 * Lua * z2 + np.cross(ax, pb0[k] - oe))   # mm per rad
        P["upper_arm_length_mm"] = float(np.linalg.norm(Fnom[0][e_j - 1][:3, 3] - Fnom[0][1][:3, 3]))

    def robot_points(m):
        Pts = np.zeros((N, 3))
        for k in range(N):
            q = Q[k].copy()
            if m != 0 and kind == "harmonic_creep_dwell":
                q[j - 1] += m * creep[k]
            elif m != 0 and kind == "wrist_flip_hose":
                q[FLIP[rbase][1] - 1] += m * flip[k]
            if m != 0 and kind in ("harmonic_creep_dwell", "wrist_flip_hose"):
                F_ = frames(true_j, q, "dh")
                pb = (F_[-1] @ np.array([*tool_true, 1.0]))[:3]
            else:
                pb = pb0[k].copy()
            if m != 0 and kind == "upper_arm_torsion":
                pb = pb + m * tors_field[k]
            elif m != 0 and kind == "upper_arm_thermal_bow":
                pb = pb + m * bow_field[k]
            Pts[k] = to_rig(pb)
        return Pts

    P0 = robot_points(0.0)
    L0 = None
    if not points:
        L0 = np.linalg.norm(P0[:, None, :] - anchors[None, :, :], axis=2) - r
        U0 = (P0[:, None, :] - anchors[None, :, :]) / (L0 + r)[:, :, None]
        T_home = to_rig((frames(true_j, home, "dh")[-1] @ np.array([*tool_true, 1.0]))[:3])
        L_home = np.linalg.norm(T_home - anchors, axis=1) - r
        dL = np.diff(np.vstack([L_home[None, :], L0]), axis=0)   # each string's change into the pose

    # ---- sensor-side shapes
    if kind == "string_retract_slack":
        rr = np.maximum(0.0, -dL[:, sg - 1])
        raw = rr * np.exp(-dwell / P["slack_tau_s"])
        e = lsq_remove(raw, [np.ones(N), L0[:, sg - 1]])
        P["share_left_after_offset_scale"] = float(np.std(e) / np.std(raw))
        P["retractions"] = int(np.sum(rr > 0.05))
        slack = unit_rms(e)
    if kind == "cable_twist":
        A = anchors[sg - 1]
        phi = 0.0
        prevq = np.asarray(home, float)
        F_ = frames(true_j, prevq, "dh")
        Rprev = Rb @ F_[-1][:3, :3]
        phis = np.zeros(N)
        nsub = 36
        for k in range(N):
            for i in range(1, nsub + 1):
                qi = prevq + (Q[k] - prevq) * i / nsub
                F_ = frames(true_j, qi, "dh")
                Ri = Rb @ F_[-1][:3, :3]
                Ti = to_rig((F_[-1] @ np.array([*tool_true, 1.0]))[:3])
                u = (Ti - A) / np.linalg.norm(Ti - A)
                phi += rot_log(Ri @ Rprev.T) @ u
                Rprev = Ri
            phis[k] = phi
            prevq = Q[k]
        e = lsq_remove(phis, [np.ones(N), L0[:, sg - 1], t])
        P["twist_range_rad"] = [float(phis.min()), float(phis.max())]
        P["share_left_after_offset_scale_drift"] = float(np.std(e) / np.std(phis))
        twist = unit_rms(e) * P["sign"]
    if kind == "hook_ring_slip":
        k0 = int(np.searchsorted(t, P["event_frac"] * t[-1]))
        H = (np.arange(N) >= k0).astype(float)
        ta = np.array(tool_true) / np.linalg.norm(tool_true)
        dl = d - (d @ ta) * ta
        dl /= np.linalg.norm(dl)
        u = U0[:, sg - 1]
        raw = -H * np.einsum("ki,kij,j->k", u, Rf_rig, dl)
        e = lsq_remove(raw, [np.ones(N), H, H * u[:, 0], H * u[:, 1], H * u[:, 2]])
        P["k0"], P["t0_s"] = k0, float(t[k0])
        P["delta_dir_flange"] = dl.tolist()
        P["share_left_after_offset_step_anchor_step"] = float(np.std(e) / np.std(raw))
        slip = unit_rms(e) * P["sign"]
    if kind == "eyelet_capstan_friction":
        A = anchors[sg - 1]
        ax = P0.mean(0) - A
        ax /= np.linalg.norm(ax)
        th = np.arccos(np.clip(U0[:, sg - 1] @ ax, -1, 1))
        s_dir = sign_state(L0[:, sg - 1], L_home[sg - 1])
        ls = L0[:, sg - 1]
        raw = -ls * np.exp(s_dir * P["capstan_mu"] * th)
        e = lsq_remove(raw, [np.ones(N), ls, s_dir, th])
        P["wrap_angle_deg"] = [float(th.min() / D2R), float(th.max() / D2R)]
        P["frac_extending"] = float(np.mean(s_dir > 0))
        P["share_left_after_offset_scale_direction_angle"] = float(np.std(e) / np.std(raw - raw.mean()))
        capstan = unit_rms(e)
    if kind == "frame_tension_twist":
        Cn = anchors[:4]
        cc = Cn.mean(0)
        nv = np.linalg.svd(Cn - cc)[2][-1]
        if nv @ (P0.mean(0) - cc) < 0:
            nv = -nv
        s_tw = np.zeros(m_an)
        s_tw[:4] = [1.0, -1.0, -1.0, 1.0]   # A, B, C, D: the diagonals A-D and B-C move opposite
        Fi = 1.0 + P["twist_kappa"] * (L0 - L0.mean(0)) / L0.mean(0)
        nu = U0 @ nv   # N x m
        load = np.sum(s_tw[None, :] * Fi * nu, 1)
        w = (load - load.mean()) / load.std()
        E = -w[:, None] * s_tw[None, :] * nu
        twistE = E - E.mean(0)
        P["frame_normal_rig"] = nv.tolist()
        P["twist_load_range"] = [float(load.min()), float(load.max())]

    # ---- instrument-side fields (point data)
    if camera:
        zc = P0.mean(0) / np.linalg.norm(P0.mean(0))
        xc = np.cross([0, 0, 1.0], zc)
        xc /= np.linalg.norm(xc)
        yc = np.cross(zc, xc)
        Rc = np.column_stack([xc, yc, zc])   # camera frame -> rig frame
        P["camera_axis_rig"] = zc.tolist()
    if kind == "tracker_beam_break":
        Tprev = np.vstack([to_rig((frames(true_j, home, "dh")[-1] @ np.array([*tool_true, 1.0]))[:3])[None, :],
                           P0[:-1]])
        ml = np.linalg.norm(P0 - Tprev, axis=1)
        thr = float(np.quantile(ml, P["break_quantile"]))
        brk = ml > thr
        seg = np.cumsum(brk)
        roff = adm_offsets[seg]
        Bm = P0 / np.linalg.norm(P0, axis=1)[:, None]
        disp = roff[:, None] * Bm
        fld = remove_similarity(disp, P0)
        P["move_threshold_mm"] = thr
        P["n_breaks"] = int(brk.sum())
        P["share_left_after_similarity"] = float(np.sqrt(np.mean(fld ** 2)) / np.sqrt(np.mean(disp ** 2)))
        field = fld / math.sqrt(np.mean(np.sum(fld ** 2, 1)))
    if kind == "tracker_curtain_film":
        # the film's plane: vertical, facing the tracker along the horizontal direction to the robot base, at a
        # fraction of the way; it covers the part of the plane beyond a vertical edge (lateral) and below a
        # horizontal one (the strips hang to the floor from a rail above the field of view, cut short at its top
        # by the rail's valance): both edges at quantiles of where the lines of sight cross the plane
        bh = np.array([base_xyz[0], base_xyz[1], 0.0])
        nrm_c = bh / np.linalg.norm(bh)
        lat = np.array([-nrm_c[1], nrm_c[0], 0.0])
        dpl = P["curtain_frac"] * np.linalg.norm(bh)
        Bm = P0 / np.linalg.norm(P0, axis=1)[:, None]
        cosi = Bm @ nrm_c
        sint = P0 @ nrm_c
        sP = dpl / cosi                         # range at which each beam crosses the plane
        Xi = Bm * sP[:, None]
        yl, zl = Xi @ lat, Xi[:, 2]
        crosses = (cosi > 0.05) & (sint > dpl)
        qy, qz = P["curtain_edge_quantiles"]
        y_edge = float(np.quantile(yl[crosses], qy))
        z_top = float(np.quantile(zl[crosses], 1.0 - qz))
        inside = crosses & (yl > y_edge) & (zl < z_top)
        ng = P["curtain_group_index"]
        th_i = np.arccos(np.clip(cosi, -1, 1))
        th_r = np.arcsin(np.sin(th_i) / ng)
        # per unit thickness: optical path excess along the beam, lateral shift of a plane-parallel plate
        opl = ng / np.cos(th_r) - np.cos(th_i - th_r) / np.cos(th_r)
        lat_sh = np.sin(th_i - th_r) / np.cos(th_r)
        disp = np.zeros((N, 3))
        for k in np.where(inside)[0]:
            pd = nrm_c - cosi[k] * Bm[k]       # in the plane of incidence, perpendicular to the beam
            nn = np.linalg.norm(pd)
            pd = pd / nn if nn > 1e-9 else np.zeros(3)
            disp[k] = opl[k] * Bm[k] - lat_sh[k] * pd
        fld = remove_similarity(disp, P0)
        raw_rms = float(np.sqrt(np.mean(np.sum(fld ** 2, 1))))
        P["curtain_plane_distance_mm"] = dpl
        P["curtain_edges_mm"] = {"lateral_edge": y_edge, "top": z_top}
        P["frac_beams_through_film"] = float(np.mean(inside))
        P["field_rms_mm_per_mm_thickness"] = raw_rms
        P["share_left_after_similarity"] = float(raw_rms / np.sqrt(np.mean(np.sum(disp ** 2, 1))))
        field = fld / raw_rms
    if kind == "stereo_camera_knock":
        k0 = int(np.searchsorted(t, P["event_frac"] * t[-1]))
        H = (np.arange(N) >= k0).astype(float)
        zcam = P0 @ Rc[:, 2]
        zbar = float(zcam.mean())
        dz = (zcam / zbar) ** 2
        disp = H[:, None] * (dz / zcam)[:, None] * P0
        sc = similarity_cols(P0)
        fld = lsq_remove_disp(disp, sc + [H[:, None] * c for c in sc])
        P["k0"], P["t0_s"] = k0, float(t[k0])
        P["share_left_after_similarity_and_step"] = float(np.sqrt(np.mean(fld ** 2)) /
                                                          np.sqrt(np.mean((disp - disp.mean(0)) ** 2)))
        P["depth_range_mm"] = [float(zcam.min()), float(zcam.max())]
        field = fld / math.sqrt(np.mean(np.sum(fld ** 2, 1)))

    def rig_view(X, m):
        if m == 0 or kind not in RIG_POINT_KINDS:
            return X
        return X + m * field

    def measure(Pts, m):
        """noise-free readings (strings) or points (tracker / camera) of the true points Pts with the effect at m"""
        X = rig_view(Pts, m)
        if points:
            return X
        L = np.linalg.norm(X[:, None, :] - anchors[None, :, :], axis=2) - r
        if m != 0:
            if kind == "frame_tension_twist":
                L = L + m * twistE
            elif KINDS.get(kind, ("", ""))[1] == "sensor":
                s_ = sg - 1
                if kind == "string_retract_slack":
                    L[:, s_] += m * slack
                elif kind == "cable_twist":
                    L[:, s_] += m * twist
                elif kind == "hook_ring_slip":
                    L[:, s_] += m * slip
                elif kind == "eyelet_capstan_friction":
                    L[:, s_] += m * capstan
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
        # signs: physical where the physics fixes it (creep and torsion follow the load, a loose wrap reads
        # long, the capstan stretches the pulled cable, a film lengthens the optical path); the beam-break
        # offsets, the twist and the slip carry a random sign of their own; random for the hose's side, the
        # bow's sense, the frame's twist response and the knocked camera's yaw
        if kind in ("wrist_flip_hose", "upper_arm_thermal_bow", "frame_tension_twist", "stereo_camera_knock"):
            mag *= P["sign"]
        erms = eff_rms(mag)
    if kind == "tracker_curtain_film":
        P["film_thickness_mm"] = float(abs(mag) / P["field_rms_mm_per_mm_thickness"])
    if kind == "upper_arm_torsion":
        P["implied_torsion_compliance_rad_per_Nm"] = float(abs(mag) / tors_raw_rms)
    if kind == "upper_arm_thermal_bow":
        P["implied_bow_rad_per_K"] = float(abs(mag) / bow_raw_std)
    if kind == "harmonic_creep_dwell":
        P["implied_creep_compliance_deg_per_Nm"] = float(abs(mag) / creep_raw_rms)

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
             "ratio": erms / point_noise, "scaling": "as gen3 ... gen7: RMS over the poses of the noise-free "
             "displacement of the located point (strings: multilaterated with the nominal anchors from the "
             "readings; tracker / camera: the measured point) with the effect against without it; the effect's "
             "reparametrisation part (and, where the kind says so, its catalogue part) is taken out",
             "robot": rname, "robot_convention_written": robot_file.get("convention", "dh"),
             "deviations_convention": "dh (simulated on the DH chain)",
             "rig": spec["rig"], "n_poses": N, "cols": spec["cols"], "sigma": sigma,
             "session_s": float(t[-1]), "dwell_s": [float(dwell.min()), float(dwell.max())],
             "temp_rise_c": float(rise), "temp_swing_c": float(swing),
             "deviations": devs, "tool_point_mm": tool_true, **rng_info,
             "base_in_rig": {"xyz_mm": base_xyz.tolist(), "rpy_deg": base_rpy.tolist()}}
    json.dump(truth, open(f"{dname}/truth3.json", "w"), indent=1)
    return truth


# ---------------------------------------------------------------- the plan
def plan():
    R = np.random.default_rng(8080808)
    specs = []
    ROB = ["er3a", "ur5", "er3a_mdh", "ur5_mdh", "arm7", "er3a"]
    RIGS_ROBOT = ["std4", "s3tilt", "std4", "points", "s5np", "std4"]
    RIGS_STR = ["std4", "s5np", "std4", "s3tilt", "std4", "s5np"]
    NSTR = {"std4": 4, "s3tilt": 3, "s5np": 5}

    def add(kind, half, i, robot, rig, params, places, drivers, cols):
        idx = len(specs)
        tag = params.get("joint") or params.get("sensor") or ""
        specs.append({"name": f"{idx:03d}_{kind}{tag}_{robot}_{rig}", "kind": kind, "half": half,
                      "robot": robot, "rig": rig, "n": int(R.integers(150, 201)), "seed": 1600000 + idx,
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
            n_j = 7 if rb == "arm7" else 6
            if kind == "harmonic_creep_dwell":
                jj = [2, e, 2, e, 2, e][i]
                prm = {"joint": jj}
                cols = with_time(i)
                places = [place("joint", jj), place("motion", jj)]
                drivers = [f"the change of joint {jj}'s gravity torque over the last move, times exp(-dwell/tau) "
                           f"(the dwell = time_s's step less the move)"]
            elif kind == "upper_arm_torsion":
                rb = ["er3a", "ur5", "er3a_mdh", "ur5_mdh", "ur5", "er3a"][i]   # not arm7: there it is joint 3
                e = 3
                places = [place("configuration"), place("joint", 2), place("joint", e)]
                drivers = ["the outboard gravity moment along the upper arm (lateral COM offset of forearm / "
                           "wrist x cos of the arm's elevation: q2, q3 and the wrist)"]
            elif kind == "wrist_flip_hose":
                fj, dj = FLIP[rb.replace("_mdh", "")]
                prm = {"joint": dj, "source_joint": fj}
                places = [place("configuration"), place("joint", fj), place("joint", dj)]
                drivers = [f"the sign of q{fj} (wrist flip), on joint {dj}"]
            elif kind == "upper_arm_thermal_bow":
                cols = [["time_s", "temp_c"], ["time_s", "temp_c", "payload_kg"], ["time_s"], ["temp_c"],
                        ["time_s", "temp_c"], ["time_s", "temp_c"]][i]
                places = [place("temperature"), place("time"), place("order")]
                drivers = ["the temperature history (T - lag(T)): the upper arm's transient gradient"]
            elif KINDS[kind][1] == "sensor":
                rig = RIGS_STR[i]
                s = int(R.integers(1, NSTR[rig] + 1))
                prm = {"sensor": s}
                if kind == "string_retract_slack":
                    cols = with_time(i)
                    places = [place("string", sensor=s), place("motion", sensor=s)]
                    drivers = [f"string {s}'s retraction into the pose, decaying over the dwell"]
                elif kind == "cable_twist":
                    places = [place("string", sensor=s), place("configuration"), place("joint", n_j),
                              place("motion", sensor=s)]
                    drivers = [f"the flange's accumulated rotation about string {s} (mostly joint {n_j})"]
                elif kind == "hook_ring_slip":
                    cols = with_time(i)
                    places = [place("time", sensor=s), place("order", sensor=s), place("string", sensor=s)]
                    drivers = [f"a step at t0 on string {s} that turns with the flange's orientation"]
                elif kind == "eyelet_capstan_friction":
                    places = [place("string", sensor=s), place("motion", sensor=s), place("workspace", sensor=s)]
                    drivers = [f"string {s}'s direction of travel times its wrap angle at the eyelet times its length"]
            elif kind == "frame_tension_twist":
                rig = ["std4", "s5np", "std4", "s5np", "std4", "s5np"][i]
                places = [place("workspace")]
                drivers = ["where T is (the strings' tensions loading the frame's twist mode)"]
            elif kind in ("tracker_beam_break", "tracker_curtain_film"):
                rig = "points"
                if kind == "tracker_beam_break":
                    cols = with_time(i)
                    places = [place("motion"), place("time"), place("order")]
                    drivers = ["the moves longer than the 80-90 % quantile (beam breaks): a range offset per segment"]
                else:
                    places = [place("workspace")]
                    drivers = ["lines of sight through the film (where T is seen from the tracker)"]
            elif kind == "stereo_camera_knock":
                rig = "camera"
                cols = with_time(i)
                places = [place("time"), place("order"), place("workspace")]
                drivers = ["a step at t0 of a depth-quadratic warp along the camera's rays"]
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
    means the effect is invisible to the geometric fit. Per kind for tune8, aggregate only for heldback8
    unless detail."""
    import score3
    specs = json.load(open(f"{OUT}/plan.json"))
    rows = []
    for s in specs:
        if only and only not in s["name"]:
            continue
        d = f"{OUT}/{s['name']}"
        if not os.path.exists(f"{d}/oracle/report.json"):
            gen3.run_tool(f"{d}/oracle", "off", "report")
        if not os.path.exists(f"{d}/report_off.json"):
            gen3.run_tool(d, "off", "report_off")
        try:
            off = json.load(open(f"{d}/report_off.json"))["stats"]["test"]["after"]["rms_mm"]
            orc = json.load(open(f"{d}/oracle/report.json"))["stats"]["test"]["after"]["rms_mm"]
        except Exception:
            continue
        rows.append((s["name"], s["kind"], s["half"], off / orc))
    json.dump(rows, open(f"{OUT}/visible8.json", "w"), indent=1)
    for h in HALVES:
        rr = [r for r in rows if r[2] == h]
        for k in dict.fromkeys(r[1] for r in rr):
            vals = [r[3] for r in rr if r[1] == k]
            if h == "tune8" or detail or k == "none":
                print(f"{h:9s} {k:26s} off/oracle gmean {score3.gmean(vals):6.3f} min {min(vals):6.3f} "
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
    json.dump(rows, open(f"{OUT}/scores8.json", "w"), indent=1)
    shown = [r for r in rows if full or r["half"] == "tune8"]
    print(f"{'dataset':52s} {'eff/noise':>9s} {'tool':>7s} {'oracle':>7s} {'ratio':>6s} {'category':12s} findings")
    for r in shown:
        f = lambda x: "   -   " if x is None else f"{x:7.4f}"
        print(f"{r['name']:52s} {r['ratio_eff']:9.2f} {f(r.get('tool_rms'))} {f(r.get('oracle_rms'))} "
              f"{'' if r.get('ratio') is None else format(r['ratio'], '6.3f'):>6s} {r['cat']:12s} "
              f"{'; '.join(r.get('findings', []))}")
    print()
    print("(located: an unexplained finding at the right place, or the right name for a kind since taken into the catalogue)")
    print(f"{'kind':26s} {'half':9s} {'n':>2s} {'located':>7s} {'wrongpl':>7s} {'silent':>6s} {'named':>5s} "
          f"{'named>=1%':>9s} {'ratio':>6s}")
    for h in HALVES:
        if h == "heldback8" and not full:
            print(f"(heldback8: per-kind lines withheld; `score full` shows them)")
            continue
        rh = [r for r in rows if r["half"] == h]
        for k in dict.fromkeys(r["kind"] for r in rh):
            rr = [r for r in rh if r["kind"] == k]
            print(f"{k:26s} {h:9s} {len(rr):2d} {sum(r['cat'] in ('located', 'named_right') for r in rr):7d} "
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
    json.dump(sums, open(f"{OUT}/summary8.json", "w"), indent=1)
    return sums


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "list"
    if cmd == "list":
        for k, v in KINDS.items():
            print(f"{k:26s} {v[0]:9s} {v[1]:6s} ~{v[4]:17s} {v[5]}")
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
