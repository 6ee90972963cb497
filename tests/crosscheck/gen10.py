#!/usr/bin/env python3
"""Tenth independent cross-check of drawcal: another fresh, blind set of physics OUTSIDE the catalogue,
with a tune half (tune10) and a held-back half (heldback10).

Written blind: from physics descriptions of industrial arms (strain-wave reducers whose stiffness ripples
with the output angle, a slewing bearing with tilting clearance, a toothed belt that creeps under load, a
robot on a steel pedestal column), drawstring encoder rigs (an aramid replacement cable that follows the
room's humidity, a contaminated encoder code disk, a sensor on a thin bracket, a worn oval exit eyelet, an
aluminium / steel frame that racks as it warms, a base plate shared by the robot and the frame) and stereo
cameras (a mount creeping in yaw after being re-tightened, the centroid bias of a defocused marker through a
vignetted lens), from DATA_FORMAT.md, README.md, docs/CLI.md and the earlier cross-check simulators (gen2.py
... gen9.py, sim.py), README3.md and their scorer score3.py only -- WITHOUT reading src/, docs/PHYSICS.md,
EVAL.md, BENCHMARKS.md, tests/*.rs, tests/engine/, tests/api/ or the git history, and without looking at the
tool's findings to design or adjust the kinds.  The tool measured is the binary /tmp/bin/drawcal-base, run
as given (built from main, as the brief states; not checked here, the git history being out of bounds).

None of the kinds below is a catalogue effect (joint_compliance, backlash, joint_periodic, joint_scale,
base_tilt, thermal_expansion, sensor_scale, sensor_offset, sensor_drift, cable_sag, anchor_step,
rig_step, rig_drift) nor one of gen3.py's ... gen9.py's kinds (shared_plate_flex is a relative of
gen5's platform_tilt: see the design notes).  Several RESEMBLE a catalogue effect without being it
(`resembles` in KINDS): naming that catalogue effect -- or any other -- is a misname.  Each effect's part
that is an exact reparametrisation of the geometric model (a constant joint offset, a base / rig pose, a
tool offset, a string offset, for point data the best similarity transform, and for the robot-side
displacement kinds the whole first-order geometric Jacobian: every DH parameter a, d, alpha, theta, beta,
the tool point and the base pose) is taken out, and so, where the kind says so, is the part that IS a
catalogue effect (a compliance proportional to each joint's gravity torque, with and without the payload;
a base tilt linear in the gravity moment about the base origin, with and without the payload, taken with
a symmetric 2 x 2 compliance so that an anisotropic mount is covered; a joint's 1x / 2x harmonics and
scale; a string's scale / offset / linear drift; a single offset step; a rig pose growing linearly in
time = rig_drift; a uniform scale of the anchors -- and of the robot -- with the temperature), so that
what is left is out of the catalogue (`share_left...` in truth3.json `params`).

The kinds (half, side, ~resembles, driver):
  flexspline_stiffness_ripple tune10 robot ~joint_compliance  joint 2's or the elbow's strain-wave reducer
        has a torsional stiffness that varies with the output angle, twice per revolution of the output-side
        pattern: deflection = tau/K * (1 + a*cos(2q + phi)), tau the joint's gravity torque WITH the payload
        (payload_kg in blocks of 0 / 1.5 / 3 kg, always written); the pure compliance (tau/K, with and without
        the payload), the joint's 1x / 2x harmonics, a scale and the mean taken out: what is left is the
        product of the torque and the angle's 2x harmonic.
  slewing_bearing_clearance tune10 robot   ~base_tilt         joint 1's slewing bearing has tilting
        clearance: the arm above it tilts by theta_c*tanh(|M|/M0) about the direction of the overturning
        moment M (the horizontal gravity moment of the links and the payload about the bearing centre, the base
        origin; it turns with joint 1 and grows with the reach; M0 at the 15-40 % quantile of |M|, so that
        most poses have the clearance taken up); the geometric Jacobian (base pose: the constant tilt), the
        part linear in M (a base tilt) and every joint's gravity compliance taken out in displacement space:
        a saturating tilt set by the reach and joint 1's angle.  payload_kg always written.
  cable_humidity_stretch tune10    sensor ~sensor_scale      one string's cable is an aramid replacement
        whose length follows the room's humidity (NOT recorded): the reading is short by e(t)*l, e(t) a slow
        humidity wave (a 25-45 min cycle plus a trend of up to 30 % of its amplitude over the session); the
        string's offset, scale and a linear drift in time (sensor_drift) taken out: the string's length times
        a nonlinear function of time.
  encoder_disk_contamination tune10 sensor ~sensor_offset    one string's encoder code disk has a
        contamination spot: the reading is off by b (sign random) over a window of 5-15 deg of drum rotation
        (edges smoothed over ~1 deg), recurring every drum revolution (circumference 150-250 mm, the window's
        phase random among those that cover >= 3 poses, one of them held out): a pulse train in the string's
        own length; offset and scale taken out.
  stereo_camera_creep    tune10    rig    ~rig_drift         camera (stereo, baseline 300 mm) data: one
        camera's mount creeps in yaw after being re-tightened at the start, psi(t) = psi0*(1 - exp(-t/tau)),
        tau 20-60 min; the points are triangulated (midpoint of the rays) with the stale extrinsics, so the
        error grows with depth, mostly along the line of sight; the best similarity transform and a rig pose
        growing linearly in time (rig_drift) taken out: the curvature of the creep times a depth-dependent
        field.
  frame_thermal_shear    tune10    rig    ~thermal_expansion the string frame's posts are aluminium and its
        diagonal braces steel: as the (recorded) temperature rises the frame racks instead of scaling, each
        anchor moving by gamma*(T - T0)*(z_anchor - z_floor) along one horizontal direction (random), the
        floor 1 m below the lowest anchor; string i reads -u_i.dA_i; per-string offsets, the rig pose, its
        linear drift (rig_drift) and uniform scales of the anchors and of the robot with T (thermal_expansion)
        taken out: a temperature-driven anchor motion (non-uniform where the anchors' heights differ; a rig
        translation following T - linear(t) where they do not).  temp_c always written.
  belt_creep_joint       heldback10 robot ~                  joint 3 (or 5, random) is driven through a
        toothed belt that creeps under load: each move adds c*tau*|dq| to the joint's zero (tau the joint's
        gravity torque during the move, the mean of its values at the move's two ends; dq the move's travel on
        that joint), cumulating over the session (a monotone-ish walk in the visiting order); a constant
        offset, a linear drift in time of that zero and the best single step taken out.
  pedestal_column_bend   heldback10 robot ~joint_compliance  the robot stands on a 0.6-1.0 m steel column
        that bends under the overturning moment M (links and payload): the base translates horizontally by
        (M x z)*H^2/(2EI) and tilts by M*H/(EI) about M's direction; the geometric Jacobian (base pose), a base
        tilt linear in M (which the column's tilt IS) and every joint's gravity compliance taken out in
        displacement space: mostly the lateral translation, set by the reach and joint 1's angle.
        payload_kg always written.
  bracket_flex_tension   heldback10 sensor ~sensor_scale     one sensor hangs on a thin bracket that bends in
        its weak direction w (random) under the string's tension F = F0*(1 + kappa*(l - mean l)/mean l)
        (spring motor, kappa 0.3-0.7): the exit point moves by F*(u.w)/k_b along w, the reading changes by
        -(u.w)^2*F/k_b (u the string's unit direction); offset and scale taken out: the string's direction
        times its tension.
  oval_eyelet_wear       heldback10 sensor ~                 one string's exit eyelet has worn into a slot of
        half-length s along an axis a across the string's mean direction (random roll): the string pulls
        the exit point to the end of the slot on its side, shift = s*tanh((u.a)/eps)*a, eps 0.02-0.05, so the
        reading changes by -u.shift = -s*(u.a)*tanh((u.a)/eps); offset and scale taken out: the string's
        direction, a rounded |u.a| (a kink across u.a = 0).
  stereo_defocus_centroid_bias heldback10 rig ~              camera (stereo, baseline 300 mm, both cameras
        aimed at the workspace's centre) data: each camera is focused at a fixed distance d_f (its median
        depth x 0.9-1.1); the blurred image of a spherical marker off the focal plane, through a radially
        vignetted lens, has its centroid pulled towards the image centre by beta*(depth - d_f)^2 * (the point's
        lateral offset from that camera's optical axis); the two biased rays are triangulated (midpoint);
        the best similarity transform taken out: a field over the workspace (depth and lateral position).
  shared_plate_flex      heldback10 rig   ~base_tilt         the string frame and the robot share one base
        plate; as the arm reaches out the plate flexes and the frame's anchors rotate rigidly by kappa*M
        about the plate's centre (M the robot's overturning moment with the payload, as in
        slewing_bearing_clearance; the centre 200-600 mm below the robot's base origin and 0-300 mm beside it;
        the robot itself does not tilt relative to its base); string i reads -u_i.dA_i; per-string offsets,
        the rig pose, its drift (rig_drift) and the base tilt linear in M (the rotation part, exactly a base
        tilt relative to the rig) taken out: a translation of the frame relative to the robot driven by the
        robot's pose (not by time).  payload_kg always written.

Kinematics, robots, rigs, multilateration and pose sampling are the earlier simulators' (imported from
sim.py / gen2.py / gen3.py, one definition; lsq_remove, lag and CAMERA_SIGMA from gen6.py,
remove_similarity and elbow_joint from gen7.py, lsq_remove_disp, unit_rms and similarity_cols from gen8.py,
reading_cols_rig and triangulate from gen9.py).  Robots: ER3A and UR5 (DH), the same two written as Craig
MDH (er3a_mdh, ur5_mdh: simulated on the DH chain with DH deviations, robot.json written as gen2.dh_to_mdh
of the nominal, an exact reparametrisation) and gen2's 7-axis arm7.  The clock is gen3's (6-12 s dwell per
pose plus the move at 30 deg/s of the slowest joint), temperature gen3's (warm-up 3-6 K plus a 1-1.5 K HVAC
swing), the payload blocks gen4's ... gen9's.  Every dataset <name>/ has a twin <name>/oracle/ with the
identical poses, split column, context columns, geometric deviations, base pose and noise realisation but
WITHOUT the effect; the tool is run on the twin with `--physics off` (its held-out RMS stands for what a
fit of the true effect would reach).  truth3.json has gen3's ... gen9's fields, so score3.py scores these
datasets unchanged; `gen10.py score` computes the per-half summary itself (tune10, heldback10, overall)
with score3.py's own functions: located right = an `unexplained` finding at one of the kind's true places
(places_ok: driver, and joint / sensor where named), misnamed = every catalogue-named finding (none of
these kinds justifies any catalogue name), ratio = tool held-out RMS / the twin's.  Conditions as gen6 ...
gen9: 6 recordings per kind (150-200 poses, effect 3-6x the point noise drawn uniformly, measured as gen3:
RMS of the noise-free displacement of the located point), 8 effect-free recordings (4 per half), string
noise 0.02 mm with 0.024 mm resolution, tracker 0.03 mm per axis, camera 0.02/0.02/0.06 mm.

Design notes (decided on the physics and the effects' visibility, not on the tool's findings):
- the shapes are normalised to unit RMS after the reparametrisation / catalogue parts are taken out and
  then scaled by the magnitude drawn for the ratio 3-6 (drawn uniformly, none adjusted; `unit` says so);
  the physical scale each implies is in truth3.json `params` (`implied_...`), and `plan` prints it; the
  ranges over the 6 recordings of each kind, and which are physical, are in the `realism` note below (filled
  in from the written truth3.json files, before any run of the tool);
- places_ok were written with the kinds, before any run of the tool, and not changed after;
- joint-local angle kinds avoid joint 1 (a joint-1 quantity moving with a global driver is a rig yaw); the
  moment-driven kinds are located on joint 1 (the moment's direction turns with it), the workspace (the
  reach) and the configuration;
- flexspline_stiffness_ripple, slewing_bearing_clearance, pedestal_column_bend and shared_plate_flex
  always write payload_kg (their torque / moment includes the payload); the time-driven kinds write
  time_s; frame_thermal_shear always writes temp_c; elsewhere the context columns are random (a payload
  written there is carried by nothing: a distractor, as in gen4 ... gen9);
- signs: physical where the physics fixes it (the reducer deflects with the torque, the arm tilts / the
  column bends towards the load, the belt creeps with the load, the humid cable is longer and reads short,
  the bent bracket and the worn slot bring the exit point towards T, the centroid is pulled towards the
  image centre, the plate tilts with the moment); random for the contamination's sign; the rack's
  direction, the bracket's weak direction, the slot's axis, the ripple's and the humidity wave's phases and
  which camera creeps are random;
- encoder_disk_contamination: the window covers only 1.4-4 % of a revolution, so with 150-200 poses the
  phase is taken as the first of 32 drawn whose window covers at least 3 poses, one of them in the test split
  (a window no pose sees is no effect); each affected pose is then off by many times the noise (an
  outlier-like pulse train, which is the physics);
- shared_plate_flex: the relative motion of a rigid rotation of the frame about the plate's centre is a
  base tilt about the robot's base origin (catalogue, taken out) plus a translation kappa*M x (o_base -
  c_plate): what is left is that translation, horizontal for the centre's depth below the base and
  vertical for its offset beside it.  After their catalogue parts are taken out pedestal_column_bend and
  shared_plate_flex both leave a pose-driven translation linear in M; they differ in the plate centre's
  horizontal offset and in what is taken out (the joints' compliance for the column);
- the robot-side displacement kinds (slewing_bearing_clearance, pedestal_column_bend) take out the whole
  first-order geometric Jacobian (stricter than gen9's base translation + tool offset); the angle kinds
  (flexspline_stiffness_ripple, belt_creep_joint) take out their parts in the joint's angle, as gen9;
- realism (ranges over the 6 recordings of each kind, `gen10.py realism`; written before any run of the tool):
    physical: the bracket's stiffness 2.8-7.3 N/mm at F0 = 5 N (a thin sheet bracket); the worn slot's
    half-length 0.92-1.76 mm (0.5-1.5 mm asked: physical to 1.2x); the contamination's error 0.70-2.1 mm
    (a misread code bit: bit 5 of 0.024 mm counts is 0.77 mm); the camera's creep 37-61 arcsec (180-290 urad;
    a re-tightened ball-head / clamp mount, at the top of what is plausible); the defocused centroid's pull
    0.9-18 um at 100 mm defocus and 300 mm off-axis (a fraction of the blur disc);
    larger than physical: the strain-wave ripple a/K = 1.2-5.5e-3 deg/(N*m), a = 1.2-5.5 of gen9's assumed
    whole compliance 1e-3 deg/(N*m), 0.28-1.25 of a CSF-25's own low-torque compliance (4.4e-3 deg/(N*m)),
    against a real ripple of ~10-20 % of the stiffness: 2-50x (peak ripple deflections 0.05-0.19 deg);
    the slewing bearing's clearance tilt theta_c = 0.044-0.14 deg against 0.005-0.02 deg: 2-28x; the
    aramid cable's humidity strain 280-630 ppm amplitude against ~30 ppm for a +-5 %RH swing (an estimate:
    ~1e-4 strain per % moisture regain, ~0.3 % regain for 5 %RH): 10-20x; the frame's rack
    gamma = 7-30x the Al / steel mismatch 1.1e-5/K, against (w^2 + h^2)/(w*h) = 2-3x for a braced panel:
    3-15x (0.20-0.45 mm/K at the top anchor); the belt's walk 0.10-0.68 deg of the joint's zero over a
    session (1.2e-5 - 1.2e-4 of the joint's travel): a healthy toothed belt does not creep at all (a
    slipping / ratcheting one does; a friction belt's elastic creep is ~1 %), so physical only for a worn
    drive; the pedestal's bending stiffness EI = 1.5e3-1.1e4 N*m^2, 3e-4 - 2.3e-3 of a 200 x 8 mm steel
    tube's 4.7e6 N*m^2: 400-3000x softer than physical (only 1.7-5.7 % of the column's bend is left after
    geometry, the base tilt and the joints' compliance: its translation, ~ M x z, is nearly a horizontal
    stretch of the arm that the link lengths and the joint-2/3 compliance absorb); the shared plate's
    rotation 1.0-3.0 mrad per 100 N*m against an estimated 1-10 urad for a bolted steel base plate:
    100-3000x (0.14-0.40 of it left after the base tilt and the rig pose);
- shares left after the catalogue / reparametrisation parts are taken out (`params`): stiffness ripple
  0.49-0.91, bearing clearance 0.23-0.27, humidity 0.58-1.0, contamination 1.0, camera creep 0.23-0.35
  (0.80-0.89 of what is left along the line of sight), thermal shear 0.46-0.62, belt creep 0.15-0.83,
  pedestal 0.017-0.057, bracket 0.68-1.0, eyelet 0.93-1.0, defocus 0.81-1.0, plate 0.14-0.40;
- checked from the written files: each effect dataset against its twin has identical joints, split,
  context columns, robot.json and rig.json and the same noise, and shows the stated effect RMS (strings
  multilaterated from both files, points differenced: within 0.7-2.6 %); the effect-free datasets equal
  their twins byte for byte; two plans into two directories are byte-identical; `plan` takes ~40 s,
  `visible` ~5 s and `run` ~40 s on 2 shared cores;
- `visible` with /tmp/bin/drawcal-base: every effect dataset with --physics off is 3.1x or more the twin's
  held-out RMS (tune10 gmean 4.87, min 3.23; heldback10 gmean 4.38, min 3.10; none below 1.5); effect-free
  1.000.

Measured once with /tmp/bin/drawcal-base (built from main), `score`:
  tune10:     located 50.0 %, misnamed 3.06 / 10 (3.06 without < 1 % gain), silent 16.7 %, wrong place
              27.8 %, ratio 3.004 (worst 6.72), false alarms 0 of 4
  heldback10: located 55.6 %, misnamed 5.83 / 10 (4.72 without < 1 % gain), silent 8.3 %, wrong place
              25.0 %, ratio 2.979 (worst 5.76), false alarms 0 of 4

Usage (from the repository root):
    python3 tests/crosscheck/gen10.py list        # one line of physics per kind
    python3 tests/crosscheck/gen10.py plan        # write every dataset and its twin
    python3 tests/crosscheck/gen10.py run [sub]   # run the tool (one process at a time, timeout)
    python3 tests/crosscheck/gen10.py score       # tune10 per dataset and per kind; heldback10 aggregate only
    python3 tests/crosscheck/gen10.py score full  # also heldback10 per dataset and per kind (unblinds it)
    python3 tests/crosscheck/gen10.py visible     # sanity: the effect datasets with --physics off against
                                                  # the twin; per kind for tune10, aggregate only for
                                                  # heldback10 (`visible full`)
    python3 tests/crosscheck/gen10.py realism     # the implied physical scales per kind (from truth3.json)
Env: XC10_OUT (default /tmp/xcheck10/ds), XCHECK_DATA (default tests/data),
     XCHECK_TOOL (default target/release/drawcal)
"""
import json, math, os, sys, copy, time
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim import rpy_to_R  # noqa: E402
import gen2  # noqa: E402
import gen3  # noqa: E402
from gen2 import frames, axes, multilaterate, make_rig, load_robot, gravity_torques, payload_torques, \
    dh_to_mdh  # noqa: E402
