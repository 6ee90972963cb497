//! The catalogue of effects as data: which effect ([`Kind`]) with its
//! fitted coefficients ([`EffectModel`]), as a report stores it in a
//! finding. What each effect does to a pose is [`crate::physics::effects`].

use serde::{Deserialize, Serialize};

/// What drives thermal expansion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ThermalDriver {
    /// Ambient temperature minus the first pose's (K).
    Temperature,
    /// Hours since the session began (no usable temperature).
    Time,
    /// Thousands of rows since the first (neither temperature nor time
    /// recorded: the visiting order stands in for the clock).
    Order,
}

/// What a data-driven correction ([`Kind::DataDriven`]) changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CorrectionTarget {
    /// One joint's angle (rad): the joint sits at commanded + correction.
    JointAngle,
    /// T relative to the rig (mm, rig frame; three coefficients per knot,
    /// x, y, z).
    Point,
    /// One string's reading (mm): the string reads this much more.
    StringReading,
    /// T relative to the rig in the spherical frame about the rig's origin
    /// (for point data, the measuring instrument's own: three coefficients
    /// per knot, an azimuth error (rad: T moves by its horizontal distance
    /// times it, along the azimuth), an elevation error (rad: by its
    /// distance, along the elevation) and a distance error (mm, along the
    /// line of sight). An instrument's angle encoders and range err in
    /// these directions, which turn with where T is.
    PointSpherical,
    /// One length of the model (an `a` or a `d`, mm): `target_index` is
    /// its index in the parameter vector (`5 · joint + 0` for a, `+ 2` for
    /// d). T moves as that length's change moves it. A link that grows
    /// with the temperature while the others do not (one aluminium part,
    /// one link warmed by a motor) is such a correction of one length in
    /// the temperature, where the catalogue's thermal expansion grows every
    /// length in proportion.
    LinkLength,
    /// The measuring instrument's scale (dimensionless, one coefficient
    /// per knot): the anchors spread about their centroid by it (each
    /// string reads less by its direction times its anchor's offset from
    /// the centroid, times the scale), or a tracker's points about its own
    /// origin. A string frame that grows with the temperature, a tracker's
    /// range off with the air's, is such a correction in the temperature,
    /// where the catalogue's thermal expansion grows the arm.
    InstrumentScale,
    /// The tool point in the flange frame (mm; three coefficients per
    /// knot, along the flange's x, y, z): T moves with the flange's
    /// orientation, where a correction of T relative to the rig does not
    /// turn. A probe that grows with the process's heat, a tool that slips
    /// in its holder or is re-seated is such a correction in the clock.
    ToolPoint,
    /// One string's zero (mm) and scale (mm per metre of its length), two
    /// coefficients per knot: the string reads `a + b · l / 1000` more at
    /// length `l` (mm). A scale that varies with where the string points
    /// (its exit walking along its drum's axis as it pays out, a guide
    /// that bends it more in some directions) is such a correction by the
    /// string's direction; a cable creeping under its spring's pull or a
    /// drum warming, one by the clock.
    StringZeroScale,
    /// Every string's scale at once (dimensionless, one coefficient per
    /// knot): each string reads its length times it more. Potentiometers
    /// sharing one excitation reference, encoders sharing one clock, read
    /// every length off in proportion when that reference drifts; the
    /// anchors spreading about their centroid
    /// ([`InstrumentScale`](Self::InstrumentScale)) is another geometry.
    ReadingScale,
    /// Half one joint's dead band (rad): the joint sits at commanded +
    /// the correction times the side it arrived from (+1 from below, -1
    /// from above; nothing where the recording does not say). A play that
    /// changes during the session (grease thinning as the drive warms,
    /// wear), where the catalogue's backlash is one constant play, is such
    /// a correction in the clock.
    JointPlay,
    /// The string frame's shape (dimensionless, nine coefficients per
    /// knot, a 3x3 matrix `D` row by row): each anchor moves by `D (A - c)`,
    /// `A` the anchor and `c` the anchors' centroid, so string `i` reads
    /// `u_i · D (A_i - c)` less (`u_i` its direction from its anchor). The
    /// correction is centred on the session (its mean over the poses is
    /// zero): how the frame changed during the session, not where rig.json
    /// put the anchors (that is `--rig-anchors`). A frame that racks, bows
    /// or tilts as it warms or settles moves its anchors unequally, which
    /// neither T moving relative to the rig nor the anchors spreading
    /// evenly ([`InstrumentScale`](Self::InstrumentScale), one of its
    /// shapes) can follow; with four anchors not in one plane any motion of
    /// them is such a field with a move of T. With point data the rig is
    /// the measuring instrument: T is read `D T` off (about the
    /// instrument's origin), the instrument turning, stretching or
    /// shearing its space during the session (a camera's mount or
    /// extrinsics creeping: its depth error grows with the depth).
    RigShape,
    /// The string frame deflected out of its plane by the strings' pull
    /// (mm per unit pull): a symmetric compliance `C` between the anchors,
    /// row by row its upper triangle (`m (m + 1) / 2` coefficients for `m`
    /// anchors), anchor `a` moving along the anchors' plane normal `n` by
    /// `Σ_i C[a][i] (u_i · n)`, `u_i` string `i`'s direction from its
    /// anchor to T (each string pulls its anchor towards T with about the
    /// same tension, and a frame is softest out of its plane). String `a`
    /// reads that move times `u_a · n` less. Its `knots` are the anchors'
    /// indices, 0 to the number of strings less one; its driver is
    /// `workspace` without a `driver_index` (where T is sets the pulls). A
    /// frame that bends or twists under the strings, or stands on soft
    /// legs, moves its anchors unequally and by where T is, which no
    /// function of one coordinate and no shape in time
    /// ([`RigShape`](Self::RigShape), affine in the anchors: it cannot
    /// twist four anchors in one plane) follows.
    FrameDeflection,
}

