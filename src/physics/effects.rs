//! The catalogue of physical effects a kinematic model leaves out.
//!
//! Every effect is linear in its own coefficients once the pose context is
//! known (commanded angles, approach direction, time, temperature, string
//! lengths, the point's position). At a pose, coefficient `c` of an effect
//! contributes
//! - a change of the joint angles `dq` (enters T through the analytic
//!   Jacobian: dT/dq_j is the θ_j column),
//! - a change of the link lengths (thermal expansion: a multiple of the
//!   nominal a and d values),
//! - a change of each string reading `dl`,
//! - a displacement of T relative to the rig `dp` (the rig, i.e. the
//!   anchors or the tracker, moved relative to the robot base).
//!
//! The same [`Context::basis`] serves the simulator (evaluated with the true
//! point and true lengths) and the identification (with the located point
//! and the measured readings), so the model fitted is exactly the model
//! simulated.

use nalgebra::Vector3;

use crate::kinematics::chain::{Chain, OutputFrame};
use crate::kinematics::{JointParam, Params};
use crate::model::Robot;
pub use crate::report::effect::{
    CorrectionDriver, CorrectionTarget, EffectModel, Kind, ThermalDriver, WORKSPACE_COORDINATES,
};

impl Kind {
    /// The physics in one sentence (`ctx` words a change point in seconds
    /// or, without a recorded clock, in rows).
    pub fn explanation(&self, ctx: &Context) -> String {
        match self {
            Kind::JointCompliance { joint_index, .. } => format!(
                "joint {} deflects in proportion to the gravity torque on it, like an elastic gearbox carrying the arm's own weight",
                joint_index + 1
            ),
            Kind::Backlash { joint_index } => format!(
                "joint {} stops short or long by a fixed amount depending on the direction it last moved (gear backlash / dead band)",
                joint_index + 1
            ),
            Kind::JointPeriodic {
                joint_index,
                harmonic,
            } => format!(
                "the angle of joint {} is off by a sinusoid repeating {} time(s) per revolution (gear or encoder eccentricity)",
                joint_index + 1,
                harmonic
            ),
            Kind::JointScale { joint_index } => format!(
                "joint {} turns by a slightly different angle than commanded, in proportion to the angle (gear-ratio or encoder-scale error)",
                joint_index + 1
            ),
            Kind::ThermalExpansion { driver, tau_h } => match (driver, tau_h) {
                (ThermalDriver::Temperature, _) => {
                    "the links grow with the ambient temperature (thermal expansion of the arm)".into()
                }
                (ThermalDriver::Time, None) => {
                    "the links grow steadily during the session (warm-up; no temperature recorded, time used instead)".into()
                }
                (ThermalDriver::Time, Some(tau)) => format!(
                    "the links grow during the session and settle, like an arm warming up towards a steady temperature with a time constant of about {tau:.2} h (no temperature recorded, time used instead)"
                ),
                (ThermalDriver::Order, None) => {
                    "the links grow steadily through the session (warm-up; neither time nor temperature recorded, the row order stands in for the clock)".into()
                }
                (ThermalDriver::Order, Some(tau)) => format!(
                    "the links grow during the session and settle, like an arm warming up towards a steady temperature, over about {:.0} rows (neither time nor temperature recorded, the row order stands in for the clock)",
                    tau * 1000.0
                ),
            },
            Kind::SensorScale { sensor_index } => format!(
                "string {} reads long or short in proportion to its length (scale error of the encoder drum)",
                sensor_index + 1
            ),
            Kind::SensorOffset { sensor_index } => format!(
                "string {} reads long or short by a constant (zero offset of the sensor)",
                sensor_index + 1
            ),
            Kind::SensorDrift { sensor_index } => format!(
                "the zero of string {} creeps steadily during the session (the encoder or its electronics drifting as they warm up)",
                sensor_index + 1
            ),
            Kind::LinkBending { link_index } => format!(
                "the link from joint {} to joint {} bends under the weight it carries (its own, the outboard links' and the payload's), like a cantilever, so its end and everything beyond it are displaced and turned, more the further the load reaches out across it",
                link_index + 1,
                link_index + 2
            ),
            Kind::ToolCompliance => {
                "the tool (its adapter, quick changer or holder) tilts about the flange under the gravity moment of the payload it carries, so T droops more the heavier the payload and the more its lever from the flange lies across gravity".into()
            }
            Kind::BaseTilt => {
                "the robot's mount (pedestal, floor or stand) tilts under the gravity moment of the arm and its payload about the base, so T moves as if the whole robot leaned, more the further the arm reaches out".into()
            }
            Kind::CableSag => {
                "the strings hang under their own weight and read longer than the straight distance, more so the longer their horizontal span (catenary)".into()
            }
            Kind::AnchorStep { sensor_index, t0_s } => format!(
                "the anchor of string {} moved during the session, {}",
                sensor_index + 1,
                ctx.when(*t0_s)
            ),
            Kind::RigStep { t0_s } => format!(
                "the whole measuring rig (anchors or tracker) moved relative to the robot base {}, e.g. knocked or re-set up",
                ctx.when(*t0_s)
            ),
            Kind::RigDrift => {
                "the measuring rig (anchors or tracker) crept steadily relative to the robot base during the session (a settling stand, a floor or a tracker drifting)".into()
            }
            Kind::DataDriven {
                target: CorrectionTarget::FrameDeflection,
                ..
            } => format!(
                "not a named physics: a data-driven correction of {} (a symmetric compliance between the anchors), fitted where the analysis located structure the catalogue does not explain",
                correction_target_words(CorrectionTarget::FrameDeflection, None, false),
            ),
            Kind::DataDriven {
                target,
                target_index,
                driver,
                driver_index,
                knots,
                period,
                ..
            } => format!(
                "not a named physics: a data-driven correction of {} as a {} function of {} ({} knots{}, chosen by cross-validation), fitted where the analysis located structure the catalogue does not explain",
                correction_target_words(*target, *target_index, ctx.anchors.is_empty()),
                if period.is_some() { "periodic" } else { "smooth" },
                correction_driver_words(*driver, *driver_index),
                knots.len(),
                period.map_or(String::new(), |p| format!(
                    " per period of {}",
                    correction_driver_amount(*driver, *driver_index, p)
                )),
            ),
        }
    }
}

/// The unit normal of the plane that best fits `anchors` (the direction
/// in which they spread least about their centroid).
pub fn plane_normal(anchors: &[Vector3<f64>]) -> Vector3<f64> {
    let c = anchors.iter().sum::<Vector3<f64>>() / anchors.len().max(1) as f64;
    let cov = anchors.iter().fold(nalgebra::Matrix3::zeros(), |acc, a| {
        acc + (a - c) * (a - c).transpose()
    });
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imin();
    eig.eigenvectors.column(k).into_owned()
}

/// How much more a string from `anchor` to `point` reads per unit of the
/// rig's scale about `centroid` (the anchors moved to centroid + (1 + s) ·
/// (anchor - centroid)), to first order: the string shortens by its
/// direction times the anchor's outward move.
pub fn reading_per_scale(
    point: &Vector3<f64>,
    anchor: &Vector3<f64>,
    centroid: &Vector3<f64>,
) -> f64 {
    let u = (point - anchor).try_normalize(0.0).unwrap_or_default();
    -u.dot(&(anchor - centroid))
}

/// What a data-driven correction corrects, in words.
/// (`point_data`: the session measured points, so the rig is the
/// measuring instrument).
pub fn correction_target_words(
    target: CorrectionTarget,
    index: Option<usize>,
    point_data: bool,
) -> String {
    let at = index.map_or(0, |i| i + 1);
    match target {
        CorrectionTarget::JointAngle => format!("joint {at}'s angle"),
        CorrectionTarget::JointPlay => format!("joint {at}'s play (half its dead band, by the side it arrived from)"),
        CorrectionTarget::Point => "the position of T relative to the rig".into(),
        CorrectionTarget::PointSpherical => {
            "the position of T in the spherical frame about the rig's origin (azimuth, elevation, distance)".into()
        }
        CorrectionTarget::StringReading => format!("string {at}'s reading"),
        CorrectionTarget::StringZeroScale => format!("string {at}'s zero and scale"),
        CorrectionTarget::LinkLength => format!("the length {}", length_name(index)),
        CorrectionTarget::InstrumentScale => {
            "the measuring instrument's scale (the anchors about their centroid, or a tracker's points about its origin)".into()
        }
        CorrectionTarget::ToolPoint => "the tool point in the flange frame".into(),
        CorrectionTarget::ReadingScale => {
            "every string's scale (each reads its length times it more)".into()
        }
        CorrectionTarget::RigShape if point_data => {
            "the measuring instrument's frame (each point read off by a linear function of where it is about the instrument's origin: the instrument turning, stretching or shearing its space)".into()
        }
        CorrectionTarget::RigShape => {
            "the string frame's shape (each anchor moved by a linear function of where it sits about the anchors' centroid)".into()
        }
        CorrectionTarget::FrameDeflection => {
            "the string frame's deflection out of its plane by the strings' pull (each anchor moved along the plane's normal in proportion to every string's pull along it)".into()
        }
    }
}

/// The name of the length a [`CorrectionTarget::LinkLength`] corrects
/// (`j2.a`), as the report names parameters.
pub fn length_name(index: Option<usize>) -> String {
    let i = index.unwrap_or(0);
    format!("j{}.{}", i / 5 + 1, JointParam::ALL[i % 5].short())
}

/// An amount of a correction's driver (internal units: rad, s, degrees C,
/// mm; a cosine for the line of sight) in words with its unit.
pub fn correction_driver_amount(driver: CorrectionDriver, index: Option<usize>, v: f64) -> String {
    match driver {
        CorrectionDriver::JointAngle
        | CorrectionDriver::JointMove
        | CorrectionDriver::MoveDirection
        | CorrectionDriver::StringDirection => {
            format!("{:.1} deg", v.to_degrees())
        }
        CorrectionDriver::Workspace if matches!(index, Some(3 | 4)) => {
            format!("{:.1} deg", v.to_degrees())
        }
        CorrectionDriver::Time => format!("{v:.0} s"),
        CorrectionDriver::Temperature => format!("{v:.2} degrees C"),
        CorrectionDriver::StringLength
        | CorrectionDriver::StringMove
        | CorrectionDriver::Workspace
        | CorrectionDriver::Motion => {
            format!("{v:.1} mm")
        }
        CorrectionDriver::GravityTorque | CorrectionDriver::GravityTorqueChange => {
            format!("{v:.1} N*m")
        }
        CorrectionDriver::LineOfSight => format!("{v:.3}"),
    }
}