from gen3 import sample_poses, place, gravity_moment_base  # noqa: E402
from gen6 import lsq_remove, CAMERA_SIGMA  # noqa: E402
from gen7 import remove_similarity, elbow_joint  # noqa: E402
from gen8 import lsq_remove_disp, unit_rms, similarity_cols  # noqa: E402
from gen9 import reading_cols_rig, triangulate  # noqa: E402

OUT = os.environ.get("XC10_OUT", "/tmp/xcheck10/ds")
SRC = os.environ.get("XCHECK_DATA", "tests/data")
TOOL = os.environ.get("XCHECK_TOOL", "target/release/drawcal")
gen2.SRC = SRC
gen3.TOOL = TOOL
D2R = math.pi / 180.0
HALVES = ("tune10", "heldback10")

# ---------------------------------------------------------------- the kinds
# kind: (half, side, unit magnitude, unit, resembles (catalogue name or ""), one line of physics)
KINDS = {
    # ---- tune10
    "flexspline_stiffness_ripple": ("tune10", "robot", 0.01, "deg per unit-RMS term", "joint_compliance",
                                    "joint 2's / the elbow's strain-wave reducer's torsional stiffness varies twice "
                                    "per output revolution: deflection tau/K*(1 + a*cos(2q + phi)), tau its gravity "
                                    "torque with the payload (blocks of 0 / 1.5 / 3 kg); the compliance, the joint's "
                                    "1x / 2x harmonics, a scale and the mean taken out: torque times the 2x harmonic"),
    "slewing_bearing_clearance": ("tune10", "robot", 0.01, "mm per unit-RMS field", "base_tilt",
                                  "joint 1's slewing bearing has tilting clearance: the arm above it tilts by "
                                  "theta_c*tanh(|M|/M0) about the overturning moment's direction (links and payload, "
                                  "about the bearing); geometry, the part linear in M (a base tilt) and every joint's "
                                  "compliance taken out: a saturating tilt set by the reach and joint 1's angle"),
    "cable_humidity_stretch": ("tune10", "sensor", 0.01, "mm per unit-RMS term", "sensor_scale",
                               "one string's aramid replacement cable follows the (unrecorded) room humidity: the "
                               "reading is short by e(t)*l, e a 25-45 min humidity wave plus a small trend; offset, "
                               "scale and a linear drift taken out: length times a nonlinear function of time"),
    "encoder_disk_contamination": ("tune10", "sensor", 0.01, "mm per unit-RMS term", "sensor_offset",
                                   "one string's encoder code disk has a contamination spot: the reading is off by b "
                                   "over 5-15 deg of drum rotation (edges ~1 deg), every drum revolution (150-250 mm "
                                   "of cable); offset and scale taken out: a pulse train in the string's own length"),
    "stereo_camera_creep": ("tune10", "rig", 0.01, "mm per unit-RMS field", "rig_drift",
                            "camera (stereo) data: one camera's mount creeps in yaw after re-tightening, "
                            "psi0*(1 - exp(-t/tau)), tau 20-60 min; triangulated with the stale extrinsics (error "
                            "grows with depth, along the line of sight); similarity and its linear drift taken out"),
    "frame_thermal_shear": ("tune10", "rig", 0.01, "mm per unit-RMS reading field", "thermal_expansion",
                            "the frame's aluminium posts against its steel braces: as the temperature rises the frame "
                            "racks, each anchor moving by gamma*(T - T0)*(height above the floor) along one horizontal "
                            "direction; offsets, rig pose and drift and uniform thermal scales taken out"),
    # ---- heldback10
    "belt_creep_joint": ("heldback10", "robot", 0.01, "deg per unit-RMS term", "",
                         "joint 3 / 5 is belt-driven and the belt creeps under load: each move adds c*tau*|dq| to the "
                         "joint's zero (tau its gravity torque, dq the move's travel), cumulating over the session; "
                         "offset, a linear drift in time and the best single step taken out"),
    "pedestal_column_bend": ("heldback10", "robot", 0.01, "mm per unit-RMS field", "joint_compliance",
                             "the robot stands on a 0.6-1.0 m steel column bent by the overturning moment: the base "
                             "translates by (M x z)H^2/2EI and tilts by M*H/EI; geometry, a base tilt linear in M and "
                             "every joint's compliance taken out: mostly the lateral translation"),
    "bracket_flex_tension": ("heldback10", "sensor", 0.01, "mm per unit-RMS term", "sensor_scale",
                             "one sensor hangs on a thin bracket bending in its weak direction w under the string's "
                             "spring-motor tension F(l): the reading changes by -(u.w)^2*F/k_b; offset and scale taken "
                             "out: the string's direction times its tension"),
    "oval_eyelet_wear": ("heldback10", "sensor", 0.01, "mm per unit-RMS term", "",
                         "one string's exit eyelet is worn into a slot of half-length s across the string's mean "
                         "direction: the exit point sits at the slot's end on the string's side, reading changed by "
                         "-s*(u.a)*tanh((u.a)/eps); offset and scale taken out: a kink across u.a = 0"),
    "stereo_defocus_centroid_bias": ("heldback10", "rig", 0.01, "mm per unit-RMS field", "",
                                     "camera (stereo) data: each camera focused at a fixed distance; a defocused "
                                     "sphere's centroid through a vignetted lens is pulled towards the image centre by "
                                     "beta*(depth - d_f)^2*(lateral offset); triangulated; similarity taken out"),
    "shared_plate_flex": ("heldback10", "rig", 0.01, "mm per unit-RMS reading field", "base_tilt",
                          "the frame and the robot share a base plate: the anchors rotate rigidly by kappa*M (the "
                          "robot's overturning moment) about the plate's centre; offsets, rig pose and drift and the "
                          "base-tilt part taken out: a frame translation driven by the robot's pose"),
}
SEEDS_PER_KIND = 6
N_NULL = 8
ROBOT_SIDE = {k for k, v in KINDS.items() if v[1] == "robot"}
RIG_POINT_KINDS = ("stereo_camera_creep", "stereo_defocus_centroid_bias")
RIG_STRING_KINDS = ("frame_thermal_shear", "shared_plate_flex")
PAYLOAD_KINDS = ("flexspline_stiffness_ripple", "slewing_bearing_clearance", "pedestal_column_bend",
                 "shared_plate_flex")