/// What drives a data-driven correction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CorrectionDriver {
    /// One joint's commanded angle (knots in rad).
    JointAngle,
    /// The session's clock (knots in s, or rows without `time_s`).
    Time,
    /// The recorded temperature (knots in degrees C).
    Temperature,
    /// One string's length (knots in mm).
    StringLength,
    /// One string's direction from its anchor: the angle between the
    /// string and its `axis` (knots in rad). Wrap over a rounded exit or
    /// eyelet grows with it; a function linear in the direction is an
    /// anchor displaced instead.
    StringDirection,
    /// Where T is in the rig's frame (for point data, the measuring
    /// instrument's own frame): `driver_index` 0, 1, 2 = its x, y, z (mm);
    /// 3 = its azimuth about the frame's z axis, 4 = its elevation above the
    /// xy-plane (rad); 5 = its distance from the frame's origin (mm). A
    /// field over the workspace (a distortion of the measuring device, a
    /// compliance of the stand) is a function of these.
    Workspace,
    /// The move of T that led to the pose, from the pose recorded before
    /// it (knots: the move's length, mm). Its correction moves T along
    /// that move (one coefficient per knot, mm): an arm not settled at the
    /// dwell overshoots or lags along its last move.
    Motion,
    /// One joint's last move: its commanded angle less the previous
    /// pose's (knots in rad; zero for the first pose). A drive that stops
    /// short by an amount graded with the move (friction, elastic wind-up),
    /// where backlash is a fixed amount by the side it arrived from, is a
    /// function of it.
    JointMove,
    /// The direction of the last move of two neighbouring joints,
    /// `driver_index` and the next: the angle of `(Δq_i, Δq_(i+1))` (knots
    /// in rad, periodic over a turn; zero for the first pose). A drive that
    /// turns both joints (a parallelogram's rod or belt driving the elbow
    /// from the turret, a coupled wrist) has its play or friction by the
    /// side its own motor last turned, the sign of a combination of the two
    /// joints' moves, which is a function of this angle; a joint's own
    /// backlash is one (the sign of its own move) too.
    MoveDirection,
    /// The change of one joint's gravity torque over the last move: its
    /// torque less the previous pose's (knots in N·m; zero for the first
    /// pose and without link masses). A drive that creeps or winds up
    /// under load (a harmonic drive's flexspline relaxing during the
    /// dwell, friction holding part of an elastic deflection) lags the
    /// change of its load, where a compliance follows the load itself.
    GravityTorqueChange,
    /// One string's last change of length: its length less at the pose
    /// recorded before (knots in mm, signed: positive pulled out; zero
    /// for the first pose). A string whose reading depends on the way it
    /// last moved (friction in its drum, stretch of its cable: pulled out
    /// against retracted) is a function of it.
    StringMove,
    /// One joint's gravity torque (knots in N·m; the robot's link masses
    /// and the payload at T): a joint whose angle error follows its load
    /// in a way no linear stiffness does (a play that gravity takes up as
    /// the load changes sign, a stiffness that hardens) is a function of
    /// it; so is a string's reading that picks up the joint's motor
    /// interference (it grows with the current holding the load).
    GravityTorque,
    /// Point data: the instrument's line of sight to T (the direction from
    /// the rig frame's origin, which is the instrument's) in the flange
    /// frame: `driver_index` 0, 1, 2 = its component along the flange's x,
    /// y, z axis (a cosine, -1 to 1). A target read off its centre by an
    /// amount that turns with the target (a reflector's vertex off its
    /// sphere's centre; a photogrammetric target's centroid shifting with
    /// the angle it is seen at) reads the range, or the point, off by a
    /// function of it. An error of the measurement, not of the robot.
    LineOfSight,
}

/// Number of workspace coordinates a [`CorrectionDriver::Workspace`]
/// indexes (x, y, z, azimuth, elevation, distance).
pub const WORKSPACE_COORDINATES: usize = 6;

impl CorrectionDriver {
    /// True when the driver is known for a future target: a joint angle
    /// is (the target's own); the session's clock and temperature history
    /// describe this session, not the next, and a string's length exists
    /// only with the rig mounted. Where T is in the workspace is known for
    /// a target too (the target itself, in the rig's frame); the move that
    /// leads to it, of T or of a joint, depends on the program that visits
    /// it; the line of sight is the measuring instrument's.
    pub fn usable_for_compensation(self) -> bool {
        matches!(
            self,
            CorrectionDriver::JointAngle | CorrectionDriver::Workspace
        )
    }
}