/// What drives a data-driven correction, in words.
pub fn correction_driver_words(driver: CorrectionDriver, index: Option<usize>) -> String {
    let at = index.map_or(0, |i| i + 1);
    match driver {
        CorrectionDriver::JointAngle => format!("joint {at}'s angle"),
        CorrectionDriver::JointMove => format!("joint {at}'s last move"),
        CorrectionDriver::MoveDirection => format!(
            "the direction of the last move of joints {at} and {} (the angle of their two moves)",
            at + 1
        ),
        CorrectionDriver::Time => "the session's clock".into(),
        CorrectionDriver::Temperature => "the temperature".into(),
        CorrectionDriver::StringLength => format!("string {at}'s length"),
        CorrectionDriver::StringMove => format!("string {at}'s last change of length"),
        CorrectionDriver::GravityTorque => format!("joint {at}'s gravity torque"),
        CorrectionDriver::GravityTorqueChange => {
            format!("the change of joint {at}'s gravity torque over the last move")
        }
        CorrectionDriver::StringDirection => {
            format!("string {at}'s angle from its axis (its mean direction, or the vertical)")
        }
        CorrectionDriver::Motion => "the length of the move that led to the pose".into(),
        CorrectionDriver::LineOfSight => format!(
            "the line of sight's component along the flange's {} axis (the direction from the instrument to T, in the flange frame)",
            ["x", "y", "z"].get(at.saturating_sub(1)).unwrap_or(&"?")
        ),
        CorrectionDriver::Workspace => format!(
            "T's {} in the rig's frame",
            [
                "x",
                "y",
                "z",
                "azimuth",
                "elevation",
                "distance from the origin"
            ]
            .get(index.unwrap_or(0))
            .unwrap_or(&"position")
        ),
    }
}

/// What one unit of each of a point correction's three coefficients per
/// knot moves T at `p` (rig frame, mm): the frame's axes for
/// [`CorrectionTarget::Point`]; for [`CorrectionTarget::PointSpherical`]
/// T's motion per radian of azimuth and of elevation about the rig's
/// origin and per millimetre of distance from it. One implementation for
/// the fit and compensation.
///
/// ```
/// use drawcal::physics::effects::{CorrectionTarget, point_frame};
/// use nalgebra::Vector3;
/// let f = point_frame(CorrectionTarget::PointSpherical, &Vector3::new(0.0, 2000.0, 0.0));
/// // A radian of azimuth moves a point 2 m out along y by 2000 mm in -x.
/// assert!((f[0] - Vector3::new(-2000.0, 0.0, 0.0)).norm() < 1e-9);
/// assert!((f[1] - Vector3::new(0.0, 0.0, 2000.0)).norm() < 1e-9);
/// assert!((f[2] - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-9);
/// ```
pub fn point_frame(target: CorrectionTarget, p: &Vector3<f64>) -> [Vector3<f64>; 3] {
    if target != CorrectionTarget::PointSpherical {
        return [Vector3::x(), Vector3::y(), Vector3::z()];
    }
    let (az, el) = (p.y.atan2(p.x), p.z.atan2(p.xy().norm()));
    let (horizontal, r) = (p.xy().norm(), p.norm());
    [
        Vector3::new(-az.sin(), az.cos(), 0.0) * horizontal,
        Vector3::new(-el.sin() * az.cos(), -el.sin() * az.sin(), el.cos()) * r,
        Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()),
    ]
}

/// Coordinate `index` of a point `p` (rig frame, mm) as
/// [`CorrectionDriver::Workspace`] numbers them: x, y, z (mm), azimuth
/// about z and elevation above the xy-plane (rad), distance from the
/// origin (mm).
pub fn workspace_coordinate(p: &Vector3<f64>, index: usize) -> f64 {
    match index {
        0..=2 => p[index],
        3 => p.y.atan2(p.x),
        4 => p.z.atan2(p.xy().norm()),
        _ => p.norm(),
    }
}

/// Piecewise-linear ("hat") weights of `x` between increasing `knots`:
/// the two knots around `x` and their weights, `x` held at the end knots
/// beyond them; with a `period`, `x` is taken modulo it and the last knot
/// is joined to the first one period on. One implementation for the fit
/// and compensation.
///
/// ```
/// use drawcal::physics::effects::hat_weights;
/// assert_eq!(hat_weights(&[0.0, 10.0], None, 2.5), [(0, 0.75), (1, 0.25)]);
/// assert_eq!(hat_weights(&[0.0, 10.0], None, 12.0), [(1, 1.0), (1, 0.0)]);
/// // Periodic over 20: 15 lies halfway from the knot at 10 back to the one at 0.
/// assert_eq!(hat_weights(&[0.0, 10.0], Some(20.0), 55.0), [(1, 0.5), (0, 0.5)]);
/// ```
pub fn hat_weights(knots: &[f64], period: Option<f64>, x: f64) -> [(usize, f64); 2] {
    let k = knots.len();
    if k == 0 {
        return [(0, 0.0), (0, 0.0)];
    }
    if let Some(p) = period.filter(|p| *p > 0.0 && k > 1) {
        let x = x.rem_euclid(p);
        let s = knots.partition_point(|&v| v <= x);
        // Between knot s-1 and knot s, wrapping past either end.
        let (lo, hi, a, b) = match s {
            0 => (k - 1, 0, knots[k - 1] - p, knots[0]),
            s if s == k => (k - 1, 0, knots[k - 1], knots[0] + p),
            s => (s - 1, s, knots[s - 1], knots[s]),
        };
        let t = (x - a) / (b - a);
        return [(lo, 1.0 - t), (hi, t)];
    }
    if k == 1 || x <= knots[0] {
        return [(0, 1.0), (0, 0.0)];
    }
    if x >= knots[k - 1] {
        return [(k - 1, 1.0), (k - 1, 0.0)];
    }
    let s = knots.partition_point(|&v| v <= x).clamp(1, k - 1);
    let t = (x - knots[s - 1]) / (knots[s] - knots[s - 1]);
    [(s - 1, 1.0 - t), (s, t)]
}

/// [`hat_weights`] as the knots that weigh: ascending (a periodic scan
/// wraps the last knot to the first), each knot once (a knot named twice
/// weighs the sum), an entry of weight zero weighing nothing.
pub fn live_knots(weights: [(usize, f64); 2]) -> [(usize, f64); 2] {
    let [(k0, w0), (k1, w1)] = weights;
    if k0 == k1 {
        [(k0, w0 + w1), (k0, 0.0)]
    } else if k0 < k1 {
        weights
    } else {
        [(k1, w1), (k0, w0)]
    }
}

/// A session's values of one driver, sorted, with their running sums: the
/// mean of each knot's hat weight over the session in `O(knots log poses)`
/// rather than a pass over the poses for every pose (a correction centred
/// on the session, [`CorrectionTarget::RigShape`]).
#[derive(Debug, Clone, Default)]
pub struct SortedValues {
    values: Vec<f64>,
    /// `sums[i]` is the sum of the `i` smallest values.
    sums: Vec<f64>,
}

impl SortedValues {
    /// The values, in any order (NaN sorts last).
    pub fn new(values: impl IntoIterator<Item = f64>) -> Self {
        let mut values: Vec<f64> = values.into_iter().collect();
        values.sort_by(f64::total_cmp);
        let mut sums = Vec::with_capacity(values.len() + 1);
        sums.push(0.0);
        for v in &values {
            sums.push(sums.last().copied().unwrap_or(0.0) + v);
        }
        SortedValues { values, sums }
    }

    /// The mean over the values of each knot's [`hat_weights`] (no
    /// period): a value below the first knot weighs 1 on it, one past the
    /// last 1 on that, one between knots `a` and `b` `(x - a) / (b - a)` on
    /// `b` and the rest on `a`.
    ///
    /// ```
    /// use drawcal::physics::effects::SortedValues;
    /// let v = SortedValues::new([-1.0, 2.5, 7.5, 12.0]);
    /// assert_eq!(v.mean_hat_weights(&[0.0, 10.0]), vec![0.5, 0.5]);
    /// ```
    pub fn mean_hat_weights(&self, knots: &[f64]) -> Vec<f64> {
        let k = knots.len();
        let mut out = vec![0.0; k];
        let count = self.values.len();
        if k == 0 || count == 0 {
            return out;
        }
        // How many values lie below v.
        let below = |v: f64| self.values.partition_point(|&x| x < v);
        let first = below(knots[0]);
        out[0] += first as f64;
        let mut lo = first;
        for s in 1..k {
            let (a, b) = (knots[s - 1], knots[s]);
            let hi = below(b);
            let n = (hi - lo) as f64;
            let t = (self.sums[hi] - self.sums[lo] - n * a) / (b - a);
            out[s - 1] += n - t;
            out[s] += t;
            lo = hi;
        }
        out[k - 1] += (count - lo) as f64;
        out.iter_mut().for_each(|w| *w /= count as f64);
        out
    }
}

/// What the effects need to know about one pose.
#[derive(Debug, Clone)]
pub struct PoseContext {
    /// Commanded joint angles (rad).
    pub q_rad: Vec<f64>,
    /// Direction each joint last moved (+1, -1; 0 before any motion).
    pub direction: Vec<f64>,
    /// Each joint's last move: its angle less the previous pose's (rad;
    /// zero for the first pose).
    pub move_q_rad: Vec<f64>,
    /// Seconds since the session began.
    pub time_s: f64,
    /// Thermal driver value (K or h).
    pub thermal: f64,
    /// The recorded temperature (°C; none when the pose has none).
    pub temp_c: Option<f64>,
    /// The point T in the rig frame used by sensor-side effects (true point
    /// in the simulator, located point in the analysis).
    pub point_rig: Vector3<f64>,
    /// The move that led to the pose: `point_rig` less the previous pose's
    /// (zero for the first pose, whose approach is not recorded).
    pub move_rig: Vector3<f64>,
    /// Per joint: gravity torque (N·m, from masses and payload) or the
    /// unit-mass regressors (m) of every link frame origin 0..n, the tool
    /// (n) and the payload (n + 1, the tool's times `payload_kg`).
    torque: Vec<Vec<f64>>,
    /// Per joint: its gravity torque less the previous pose's (N·m; zero
    /// for the first pose and without link masses).
    pub torque_change_nm: Vec<f64>,
    /// Per pair of neighbouring joints `(i, i + 1)`: the direction of their
    /// last move, the angle of `(Δq_i, Δq_(i+1))` (rad); where neither
    /// moved, the pair's previous direction (a drive's play keeps the side
    /// it last turned, as backlash does); zero before any move.
    pub move_direction_rad: Vec<f64>,
    /// Displacement of T in the rig frame (mm) per rad/(N·m) of a base
    /// tilt: the gravity moment of the arm and payload about the base
    /// origin (N·m), as a rotation, applied to T (zero without masses).
    tilt: Vector3<f64>,
    /// Size of that gravity moment (N·m; zero without masses).
    pub base_moment_nm: f64,
    /// Displacement of T in the rig frame (mm) per rad/(N·m) of a tool's
    /// compliance: the gravity moment of the payload at T about the
    /// flange origin (N·m), as a rotation, applied to T's lever from the
    /// flange (zero without a payload).
    droop: Vector3<f64>,
    /// Size of that gravity moment (N·m; zero without a payload).
    pub flange_moment_nm: f64,
    /// Per joint `j` but the last: displacement of T in the rig frame
    /// (mm) per 1/(N·m²) of the link from joint `j`'s axis to joint `j +
    /// 1`'s bending under its load (empty without masses).
    bending: Vec<Vector3<f64>>,
    /// Per joint `j` but the last: the load's bending moment at that
    /// link's root across it (N·m; empty without masses).
    pub bending_moment_nm: Vec<f64>,
    /// Displacement of T in the rig frame (mm) per mm of each length of
    /// [`Context::lengths`], in that order, at the nominal geometry (a
    /// length's change moves T by this to first order; the deviations
    /// change it by a part in a thousand).
    d_lengths: Vec<Vector3<f64>>,
    /// The flange's x, y and z axes in the rig frame at the nominal
    /// geometry: how T moves per mm of the tool point along each.
    pub flange_axes_rig: [Vector3<f64>; 3],
}