STEREO_BASELINE_MM = 300.0
DALPHA_AL_STEEL = 1.1e-5          # 1/K, aluminium (2.3e-5) against steel (1.2e-5)
ASSUMED_COMPLIANCE = 1e-3         # deg/(N*m), a small arm's joint compliance (as gen9)
TENSION_F0_N = 5.0                # a drawstring sensor's spring-motor tension
EI_UNIT = 1.0e6                   # N*m^2, the column's bending stiffness the unit field is computed with
PSI_UNIT = 1e-4                   # rad, the camera creep's unit
BETA_UNIT = 1e-5                  # centroid pull per mm lateral at 100 mm defocus, the unit
KAPPA_UNIT = 1e-6                 # rad/(N*m), the plate's unit


def rot_about(axis, ang):
    """rotation matrix about the unit axis by ang (rad)"""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K


def geom_cols(true_j, Q, tool_true, pb0, Ftrue):
    """first-order geometric Jacobian of T (base frame) as N x 3 columns: every DH parameter a, d, alpha,
    theta (and beta where the nominal axes are parallel), the tool point and the base pose (translation and
    rotation about the base origin): an exact reparametrisation of the geometric model"""
    N, n = len(Q), len(true_j)
    cols = []
    for i in range(n):
        keys = ["a_mm", "d_mm", "alpha_deg", "theta_offset_deg"]
        if i < n - 1 and abs(math.sin(true_j[i]["alpha_deg"] * D2R)) < 0.01:
            keys.append("beta_deg")
        for key in keys:
            h = 1e-3
            jj = copy.deepcopy(true_j)
            jj[i][key] += h
            c = np.array([(frames(jj, Q[k], "dh")[-1] @ np.array([*tool_true, 1.0]))[:3] for k in range(N)])
            cols.append((c - pb0) / h)
    for a in range(3):
        cols.append(np.array([Ftrue[k][-1][:3, a] for k in range(N)]))       # tool point
        e = np.zeros((N, 3))
        e[:, a] = 1.0
        cols.append(e)                                                     # base translation
        ea = np.zeros(3)
        ea[a] = 1.0
        cols.append(np.cross(ea[None, :], pb0 / 1000.0))                   # base rotation
    return cols