/// One effect of the catalogue. Joint and sensor indices are 0-based here
/// (reports and files use 1-based numbers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Kind {
    /// Joint `joint_index` deflects in proportion to the gravity torque on
    /// it, the payload hanging at T included (`payload_kg`). With link
    /// masses: one coefficient (rad/(N·m)). Without: one coefficient per
    /// regressor, a unit mass at the origin of link frame `regressors[r]`
    /// (index n = the tool point, n + 1 = the payload at the tool point:
    /// the tool's lever times `payload_kg`), coefficient in rad/m.
    JointCompliance {
        /// 0-based joint.
        joint_index: usize,
        /// Empty when the robot's link masses are used; else the link
        /// frames (0-based, n = tool point, n + 1 = payload) carrying the
        /// unit masses.
        #[serde(default)]
        regressors: Vec<usize>,
    },
    /// Half the dead band of joint `joint_index`: `dq = b · sign(last move)`
    /// (coefficient 0). The recording does not say how the joint arrived
    /// at the poses before its first move: there `dq` is a free offset
    /// (coefficient 1), so that an unknown approach neither biases `b` nor
    /// leaves a residual for another effect to explain. Compensation knows
    /// the approach and uses `b` alone.
    Backlash {
        /// 0-based joint.
        joint_index: usize,
    },
    /// `dq = s sin(h q) + c cos(h q)` of joint `joint_index`.
    JointPeriodic {
        /// 0-based joint.
        joint_index: usize,
        /// Harmonic h (1 = once per revolution).
        harmonic: u32,
    },
    /// `dq = s · q` of joint `joint_index`: the joint turns by a slightly
    /// different angle than commanded, in proportion to the angle from its
    /// zero (a gear-ratio or encoder-scale error).
    JointScale {
        /// 0-based joint.
        joint_index: usize,
    },
    /// Every nominal a and d scales by `1 + k · driver`. Driven by time or
    /// row order with `tau_h`, by the warm-up curve `tau_h · (1 - exp(-h /
    /// tau_h))` of the driver `h` (hours, or thousands of rows, since the
    /// first pose) instead: settling towards a steady temperature with that
    /// time constant, in the driver's unit; `k` is then the initial rate.
    ThermalExpansion {
        /// Temperature, time or row order.
        driver: ThermalDriver,
        /// Time constant of a warm-up that settles (h, or thousands of rows
        /// with [`ThermalDriver::Order`]); none: linear.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tau_h: Option<f64>,
    },
    /// String `sensor_index` reads `s · l` too long.
    SensorScale {
        /// 0-based sensor.
        sensor_index: usize,
    },
    /// String `sensor_index` reads `o` too long.
    SensorOffset {
        /// 0-based sensor.
        sensor_index: usize,
    },
    /// String `sensor_index` reads `v · h` too long, `h` the hours since
    /// the first pose (thousands of rows without a recorded clock): its
    /// zero creeps during the session.
    SensorDrift {
        /// 0-based sensor.
        sensor_index: usize,
    },
    /// Every string hangs under its own weight and reads longer than the
    /// chord by `c · h² · d` (h horizontal span, d length, in m; c in mm/m³).
    CableSag,
    /// The robot's mount (pedestal, floor, stand) tilts about the base
    /// origin by `c` (rad/(N·m)) times the gravity moment of the arm and
    /// the payload about it, a vector in the horizontal plane: T moves by
    /// that rotation about the base origin. Needs link masses.
    BaseTilt,
    /// The tool (its adapter, quick changer or holder) tilts about the
    /// flange origin by `c` (rad/(N·m)) times the gravity moment of the
    /// payload at T about the flange origin: T droops by that rotation of
    /// its lever from the flange. Known only where poses carry a payload
    /// (`payload_kg`); the tool's own weight is not modelled (robot.json
    /// does not give it).
    ToolCompliance,
    /// The link between joint `link_index`'s axis and the next joint's
    /// (0-based: 1 is the upper arm of a six-axis arm) bends as a
    /// cantilever from the first axis under the weight it carries: its
    /// own, spread along it, and at its end the outboard links' and the
    /// payload's, as a force and a moment (the components across the
    /// link; its twist is not modelled). The end moves and turns by
    /// Euler-Bernoulli's tip deflections times the coefficient `1/EI`
    /// (1/(N·m²)), and T with it. Needs link masses.
    LinkBending {
        /// 0-based joint at the link's fixed end.
        link_index: usize,
    },
    /// Anchor `sensor_index` moved by a vector (mm, rig frame) at `t0_s`.
    AnchorStep {
        /// 0-based sensor.
        sensor_index: usize,
        /// Time of the move (s); poses with `time_s > t0_s` see it.
        t0_s: f64,
    },
    /// The whole rig (every anchor, or the tracker) moved rigidly relative
    /// to the robot base at `t0_s`: a translation (mm, 3 coefficients) and
    /// a small rotation (mrad, 3) about the centre of the measured points.
    RigStep {
        /// Time of the move (s); poses with `time_s > t0_s` see it.
        t0_s: f64,
    },
    /// The rig creeps steadily relative to the robot base: a translation
    /// rate (mm/h, 3 coefficients) and a rotation rate (mrad/h, 3) about the
    /// centre of the measured points, times the hours since the first pose.
    RigDrift,
    /// Not a named physics: a data-driven correction of structure the
    /// catalogue left unexplained, a piecewise-linear function of its
    /// driver between `knots` (one coefficient per knot, three for a point
    /// target), held constant beyond the end knots; or, with a `period`,
    /// a periodic one (the driver taken modulo the period, `knots` within
    /// one period and the last joined to the first). Fitted only where the
    /// analysis located unexplained structure, its number of knots (and
    /// period) chosen by cross-validation on the train poses.
    DataDriven {
        /// What it corrects.
        target: CorrectionTarget,
        /// The joint or string it corrects (0-based; none for a point).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        target_index: Option<usize>,
        /// What it is a function of.
        driver: CorrectionDriver,
        /// The joint or string whose angle or length drives it (0-based).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        driver_index: Option<usize>,
        /// Knots in the driver's unit (rad, s, degrees C, mm), increasing.
        knots: Vec<f64>,
        /// The period in the driver's unit, for a periodic correction
        /// (then every knot lies in `[0, period)`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        period: Option<f64>,
        /// The range of the driver the train poses covered, for a periodic
        /// correction (its knots span one period, not the range).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        range: Option<[f64; 2]>,
        /// The unit vector (rig frame) a string's direction is measured
        /// from, for [`CorrectionDriver::StringDirection`]: the string's
        /// mean direction over the train poses.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        axis: Option<[f64; 3]>,
    },
}