impl PoseContext {
    /// T's displacement (mm, rig frame) per unit coefficient of an effect
    /// that moves T under a gravity load rather than turning a joint: a
    /// base tilt, a tool's compliance, a link's bending (zero for any
    /// other effect, and where the load is unknown).
    fn load_shift(&self, kind: &Kind) -> Vector3<f64> {
        match kind {
            Kind::BaseTilt => self.tilt,
            Kind::ToolCompliance => self.droop,
            Kind::LinkBending { link_index } => {
                self.bending.get(*link_index).copied().unwrap_or_default()
            }
            _ => Vector3::zeros(),
        }
    }
}

/// The pose contexts of a whole session and the fixed quantities effects use.
#[derive(Debug, Clone)]
pub struct Context {
    /// Number of joints.
    pub n_joints: usize,
    /// Anchors in the rig frame (empty for point data).
    pub anchors: Vec<Vector3<f64>>,
    /// Common string constant r (mm).
    pub r_mm: f64,
    /// Unit vector of gravity in the rig frame.
    pub gravity_rig: Vector3<f64>,
    /// True when the robot has link masses (one compliance coefficient).
    pub has_masses: bool,
    /// Thermal driver used.
    pub thermal_driver: ThermalDriver,
    /// `(parameter index, nominal value)` of every nonzero a and d
    /// ([`nominal_lengths`]).
    pub lengths: Vec<(usize, f64)>,
    /// The temperature (°C) at which the thermal driver is zero (the first
    /// pose's), when the driver is [`ThermalDriver::Temperature`].
    pub temp_ref_c: Option<f64>,
    /// Every pose has a recorded `time_s`. Otherwise the row index stands
    /// in for the clock (change points are then places in the row order).
    pub timed: bool,
    /// The session's median payload (kg) when any pose recorded one: what
    /// compensation assumes the robot carries unless told otherwise.
    pub payload_ref_kg: Option<f64>,
    /// Per joint `j`: the distance (mm) from its axis's origin to joint
    /// `j + 1`'s, the span of the link a [`Kind::LinkBending`] bends (zero
    /// for the last joint).
    pub link_spans_mm: Vec<f64>,
    /// Centre of the poses' points (rig frame, mm): the pivot of rig rotations,
    /// so that their coefficients are not mostly translation.
    pub centre_rig: Vector3<f64>,
    /// Per pose, in visiting order.
    pub poses: Vec<PoseContext>,
    /// The poses' clock ([`CorrectionDriver::Time`]'s values), sorted.
    pub sorted_time_s: SortedValues,
    /// The poses' temperature ([`CorrectionDriver::Temperature`]'s
    /// values), sorted.
    pub sorted_temp_c: SortedValues,
}

/// Input for building a [`Context`]: one pose in visiting order.
pub struct PoseInput<'a> {
    /// Commanded angles (rad).
    pub q_rad: &'a [f64],
    /// Time (s), if recorded.
    pub time_s: Option<f64>,
    /// Temperature (°C), if recorded.
    pub temp_c: Option<f64>,
    /// Payload at the tool point (kg), if recorded; none counts as 0.
    pub payload_kg: Option<f64>,
    /// T in the rig frame (true or located).
    pub point_rig: Vector3<f64>,
}

/// Most unit-mass regressors one mass-free compliance carries: the tool and
/// the frames of the links the joint lifts (a UR's shoulder carries the
/// tool, the wrist, the forearm and the elbow: with three, the elbow's pure
/// `cos q` term was left for a separate periodic error of the same joint).
/// Each is a coefficient the look-elsewhere threshold charges for.
pub const MAX_COMPLIANCE_REGRESSORS: usize = 4;

/// Shortest link (mm, between consecutive joint axes' origins) proposed
/// as bending: a cantilever's tip moves with the cube of its span, so an
/// offset of a few centimetres between axes is stiff beside the upper arm
/// and forearm (0.3-0.6 m on arms of 3-10 kg payload).
pub const MIN_BENDING_SPAN_MM: f64 = 200.0;

/// `(parameter index, nominal value)` of every nonzero a and d of `robot`:
/// the lengths thermal expansion scales. A thermal multiplier `m` adds
/// `m · value` to parameter `index` (of any parameter vector with the
/// joint layout of [`Params`], nominal or calibrated). One implementation
/// for the analysis, the simulator and compensation.
pub fn nominal_lengths(robot: &Robot) -> Vec<(usize, f64)> {
    let nominal = Params::of_robot(robot);
    let l = nominal.layout;
    let mut lengths = Vec::new();
    for j in 0..robot.dof() {
        for jp in [JointParam::A, JointParam::D] {
            let i = l.joint(j, jp);
            if nominal.values[i] != 0.0 {
                lengths.push((i, nominal.values[i]));
            }
        }
    }
    lengths
}

/// The direction a joint arrives from when it goes from `prev_rad` to
/// `cur_rad`: the sign of the move, or `carried` (the direction before)
/// when it does not move. One rule for the analysis, the simulator and
/// compensation.
pub fn step_direction(prev_rad: f64, cur_rad: f64, carried: f64) -> f64 {
    let d = cur_rad - prev_rad;
    if d.abs() > 1e-7 { d.signum() } else { carried }
}

/// Direction each joint last moved, from the row order: the sign of the
/// change from the previous pose, carried over when a joint did not move.
/// The first pose has no known approach and gets 0.
pub fn approach_directions(q: &[&[f64]]) -> Vec<Vec<f64>> {
    let n = q.first().map_or(0, |v| v.len());
    let mut dir = vec![0.0; n];
    let mut out = Vec::with_capacity(q.len());
    for (i, qi) in q.iter().enumerate() {
        if i > 0 {
            for (j, d) in dir.iter_mut().enumerate() {
                *d = step_direction(q[i - 1][j], qi[j], *d);
            }
        }
        out.push(dir.clone());
    }
    out
}

/// What each pose changed from the one before, which the context's first
/// pass (one pose at a time) cannot see: each neighbouring joint pair's
/// move direction (kept where neither joint moved, as a play keeps its
/// side) and, with link masses, each joint's change of gravity torque.
fn fill_changes(poses: &mut [PoseContext], n: usize, has_masses: bool) {
    for i in 1..poses.len() {
        for pair in 0..n.saturating_sub(1) {
            let (a, b) = (poses[i].move_q_rad[pair], poses[i].move_q_rad[pair + 1]);
            poses[i].move_direction_rad[pair] = if a == 0.0 && b == 0.0 {
                poses[i - 1].move_direction_rad[pair]
            } else {
                b.atan2(a)
            };
        }
        if has_masses {
            poses[i].torque_change_nm = (0..n)
                .map(|j| poses[i].torque[j][0] - poses[i - 1].torque[j][0])
                .collect();
        }
    }
}

/// A warm-up settling with time constant `tau`: its progress after `h`
/// (both in the thermal driver's unit, hours or thousands of rows), `tau ·
/// (1 - exp(-h / tau))`, which grows like `h` at first.
pub fn warm_up(h: f64, tau: f64) -> f64 {
    tau * (1.0 - (-h / tau).exp())
}

/// Per joint of a pose (link frames `frames`, joint axes `axes`, T at
/// `tool`, base frame): the gravity torque on it (N·m) from the link
/// `masses` and the `payload_kg` at T, or without masses the unit-mass
/// regressors (m) of every link frame origin, the tool and the payload
/// (see `PoseContext::torque`).
fn gravity_torques(
    frames: &[crate::kinematics::chain::Frame],
    axes: &[(Vector3<f64>, Vector3<f64>)],
    tool: &Vector3<f64>,
    masses: Option<&Vec<crate::model::LinkMass>>,
    g_base: Vector3<f64>,
    payload_kg: f64,
) -> Vec<Vec<f64>> {
    let n = axes.len();
    let g_unit = g_base.normalize();
    (0..n)
        .map(|j| {
            let (z, o) = axes[j];
            let lever = |x: &Vector3<f64>| z.dot(&((x - o) * 1e-3).cross(&g_unit));
            match masses {
                Some(ms) => {
                    let mut tau = 0.0;
                    for (k, lm) in ms.iter().enumerate().skip(j) {
                        let c = Vector3::new(lm.com_mm[0], lm.com_mm[1], lm.com_mm[2]);
                        let x = frames[k].apply(&c);
                        tau += lm.mass_kg * g_base.norm() * lever(&x);
                    }
                    tau += payload_kg * g_base.norm() * lever(tool);
                    vec![tau]
                }
                None => (0..=n + 1)
                    .map(|k| {
                        if k < j {
                            0.0
                        } else if k == n + 1 {
                            payload_kg * lever(tool)
                        } else if k == n {
                            lever(tool)
                        } else {
                            lever(&frames[k].o)
                        }
                    })
                    .collect(),
            }
        })
        .collect()
}

/// A base tilt at one pose (base frame): T's displacement (mm) per
/// rad/(N·m), and the size of the gravity moment (N·m) of the links
/// `masses` and the `payload_kg` at T about the base origin. Gravity is
/// perpendicular to every moment it makes, so the moment is horizontal:
/// the axis the mount tilts about.
fn base_tilt(
    frames: &[crate::kinematics::chain::Frame],
    tool: &Vector3<f64>,
    masses: &[crate::model::LinkMass],
    g_base: Vector3<f64>,
    payload_kg: f64,
) -> (Vector3<f64>, f64) {
    let force = |kg: f64| g_base * kg;
    let mut moment = Vector3::zeros();
    for (k, lm) in masses.iter().enumerate() {
        let c = Vector3::new(lm.com_mm[0], lm.com_mm[1], lm.com_mm[2]);
        moment += (frames[k].apply(&c) * 1e-3).cross(&force(lm.mass_kg));
    }
    moment += (tool * 1e-3).cross(&force(payload_kg));
    (moment.cross(tool), moment.norm())
}

/// A tool's compliance at one pose (base frame; flange origin `flange`
/// and T at `tool`, mm): T's displacement (mm) per rad/(N·m), and the
/// size of the gravity moment (N·m) of the `payload_kg` at T about the
/// flange origin. The tool turns about the flange by the moment.
fn tool_droop(
    flange: &Vector3<f64>,
    tool: &Vector3<f64>,
    g_base: Vector3<f64>,
    payload_kg: f64,
) -> (Vector3<f64>, f64) {
    let lever = tool - flange;
    let moment = (lever * 1e-3).cross(&(g_base * payload_kg));
    (moment.cross(&lever), moment.norm())
}