def tilt_fields(Mb, pb0):
    """N x 3 displacement fields of T (base frame) for a base tilt about the base origin linear in the
    horizontal moment Mb (N x 3, N*m): omega = C*M_h with C symmetric 2 x 2 (3 fields)"""
    out = []
    for C in (np.array([[1.0, 0], [0, 0]]), np.array([[0, 0], [0, 1.0]]), np.array([[0, 1.0], [1.0, 0]])):
        om = np.zeros_like(Mb)
        om[:, :2] = Mb[:, :2] @ C.T
        out.append(np.cross(om, pb0 / 1000.0))
    return out


def compliance_cols(tau, AXn, pb0, n):
    """N x 3 displacement fields of T for each joint 2..n deflected in proportion to tau[:, j-1]"""
    N = len(pb0)
    return [np.array([tau[k, jj - 1] * np.cross(AXn[k][jj - 1][1], pb0[k] - AXn[k][jj - 1][0]) / 1000.0
                      for k in range(N)]) for jj in range(2, n + 1)]


def best_step_remove(raw, base_cols):
    """raw minus its least-squares part in span(base_cols + the best single step H(k >= ks))"""
    N = len(raw)
    best, e, kbest = None, None, None
    for ks in range(1, N):
        H = (np.arange(N) >= ks).astype(float)
        ee = lsq_remove(raw, base_cols + [H])
        if best is None or ee @ ee < best:
            best, e, kbest = ee @ ee, ee, ks
    return e, kbest