impl Kind {
    /// Catalogue name as in reports and truth.json.
    pub fn name(&self) -> &'static str {
        match self {
            Kind::JointCompliance { .. } => "joint_compliance",
            Kind::Backlash { .. } => "backlash",
            Kind::JointPeriodic { .. } => "joint_periodic",
            Kind::JointScale { .. } => "joint_scale",
            Kind::ThermalExpansion { .. } => "thermal_expansion",
            Kind::SensorScale { .. } => "sensor_scale",
            Kind::SensorOffset { .. } => "sensor_offset",
            Kind::SensorDrift { .. } => "sensor_drift",
            Kind::CableSag => "cable_sag",
            Kind::BaseTilt => "base_tilt",
            Kind::ToolCompliance => "tool_compliance",
            Kind::LinkBending { .. } => "link_bending",
            Kind::AnchorStep { .. } => "anchor_step",
            Kind::RigStep { .. } => "rig_step",
            Kind::RigDrift => "rig_drift",
            Kind::DataDriven { .. } => "data_driven",
        }
    }

    /// 0-based joint, where it applies.
    pub fn joint(&self) -> Option<usize> {
        match self {
            Kind::JointCompliance { joint_index, .. }
            | Kind::Backlash { joint_index }
            | Kind::JointPeriodic { joint_index, .. }
            | Kind::JointScale { joint_index } => Some(*joint_index),
            Kind::DataDriven {
                target: CorrectionTarget::JointAngle,
                target_index,
                ..
            } => *target_index,
            _ => None,
        }
    }

    /// 0-based joint where the effect acts, as a finding places it: a
    /// joint effect's own joint, or the joint at a bending link's root
    /// (the bending turns what follows by the load that joint carries, as
    /// its compliance does). [`Kind::joint`] is the joint whose angle the
    /// effect changes; a bending link changes none.
    pub fn acting_joint(&self) -> Option<usize> {
        match self {
            Kind::LinkBending { link_index } => Some(*link_index),
            k => k.joint(),
        }
    }

    /// 0-based sensor, where it applies.
    pub fn sensor(&self) -> Option<usize> {
        match self {
            Kind::SensorScale { sensor_index }
            | Kind::SensorOffset { sensor_index }
            | Kind::SensorDrift { sensor_index }
            | Kind::AnchorStep { sensor_index, .. } => Some(*sensor_index),
            Kind::DataDriven {
                target: CorrectionTarget::StringReading | CorrectionTarget::StringZeroScale,
                target_index,
                ..
            } => *target_index,
            _ => None,
        }
    }

    /// True when the effect moves T relative to the rig (the robot, or
    /// the whole rig relative to the robot), false when it changes what one
    /// string reads.
    pub fn robot_side(&self) -> bool {
        matches!(
            self,
            Kind::JointCompliance { .. }
                | Kind::Backlash { .. }
                | Kind::JointPeriodic { .. }
                | Kind::JointScale { .. }
                | Kind::ThermalExpansion { .. }
                | Kind::RigStep { .. }
                | Kind::RigDrift
                | Kind::BaseTilt
                | Kind::ToolCompliance
                | Kind::LinkBending { .. }
                | Kind::DataDriven {
                    target: CorrectionTarget::JointAngle
                        | CorrectionTarget::Point
                        | CorrectionTarget::PointSpherical
                        | CorrectionTarget::LinkLength
                        | CorrectionTarget::ToolPoint,
                    ..
                }
        )
    }

    /// The string frame's deflection ([`CorrectionTarget::FrameDeflection`])
    /// of a rig of `n_anchors` anchors, every one of them in the frame.
    pub fn frame_deflection(n_anchors: usize) -> Kind {
        Kind::DataDriven {
            target: CorrectionTarget::FrameDeflection,
            target_index: None,
            driver: CorrectionDriver::Workspace,
            driver_index: None,
            knots: (0..n_anchors).map(|a| a as f64).collect(),
            period: None,
            range: None,
            axis: None,
        }
    }

    /// True for a data-driven correction (not a named physics).
    pub fn is_data_driven(&self) -> bool {
        matches!(self, Kind::DataDriven { .. })
    }

    /// The range of its driver a data-driven correction was fitted on:
    /// beyond it no pose supports it.
    pub fn fitted_range(&self) -> Option<(f64, f64)> {
        match self {
            Kind::DataDriven {
                range: Some([lo, hi]),
                ..
            } => Some((*lo, *hi)),
            Kind::DataDriven { knots, .. } => Some((*knots.first()?, *knots.last()?)),
            _ => None,
        }
    }

    /// What a data-driven correction does beyond [`Kind::fitted_range`],
    /// in words.
    pub fn beyond_range(&self) -> &'static str {
        match self {
            Kind::DataDriven {
                period: Some(_), ..
            } => "it is continued periodically there",
            _ => "it is held at its end value there",
        }
    }

    /// Time of a change point, for effects that have one.
    pub fn change_time_s(&self) -> Option<f64> {
        match self {
            Kind::AnchorStep { t0_s, .. } | Kind::RigStep { t0_s } => Some(*t0_s),
            _ => None,
        }
    }

    /// The same effect with its change point moved to `t0_s` (unchanged
    /// for effects without one).
    pub fn with_change_time(&self, t0_s: f64) -> Kind {
        match self {
            Kind::AnchorStep { sensor_index, .. } => Kind::AnchorStep {
                sensor_index: *sensor_index,
                t0_s,
            },
            Kind::RigStep { .. } => Kind::RigStep { t0_s },
            other => other.clone(),
        }
    }

    /// Number of coefficients.
    pub fn n_coef(&self) -> usize {
        match self {
            Kind::JointCompliance { regressors, .. } => regressors.len().max(1),
            Kind::JointPeriodic { .. } | Kind::Backlash { .. } => 2,
            Kind::AnchorStep { .. } => 3,
            Kind::RigStep { .. } | Kind::RigDrift => 6,
            Kind::DataDriven {
                driver: CorrectionDriver::Motion,
                knots,
                ..
            } => knots.len(),
            Kind::DataDriven {
                target:
                    CorrectionTarget::Point
                    | CorrectionTarget::PointSpherical
                    | CorrectionTarget::ToolPoint,
                knots,
                ..
            } => 3 * knots.len(),
            Kind::DataDriven {
                target: CorrectionTarget::StringZeroScale,
                knots,
                ..
            } => 2 * knots.len(),
            Kind::DataDriven {
                target: CorrectionTarget::RigShape,
                knots,
                ..
            } => 9 * knots.len(),
            Kind::DataDriven {
                target: CorrectionTarget::FrameDeflection,
                knots,
                ..
            } => knots.len() * (knots.len() + 1) / 2,
            Kind::DataDriven { knots, .. } => knots.len(),
            _ => 1,
        }
    }
}