/// A link bending at one pose (base frame): T's displacement (mm) per
/// 1/(N·m²) of the link from joint `j`'s axis origin to joint `j + 1`'s
/// (`axes`), a cantilever from the first, under its own weight (link `j`
/// of `masses`, spread evenly along it) and, at its end, the force and
/// moment of the outboard links and the `payload_kg` at T; and the size of
/// the bending moment at its root (N·m). Only the load's components across
/// the link bend it: Euler-Bernoulli's tip deflection `F L³/3 + (M × e)
/// L²/2 + w L⁴/8` and rotation `e × F L²/2 + M L + e × w L³/6`, `e` along
/// the link, applied to T's lever from the end.
fn link_bending(
    frames: &[crate::kinematics::chain::Frame],
    axes: &[(Vector3<f64>, Vector3<f64>)],
    tool: &Vector3<f64>,
    masses: &[crate::model::LinkMass],
    g_base: Vector3<f64>,
    payload_kg: f64,
    j: usize,
) -> (Vector3<f64>, f64) {
    let (root, end) = (axes[j].1 * 1e-3, axes[j + 1].1 * 1e-3);
    let span = end - root;
    let l = span.norm();
    if l < 1e-9 {
        return (Vector3::zeros(), 0.0);
    }
    let e = span / l;
    let across = |v: Vector3<f64>| v - e * e.dot(&v);
    let (mut force, mut moment) = (
        g_base * payload_kg,
        (tool * 1e-3 - end).cross(&(g_base * payload_kg)),
    );
    for (k, lm) in masses.iter().enumerate().skip(j + 1) {
        let c = frames[k].apply(&Vector3::new(lm.com_mm[0], lm.com_mm[1], lm.com_mm[2])) * 1e-3;
        force += g_base * lm.mass_kg;
        moment += (c - end).cross(&(g_base * lm.mass_kg));
    }
    let w = across(g_base * masses[j].mass_kg / l);
    let (f, m) = (across(force), across(moment));
    let tip = f * (l.powi(3) / 3.0) + m.cross(&e) * (l * l / 2.0) + w * (l.powi(4) / 8.0);
    let turn = e.cross(&f) * (l * l / 2.0) + m * l + e.cross(&w) * (l.powi(3) / 6.0);
    let root_moment = m + e.cross(&f) * l + e.cross(&w) * (l * l / 2.0);
    (
        (tip + turn.cross(&(tool * 1e-3 - end))) * 1e3,
        root_moment.norm(),
    )
}

/// What every pose's context is built from: the robot's nominal chain
/// and masses, gravity, and the session's clock and temperature
/// ([`Context::new`]).
struct Session<'r> {
    n_joints: usize,
    chain: Chain,
    nominal: Params,
    base_rotation: nalgebra::Matrix3<f64>,
    /// Gravity in the robot's base frame (m/s^2).
    g_base: Vector3<f64>,
    masses: Option<&'r Vec<crate::model::LinkMass>>,
    lengths: Vec<(usize, f64)>,
    thermal_driver: ThermalDriver,
    timed: bool,
    /// The first pose's temperature and time: the thermal driver's zero.
    temp_ref: f64,
    t_ref: f64,
}

impl<'r> Session<'r> {
    fn of(robot: &'r Robot, base_rotation: &nalgebra::Matrix3<f64>, poses: &[PoseInput]) -> Self {
        let n = robot.dof();
        let temps: Vec<f64> = poses.iter().filter_map(|p| p.temp_c).collect();
        let temp_range = temps.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - temps.iter().cloned().fold(f64::INFINITY, f64::min);
        // A temperature that never changes cannot drive anything; then the
        // session clock stands in for warm-up.
        let use_temp = temps.len() == poses.len() && temp_range > 0.05;
        let timed = poses.iter().all(|p| p.time_s.is_some());
        let thermal_driver = if use_temp {
            ThermalDriver::Temperature
        } else if timed {
            ThermalDriver::Time
        } else {
            ThermalDriver::Order
        };
        Session {
            n_joints: n,
            chain: Chain::new(robot.convention, n, 0),
            nominal: Params::of_robot(robot),
            base_rotation: *base_rotation,
            g_base: robot
                .gravity_in_base
                .map(|g| Vector3::new(g[0], g[1], g[2]))
                .unwrap_or(Vector3::new(0.0, 0.0, -9.81)),
            masses: robot.links.as_ref().filter(|l| l.len() == n),
            lengths: nominal_lengths(robot),
            thermal_driver,
            timed,
            temp_ref: poses.first().and_then(|p| p.temp_c).unwrap_or(0.0),
            t_ref: poses.first().and_then(|p| p.time_s).unwrap_or(0.0),
        }
    }

    /// The context of pose `i`, `p` (`before`: the pose recorded before
    /// it), arriving from `direction`; `jac` is scratch.
    fn pose(
        &self,
        i: usize,
        p: &PoseInput,
        before: Option<&PoseInput>,
        direction: Vec<f64>,
        jac: &mut crate::kinematics::chain::PointJacobian,
    ) -> PoseContext {
        let (chain, values, rot) = (&self.chain, &self.nominal.values, &self.base_rotation);
        let frames = chain.link_frames(values, p.q_rad, OutputFrame::Base);
        let axes = chain.joint_axes(values, p.q_rad, OutputFrame::Base);
        let (flange, tool) = chain.point(values, p.q_rad, OutputFrame::Base);
        let payload = p.payload_kg.unwrap_or(0.0);
        let torque = gravity_torques(&frames, &axes, &tool, self.masses, self.g_base, payload);
        let (tilt, base_moment_nm) = match self.masses {
            Some(ms) => {
                let (tilt, moment) = base_tilt(&frames, &tool, ms, self.g_base, payload);
                (rot * tilt, moment)
            }
            None => (Vector3::zeros(), 0.0),
        };
        let (droop, flange_moment_nm) = tool_droop(&flange.o, &tool, self.g_base, payload);
        // Without masses nothing bends: no room taken per pose.
        let (bending, bending_moment_nm): (Vec<Vector3<f64>>, Vec<f64>) = match self.masses {
            Some(ms) => (0..self.n_joints.saturating_sub(1))
                .map(|j| {
                    let (d, m) = link_bending(&frames, &axes, &tool, ms, self.g_base, payload, j);
                    (rot * d, m)
                })
                .unzip(),
            None => (Vec::new(), Vec::new()),
        };
        chain.point_jacobian(values, p.q_rad, OutputFrame::Base, jac);
        let thermal = match self.thermal_driver {
            ThermalDriver::Temperature => p.temp_c.unwrap_or(self.temp_ref) - self.temp_ref,
            ThermalDriver::Time => (p.time_s.unwrap_or(self.t_ref) - self.t_ref) / 3600.0,
            ThermalDriver::Order => i as f64 / 1000.0,
        };
        PoseContext {
            q_rad: p.q_rad.to_vec(),
            direction,
            move_q_rad: match before {
                None => vec![0.0; p.q_rad.len()],
                Some(b) => p.q_rad.iter().zip(b.q_rad).map(|(q, r)| q - r).collect(),
            },
            // A partly filled time_s column is no clock: the row index
            // stands in throughout, never mixed with seconds.
            time_s: match p.time_s {
                Some(t) if self.timed => t,
                _ => i as f64,
            },
            thermal,
            temp_c: p.temp_c,
            point_rig: p.point_rig,
            move_rig: before.map_or(Vector3::zeros(), |b| p.point_rig - b.point_rig),
            torque,
            torque_change_nm: vec![0.0; self.n_joints],
            move_direction_rad: vec![0.0; self.n_joints.saturating_sub(1)],
            tilt,
            base_moment_nm,
            droop: rot * droop,
            flange_moment_nm,
            bending,
            bending_moment_nm,
            d_lengths: self
                .lengths
                .iter()
                .map(|&(k, _)| rot * jac.d_params[k])
                .collect(),
            flange_axes_rig: [0, 1, 2].map(|c| rot * flange.r.column(c)),
        }
    }
}

impl Context {
    /// Build the contexts. `base_rotation` is the rotation of the robot base
    /// in the rig frame (for the direction of gravity in the rig); the
    /// nominal geometry and masses come from `robot`. Without
    /// `gravity_in_base` gravity is taken as -z of the base (upright arm).
    pub fn new(
        robot: &Robot,
        anchors: Vec<Vector3<f64>>,
        r_mm: f64,
        base_rotation: &nalgebra::Matrix3<f64>,
        poses: &[PoseInput],
    ) -> Self {
        let n = robot.dof();
        let session = Session::of(robot, base_rotation, poses);
        let qs: Vec<&[f64]> = poses.iter().map(|p| p.q_rad).collect();
        let mut jac = session.chain.new_jacobian();
        let mut ctx_poses: Vec<PoseContext> = poses
            .iter()
            .zip(approach_directions(&qs))
            .enumerate()
            .map(|(i, (p, direction))| {
                let before = i.checked_sub(1).map(|k| &poses[k]);
                session.pose(i, p, before, direction, &mut jac)
            })
            .collect();
        fill_changes(&mut ctx_poses, n, session.masses.is_some());
        let mut payloads: Vec<f64> = poses.iter().filter_map(|p| p.payload_kg).collect();
        payloads.sort_by(f64::total_cmp);
        let payload_ref_kg = (!payloads.is_empty()).then(|| payloads[payloads.len() / 2]);
        let centre_rig = poses
            .iter()
            .fold(Vector3::zeros(), |acc, p| acc + p.point_rig)
            / poses.len().max(1) as f64;
        // A rigid link's span between the axes is the same at every pose.
        let link_spans_mm = match poses.first() {
            Some(p) => {
                let axes =
                    session
                        .chain
                        .joint_axes(&session.nominal.values, p.q_rad, OutputFrame::Base);
                (0..n)
                    .map(|j| {
                        axes.get(j + 1)
                            .map_or(0.0, |next| (next.1 - axes[j].1).norm())
                    })
                    .collect()
            }
            None => vec![0.0; n],
        };
        let mut ctx = Context {
            link_spans_mm,
            n_joints: n,
            anchors,
            r_mm,
            gravity_rig: base_rotation * session.g_base.normalize(),
            has_masses: session.masses.is_some(),
            thermal_driver: session.thermal_driver,
            temp_ref_c: (session.thermal_driver == ThermalDriver::Temperature)
                .then_some(session.temp_ref),
            timed: session.timed,
            payload_ref_kg,
            centre_rig,
            lengths: session.lengths,
            poses: ctx_poses,
            sorted_time_s: SortedValues::default(),
            sorted_temp_c: SortedValues::default(),
        };
        ctx.sorted_time_s = ctx.sorted(CorrectionDriver::Time);
        ctx.sorted_temp_c = ctx.sorted(CorrectionDriver::Temperature);
        ctx
    }

    /// The poses' values of `driver` (no index), sorted.
    fn sorted(&self, driver: CorrectionDriver) -> SortedValues {
        SortedValues::new(
            self.poses
                .iter()
                .map(|p| self.driver_value(p, driver, None, None)),
        )
    }