def share(resid, raw):
    """RMS of what is left over the RMS of the raw effect about its mean (scalar or N x d)"""
    r = np.asarray(resid, float)
    w = np.asarray(raw, float)
    return float(np.sqrt(np.mean(r ** 2)) / max(np.sqrt(np.mean((w - w.mean(0)) ** 2)), 1e-30))


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
    # ---- true geometry (as gen2 ... gen9, DH)
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
    # ---- clock (gen3's: the move at 30 deg/s of the slowest joint, then a 6-12 s dwell before the reading) and
    # temperature (gen3's: warm-up plus an HVAC swing)
    t = np.zeros(N)
    dwell = np.zeros(N)
    move_s = np.zeros(N)
    prev, tt = home, 0.0
    for k in range(N):
        mv = np.max(np.abs(Q[k] - prev)) / 30.0
        move_s[k] = mv
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
    # ---- payload in blocks of 10-20 poses (as gen4 ... gen9; carried by the physics only in PAYLOAD_KINDS, which
    # always write it)
    payload = np.zeros(N)
    levels = [0.0, 1.5, 3.0]
    k, b = 0, 0
    perm = list(rng.permutation(3))
    while k < N:
        ln = int(rng.integers(10, 21))
        payload[k:k + ln] = levels[perm[b % 3]]
        k += ln
        b += 1

    # ---- the effect's parameters (drawn whatever the kind: every kind consumes the same rng stream)
    P = dict(spec.get("params", {}))
    P.setdefault("sign", float(rng.choice([-1.0, 1.0])))
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    P.setdefault("dir", d.tolist())
    P.setdefault("ripple_phase_deg", float(rng.uniform(0, 360)))
    P.setdefault("clearance_M0_quantile", float(rng.uniform(0.15, 0.4)))
    P.setdefault("humidity_period_s", float(rng.uniform(1500, 2700)))
    P.setdefault("humidity_phase_deg", float(rng.uniform(0, 360)))
    P.setdefault("humidity_trend_frac", float(rng.uniform(-0.3, 0.3)))
    P.setdefault("drum_circumference_mm", float(rng.uniform(150, 250)))
    P.setdefault("spot_window_deg", float(rng.uniform(5, 15)))
    spot_phases = rng.uniform(0, 360, 32)
    P.setdefault("creeping_camera", int(rng.integers(0, 2)))
    P.setdefault("creep_tau_s", float(rng.uniform(1200, 3600)))
    P.setdefault("shear_azimuth_deg", float(rng.uniform(0, 360)))
    P.setdefault("column_height_mm", float(rng.uniform(600, 1000)))
    P.setdefault("tension_kappa", float(rng.uniform(0.3, 0.7)))
    P.setdefault("slot_roll_deg", float(rng.uniform(0, 360)))
    P.setdefault("slot_eps", float(rng.uniform(0.02, 0.05)))
    P.setdefault("focus_factor", [float(rng.uniform(0.9, 1.1)), float(rng.uniform(0.9, 1.1))])
    P.setdefault("plate_depth_mm", float(rng.uniform(200, 600)))
    P.setdefault("plate_offset_mm", float(rng.uniform(0, 300)))
    P.setdefault("plate_offset_azimuth_deg", float(rng.uniform(0, 360)))
    j = P.get("joint")
    sg = P.get("sensor")
    Ftrue = [frames(true_j, Q[k], "dh") for k in range(N)]
    pb0 = np.array([(Ftrue[k][-1] @ np.array([*tool_true, 1.0]))[:3] for k in range(N)])   # T, base frame
    tg_all = np.array([gravity_torques(robot, Q[k]) for k in range(N)])
    tp_all = np.array([payload_torques(robot, None, None, Q[k], payload[k]) for k in range(N)])
    AXn = [axes(nom, Q[k], "dh") for k in range(N)]
    g_base = np.asarray(robot.get("gravity_in_base", [0, 0, -9.81]), float)
    M_links = np.array([gravity_moment_base(robot, Q[k]) for k in range(N)])            # N*m, base frame
    M_tot = M_links + np.cross(pb0 / 1000.0, payload[:, None] * g_base[None, :])        # with the payload
    qshape = None   # a joint-angle error (deg per unit magnitude) on joint qjoint
    qjoint = None
    tshape = None   # a displacement of T (base frame, mm per unit magnitude)

    def harmonics(qdeg):
        x = qdeg * D2R
        return [np.ones(N), np.cos(x), np.sin(x), np.cos(2 * x), np.sin(2 * x), x]

    def robot_catalogue_cols():
        """geometry, a base tilt linear in the moment (with and without the payload) and every joint's gravity
        compliance (with and without the payload), as displacement fields of T"""
        return (geom_cols(true_j, Q, tool_true, pb0, Ftrue) + tilt_fields(M_tot, pb0) + tilt_fields(M_links, pb0)
                + compliance_cols(tg_all, AXn, pb0, n) + compliance_cols(tg_all + tp_all, AXn, pb0, n))

    # ---- robot-side shapes
    if kind == "flexspline_stiffness_ripple":
        tl = tg_all[:, j - 1]
        tau = tl + tp_all[:, j - 1]
        x = Q[:, j - 1] * D2R
        raw = tau * np.cos(2 * x + P["ripple_phase_deg"] * D2R)
        e = lsq_remove(raw, harmonics(Q[:, j - 1]) + [tau, tl])
        P["share_left_after_compliance_harmonics_scale"] = float(np.std(e) / np.std(raw))
        P["torque_range_nm"] = [float(tau.min()), float(tau.max())]
        raw_rms = math.sqrt(np.mean(e ** 2))   # N*m per unit a/K
        qshape, qjoint = unit_rms(e), j         # deflection with the torque: sign fixed (the phase is random)
    if kind == "slewing_bearing_clearance":
        Mn = np.linalg.norm(M_tot, axis=1)
        M0 = float(np.quantile(Mn, P["clearance_M0_quantile"]))
        om = (np.tanh(Mn / M0) / np.maximum(Mn, 1e-9))[:, None] * M_tot      # rad per rad of clearance tilt
        raw = np.cross(om, pb0)                                                # mm, the bearing at the base origin
        resid = lsq_remove_disp(raw, robot_catalogue_cols())
        raw_rms = float(np.sqrt(np.mean(np.sum(resid ** 2, 1))))
        P["clearance_M0_nm"] = M0
        P["moment_range_nm"] = [float(Mn.min()), float(np.median(Mn)), float(Mn.max())]
        P["frac_poses_past_M0"] = float(np.mean(Mn > M0))
        P["share_left_after_geometry_tilt_compliance"] = share(resid, raw)
        tshape = resid / raw_rms                # the arm tilts towards its load: sign fixed
    if kind == "pedestal_column_bend":
        Hm = P["column_height_mm"] / 1000.0
        ez = np.array([0.0, 0.0, 1.0])
        delta = 1000.0 * np.cross(M_tot, ez[None, :]) * Hm ** 2 / (2.0 * EI_UNIT)   # mm, towards the load
        om = M_tot * Hm / EI_UNIT                                                    # rad
        raw = delta + np.cross(om, pb0)
        resid = lsq_remove_disp(raw, robot_catalogue_cols())
        raw_rms = float(np.sqrt(np.mean(np.sum(resid ** 2, 1))))
        P["moment_range_nm"] = [float(np.linalg.norm(M_tot, axis=1).min()), float(np.linalg.norm(M_tot, axis=1).max())]
        P["translation_share_of_raw"] = share(delta, raw)
        P["share_left_after_geometry_tilt_compliance"] = share(resid, raw)
        tshape = resid / raw_rms                # the column bends towards the load: sign fixed
    if kind == "belt_creep_joint":
        tau = tg_all[:, j - 1]
        tau_home = gravity_torques(robot, home)[j - 1]
        tprev = np.concatenate([[tau_home], tau[:-1]])
        qprev = np.concatenate([[home[j - 1]], Q[:-1, j - 1]])
        dq = np.abs(Q[:, j - 1] - qprev)
        inc = 0.5 * (tprev + tau) * dq          # N*m*deg
        raw = np.cumsum(inc)
        e, kbest = best_step_remove(raw, [np.ones(N), t])
        P["share_left_after_offset_drift_step"] = float(np.std(e) / np.std(raw))
        P["best_step_pose"] = int(kbest)
        P["torque_range_nm"] = [float(tau.min()), float(tau.max())]
        P["frac_moves_positive_torque"] = float(np.mean(0.5 * (tprev + tau) > 0))
        P["travel_deg_total"] = float(dq.sum())
        P["walk_range_nm_deg"] = float(raw.max() - raw.min())
        raw_rms = math.sqrt(np.mean(e ** 2))   # N*m*deg per unit c
        qshape, qjoint = unit_rms(e), j         # the belt creeps with the load: sign fixed

    def robot_points(m):
        Pts = np.zeros((N, 3))
        for k in range(N):
            if m != 0 and qshape is not None:
                q = Q[k].copy()
                q[qjoint - 1] += m * qshape[k]
                F_ = frames(true_j, q, "dh")
                pb = (F_[-1] @ np.array([*tool_true, 1.0]))[:3]
            else:
                pb = pb0[k]
            if m != 0 and tshape is not None:
                pb = pb + m * tshape[k]
            Pts[k] = to_rig(pb)
        return Pts

    P0 = robot_points(0.0)
    L0 = None
    if not points:
        L0 = np.linalg.norm(P0[:, None, :] - anchors[None, :, :], axis=2) - r
        U0 = (P0[:, None, :] - anchors[None, :, :]) / (L0 + r)[:, :, None]

    # ---- sensor-side shapes
    if kind == "cable_humidity_stretch":
        ls = L0[:, sg - 1]
        ew = (np.sin(2 * math.pi * t / P["humidity_period_s"] + P["humidity_phase_deg"] * D2R)
              + P["humidity_trend_frac"] * t / t[-1])            # strain per unit amplitude
        raw = -ew * ls                                            # the humid (longer) cable reads short
        e = lsq_remove(raw, [np.ones(N), ls, t])
        P["share_left_after_offset_scale_drift"] = float(np.std(e) / np.std(raw))
        P["humidity_cycles_in_session"] = float(t[-1] / P["humidity_period_s"])
        raw_rms = math.sqrt(np.mean(e ** 2))    # mm per unit strain amplitude
        sshape = unit_rms(e)                    # sign fixed by the physics (the wave's phase is random)
    if kind == "encoder_disk_contamination":
        ls = L0[:, sg - 1]
        C = P["drum_circumference_mm"]
        w = P["spot_window_deg"]
        theta = 360.0 * ls / C

        def pulse(ph):
            dth = (theta - ph + 180.0) % 360.0 - 180.0
            return 0.5 * (np.tanh((dth + 0.5 * w) / 0.5) - np.tanh((dth - 0.5 * w) / 0.5))

        chosen = None
        for i_ph, ph in enumerate(spot_phases):
            pu = pulse(ph)
            hit = pu > 0.5
            if hit.sum() >= 3 and np.any(hit & (split == "test")):
                chosen = (i_ph, ph)
                break
        if chosen is None:    # never seen in the plan below; the widest coverage then
            i_ph = int(np.argmax([np.sum(pulse(ph) > 0.5) for ph in spot_phases]))
            chosen = (i_ph, spot_phases[i_ph])
        raw = pulse(chosen[1])
        e = lsq_remove(raw, [np.ones(N), ls])
        P["spot_phase_deg"] = float(chosen[1])
        P["spot_phase_draw"] = int(chosen[0])
        P["poses_in_window"] = int(np.sum(raw > 0.5))
        P["test_poses_in_window"] = int(np.sum((raw > 0.5) & (split == "test")))
        P["drum_revolutions_over_range"] = float((ls.max() - ls.min()) / C)
        P["share_left_after_offset_scale"] = float(np.std(e) / np.std(raw))
        raw_rms = math.sqrt(np.mean(e ** 2))    # per mm of b
        sshape = unit_rms(e) * P["sign"]
    if kind == "bracket_flex_tension":
        ls = L0[:, sg - 1]
        wv = np.array(P["dir"])
        u = U0[:, sg - 1]
        F = 1.0 + P["tension_kappa"] * (ls - ls.mean()) / ls.mean()        # F / F0
        raw = -((u @ wv) ** 2) * F                                          # mm per mm of F0/k_b
        e = lsq_remove(raw, [np.ones(N), ls])
        P["uw_range"] = [float((u @ wv).min()), float((u @ wv).max())]
        P["share_left_after_offset_scale"] = float(np.std(e) / np.std(raw))
        raw_rms = math.sqrt(np.mean(e ** 2))
        sshape = unit_rms(e)                    # the exit point is pulled towards T: the reading shortens
    if kind == "oval_eyelet_wear":
        ls = L0[:, sg - 1]
        u = U0[:, sg - 1]
        um = u.mean(0)
        um /= np.linalg.norm(um)
        ref = np.array([0.0, 0.0, 1.0]) if abs(um[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        e1 = np.cross(um, ref)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(um, e1)
        ro = P["slot_roll_deg"] * D2R
        a = math.cos(ro) * e1 + math.sin(ro) * e2                 # the slot's axis, across the mean direction
        ua = u @ a
        raw = -ua * np.tanh(ua / P["slot_eps"])                   # mm per mm of slot half-length
        e = lsq_remove(raw, [np.ones(N), ls])
        P["slot_axis_rig"] = a.tolist()
        P["ua_range"] = [float(ua.min()), float(ua.max())]
        P["frac_ua_positive"] = float(np.mean(ua > 0))
        P["share_left_after_offset_scale"] = float(np.std(e) / np.std(raw))
        raw_rms = math.sqrt(np.mean(e ** 2))
        sshape = unit_rms(e)                    # the exit point moves towards T: the reading shortens

    # ---- rig-side fields on the strings (N x m reading changes)
    if kind in RIG_STRING_KINDS:
        base_cols = reading_cols_rig(U0, anchors, t)
        if kind == "frame_thermal_shear":
            dT = temp_true - temp_true[0]
            az = P["shear_azimuth_deg"] * D2R
            hdir = np.array([math.cos(az), math.sin(az), 0.0])
            zf = anchors[:, 2].min() - 1000.0                      # floor 1 m below the lowest anchor
            Hp = anchors[:, 2] - zf
            dA = dT[:, None, None] * Hp[None, :, None] * hdir[None, None, :]   # mm per unit gamma (1/K)
            E = -np.einsum("kic,kic->ki", U0, dA)
            Tc = temp_true - temp_true.mean()
            scl = [-np.einsum("kic,ic->ki", U0, anchors - anchors.mean(0)) * Tc[:, None],     # anchors' scale
                   np.einsum("kic,kc->ki", U0, (Rb @ pb0.T).T) * Tc[:, None]]                 # robot's scale
            Er = lsq_remove_disp(E, base_cols + scl)
            P["anchor_heights_above_floor_mm"] = Hp.tolist()
            P["temp_change_range_K"] = [float(dT.min()), float(dT.max())]
            P["anchor_heights_differ"] = bool(np.ptp(Hp) > 1.0)
        else:
            Mr = (Rb @ M_tot.T).T                                   # rig frame, N*m
            az = P["plate_offset_azimuth_deg"] * D2R
            cp = base_xyz + np.array([P["plate_offset_mm"] * math.cos(az), P["plate_offset_mm"] * math.sin(az),
                                      -P["plate_depth_mm"]])
            om = Mr * KAPPA_UNIT                                    # rad per unit kappa
            dA = np.cross(om[:, None, :], (anchors - cp)[None, :, :])           # N x m x 3, mm
            E = -np.einsum("kic,kic->ki", U0, dA)
            tilt = [np.einsum("kic,kc->ki", U0, (Rb @ f.T).T) for f in tilt_fields(M_tot, pb0) + tilt_fields(M_links, pb0)]
            Er = lsq_remove_disp(E, base_cols + tilt)
            P["plate_centre_rig_mm"] = cp.tolist()
            P["moment_range_nm"] = [float(np.linalg.norm(M_tot, axis=1).min()), float(np.linalg.norm(M_tot, axis=1).max())]
        P["share_left_after_rig_and_catalogue_parts"] = float(np.sqrt(np.mean(Er ** 2)) / np.sqrt(np.mean((E - E.mean(0)) ** 2)))
        raw_rms = float(np.sqrt(np.mean(Er ** 2)))
        rigE = Er / raw_rms      # signs fixed by the physics: the frame racks with the warming, the plate tilts with M

    # ---- instrument-side fields (point data)
    if camera:
        zc = P0.mean(0) / np.linalg.norm(P0.mean(0))
        xc = np.cross([0, 0, 1.0], zc)
        xc /= np.linalg.norm(xc)
        yc = np.cross(zc, xc)
        Rc = np.column_stack([xc, yc, zc])   # camera frame -> rig frame
        P["camera_axis_rig"] = zc.tolist()
        cams = [-0.5 * STEREO_BASELINE_MM * xc, 0.5 * STEREO_BASELINE_MM * xc]
    if kind == "stereo_camera_creep":
        ic = P["creeping_camera"]
        psi = PSI_UNIT * (1.0 - np.exp(-t / P["creep_tau_s"]))
        disp = np.zeros((N, 3))
        for k in range(N):
            T = P0[k]
            rays = [(c, T - c) for c in cams]
            c = cams[ic]
            rays[ic] = (c, rot_about(yc, -psi[k]) @ (T - c))     # the stale extrinsics: the ray turned back by psi
            disp[k] = triangulate(rays[0][0], rays[0][1], rays[1][0], rays[1][1]) - T
        sc = similarity_cols(P0)
        tn = (t - t.mean()) / max(t.std(), 1e-9)
        fld = lsq_remove_disp(disp, sc + [c_ * tn[:, None] for c_ in sc[:6]])
        raw_rms = float(np.sqrt(np.mean(np.sum(fld ** 2, 1))))
        dep = (P0 - 0.0) @ zc
        P["depth_range_mm"] = [float(dep.min()), float(dep.max())]
        P["creep_end_fraction"] = float(1.0 - math.exp(-t[-1] / P["creep_tau_s"]))
        P["share_left_after_similarity_and_drift"] = share(fld, disp)
        P["along_sight_share"] = float(np.sqrt(np.mean((fld @ zc) ** 2) / np.mean(np.sum(fld ** 2, 1))))
        field = fld / raw_rms                   # the sign of the yaw is the creep's: fixed
    if kind == "stereo_defocus_centroid_bias":
        disp = np.zeros((N, 3))
        cen = P0.mean(0)
        cfr = []
        for i_c, c in enumerate(cams):
            zi = (cen - c) / np.linalg.norm(cen - c)
            xi = np.cross([0, 0, 1.0], zi)
            xi /= np.linalg.norm(xi)
            yi = np.cross(zi, xi)
            dep = (P0 - c) @ zi
            cfr.append((c, zi, xi, yi, float(np.median(dep) * P["focus_factor"][i_c])))
        for k in range(N):
            T = P0[k]
            rays = []
            for (c, zi, xi, yi, df) in cfr:
                v = T - c
                dz = (v @ zi - df) / 100.0
                lat = (v @ xi) * xi + (v @ yi) * yi
                rays.append((c, v - BETA_UNIT * dz * dz * lat))    # pulled towards the optical axis
            disp[k] = triangulate(rays[0][0], rays[0][1], rays[1][0], rays[1][1]) - T
        fld = remove_similarity(disp, P0)
        raw_rms = float(np.sqrt(np.mean(np.sum(fld ** 2, 1))))
        P["focus_distance_mm"] = [cf[4] for cf in cfr]
        P["defocus_range_mm"] = [float(min(((P0 - cf[0]) @ cf[1] - cf[4]).min() for cf in cfr)),
                                 float(max(((P0 - cf[0]) @ cf[1] - cf[4]).max() for cf in cfr))]
        P["share_left_after_similarity"] = share(fld, disp)
        field = fld / raw_rms

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
            if kind in RIG_STRING_KINDS:
                L = L + m * rigE
            elif KINDS.get(kind, ("", ""))[1] == "sensor":
                L[:, sg - 1] += m * sshape
        return L

    def located(X, guess):
        if points:
            return X
        return np.array([multilaterate(anchors, X[k] + r, guess[k]) for k in range(N)])

    M0pts = located(measure(P0, 0.0), P0)
    if camera:
        noise = (noise / sigma * np.array(CAMERA_SIGMA)[None, :]) @ Rc.T   # camera frame -> rig frame
        point_noise = float(np.linalg.norm(CAMERA_SIGMA))
    elif points:
        point_noise = float(sigma * math.sqrt(3))
    else:
        Ln = measure(P0, 0.0) + noise
        Ln = np.round(Ln / res) * res
        point_noise = float(np.sqrt(np.mean(np.sum((located(Ln, P0) - M0pts) ** 2, axis=1))))

    robot_kind = kind in ROBOT_SIDE

    def eff_rms(m):
        Pm = robot_points(m) if robot_kind else P0
        Mm = located(measure(Pm, m), Pm)
        return float(np.sqrt(np.mean(np.sum((Mm - M0pts) ** 2, axis=1))))

    mag, erms = 0.0, 0.0
    if kind != "none":
        u_ = KINDS[kind][2]
        ru = eff_rms(u_)
        mag = u_ * spec["ratio"] * point_noise / ru
        erms = eff_rms(mag)
    # ---- the physical scale each magnitude implies
    phys = abs(mag) / raw_rms if kind != "none" else 0.0
    if kind == "flexspline_stiffness_ripple":
        P["implied_a_over_K_deg_per_Nm"] = float(phys)
        P["implied_ripple_a_at_1e-3_deg_per_Nm"] = float(phys / ASSUMED_COMPLIANCE)
        P["implied_peak_ripple_deflection_deg"] = float(phys * np.max(np.abs(
            (tg_all[:, j - 1] + tp_all[:, j - 1]) * np.cos(2 * Q[:, j - 1] * D2R + P["ripple_phase_deg"] * D2R))))
    if kind == "slewing_bearing_clearance":
        P["implied_theta_c_deg"] = float(phys / D2R)
    if kind == "pedestal_column_bend":
        Hm = P["column_height_mm"] / 1000.0
        EI = EI_UNIT / phys
        P["implied_EI_Nm2"] = float(EI)
        # a steel tube 200 mm x 8 mm: I = pi/64*(0.2^4 - 0.184^4) = 2.23e-5 m^4, EI = 4.7e6 N*m^2
        P["implied_EI_over_steel_tube_200x8"] = float(EI / 4.7e6)
        P["implied_translation_mm_at_100Nm"] = float(1000.0 * 100.0 * Hm ** 2 / (2 * EI))
    if kind == "belt_creep_joint":
        P["implied_c_deg_per_Nm_deg"] = float(phys)
        P["implied_walk_range_deg"] = float(phys * P["walk_range_nm_deg"])
        P["implied_walk_over_travel"] = float(phys * P["walk_range_nm_deg"] / max(P["travel_deg_total"], 1e-9))
    if kind == "cable_humidity_stretch":
        P["implied_strain_amplitude_ppm"] = float(phys * 1e6)
    if kind == "encoder_disk_contamination":
        P["implied_b_mm"] = float(phys)
    if kind == "bracket_flex_tension":
        P["implied_F0_over_kb_mm"] = float(phys)
        P["implied_kb_N_per_mm_at_5N"] = float(TENSION_F0_N / phys)
    if kind == "oval_eyelet_wear":
        P["implied_slot_half_length_mm"] = float(phys)
    if kind == "frame_thermal_shear":
        P["implied_gamma_per_K"] = float(phys)
        P["implied_gamma_over_dalpha_al_steel"] = float(phys / DALPHA_AL_STEEL)
        P["implied_top_anchor_shift_mm_per_K"] = float(phys * max(P["anchor_heights_above_floor_mm"]))
    if kind == "shared_plate_flex":
        P["implied_kappa_urad_per_100Nm"] = float(phys * KAPPA_UNIT * 100.0 * 1e6)
    if kind == "stereo_camera_creep":
        P["implied_psi0_urad"] = float(phys * PSI_UNIT * 1e6)
        P["implied_psi0_arcsec"] = float(phys * PSI_UNIT / D2R * 3600.0)
    if kind == "stereo_defocus_centroid_bias":
        P["implied_pull_per_mm_lateral_at_100mm_defocus"] = float(phys * BETA_UNIT)
        P["implied_pull_um_at_100mm_defocus_300mm_off_axis"] = float(phys * BETA_UNIT * 300.0 * 1000.0)

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
             "ratio": erms / point_noise, "scaling": "as gen3 ... gen9: RMS over the poses of the noise-free "
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
    R = np.random.default_rng(10101010)
    specs = []
    ROB = ["er3a", "ur5", "er3a_mdh", "ur5_mdh", "arm7", "er3a"]
    RIGS_ROBOT = ["std4", "s3tilt", "std4", "points", "s5np", "std4"]
    RIGS_STR = ["std4", "s5np", "std4", "s3tilt", "std4", "s5np"]
    NSTR = {"std4": 4, "s3tilt": 3, "s5np": 5}

    def add(kind, half, i, robot, rig, params, places, drivers, cols):
        idx = len(specs)
        tag = params.get("joint") or params.get("sensor") or ""
        specs.append({"name": f"{idx:03d}_{kind}{tag}_{robot}_{rig}", "kind": kind, "half": half,
                      "robot": robot, "rig": rig, "n": int(R.integers(150, 201)), "seed": 2000000 + idx,
                      "sigma": 0.02 if rig not in ("points", "camera") else 0.03, "ratio": float(R.uniform(3, 6)),
                      "params": params, "places_ok": places, "drivers": drivers, "cols": cols})

    def rand_cols():
        return [["time_s", "temp_c"], ["time_s"], [], ["time_s", "temp_c", "payload_kg"]][int(R.integers(0, 4))]

    def with_time(i):
        return [["time_s", "temp_c"], ["time_s"], ["time_s", "temp_c", "payload_kg"]][i % 3]

    def with_payload(i):
        return [["time_s", "temp_c", "payload_kg"], ["payload_kg"], ["time_s", "payload_kg"]][i % 3]

    for kind in KINDS:
        half = KINDS[kind][0]
        for i in range(SEEDS_PER_KIND):
            rb = ROB[i]
            rig = RIGS_ROBOT[i]
            cols = rand_cols()
            prm = {}
            e = elbow_joint(rb.replace("_mdh", ""))
            if kind == "flexspline_stiffness_ripple":
                jj = int(R.choice([2, e]))
                prm = {"joint": jj}
                cols = with_payload(i)
                places = [place("joint", jj), place("configuration"), place("payload")]
                drivers = [f"joint {jj}'s gravity torque with the payload times cos(2*q{jj} + phi)"]
            elif kind == "slewing_bearing_clearance":
                cols = with_payload(i)
                places = [place("joint", 1), place("workspace"), place("configuration")]
                drivers = ["the overturning moment (reach, payload) saturating, its direction turning with joint 1"]
            elif kind == "belt_creep_joint":
                jj = int(R.choice([3, 5]))
                prm = {"joint": jj}
                cols = with_time(i)
                places = [place("time", jj), place("order", jj), place("motion", jj)]
                drivers = [f"the cumulative load-weighted travel of joint {jj} (time / visiting order, each move)"]
            elif kind == "pedestal_column_bend":
                cols = with_payload(i)
                places = [place("joint", 1), place("workspace"), place("configuration")]
                drivers = ["the overturning moment (reach, payload), its direction turning with joint 1: a lateral "
                           "translation of the base"]
            elif KINDS[kind][1] == "sensor":
                rig = RIGS_STR[i]
                s = int(R.integers(1, NSTR[rig] + 1))
                prm = {"sensor": s}
                if kind == "cable_humidity_stretch":
                    cols = with_time(i)
                    places = [place("time", sensor=s), place("order", sensor=s), place("string", sensor=s)]
                    drivers = [f"the room's humidity in time times string {s}'s length"]
                elif kind == "encoder_disk_contamination":
                    places = [place("string", sensor=s)]
                    drivers = [f"string {s}'s length (its drum angle: a pulse every drum revolution)"]
                elif kind == "bracket_flex_tension":
                    places = [place("string", sensor=s), place("workspace", sensor=s)]
                    drivers = [f"string {s}'s direction against its bracket's weak direction, times its tension"]
                elif kind == "oval_eyelet_wear":
                    places = [place("string", sensor=s), place("workspace", sensor=s)]
                    drivers = [f"string {s}'s direction across its worn eyelet's slot"]
            elif kind == "frame_thermal_shear":
                rig = ["s5np", "s3tilt", "std4", "s5np", "s3tilt", "s5np"][i]
                cols = [["time_s", "temp_c"], ["temp_c"], ["time_s", "temp_c", "payload_kg"], ["time_s", "temp_c"],
                        ["temp_c"], ["time_s", "temp_c"]][i]
                places = [place("temperature"), place("string")]
                drivers = ["the temperature (the frame racks with it, anchors moving by their height)"]
            elif kind == "shared_plate_flex":
                rig = ["std4", "s5np", "std4", "s3tilt", "std4", "s5np"][i]
                cols = with_payload(i)
                places = [place("workspace"), place("joint", 1), place("configuration")]
                drivers = ["the robot's overturning moment (reach, payload, joint 1's angle) moving the frame"]
            elif kind == "stereo_camera_creep":
                rig = "camera"
                cols = with_time(i)
                places = [place("time"), place("order"), place("workspace")]
                drivers = ["time (the mount's creep) times where T is (depth)"]
            elif kind == "stereo_defocus_centroid_bias":
                rig = "camera"
                places = [place("workspace")]
                drivers = ["where T is: its depth against the focus and its offset from each optical axis"]
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
    means the effect is invisible to the geometric fit. Per kind for tune10, aggregate only for heldback10
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
    json.dump(rows, open(f"{OUT}/visible10.json", "w"), indent=1)
    for h in HALVES:
        rr = [r for r in rows if r[2] == h]
        for k in dict.fromkeys(r[1] for r in rr):
            vals = [r[3] for r in rr if r[1] == k]
            if h == "tune10" or detail or k == "none":
                print(f"{h:10s} {k:28s} off/oracle gmean {score3.gmean(vals):6.3f} min {min(vals):6.3f} "
                      f"max {max(vals):6.3f}  " + " ".join(f"{v:.2f}" for v in vals))
        eff = [r[3] for r in rr if r[1] != "none"]
        nul = [r[3] for r in rr if r[1] == "none"]
        if eff:
            print(f"{h:10s} ALL EFFECTS off/oracle gmean {score3.gmean(eff):6.3f} min {min(eff):6.3f}; "
                  f"{sum(v < 1.5 for v in eff)} of {len(eff)} below 1.5; effect-free gmean {score3.gmean(nul):.3f}")


def realism():
    """the implied physical scales (truth3.json params `implied_...`) and the shares left, per kind: ranges
    over its recordings (no tool output is read)"""
    specs = json.load(open(f"{OUT}/plan.json"))
    by = {}
    for s in specs:
        p = f"{OUT}/{s['name']}/truth3.json"
        if s["kind"] == "none" or not os.path.exists(p):
            continue
        tr = json.load(open(p))
        for key, v in tr["params"].items():
            if (key.startswith("implied_") or key.startswith("share_left")) and isinstance(v, (int, float)):
                by.setdefault((s["kind"], key), []).append(float(v))
    for (k, key), vals in by.items():
        print(f"{k:28s} {key:50s} {min(vals):10.4g} .. {max(vals):10.4g}")


def score(full=False):
    import score3
    specs = json.load(open(f"{OUT}/plan.json"))
    rows = [score3.score_one(f"{OUT}/{s['name']}") for s in specs if os.path.exists(f"{OUT}/{s['name']}/run.json")]
    json.dump(rows, open(f"{OUT}/scores10.json", "w"), indent=1)
    shown = [r for r in rows if full or r["half"] == "tune10"]
    print(f"{'dataset':56s} {'eff/noise':>9s} {'tool':>7s} {'oracle':>7s} {'ratio':>6s} {'category':12s} findings")
    for r in shown:
        f = lambda x: "   -   " if x is None else f"{x:7.4f}"
        print(f"{r['name']:56s} {r['ratio_eff']:9.2f} {f(r.get('tool_rms'))} {f(r.get('oracle_rms'))} "
              f"{'' if r.get('ratio') is None else format(r['ratio'], '6.3f'):>6s} {r['cat']:12s} "
              f"{'; '.join(r.get('findings', []))}")
    print()
    print("(located: an unexplained finding at the right place, or the right name for a kind since taken into the catalogue)")
    print(f"{'kind':28s} {'half':10s} {'n':>2s} {'located':>7s} {'wrongpl':>7s} {'silent':>6s} {'named':>5s} "
          f"{'named>=1%':>9s} {'ratio':>6s}")
    for h in HALVES:
        if h == "heldback10" and not full:
            print(f"(heldback10: per-kind lines withheld; `score full` shows them)")
            continue
        rh = [r for r in rows if r["half"] == h]
        for k in dict.fromkeys(r["kind"] for r in rh):
            rr = [r for r in rh if r["kind"] == k]
            print(f"{k:28s} {h:10s} {len(rr):2d} {sum(r['cat'] in ('located', 'named_right') for r in rr):7d} "
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
    json.dump(sums, open(f"{OUT}/summary10.json", "w"), indent=1)
    return sums


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "list"
    if cmd == "list":
        for k, v in KINDS.items():
            print(f"{k:28s} {v[0]:10s} {v[1]:6s} ~{v[4]:17s} {v[5]}")
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
            imp = " ".join(f"{k[8:]}={v:.3g}" for k, v in tr["params"].items()
                           if k.startswith("implied_") and isinstance(v, (int, float)))
            print(s["name"], f"N={tr['n_poses']} noise={tr['point_noise_mm']:.4f} mag={tr['magnitude']:.4g} "
                  f"{tr['unit']} rms={tr['effect_rms_mm']:.3f} ratio={tr['ratio']:.2f}{lr} {imp} "
                  f"{time.time()-t0:.1f}s", flush=True)
    elif cmd == "run":
        run(sys.argv[2] if len(sys.argv) > 2 else None)
    elif cmd == "visible":
        visible(sys.argv[2] if len(sys.argv) > 2 and sys.argv[2] != "full" else None, "full" in sys.argv[2:])
    elif cmd == "score":
        score(full=len(sys.argv) > 2 and sys.argv[2] == "full")
    elif cmd == "realism":
        realism()
    else:
        print(__doc__)