/// An effect with its coefficients (internal units: rad, mm, dimensionless).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectModel {
    /// Which effect.
    #[serde(flatten)]
    pub kind: Kind,
    /// Coefficients, `kind.n_coef()` of them.
    pub coef: Vec<f64>,
}

impl EffectModel {
    /// True when a payload at T changes this effect's offsets on a robot of
    /// `n_joints` joints: a compliance with link masses (the payload adds
    /// its torque), or without masses one whose session varied the payload
    /// (so that its lever was fitted); a base tilt, a bending link (the
    /// payload adds its moment, its weight); a compliant tool (the payload
    /// is its load).
    pub fn payload_matters(&self, n_joints: usize) -> bool {
        let payload_regressor = n_joints + 1;
        match &self.kind {
            Kind::JointCompliance { regressors, .. } => {
                regressors.is_empty()
                    || regressors
                        .iter()
                        .zip(&self.coef)
                        .any(|(&r, &c)| r == payload_regressor && c != 0.0)
            }
            // The payload adds its moment about the base, or is the load
            // the tool gives under.
            Kind::BaseTilt | Kind::ToolCompliance | Kind::LinkBending { .. } => true,
            _ => false,
        }
    }

    /// Check an effect read from a report against the robot it belongs to
    /// (`n_joints` joints, link masses or not): its joint among them, a
    /// compliance in the form the robot's masses give (one coefficient with
    /// masses, unit-mass regressors among the link frames, the tool and the
    /// payload without), as many finite coefficients as the effect has.
    /// What is wrong, for a human.
    pub fn check(&self, n_joints: usize, has_masses: bool) -> std::result::Result<(), String> {
        if let Some(j) = self.kind.joint() {
            if j >= n_joints {
                return Err(format!(
                    "joint_index {j} (0-based) but the robot has {n_joints} joints"
                ));
            }
        }
        if self.kind == Kind::BaseTilt && !has_masses {
            return Err("a base tilt is driven by the arm's gravity moment, which needs link masses, but the robot has none".into());
        }
        if let Kind::LinkBending { link_index } = self.kind {
            if !has_masses {
                return Err("a link bends under the weight it carries, which needs link masses, but the robot has none".into());
            }
            if link_index + 1 >= n_joints {
                return Err(format!(
                    "link_index {link_index} (0-based): a bending link runs from one joint's axis to the next, and the robot has {n_joints} joints"
                ));
            }
        }
        if let Kind::JointCompliance { regressors, .. } = &self.kind {
            if regressors.is_empty() != has_masses {
                return Err(if has_masses {
                    "a compliance fitted with unit-mass regressors, but the robot has link masses"
                        .into()
                } else {
                    "a compliance fitted with link masses, but the robot has none".into()
                });
            }
            if let Some(r) = regressors.iter().find(|&&r| r > n_joints + 1) {
                return Err(format!(
                    "regressor {r}: link frames are 0..{n_joints}, the tool {n_joints}, the payload {}",
                    n_joints + 1
                ));
            }
        }
        if let Kind::DataDriven { .. } = &self.kind {
            check_correction(&self.kind)?;
        }
        if self.coef.len() != self.kind.n_coef() {
            return Err(format!(
                "{} coefficients for {}, which has {}",
                self.coef.len(),
                self.kind.name(),
                self.kind.n_coef()
            ));
        }
        if self.coef.iter().any(|c| !c.is_finite()) {
            return Err("a coefficient is not a finite number".into());
        }
        Ok(())
    }