    /// A change point `t0_s` (seconds, or a row index without `time_s`)
    /// in words: "at about 1131 s" or "around row 46 (...)".
    pub fn when(&self, t0_s: f64) -> String {
        if self.timed && t0_s >= 3600.0 {
            // Long sessions are plotted in hours: say both.
            format!("at about {t0_s:.0} s ({:.1} h)", t0_s / 3600.0)
        } else if self.timed {
            format!("at about {t0_s:.0} s")
        } else {
            format!(
                "around row {} (row order: the file has no time_s)",
                t0_s.round() as i64 + 1
            )
        }
    }

    /// The axis of time-driven evidence: (label, unit).
    pub fn time_axis(&self) -> (&'static str, &'static str) {
        if self.timed {
            ("time since the session began", "s")
        } else {
            ("row in the file (no time_s)", "row")
        }
    }

    /// Independent unit-mass regressors for the compliance of joint `j`
    /// without link masses: frames whose torque columns over the given
    /// poses are not (nearly) combinations of the ones already kept, at
    /// most [`MAX_COMPLIANCE_REGRESSORS`].
    pub fn compliance_regressors(&self, j: usize, poses: &[usize]) -> Vec<usize> {
        let n = self.n_joints;
        let mut kept: Vec<Vec<f64>> = Vec::new();
        let mut idx = Vec::new();
        // Farthest first: the tool, the payload (dropped as a multiple of
        // the tool's when it never changes) and the distal frames.
        for k in std::iter::once(n)
            .chain(std::iter::once(n + 1))
            .chain((j..n).rev())
        {
            let mut v: Vec<f64> = poses.iter().map(|&i| self.poses[i].torque[j][k]).collect();
            let norm0 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm0 < 1e-6 * (poses.len() as f64).sqrt() {
                continue;
            }
            for u in &kept {
                let d: f64 = v.iter().zip(u).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(u).for_each(|(a, b)| *a -= d * b);
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 0.1 * norm0 {
                v.iter_mut().for_each(|x| *x /= norm);
                kept.push(v);
                idx.push(k);
            }
            if idx.len() == MAX_COMPLIANCE_REGRESSORS {
                break;
            }
        }
        idx
    }

    /// True when the link from joint `j`'s axis to the next joint's is one
    /// [`Kind::LinkBending`] models: link masses known, a span of at least
    /// [`MIN_BENDING_SPAN_MM`], and not the first joint's (the column from
    /// the base carries the arm's moment about the base, and bends as the
    /// mount tilts: [`Kind::BaseTilt`] is that shape).
    pub fn can_bend(&self, j: usize) -> bool {
        self.has_masses
            && j >= 1
            && self
                .link_spans_mm
                .get(j)
                .is_some_and(|&s| s >= MIN_BENDING_SPAN_MM)
    }

    /// The basis of `kind` at pose `i`: per coefficient, `n_joints` joint
    /// angle changes (rad), one thermal multiplier of the nominal lengths,
    /// one reading change per string (mm) and a displacement of T relative
    /// to the rig (3, mm), written into `out`.
    pub fn basis(&self, kind: &Kind, i: usize, out: &mut Basis) {
        let n = self.n_joints;
        let m = self.anchors.len();
        let nc = kind.n_coef();
        out.reset(nc, n, m);
        let pc = &self.poses[i];
        match kind {
            Kind::JointCompliance {
                joint_index,
                regressors,
            } => {
                let j = *joint_index;
                if regressors.is_empty() {
                    out.dq[j] = pc.torque[j][0];
                } else {
                    for (c, &k) in regressors.iter().enumerate() {
                        out.dq[c * n + j] = pc.torque[j].get(k).copied().unwrap_or(0.0);
                    }
                }
            }
            Kind::Backlash { joint_index } => {
                let j = *joint_index;
                out.dq[j] = pc.direction[j];
                if pc.direction[j] == 0.0 {
                    out.dq[n + j] = 1.0;
                }
            }
            Kind::JointPeriodic {
                joint_index,
                harmonic,
            } => {
                let j = *joint_index;
                let (s, c) = (*harmonic as f64 * pc.q_rad[j]).sin_cos();
                out.dq[j] = s;
                out.dq[n + j] = c;
            }
            Kind::JointScale { joint_index } => out.dq[*joint_index] = pc.q_rad[*joint_index],
            Kind::ThermalExpansion { tau_h, .. } => {
                out.thermal[0] = match tau_h {
                    Some(tau) => warm_up(pc.thermal, *tau),
                    None => pc.thermal,
                }
            }
            Kind::SensorScale { sensor_index } => {
                let k = *sensor_index;
                out.dl[k] = (pc.point_rig - self.anchors[k]).norm() - self.r_mm;
            }
            Kind::SensorOffset { sensor_index } => out.dl[*sensor_index] = 1.0,
            Kind::SensorDrift { sensor_index } => out.dl[*sensor_index] = self.clock_h(pc),
            Kind::CableSag => {
                for k in 0..m {
                    let v = pc.point_rig - self.anchors[k];
                    let vert = v.dot(&self.gravity_rig);
                    let h2 = (v.norm_squared() - vert * vert).max(0.0) * 1e-6;
                    out.dl[k] = h2 * v.norm() * 1e-3;
                }
            }
            Kind::AnchorStep { sensor_index, t0_s } => {
                let k = *sensor_index;
                if pc.time_s > *t0_s {
                    let u = (pc.point_rig - self.anchors[k]).normalize();
                    for c in 0..3 {
                        out.dl[c * m + k] = -u[c];
                    }
                }
            }
            Kind::RigStep { t0_s } => {
                if pc.time_s > *t0_s {
                    self.rigid_basis(pc, 1.0, out);
                }
            }
            Kind::RigDrift => self.rigid_basis(pc, self.clock_h(pc), out),
            Kind::BaseTilt | Kind::ToolCompliance | Kind::LinkBending { .. } => {
                let shift = pc.load_shift(kind);
                out.dp[..3].copy_from_slice(shift.as_slice());
            }
            Kind::DataDriven { .. } => self.correction_basis(kind, pc, out),
        }
    }

    /// [`Self::basis`] of a data-driven correction at the pose `pc`: each
    /// knot's hat weight times how its target moves T, a joint's angle or
    /// a string's reading.
    fn correction_basis(&self, kind: &Kind, pc: &PoseContext, out: &mut Basis) {
        let Kind::DataDriven {
            target,
            target_index,
            driver,
            driver_index,
            knots,
            period,
            axis,
            ..
        } = kind
        else {
            return;
        };
        let (n, m) = (self.n_joints, self.anchors.len());
        let x = self.driver_value(pc, *driver, *driver_index, axis.as_ref());
        // Along the move that led to the pose (none for the first).
        let along = pc.move_rig.try_normalize(0.0).unwrap_or_default();
        // How T moves with the corrected length (none for a length
        // the model does not have).
        let by_length = match target {
            CorrectionTarget::LinkLength => self
                .lengths
                .iter()
                .position(|&(k, _)| Some(k) == *target_index)
                .map_or(Vector3::zeros(), |l| pc.d_lengths[l]),
            _ => Vector3::zeros(),
        };
        if *target == CorrectionTarget::RigShape {
            self.rig_shape_basis(knots, *period, *driver, *driver_index, x, pc, out);
            return;
        }
        if *target == CorrectionTarget::FrameDeflection {
            self.frame_deflection_basis(knots.len(), pc, out);
            return;
        }
        let weights = live_knots(hat_weights(knots, *period, x));
        let per_knot = kind.n_coef() / knots.len().max(1);
        out.live.clear();
        for (k, w) in weights.into_iter().filter(|(_, w)| *w != 0.0) {
            out.live.extend(k * per_knot..(k + 1) * per_knot);
            match target {
                CorrectionTarget::Point if *driver == CorrectionDriver::Motion => {
                    for r in 0..3 {
                        out.dp[k * 3 + r] += w * along[r];
                    }
                }
                CorrectionTarget::JointAngle => {
                    out.dq[k * n + target_index.unwrap_or(0)] += w;
                }
                CorrectionTarget::JointPlay => {
                    let j = target_index.unwrap_or(0);
                    out.dq[k * n + j] += w * pc.direction.get(j).copied().unwrap_or(0.0);
                }
                CorrectionTarget::StringReading => {
                    out.dl[k * m + target_index.unwrap_or(0)] += w;
                }
                CorrectionTarget::StringZeroScale => {
                    let s = target_index.unwrap_or(0);
                    let l_m = self
                        .anchors
                        .get(s)
                        .map_or(0.0, |a| (pc.point_rig - a).norm() * 1e-3);
                    out.dl[2 * k * m + s] += w;
                    out.dl[(2 * k + 1) * m + s] += w * l_m;
                }
                CorrectionTarget::LinkLength => {
                    for r in 0..3 {
                        out.dp[k * 3 + r] += w * by_length[r];
                    }
                }
                CorrectionTarget::ReadingScale => {
                    for (s, a) in self.anchors.iter().enumerate() {
                        out.dl[k * m + s] += w * (pc.point_rig - a).norm();
                    }
                }
                // Every knot at once, before the loop.
                CorrectionTarget::RigShape | CorrectionTarget::FrameDeflection => {}
                CorrectionTarget::InstrumentScale if m == 0 => {
                    for r in 0..3 {
                        out.dp[k * 3 + r] += w * pc.point_rig[r];
                    }
                }
                CorrectionTarget::InstrumentScale => {
                    let centroid = self.anchors.iter().sum::<Vector3<f64>>() / m as f64;
                    for (s, a) in self.anchors.iter().enumerate() {
                        out.dl[k * m + s] += w * reading_per_scale(&pc.point_rig, a, &centroid);
                    }
                }
                CorrectionTarget::ToolPoint => {
                    for (c, dir) in pc.flange_axes_rig.iter().enumerate() {
                        for r in 0..3 {
                            out.dp[(3 * k + c) * 3 + r] += w * dir[r];
                        }
                    }
                }
                CorrectionTarget::Point | CorrectionTarget::PointSpherical => {
                    let frame = point_frame(*target, &pc.point_rig);
                    for (c, dir) in frame.iter().enumerate() {
                        for r in 0..3 {
                            out.dp[(3 * k + c) * 3 + r] += w * dir[r];
                        }
                    }
                }
            }
        }
    }

    /// [`Self::correction_basis`] of [`CorrectionTarget::RigShape`] at a
    /// pose whose driver is `x`: knot `k`'s weight less its mean over the
    /// session's poses (the correction centred: a constant shape is where
    /// rig.json put the anchors, not a change), times how string `s`'s
    /// reading follows `D[r][c]`: `-u_s[r] (A_s - centroid)[c]`; with point
    /// data, how T's coordinate `r` follows it: `T[c]`.
    #[allow(clippy::too_many_arguments)]
    fn rig_shape_basis(
        &self,
        knots: &[f64],
        period: Option<f64>,
        driver: CorrectionDriver,
        driver_index: Option<usize>,
        x: f64,
        pc: &PoseContext,
        out: &mut Basis,
    ) {
        let m = self.anchors.len();
        if self.poses.is_empty() {
            return;
        }
        let mut weight: Vec<f64> = match (driver, period) {
            (CorrectionDriver::Time, None) => self.sorted_time_s.mean_hat_weights(knots),
            (CorrectionDriver::Temperature, None) => self.sorted_temp_c.mean_hat_weights(knots),
            // Not a shape's driver (`Kind::check` refuses it): one pass.
            _ => {
                let mut mean = vec![0.0; knots.len()];
                for p in &self.poses {
                    let xp = self.driver_value(p, driver, driver_index, None);
                    for (k, w) in hat_weights(knots, period, xp) {
                        mean[k] += w / self.poses.len() as f64;
                    }
                }
                mean
            }
        };
        weight.iter_mut().for_each(|w| *w = -*w);
        for (k, w) in hat_weights(knots, period, x) {
            weight[k] += w;
        }
        if m == 0 {
            // Point data: T read `D T` off, about the instrument's origin.
            for (k, w) in weight.iter().enumerate() {
                for r in 0..3 {
                    for c in 0..3 {
                        out.dp[(9 * k + 3 * r + c) * 3 + r] += w * pc.point_rig[c];
                    }
                }
            }
            return;
        }
        let centroid = self.anchors.iter().sum::<Vector3<f64>>() / m as f64;
        for (s, a) in self.anchors.iter().enumerate() {
            let u = (pc.point_rig - a).try_normalize(0.0).unwrap_or_default();
            let arm = a - centroid;
            for (k, w) in weight.iter().enumerate() {
                for r in 0..3 {
                    for c in 0..3 {
                        out.dl[(9 * k + 3 * r + c) * m + s] -= w * u[r] * arm[c];
                    }
                }
            }
        }
    }

    /// [`Self::correction_basis`] of [`CorrectionTarget::FrameDeflection`]
    /// for `k` anchors: coefficient `C[a][i]` (`a <= i`, the upper triangle
    /// row by row) moves anchor `a` along the anchors' plane normal `n` by
    /// `C (u_i · n)` and, off the diagonal, anchor `i` by `C (u_a · n)`;
    /// string `s` reads its anchor's move times `u_s · n` less. Nothing
    /// when the rig has not `k` anchors (a report read against another
    /// rig) or fewer than three (no plane).
    fn frame_deflection_basis(&self, k: usize, pc: &PoseContext, out: &mut Basis) {
        let m = self.anchors.len();
        if m != k || m < 3 {
            return;
        }
        let n = plane_normal(&self.anchors);
        let pull: Vec<f64> = self
            .anchors
            .iter()
            .map(|a| {
                (pc.point_rig - a)
                    .try_normalize(0.0)
                    .map_or(0.0, |u| u.dot(&n))
            })
            .collect();
        let mut c = 0;
        for a in 0..m {
            for i in a..m {
                out.dl[c * m + a] -= pull[a] * pull[i];
                if i != a {
                    out.dl[c * m + i] -= pull[i] * pull[a];
                }
                c += 1;
            }
        }
    }

    /// The weights of a data-driven correction's coefficients at pose `i`
    /// (its driver's two hat functions there): the correction's own value
    /// at the pose (an angle, a reading, a length) is their sum with the
    /// coefficients. Zero for a named effect.
    pub fn knot_weights(&self, kind: &Kind, i: usize) -> [(usize, f64); 2] {
        match kind {
            Kind::DataDriven {
                driver,
                driver_index,
                knots,
                period,
                axis,
                ..
            } => hat_weights(
                knots,
                *period,
                self.driver_value(&self.poses[i], *driver, *driver_index, axis.as_ref()),
            ),
            _ => [(0, 0.0), (0, 0.0)],
        }
    }

    /// The value of a data-driven correction's driver at pose `pc` (rad,
    /// s or rows, degrees C, mm, N·m; a cosine for the line of sight); a
    /// string's direction is measured from `axis`. A pose without a temperature reads the first pose's.
    pub fn driver_value(
        &self,
        pc: &PoseContext,
        driver: CorrectionDriver,
        index: Option<usize>,
        axis: Option<&[f64; 3]>,
    ) -> f64 {
        let i = index.unwrap_or(0);
        match driver {
            CorrectionDriver::JointAngle => pc.q_rad.get(i).copied().unwrap_or(0.0),
            CorrectionDriver::JointMove => pc.move_q_rad.get(i).copied().unwrap_or(0.0),
            CorrectionDriver::MoveDirection => pc.move_direction_rad.get(i).copied().unwrap_or(0.0),
            CorrectionDriver::Time => pc.time_s,
            CorrectionDriver::Temperature => pc.temp_c.or(self.temp_ref_c).unwrap_or(0.0),
            CorrectionDriver::Workspace => workspace_coordinate(&pc.point_rig, i),
            CorrectionDriver::LineOfSight => pc
                .flange_axes_rig
                .get(i)
                .map_or(0.0, |a| pc.point_rig.normalize().dot(a)),
            CorrectionDriver::StringLength => self
                .anchors
                .get(i)
                .map_or(0.0, |a| (pc.point_rig - a).norm() - self.r_mm),
            CorrectionDriver::Motion => pc.move_rig.norm(),
            CorrectionDriver::GravityTorque if self.has_masses => pc
                .torque
                .get(i)
                .and_then(|t| t.first())
                .copied()
                .unwrap_or(0.0),
            CorrectionDriver::GravityTorque => 0.0,
            CorrectionDriver::GravityTorqueChange => {
                pc.torque_change_nm.get(i).copied().unwrap_or(0.0)
            }
            CorrectionDriver::StringMove => self.anchors.get(i).map_or(0.0, |a| {
                (pc.point_rig - a).norm() - (pc.point_rig - pc.move_rig - a).norm()
            }),
            CorrectionDriver::StringDirection => match (self.anchors.get(i), axis) {
                (Some(a), Some(axis)) => {
                    let u = (pc.point_rig - a).normalize();
                    u.dot(&Vector3::from(*axis)).clamp(-1.0, 1.0).acos()
                }
                _ => 0.0,
            },
        }
    }

    /// The session clock of a steady drift at pose `pc`: hours since the
    /// first pose, or thousands of rows without a recorded `time_s`.
    pub fn clock_h(&self, pc: &PoseContext) -> f64 {
        let first = self.poses.first().map_or(0.0, |p| p.time_s);
        if self.timed {
            (pc.time_s - first) / 3600.0
        } else {
            (pc.time_s - first) / 1000.0
        }
    }

    /// RMS displacement of T (mm) a rig effect with coefficients `coef`
    /// causes over the given poses that it affects (a step: those after
    /// the move; a drift: all but the first). The magnitude the analysis
    /// reports and the simulator's truth states, so the two compare.
    pub fn rigid_rms_mm(&self, kind: &Kind, coef: &[f64], poses: &[usize]) -> f64 {
        let mut buf = Basis::default();
        let (mut s, mut n) = (0.0, 0usize);
        for &i in poses {
            self.basis(kind, i, &mut buf);
            if buf.dp.iter().all(|v| *v == 0.0) {
                continue;
            }
            s += (0..3)
                .map(|r| {
                    coef.iter()
                        .enumerate()
                        .map(|(k, c)| c * buf.dp[k * 3 + r])
                        .sum::<f64>()
                        .powi(2)
                })
                .sum::<f64>();
            n += 1;
        }
        (s / n.max(1) as f64).sqrt()
    }

    /// A rigid motion of the rig relative to the base, scaled by `w`:
    /// T moves by `-(v + ω × (T - centre))` relative to the rig, with T the
    /// pose's `point_rig` (true point in the simulator, located point in the
    /// analysis; the lever arm needs no better) (the rig
    /// moving by +v makes T appear to move by -v, so the coefficients are
    /// the rig's own motion; rotations in mrad).
    fn rigid_basis(&self, pc: &PoseContext, w: f64, out: &mut Basis) {
        let arm = pc.point_rig - self.centre_rig;
        for c in 0..3 {
            out.dp[c * 3 + c] = -w;
            let mut e = Vector3::zeros();
            e[c] = 1.0;
            let d = -w * e.cross(&arm) * 1e-3;
            for r in 0..3 {
                out.dp[(3 + c) * 3 + r] = d[r];
            }
        }
    }

    /// Sum of the effects at pose `i`: joint angle changes (rad), thermal
    /// multiplier, reading changes (mm).
    pub fn apply(&self, effects: &[EffectModel], i: usize, buf: &mut Basis) -> Delta {
        let (n, m) = (self.n_joints, self.anchors.len());
        let mut d = Delta::zeros(n, m);
        for e in effects {
            self.basis(&e.kind, i, buf);
            d.add(&e.coef, buf, n, m);
        }
        d
    }

    /// [`Self::apply`] from each effect's basis at the pose, already made
    /// (`bases[e]` of `effects[e]`, as [`Self::basis`] gives it): the same
    /// sums, for a caller that needs the bases too.
    pub fn apply_bases(&self, effects: &[EffectModel], bases: &[Basis]) -> Delta {
        let (n, m) = (self.n_joints, self.anchors.len());
        let mut d = Delta::zeros(n, m);
        for (e, buf) in effects.iter().zip(bases) {
            d.add(&e.coef, buf, n, m);
        }
        d
    }

    /// The flange's axes at each pose taken from `flange_rig(i)` (pose
    /// `i`'s flange orientation in the rig frame, as a calibrated geometry
    /// has it) rather than the nominal geometry: a correction of the tool
    /// point then moves T exactly as the geometry's own tool point does,
    /// so that its constant part is aliased with it exactly (and left to
    /// it by the alias check) rather than nearly, which a joint fit would
    /// cancel in large opposite amounts that the nonlinear model does not.
    pub fn with_flange_of(mut self, flange_rig: impl Fn(usize) -> nalgebra::Matrix3<f64>) -> Self {
        for (i, pc) in self.poses.iter_mut().enumerate() {
            let r = flange_rig(i);
            pc.flange_axes_rig = [0, 1, 2].map(|c| r.column(c).into_owned());
        }
        self
    }

    /// Parameters with the thermal multiplier applied to the nominal lengths.
    pub fn apply_thermal(&self, p: &mut [f64], thermal: f64) {
        if thermal != 0.0 {
            for &(i, v) in &self.lengths {
                p[i] += thermal * v;
            }
        }
    }
}

/// Per-coefficient basis at one pose (see [`Context::basis`]).
#[derive(Debug, Clone, Default)]
pub struct Basis {
    /// `n_coef × n_joints`, row-major.
    pub dq: Vec<f64>,
    /// One per coefficient.
    pub thermal: Vec<f64>,
    /// `n_coef × n_strings`, row-major.
    pub dl: Vec<f64>,
    /// `n_coef × 3`, row-major: displacement of T relative to the rig (mm).
    pub dp: Vec<f64>,
    /// The coefficients that may move anything at this pose, ascending:
    /// all of them, except that a data-driven correction's knots whose hat
    /// weight is zero here are left out. The rest of the rows above are
    /// zero, so a sum over the basis may visit these alone (a correction of
    /// 32 knots has at most two live at a pose).
    pub live: Vec<usize>,
}

impl Basis {
    /// Zero, for `nc` coefficients, `n` joints and `m` strings, every
    /// coefficient live. Only the coefficients live at the last pose can
    /// be nonzero ([`Context::basis`] writes no other), so a basis of the
    /// same shape clears those alone (a 32-knot correction's two).
    fn reset(&mut self, nc: usize, n: usize, m: usize) {
        if self.thermal.len() == nc && self.dq.len() == nc * n && self.dl.len() == nc * m {
            for &c in &self.live {
                self.dq[c * n..(c + 1) * n].fill(0.0);
                self.thermal[c] = 0.0;
                self.dl[c * m..(c + 1) * m].fill(0.0);
                self.dp[c * 3..(c + 1) * 3].fill(0.0);
            }
        } else {
            self.dq.clear();
            self.dq.resize(nc * n, 0.0);
            self.thermal.clear();
            self.thermal.resize(nc, 0.0);
            self.dl.clear();
            self.dl.resize(nc * m, 0.0);
            self.dp.clear();
            self.dp.resize(nc * 3, 0.0);
        }
        self.live.clear();
        self.live.extend(0..nc);
    }
}

/// The summed effect at a pose.
#[derive(Debug, Clone)]
pub struct Delta {
    /// Joint angle changes (rad): the joint sits at commanded + dq.
    pub dq: Vec<f64>,
    /// Thermal multiplier of the nominal lengths.
    pub thermal: f64,
    /// Reading changes (mm): the string reads this much more.
    pub dl: Vec<f64>,
    /// Displacement of T relative to the rig (mm, rig frame).
    pub dp: Vector3<f64>,
}

impl Delta {
    /// No change, for `n` joints and `m` strings.
    fn zeros(n: usize, m: usize) -> Self {
        Delta {
            dq: vec![0.0; n],
            thermal: 0.0,
            dl: vec![0.0; m],
            dp: Vector3::zeros(),
        }
    }