    /// The effect with every coefficient zero (a candidate before its fit).
    pub fn zero(kind: Kind) -> Self {
        EffectModel {
            coef: vec![0.0; kind.n_coef()],
            kind,
        }
    }
}

/// The rules of a data-driven correction ([`Kind::DataDriven`]; other
/// kinds pass): knots, period and range well formed, the driver's index
/// or axis where it needs one, and each target with the drivers it
/// follows. What is wrong, for a human.
fn check_correction(kind: &Kind) -> std::result::Result<(), String> {
    let Kind::DataDriven {
        target,
        target_index,
        driver,
        driver_index,
        knots,
        period,
        range,
        axis,
    } = kind
    else {
        return Ok(());
    };
    check_knots(*driver, knots, *period, *range, axis.as_ref())?;
    if *target == CorrectionTarget::FrameDeflection
        && (period.is_some() || knots.iter().enumerate().any(|(a, &k)| k != a as f64))
    {
        return Err(
                "a frame's deflection lists the anchors as its knots: 0, 1, ... up to the number of strings less one, and has no period"
                    .into(),
            );
    }
    check_driver(*target, *target_index, *driver, *driver_index)?;
    check_target(*target, *target_index, *driver, *driver_index)
}

/// A correction's function: its knots, period, range and (a string's
/// direction only) axis.
fn check_knots(
    driver: CorrectionDriver,
    knots: &[f64],
    period: Option<f64>,
    range: Option<[f64; 2]>,
    axis: Option<&[f64; 3]>,
) -> std::result::Result<(), String> {
    if (driver == CorrectionDriver::StringDirection) != axis.is_some()
        || axis.is_some_and(|a| {
            !(a.iter().all(|c| c.is_finite())
                && (a.iter().map(|c| c * c).sum::<f64>().sqrt() - 1.0).abs() < 1e-6)
        })
    {
        return Err(
                "a correction by a string's direction needs its axis (a unit vector), and only it has one"
                    .into(),
            );
    }
    if range.is_some_and(|[lo, hi]| !(lo.is_finite() && hi.is_finite() && lo <= hi)) {
        return Err("a data-driven correction's range must be two finite, ordered values".into());
    }
    if knots.len() < 2
        || knots.iter().any(|k| !k.is_finite())
        || knots.windows(2).any(|w| w[1] <= w[0])
    {
        return Err("a data-driven correction needs two or more finite, increasing knots".into());
    }
    if let Some(p) = period
        && !(p.is_finite() && p > 0.0 && knots[0] >= 0.0 && knots[knots.len() - 1] < p)
    {
        return Err(
            "a periodic correction needs a finite, positive period and its knots within one period"
                .into(),
        );
    }
    Ok(())
}

/// A frame's deflection by where T is: linear in all three of T's
/// coordinates (no `driver_index`), of every anchor at once (no
/// `target_index`).
fn check_frame_deflection(
    target_index: Option<usize>,
    driver: CorrectionDriver,
    driver_index: Option<usize>,
) -> std::result::Result<(), String> {
    if target_index.is_some() || driver != CorrectionDriver::Workspace || driver_index.is_some() {
        return Err(
                "a frame's deflection moves every anchor by the strings' pull, which where T is sets: its driver is workspace, with no driver_index and no target_index"
                    .into(),
            );
    }
    Ok(())
}