    /// Add one effect of coefficients `coef` and basis `buf` (`n` joints,
    /// `m` strings).
    fn add(&mut self, coef: &[f64], buf: &Basis, n: usize, m: usize) {
        for &c in &buf.live {
            let v = coef[c];
            for j in 0..n {
                self.dq[j] += v * buf.dq[c * n + j];
            }
            self.thermal += v * buf.thermal[c];
            for k in 0..m {
                self.dl[k] += v * buf.dl[c * m + k];
            }
            for r in 0..3 {
                self.dp[r] += v * buf.dp[c * 3 + r];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A horizontal link (along x, 0.5 m, from joint 0's axis at the
    /// origin to joint 1's) under gravity along -z: each load alone against
    /// the textbook cantilever. T 0.2 m beyond the link's end along x turns
    /// with the end's rotation.
    #[test]
    fn a_bending_links_deflections_are_the_textbook_cantilevers() {
        use crate::kinematics::chain::Frame;
        use crate::model::LinkMass;
        let (l, g): (f64, f64) = (0.5, 9.81);
        let at = |x_mm: f64| Frame {
            r: nalgebra::Matrix3::identity(),
            o: Vector3::new(x_mm, 0.0, 0.0),
        };
        // Link 1's frame at the link's end; joint axes along y.
        let frames = [at(0.0), at(500.0), at(500.0)];
        let axes = [
            (Vector3::y(), Vector3::zeros()),
            (Vector3::y(), Vector3::new(500.0, 0.0, 0.0)),
            (Vector3::y(), Vector3::new(500.0, 0.0, 0.0)),
        ];
        let mass = |kg: f64, x_mm: f64| LinkMass {
            mass_kg: kg,
            com_mm: [x_mm, 0.0, 0.0],
        };
        let gravity = Vector3::new(0.0, 0.0, -g);
        let end = Vector3::new(500.0, 0.0, 0.0);
        let tool = Vector3::new(700.0, 0.0, 0.0);
        let close = |a: Vector3<f64>, b: Vector3<f64>| (a - b).norm() < 1e-9 * b.norm().max(1.0);
        let bend = |ms: &[LinkMass], t: &Vector3<f64>, kg: f64| {
            link_bending(&frames, &axes, t, ms, gravity, kg, 0)
        };
        // A point mass at the end: F L^3 / 3 down, the end turned by F L^2 / 2.
        let m = 3.0;
        let f = m * g;
        let (d, root) = bend(&[mass(0.0, 0.0), mass(m, 0.0), mass(0.0, 0.0)], &end, 0.0);
        assert!(
            close(d, Vector3::new(0.0, 0.0, -f * l.powi(3) / 3.0 * 1e3)),
            "{d:?}"
        );
        assert!((root - f * l).abs() < 1e-9);
        let (d, _) = bend(&[mass(0.0, 0.0), mass(m, 0.0), mass(0.0, 0.0)], &tool, 0.0);
        let expect = -f * l.powi(3) / 3.0 - f * l * l / 2.0 * 0.2;
        assert!(close(d, Vector3::new(0.0, 0.0, expect * 1e3)), "{d:?}");
        // The same weight as a payload at the end: the same bending.
        let (d, _) = bend(&[mass(0.0, 0.0), mass(0.0, 0.0), mass(0.0, 0.0)], &end, m);
        assert!(
            close(d, Vector3::new(0.0, 0.0, -f * l.powi(3) / 3.0 * 1e3)),
            "{d:?}"
        );
        // A mass 0.1 m beyond the end: the force and a moment f * 0.1,
        // M L^2 / 2 more at the end.
        let (d, root) = bend(&[mass(0.0, 0.0), mass(m, 100.0), mass(0.0, 0.0)], &end, 0.0);
        let expect = -f * l.powi(3) / 3.0 - f * 0.1 * l * l / 2.0;
        assert!(close(d, Vector3::new(0.0, 0.0, expect * 1e3)), "{d:?}");
        assert!((root - f * (l + 0.1)).abs() < 1e-9);
        // The link's own weight, spread along it: w L^4 / 8.
        let (d, root) = bend(&[mass(m, 250.0), mass(0.0, 0.0), mass(0.0, 0.0)], &end, 0.0);
        assert!(
            close(d, Vector3::new(0.0, 0.0, -f / l * l.powi(4) / 8.0 * 1e3)),
            "{d:?}"
        );
        assert!((root - f * l / 2.0).abs() < 1e-9);
        // A load along the link bends nothing.
        let up = [
            (Vector3::y(), Vector3::zeros()),
            (Vector3::y(), Vector3::new(0.0, 0.0, 500.0)),
            (Vector3::y(), Vector3::new(0.0, 0.0, 500.0)),
        ];
        let (d, root) = link_bending(
            &[
                at(0.0),
                Frame {
                    r: nalgebra::Matrix3::identity(),
                    o: Vector3::new(0.0, 0.0, 500.0),
                },
                at(0.0),
            ],
            &up,
            &Vector3::new(0.0, 0.0, 500.0),
            &[mass(0.0, 0.0), mass(m, 0.0), mass(0.0, 0.0)],
            gravity,
            0.0,
            0,
        );
        assert!(d.norm() < 1e-12 && root.abs() < 1e-12, "{d:?} {root}");
    }

    /// A tool's droop per unit compliance against T turned exactly about
    /// the flange by the payload's moment times a small compliance: the
    /// first-order column is the rotation's derivative.
    #[test]
    fn a_tools_droop_is_the_derivative_of_its_rotation_about_the_flange() {
        let flange = Vector3::new(400.0, -120.0, 650.0);
        let tool = flange + Vector3::new(60.0, 35.0, -140.0);
        let g = Vector3::new(0.3, -0.2, -9.8);
        let kg = 2.5;
        let (droop, moment_nm) = tool_droop(&flange, &tool, g, kg);
        let moment = ((tool - flange) * 1e-3).cross(&(g * kg));
        assert!((moment_nm - moment.norm()).abs() < 1e-12);
        let c = 1e-7;
        let turned = flange + nalgebra::Rotation3::from_scaled_axis(moment * c) * (tool - flange);
        let fd = (turned - tool) / c;
        assert!(
            (fd - droop).norm() < 1e-6 * droop.norm(),
            "{fd:?} vs {droop:?}"
        );
        // No payload: no droop.
        assert_eq!(tool_droop(&flange, &tool, g, 0.0).0, Vector3::zeros());
    }

    /// The reading change per unit of the rig's scale against the exact
    /// change of the string's length when the anchor moves outward.
    #[test]
    fn reading_per_scale_matches_the_string_length_of_a_scaled_rig() {
        let centroid = Vector3::new(500.0, 400.0, 300.0);
        let anchor = Vector3::new(-200.0, 1300.0, -50.0);
        let point = Vector3::new(700.0, 350.0, 800.0);
        let eps = 1e-7;
        let scaled: Vector3<f64> = centroid + (anchor - centroid) * (1.0 + eps);
        let exact = ((point - scaled).norm() - (point - anchor).norm()) / eps;
        let linear = reading_per_scale(&point, &anchor, &centroid);
        assert!(
            (exact - linear).abs() < 1e-4 * linear.abs(),
            "{exact} vs {linear}"
        );
    }

    /// A correction of the tool point moves T as the tool point parameter
    /// does: its basis, per coefficient, against central differences of T
    /// (rig frame) in the model's tool point along the flange's x, y, z.
    #[test]
    fn tool_point_basis_matches_finite_differences_of_the_tool_point() {
        let robot = crate::model::Robot::from_json(include_str!(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/real_ur10_ipa_random/robot.json"
        )))
        .unwrap();
        let n = robot.dof();
        let base_rotation = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
        let qs = [
            vec![0.3, -1.1, 0.9, -0.4, 1.2, 0.7],
            vec![-1.4, -0.6, 1.8, 0.5, -0.9, 2.1],
        ];
        let poses: Vec<PoseInput> = qs
            .iter()
            .enumerate()
            .map(|(i, q)| PoseInput {
                q_rad: &q[..n],
                time_s: Some(100.0 * i as f64),
                temp_c: None,
                payload_kg: None,
                point_rig: Vector3::zeros(),
            })
            .collect();
        let ctx = Context::new(&robot, vec![], 0.0, &base_rotation, &poses);
        let kind = Kind::DataDriven {
            target: CorrectionTarget::ToolPoint,
            target_index: None,
            driver: CorrectionDriver::Time,
            driver_index: None,
            knots: vec![0.0, 100.0],
            period: None,
            range: None,
            axis: None,
        };
        let nominal = Params::of_robot(&robot);
        let chain = Chain::new(robot.convention, n, 0);
        let t = nominal.layout.tool();
        let h = 1e-4;
        let mut buf = Basis::default();
        for (i, q) in qs.iter().enumerate() {
            ctx.basis(&kind, i, &mut buf);
            for c in 0..3 {
                let at = |step: f64| {
                    let mut v = nominal.values.clone();
                    v[t + c] += step;
                    base_rotation * chain.point(&v, &q[..n], OutputFrame::Base).1
                };
                let fd = (at(h) - at(-h)) / (2.0 * h);
                // Pose i sits on knot i: its weight is 1 there.
                let col = Vector3::from_fn(|r, _| buf.dp[(3 * i + c) * 3 + r]);
                assert!(
                    (fd - col).norm() < 1e-6,
                    "pose {i} axis {c}: {fd:?} vs {col:?}"
                );
            }
        }
    }

    /// The session means of the hat weights from the sorted values equal a
    /// pass over the values, on and between knots, below and past them.
    #[test]
    fn mean_hat_weights_equal_a_pass_over_the_values() {
        let values: Vec<f64> = (0..200)
            .map(|i| ((i * 37 % 101) as f64) * 0.7 - 10.0)
            .chain([0.0, 5.0, 12.5, 30.0, 30.0])
            .collect();
        let sorted = SortedValues::new(values.iter().copied());
        for knots in [
            vec![5.0],
            vec![0.0, 30.0],
            vec![0.0, 5.0, 12.5, 30.0],
            vec![-20.0, 100.0],
        ] {
            let mut direct = vec![0.0; knots.len()];
            for &x in &values {
                for (k, w) in hat_weights(&knots, None, x) {
                    direct[k] += w / values.len() as f64;
                }
            }
            let fast = sorted.mean_hat_weights(&knots);
            for (a, b) in direct.iter().zip(&fast) {
                assert!((a - b).abs() < 1e-12, "{knots:?}: {direct:?} vs {fast:?}");
            }
        }
    }

    /// The UR10's context at `points` (rig frame, 100 s apart, the joints
    /// at zero) with `anchors` (none: point data), and the rig's shape by
    /// the clock with a knot at each pose.
    fn shape_by_clock(anchors: Vec<Vector3<f64>>, points: &[Vector3<f64>]) -> (Context, Kind) {
        let robot = crate::model::Robot::from_json(include_str!(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/real_ur10_ipa_random/robot.json"
        )))
        .unwrap();
        let q = [0.0; 6];
        let poses: Vec<PoseInput> = points
            .iter()
            .enumerate()
            .map(|(i, p)| PoseInput {
                q_rad: &q,
                time_s: Some(100.0 * i as f64),
                temp_c: None,
                payload_kg: None,
                point_rig: *p,
            })
            .collect();
        let ctx = Context::new(&robot, anchors, 0.0, &nalgebra::Matrix3::identity(), &poses);
        let kind = Kind::DataDriven {
            target: CorrectionTarget::RigShape,
            target_index: None,
            driver: CorrectionDriver::Time,
            driver_index: None,
            knots: (0..points.len()).map(|i| 100.0 * i as f64).collect(),
            period: None,
            range: None,
            axis: None,
        };
        (ctx, kind)
    }

    /// The shape `D` of [`shape_by_clock`]'s three knots at pose `i`, which
    /// sits on knot `i`: centred, its weights are 1 - 1/3 there and -1/3 at
    /// the other two knots.
    fn centred_shape(coef: &[f64], i: usize) -> nalgebra::Matrix3<f64> {
        nalgebra::Matrix3::from_fn(|r, c| {
            (0..3)
                .map(|k| {
                    let w = if k == i { 2.0 / 3.0 } else { -1.0 / 3.0 };
                    w * coef[9 * k + 3 * r + c]
                })
                .sum::<f64>()
        })
    }

    /// A correction of the frame's shape against the exact readings of a
    /// frame deformed by it: each anchor moved by `D (A - centroid)`, `D`
    /// the knots' matrices weighted by the centred hat weights; and a
    /// shape constant over the session (rig.json's anchors off, not a
    /// change) corrects nothing.
    #[test]
    fn rig_shape_basis_matches_the_readings_of_a_deformed_frame() {
        let anchors = vec![
            Vector3::new(-900.0, -800.0, 1500.0),
            Vector3::new(1100.0, -700.0, 1600.0),
            Vector3::new(1000.0, 1200.0, 200.0),
            Vector3::new(-800.0, 1000.0, 1700.0),
        ];
        let points = [
            Vector3::new(300.0, 100.0, 400.0),
            Vector3::new(-200.0, 350.0, 650.0),
            Vector3::new(150.0, -300.0, 900.0),
        ];
        let (ctx, kind) = shape_by_clock(anchors.clone(), &points);
        assert_eq!(kind.n_coef(), 27);
        let coef: Vec<f64> = (0..27)
            .map(|c| 1e-6 * ((c * 7 % 11) as f64 - 5.0))
            .collect();
        let centroid = anchors.iter().sum::<Vector3<f64>>() / 4.0;
        let mut buf = Basis::default();
        for (i, t) in points.iter().enumerate() {
            ctx.basis(&kind, i, &mut buf);
            let d = centred_shape(&coef, i);
            for (s, a) in anchors.iter().enumerate() {
                let moved = a + d * (a - centroid);
                let exact = (t - moved).norm() - (t - a).norm();
                let linear: f64 = (0..27).map(|c| coef[c] * buf.dl[c * 4 + s]).sum();
                assert!(
                    (exact - linear).abs() < 1e-3 * exact.abs().max(1e-5),
                    "pose {i} string {s}: {exact} vs {linear}"
                );
            }
            let constant: Vec<f64> = (0..27).map(|c| coef[c % 9]).collect();
            for s in 0..4 {
                let v: f64 = (0..27).map(|c| constant[c] * buf.dl[c * 4 + s]).sum();
                assert!(v.abs() < 1e-12, "a constant shape read {v} on string {s}");
            }
        }
    }

    /// A frame's deflection against the exact readings of a frame deflected
    /// by it: each anchor `a` moved along the anchors' plane normal by
    /// `Σ_i C[a][i] (u_i · n)`, `C` symmetric, from the upper triangle the
    /// coefficients hold; four anchors in one plane twisting (A and D
    /// against B and C) is one such deflection.
    #[test]
    fn frame_deflection_basis_matches_the_readings_of_a_deflected_frame() {
        let anchors = vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.0, 900.0, 0.0),
            Vector3::new(1200.0, 0.0, 0.0),
            Vector3::new(1200.0, 900.0, 0.0),
        ];
        let n = plane_normal(&anchors);
        assert!((n.z.abs() - 1.0).abs() < 1e-12, "{n:?}");
        let points = [
            Vector3::new(300.0, 100.0, -400.0),
            Vector3::new(800.0, 350.0, -650.0),
            Vector3::new(550.0, 700.0, -250.0),
        ];
        let (ctx, _) = shape_by_clock(anchors.clone(), &points);
        let deflection = |knots: Vec<f64>, driver_index| Kind::DataDriven {
            target: CorrectionTarget::FrameDeflection,
            target_index: None,
            driver: CorrectionDriver::Workspace,
            driver_index,
            knots,
            period: None,
            range: None,
            axis: None,
        };
        let kind = deflection(vec![0.0, 1.0, 2.0, 3.0], None);
        assert_eq!(kind.n_coef(), 10);
        let coef: Vec<f64> = (0..10)
            .map(|c| 1e-3 * ((c * 7 % 11) as f64 - 5.0))
            .collect();
        let checked = |kind: &Kind| {
            EffectModel {
                kind: kind.clone(),
                coef: vec![0.0; kind.n_coef()],
            }
            .check(6, false)
        };
        assert!(checked(&kind).is_ok(), "{:?}", checked(&kind));
        let mut cm = nalgebra::Matrix4::zeros();
        let mut c = 0;
        for a in 0..4 {
            for i in a..4 {
                cm[(a, i)] = coef[c];
                cm[(i, a)] = coef[c];
                c += 1;
            }
        }
        let mut buf = Basis::default();
        for (k, t) in points.iter().enumerate() {
            ctx.basis(&kind, k, &mut buf);
            let pull: Vec<f64> = anchors
                .iter()
                .map(|a| (t - a).normalize().dot(&n))
                .collect();
            for (s, a) in anchors.iter().enumerate() {
                let along: f64 = (0..4).map(|i| cm[(s, i)] * pull[i]).sum();
                let exact = (t - (a + n * along)).norm() - (t - a).norm();
                let linear: f64 = (0..10).map(|c| coef[c] * buf.dl[c * 4 + s]).sum();
                assert!(
                    (exact - linear).abs() < 1e-3 * exact.abs().max(1e-6),
                    "pose {k} string {s}: {exact} vs {linear}"
                );
            }
        }
        // Knots that are not the anchors' indices, or a coordinate: refused.
        for bad in [
            deflection(vec![0.0, 2.0, 3.0], None),
            deflection(vec![0.0, 1.0, 2.0, 3.0], Some(0)),
        ] {
            assert!(checked(&bad).is_err(), "{bad:?}");
        }
    }

    /// With point data the rig's shape is the instrument's frame: T moves
    /// by `D T` about the instrument's origin, `D` the knots' matrices
    /// weighted and centred on the session; a constant `D` moves nothing.
    #[test]
    fn rig_shape_basis_with_point_data_moves_t_by_the_frame() {
        let points = [
            Vector3::new(2300.0, 100.0, 400.0),
            Vector3::new(1800.0, 350.0, 650.0),
            Vector3::new(2150.0, -300.0, 900.0),
        ];
        let (ctx, kind) = shape_by_clock(vec![], &points);
        let coef: Vec<f64> = (0..27)
            .map(|c| 1e-6 * ((c * 5 % 13) as f64 - 6.0))
            .collect();
        let mut buf = Basis::default();
        for (i, t) in points.iter().enumerate() {
            ctx.basis(&kind, i, &mut buf);
            let d = centred_shape(&coef, i);
            let want = d * t;
            for r in 0..3 {
                let got: f64 = (0..27).map(|c| coef[c] * buf.dp[c * 3 + r]).sum();
                assert!(
                    (got - want[r]).abs() < 1e-12 * want.norm().max(1.0),
                    "pose {i} axis {r}: {got} vs {}",
                    want[r]
                );
            }
            assert!(buf.dl.iter().all(|&v| v == 0.0), "no strings to read");
            let constant: Vec<f64> = (0..27).map(|c| coef[c % 9]).collect();
            for r in 0..3 {
                let v: f64 = (0..27).map(|c| constant[c] * buf.dp[c * 3 + r]).sum();
                assert!(v.abs() < 1e-12, "a constant frame moved T by {v} along {r}");
            }
        }
    }

    /// The spherical frame's directions against finite differences of the
    /// spherical coordinates: a step along the azimuth direction changes
    /// the azimuth by the step, and so on, each leaving the other two.
    #[test]
    fn point_frame_matches_finite_differences_of_the_coordinates() {
        let h = 1e-6;
        for p in [
            Vector3::new(1200.0, -300.0, 450.0),
            Vector3::new(-800.0, 1500.0, -200.0),
            Vector3::new(100.0, 50.0, 2000.0),
        ] {
            let f = point_frame(CorrectionTarget::PointSpherical, &p);
            for (c, dir) in f.iter().enumerate() {
                let index = [3, 4, 5][c];
                for other in 3..WORKSPACE_COORDINATES {
                    let want = if other == index { 1.0 } else { 0.0 };
                    let d = (workspace_coordinate(&(p + h * dir), other)
                        - workspace_coordinate(&(p - h * dir), other))
                        / (2.0 * h);
                    assert!((d - want).abs() < 1e-6, "{p:?} {c} {other}: {d}");
                }
            }
        }
        assert_eq!(
            point_frame(CorrectionTarget::Point, &Vector3::new(1.0, 2.0, 3.0)),
            [Vector3::x(), Vector3::y(), Vector3::z()]
        );
    }
}