/// What each driver may correct, and which of its values it needs.
fn check_driver(
    target: CorrectionTarget,
    target_index: Option<usize>,
    driver: CorrectionDriver,
    driver_index: Option<usize>,
) -> std::result::Result<(), String> {
    if target == CorrectionTarget::FrameDeflection {
        return check_frame_deflection(target_index, driver, driver_index);
    }
    if driver == CorrectionDriver::Workspace
        && driver_index.is_none_or(|d| d >= WORKSPACE_COORDINATES)
    {
        return Err(format!(
            "a correction over the workspace needs a driver_index from 0 to {}",
            WORKSPACE_COORDINATES - 1
        ));
    }
    if driver == CorrectionDriver::JointMove && target != CorrectionTarget::JointAngle {
        return Err(
                "a correction by a joint's last move corrects a joint's angle: its target must be joint_angle"
                    .into(),
            );
    }
    if driver == CorrectionDriver::MoveDirection
        && (target != CorrectionTarget::JointAngle
            || !matches!((target_index, driver_index), (Some(t), Some(d)) if t == d || t == d + 1))
    {
        return Err(
                "a correction by the direction of two joints' last move corrects one of them: its target must be joint_angle with target_index equal to driver_index or the next"
                    .into(),
            );
    }
    if driver == CorrectionDriver::StringMove
        && (target != CorrectionTarget::StringReading || driver_index != target_index)
    {
        return Err(
                "a correction by a string's last change corrects that string's reading: its target must be string_reading with target_index equal to driver_index"
                    .into(),
            );
    }
    if driver == CorrectionDriver::GravityTorque
        && !matches!(
            target,
            CorrectionTarget::JointAngle | CorrectionTarget::StringReading
        )
    {
        return Err(
                "a correction by a joint's gravity torque corrects a joint's angle or a string's reading: its target must be joint_angle or string_reading"
                    .into(),
            );
    }
    if driver == CorrectionDriver::GravityTorqueChange
        && (target != CorrectionTarget::JointAngle
            || driver_index.is_none()
            || target_index != driver_index)
    {
        return Err(
                "a correction by the change of a joint's gravity torque corrects that joint's angle: its target must be joint_angle with target_index equal to driver_index"
                    .into(),
            );
    }
    if matches!(
        driver,
        CorrectionDriver::GravityTorque
            | CorrectionDriver::JointMove
            | CorrectionDriver::JointAngle
    ) && driver_index.is_none()
    {
        return Err("a correction by a joint's angle, move or load needs its driver_index".into());
    }
    if driver == CorrectionDriver::Motion && target != CorrectionTarget::Point {
        return Err("a correction by the motion moves T: its target must be point".into());
    }
    if driver == CorrectionDriver::LineOfSight
        && (target != CorrectionTarget::PointSpherical || driver_index.is_none_or(|d| d > 2))
    {
        return Err(
                "a correction by the line of sight corrects the point in the instrument's spherical frame (target point_spherical) by one of its components in the flange frame (driver_index 0, 1 or 2)"
                    .into(),
            );
    }
    Ok(())
}

/// What drives each target, and which targets name a joint or a string.
fn check_target(
    target: CorrectionTarget,
    target_index: Option<usize>,
    driver: CorrectionDriver,
    driver_index: Option<usize>,
) -> std::result::Result<(), String> {
    if target == CorrectionTarget::StringZeroScale
        && !match driver {
            CorrectionDriver::StringDirection => driver_index == target_index,
            CorrectionDriver::Time => driver_index.is_none(),
            _ => false,
        }
    {
        return Err(
                "a correction of a string's zero and scale follows that string's direction (driver string_direction with driver_index equal to target_index) or the clock (driver time)"
                    .into(),
            );
    }
    if matches!(
        target,
        CorrectionTarget::InstrumentScale | CorrectionTarget::ReadingScale
    ) && (target_index.is_some()
        || !matches!(
            driver,
            CorrectionDriver::Time | CorrectionDriver::Temperature
        ))
    {
        return Err(
                "a correction of the instrument's scale has no target_index and follows the clock or the temperature"
                    .into(),
            );
    }
    if target == CorrectionTarget::PointSpherical
        && !matches!(
            driver,
            CorrectionDriver::Workspace | CorrectionDriver::LineOfSight
        )
    {
        return Err(
                "a correction in the spherical frame is a field over the workspace or a function of the line of sight: its driver must be workspace or line_of_sight"
                    .into(),
            );
    }
    if target == CorrectionTarget::ToolPoint
        && (target_index.is_some()
            || !matches!(
                driver,
                CorrectionDriver::Time | CorrectionDriver::Temperature
            ))
    {
        return Err(
                "a correction of the tool point has no target_index and follows the clock or the temperature"
                    .into(),
            );
    }
    if target == CorrectionTarget::RigShape
        && (target_index.is_some()
            || !matches!(
                driver,
                CorrectionDriver::Time | CorrectionDriver::Temperature
            ))
    {
        return Err(
                "a correction of the rig's shape has no target_index and follows the clock or the temperature"
                    .into(),
            );
    }
    if target == CorrectionTarget::JointPlay
        && !matches!(
            driver,
            CorrectionDriver::Time | CorrectionDriver::Temperature
        )
    {
        return Err(
                "a correction of a joint's play follows the clock or the temperature (a play that changes as the drive warms or wears): its driver must be time or temperature"
                    .into(),
            );
    }
    if !matches!(
        target,
        CorrectionTarget::Point
            | CorrectionTarget::PointSpherical
            | CorrectionTarget::InstrumentScale
            | CorrectionTarget::ReadingScale
            | CorrectionTarget::ToolPoint
            | CorrectionTarget::RigShape
            | CorrectionTarget::FrameDeflection
    ) && target_index.is_none()
    {
        return Err("a data-driven correction of a joint or string needs its target_index".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn correction(
        target: CorrectionTarget,
        driver: CorrectionDriver,
        driver_index: Option<usize>,
        knots: Vec<f64>,
    ) -> Kind {
        Kind::DataDriven {
            target,
            target_index: None,
            driver,
            driver_index,
            knots,
            period: None,
            range: None,
            axis: None,
        }
    }

    #[test]
    fn a_correction_by_the_line_of_sight_corrects_the_point_in_the_instruments_frame() {
        let ok = |k: &Kind| check_correction(k);
        let sight = |target, index| {
            correction(
                target,
                CorrectionDriver::LineOfSight,
                index,
                vec![-1.0, 0.0, 1.0],
            )
        };
        assert_eq!(
            ok(&sight(CorrectionTarget::PointSpherical, Some(2))),
            Ok(())
        );
        // Its components are the flange's x, y and z.
        assert!(ok(&sight(CorrectionTarget::PointSpherical, Some(3))).is_err());
        assert!(ok(&sight(CorrectionTarget::PointSpherical, None)).is_err());
        // Only the point in the instrument's directions.
        assert!(ok(&sight(CorrectionTarget::Point, Some(0))).is_err());
        // And the spherical frame takes the workspace or the line of sight.
        let by_time = correction(
            CorrectionTarget::PointSpherical,
            CorrectionDriver::Time,
            None,
            vec![0.0, 10.0],
        );
        assert!(ok(&by_time).unwrap_err().contains("line_of_sight"));
        // Knots increase.
        let flat = correction(
            CorrectionTarget::PointSpherical,
            CorrectionDriver::LineOfSight,
            Some(0),
            vec![0.5, 0.5],
        );
        assert!(ok(&flat).unwrap_err().contains("increasing knots"));
    }

    #[test]
    fn a_correction_by_two_joints_move_direction_corrects_one_of_them() {
        let by_moves = |target, target_index, driver_index| Kind::DataDriven {
            target,
            target_index,
            driver: CorrectionDriver::MoveDirection,
            driver_index,
            knots: vec![0.0, 1.0, 2.0, 3.0],
            period: Some(std::f64::consts::TAU),
            range: None,
            axis: None,
        };
        let joint = CorrectionTarget::JointAngle;
        assert_eq!(check_correction(&by_moves(joint, Some(1), Some(1))), Ok(()));
        assert_eq!(check_correction(&by_moves(joint, Some(2), Some(1))), Ok(()));
        // Not a joint outside the pair, not a string.
        assert!(check_correction(&by_moves(joint, Some(3), Some(1))).is_err());
        assert!(check_correction(&by_moves(joint, Some(1), None)).is_err());
        let string = CorrectionTarget::StringReading;
        assert!(check_correction(&by_moves(string, Some(1), Some(1))).is_err());
    }

    #[test]
    fn a_joints_play_follows_the_clock_or_the_temperature() {
        let play = |target_index, driver| Kind::DataDriven {
            target: CorrectionTarget::JointPlay,
            target_index,
            driver,
            driver_index: None,
            knots: vec![0.0, 600.0, 1200.0],
            period: None,
            range: None,
            axis: None,
        };
        assert_eq!(
            check_correction(&play(Some(1), CorrectionDriver::Time)),
            Ok(())
        );
        assert_eq!(
            check_correction(&play(Some(1), CorrectionDriver::Temperature)),
            Ok(())
        );
        // Its joint is needed; a play by a string's length is no physics.
        assert!(check_correction(&play(None, CorrectionDriver::Time)).is_err());
        let err = check_correction(&play(Some(1), CorrectionDriver::StringLength)).unwrap_err();
        assert!(err.contains("time or temperature"), "{err}");
    }

    #[test]
    fn compensation_uses_a_correction_only_where_a_target_knows_its_driver() {
        assert!(CorrectionDriver::JointAngle.usable_for_compensation());
        assert!(CorrectionDriver::Workspace.usable_for_compensation());
        for d in [
            CorrectionDriver::Time,
            CorrectionDriver::Temperature,
            CorrectionDriver::LineOfSight,
            CorrectionDriver::JointMove,
            CorrectionDriver::MoveDirection,
            CorrectionDriver::GravityTorqueChange,
        ] {
            assert!(!d.usable_for_compensation(), "{d:?}");
        }
    }
}
