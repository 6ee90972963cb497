//! Modelling what has no name: where the analysis located structure that
//! no catalogue effect explains, a data-driven correction in the located
//! driver (a smooth function of a joint's angle acting on some joint's
//! angle, of the clock, the temperature or T's place in the workspace
//! moving T, of a string's length or the clock changing that string's
//! reading), piecewise linear between
//! knots at quantiles of the driver over the train poses. Its family and
//! number of knots are chosen by 5-fold cross-validation on the train
//! poses, it is fitted jointly with the geometry and the accepted effects
//! (one linearised step: the correction is linear and the model already
//! fitted), and it is kept only through the held-out gate every named
//! effect passes.
//!
//! It is reported as `data_driven`, never as a physics name: the finding
//! says where and what it corrects, and whether compensation can use it
//! (a function of joint angles can, inside the range the poses covered; a
//! function of the clock or of the temperature history describes this
//! session, not the next; a string's reading is the measurement's, not the
//! robot's).
//!
//! Beyond those: a joint's angle or the measuring instrument's scale as a
//! function of the clock (or the temperature, for the scale), a string's
//! reading by its last change of length, a joint's angle by its gravity
//! torque (the last two smooth or jumping where the driver changes sign),
//! a string's zero and scale by its direction about an axis fitted from
//! the residual ([`aimed`]), every string's scale by the clock or the
//! temperature, a joint's play (by the side it arrived from) by the clock,
//! and, where the naming gate took named steps out, a function of the
//! clock jumping there.

use nalgebra::{DMatrix, Vector3};

use super::candidates::Candidate;
use super::compensation_use;
use super::fixed::{FixedBase, TargetPatterns, with_candidate};
use super::gates::{self, Before};
use super::magnitude::magnitude;
use super::normals::{Normals, cv_sse, normals, solve_subset, unaliased};
use super::refit::FitInfo;
use super::{Inputs, State};
use crate::physics::effects::{
    CorrectionDriver, CorrectionTarget, EffectModel, Kind, WORKSPACE_COORDINATES,
};
use crate::physics::evidence::evidence_plot;
use crate::physics::periodogram;
use crate::physics::problem::EffectProblem;
use crate::report::{EffectParameters, Finding, FindingModel, Place};

/// Knot counts tried for a function of a joint angle or a string's length
/// (a joint's range holds a few features at most).
const JOINT_KNOTS: [usize; 8] = [3, 4, 6, 8, 12, 16, 24, 32];
/// Knot counts tried for a function of time or temperature: a long
/// session can drift through many states, so up to one knot per eight
/// train poses.
const CLOCK_KNOTS: [usize; 14] = [3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256];
/// Knots of the rig's shape (the string frame's, or with point data the
/// instrument's frame) in the clock or the temperature
/// ([`CorrectionTarget::RigShape`], nine coefficients a knot): a frame
/// bends and settles slowly.
const RIG_SHAPE_KNOTS: [usize; 4] = [2, 3, 4, 6];
/// Above this many columns a candidate's alias check is not run column by
/// column (it costs the cube of the columns for each): its first knot's
/// columns are left out instead, the only part a geometry holds (a constant
/// shift: the base's translation, a joint's zero offset).
const ALIAS_CHECK_MAX_COLUMNS: usize = 48;
/// Knot counts tried for a string's zero and scale by its direction (two
/// coefficients per knot; the scale of a string varies slowly with where
/// it points).
const ZERO_SCALE_KNOTS: [usize; 5] = [2, 3, 4, 6, 8];
/// Fewest train poses per knot (each knot's coefficient needs its poses).
const POSES_PER_KNOT: usize = 8;
/// At most this many corrections (one per located driver, strongest
/// first).
pub(super) const MAX_CORRECTIONS: usize = 3;

/// Try a data-driven correction at each of the located `places`
/// (strongest first, at most [`MAX_CORRECTIONS`] kept); each kept one is
/// a finding, and `state` moves to the model with it.
pub(super) fn correct(inputs: &Inputs, state: &mut State, places: &[Place]) {
    let mut tried: Vec<Kind> = Vec::new();
    let mut kept = 0;
    // A field over the workspace after the joints and strings (a string's
    // direction included): it is the most general shape (it can take up
    // part of what one joint's angle drives), so the specific driver has
    // the first say; the line of sight (point data, at the configuration)
    // after the field, as the point's own error where the field did not
    // take it. Functions of the
    // clock or the temperature last: over a long session they carry
    // hundreds of coefficients, and every later candidate's fit would carry
    // them too (its normal equations grow with the cube).
    let rank = |p: &Place| match (p.driver.as_str(), p.sensor) {
        ("time" | "temperature", _) => 3,
        ("configuration", None) => 2,
        ("workspace", None) => 1,
        _ => 0,
    };
    let mut ordered: Vec<&Place> = places.iter().collect();
    ordered.sort_by_key(|p| rank(p));
    for place in ordered {
        if kept == MAX_CORRECTIONS {
            break;
        }
        let family: Vec<Vec<Kind>> = families(inputs, place, &state.jumps_s)
            .into_iter()
            .filter(|f| {
                f.first()
                    .is_some_and(|k| !tried.iter().any(|t| super::candidates::same_slot(t, k)))
            })
            .collect();
        if family.is_empty() {
            continue;
        }
        tried.extend(family.iter().filter_map(|f| f.first().cloned()));
        if try_place(inputs, state, &family, place) {
            kept += 1;
        }
    }
}

/// The train poses' values of a driver, and the candidate families built
/// on them.
struct Slots<'a> {
    ctx: &'a crate::physics::effects::Context,
    train: &'a [usize],
    /// Where a function of the clock may jump ([`State::jumps_s`]).
    jumps_s: &'a [f64],
}

impl<'a> Slots<'a> {
    /// The train poses of `inputs`, jumping (a function of the clock) at
    /// `jumps_s`.
    fn of(inputs: &'a Inputs, jumps_s: &'a [f64]) -> Self {
        Slots {
            ctx: &inputs.ctx,
            train: &inputs.obs.train,
            jumps_s,
        }
    }

    /// The driver's value at every train pose (a string's direction from
    /// `axis`).
    fn values(
        &self,
        driver: CorrectionDriver,
        index: Option<usize>,
        axis: Option<&[f64; 3]>,
    ) -> Vec<f64> {
        self.train
            .iter()
            .map(|&i| {
                self.ctx
                    .driver_value(&self.ctx.poses[i], driver, index, axis)
            })
            .collect()
    }

    /// Piecewise-linear candidates of one slot at each of `counts` knots
    /// the train poses allow, knots at quantiles of the driver.
    fn knotted_about(
        &self,
        (target, target_index): (CorrectionTarget, Option<usize>),
        (driver, driver_index): (CorrectionDriver, Option<usize>),
        axis: Option<[f64; 3]>,
        counts: &[usize],
    ) -> Vec<Kind> {
        let v = self.values(driver, driver_index, axis.as_ref());
        counts
            .iter()
            .filter(|&&k| k * POSES_PER_KNOT <= self.train.len())
            .filter_map(|&k| knots_at_quantiles(&v, k))
            .map(|knots| Kind::DataDriven {
                target,
                target_index,
                driver,
                driver_index,
                knots,
                period: None,
                range: None,
                axis,
            })
            .collect()
    }

    /// Candidates of one slot as a function of the clock at every knot
    /// count the train poses allow; with named steps taken out of the
    /// model, the same again with a jump at each of them (what a knock,
    /// a re-homing or a lost encoder count does, which a smooth function
    /// spreads over a knot's interval).
    fn clocked(&self, target: CorrectionTarget, target_index: Option<usize>) -> Vec<Kind> {
        let mut out = self.knotted(
            target,
            target_index,
            CorrectionDriver::Time,
            None,
            &CLOCK_KNOTS,
        );
        if self.jumps_s.is_empty() {
            return out;
        }
        let times: Vec<f64> = self.ctx.poses.iter().map(|p| p.time_s).collect();
        out.extend(jumping(&out, &times, self.jumps_s));
        out
    }

    /// Candidates of one slot at [`MOVE_KNOTS`], smooth and, as well,
    /// jumping where the driver changes sign: a string's last change
    /// turning from retracted to pulled out, a joint's gravity torque
    /// turning over (a friction, a stretch or a play that takes the sign).
    fn signed(
        &self,
        (target, target_index): (CorrectionTarget, Option<usize>),
        (driver, driver_index): (CorrectionDriver, Option<usize>),
    ) -> Vec<Kind> {
        let mut out = self.knotted(target, target_index, driver, driver_index, &MOVE_KNOTS);
        let values: Vec<f64> = self
            .ctx
            .poses
            .iter()
            .map(|pc| self.ctx.driver_value(pc, driver, driver_index, None))
            .collect();
        out.extend(jumping(&out, &values, &[0.0]));
        out
    }

    /// [`Self::knotted_about`] for a driver without an axis.
    fn knotted(
        &self,
        target: CorrectionTarget,
        target_index: Option<usize>,
        driver: CorrectionDriver,
        driver_index: Option<usize>,
        counts: &[usize],
    ) -> Vec<Kind> {
        self.knotted_about((target, target_index), (driver, driver_index), None, counts)
    }

    /// Periodic candidates of one slot at every period scanned (see
    /// `periodogram`), [`SCAN_KNOTS`] knots per period.
    fn periodic_scan(
        &self,
        target: CorrectionTarget,
        target_index: Option<usize>,
        driver: CorrectionDriver,
        driver_index: Option<usize>,
    ) -> Vec<Kind> {
        let v = self.values(driver, driver_index, None);
        let range = v
            .iter()
            .fold([f64::INFINITY, f64::NEG_INFINITY], |[a, b], &x| {
                [a.min(x), b.max(x)]
            });
        periodogram::scanned_periods(&v)
            .into_iter()
            .map(|period| {
                periodic(
                    (target, target_index),
                    (driver, driver_index),
                    period,
                    range,
                    SCAN_KNOTS,
                )
            })
            .collect()
    }

    /// The unit vector of string `s`'s (0-based) mean direction from its
    /// anchor over the train poses; none when the directions cancel.
    fn mean_direction(&self, s: usize) -> Option<[f64; 3]> {
        let mean: Vector3<f64> = self
            .train
            .iter()
            .map(|&i| (self.ctx.poses[i].point_rig - self.ctx.anchors[s]).normalize())
            .sum();
        mean.try_normalize(0.0).map(Into::into)
    }

    /// Candidates of string `s`'s (0-based) reading as a smooth function
    /// of its direction from its anchor: the angle from its mean direction
    /// (wrap over a rounded exit grows with it), and the angle from the
    /// vertical (a post bent by the string's horizontal pull, a sag: what
    /// gravity orders), each a family.
    fn by_direction(&self, s: usize) -> Vec<Vec<Kind>> {
        let down: [f64; 3] = self.ctx.gravity_rig.into();
        self.mean_direction(s)
            .into_iter()
            .chain((self.ctx.gravity_rig.norm() > 0.5).then_some(down))
            .map(|axis| {
                self.knotted_about(
                    (CorrectionTarget::StringReading, Some(s)),
                    (CorrectionDriver::StringDirection, Some(s)),
                    Some(axis),
                    &JOINT_KNOTS,
                )
            })
            .filter(|f| !f.is_empty())
            .collect()
    }

    /// String `s`'s (0-based) zero and scale as functions of its angle
    /// from `axis`, at every knot count of [`ZERO_SCALE_KNOTS`] the train
    /// poses allow.
    fn zero_scale_about(&self, s: usize, axis: [f64; 3]) -> Vec<Kind> {
        self.knotted_about(
            (CorrectionTarget::StringZeroScale, Some(s)),
            (CorrectionDriver::StringDirection, Some(s)),
            Some(axis),
            &ZERO_SCALE_KNOTS,
        )
    }
}

/// The family of string `s`'s (0-based) zero and scale by its direction
/// before it is aimed: one placeholder, which [`try_place`] replaces by
/// [`aimed`]'s candidates (the axis comes from the residual).
fn to_aim(s: usize) -> Vec<Kind> {
    vec![Kind::DataDriven {
        target: CorrectionTarget::StringZeroScale,
        target_index: Some(s),
        driver: CorrectionDriver::StringDirection,
        driver_index: Some(s),
        knots: vec![0.0, std::f64::consts::PI],
        period: None,
        range: None,
        axis: Some([0.0, 0.0, 1.0]),
    }]
}

/// The candidates of a [`to_aim`] family: the axis is the direction along
/// which the string's scale changes most, the least-squares gradient of
/// its reading's residual (the model so far held fixed) over `l · u` (`l`
/// its length, `u` its direction), fitted beside `u`, a constant and `l`.
/// A scale that varies with where the string points is, to first order,
/// such a gradient; the correction then follows it as a smooth function
/// of the angle from it.
fn aimed(inputs: &Inputs, fixed: &FixedBase, placeholder: &Kind) -> Vec<Kind> {
    let Some(s) = placeholder.sensor() else {
        return vec![];
    };
    let Inputs { obs, ctx, .. } = inputs;
    let probe = Kind::DataDriven {
        target: CorrectionTarget::StringReading,
        target_index: Some(s),
        driver: CorrectionDriver::StringLength,
        driver_index: Some(s),
        knots: vec![0.0, 1.0],
        period: None,
        range: None,
        axis: None,
    };
    let patterns = fixed.pose_patterns(inputs, &probe);
    let mut a = DMatrix::<f64>::zeros(8, 8);
    let mut g = nalgebra::DVector::<f64>::zeros(8);
    for (pos, &(vr, vv)) in patterns.iter().enumerate() {
        let v = ctx.poses[obs.train[pos]].point_rig - ctx.anchors[s];
        let l_m = v.norm() * 1e-3;
        let Some(u) = v.try_normalize(0.0) else {
            continue;
        };
        let x = [l_m * u.x, l_m * u.y, l_m * u.z, u.x, u.y, u.z, 1.0, l_m];
        for i in 0..8 {
            g[i] += x[i] * vr;
            for j in 0..8 {
                a[(i, j)] += x[i] * x[j] * vv;
            }
        }
    }
    for i in 0..8 {
        a[(i, i)] += 1e-9 * a[(i, i)].max(1e-300);
    }
    let Some(beta) = a.cholesky().map(|c| c.solve(&g)) else {
        return vec![];
    };
    let Some(axis) = Vector3::new(beta[0], beta[1], beta[2]).try_normalize(1e-12) else {
        return vec![];
    };
    Slots::of(inputs, &[]).zero_scale_about(s, axis.into())
}

/// The candidate families at a place: per family one slot (what is
/// corrected, what drives it) at every knot count the train poses allow.
fn families(inputs: &Inputs, place: &Place, jumps_s: &[f64]) -> Vec<Vec<Kind>> {
    let slots = Slots::of(inputs, jumps_s);
    let m = inputs.ctx.anchors.len();
    let mut out = match (place.driver.as_str(), place.joint, place.sensor) {
        ("joint", Some(j), _) => {
            let mut out = slots.at_joint(j - 1);
            // Or its gravity load (a counterbalance, a play gravity takes
            // up): not a function of its angle alone.
            out.extend(load_families(inputs, j - 1));
            // Or a string's reading by that load: the joint's motor
            // interfering with the string's signal in proportion to the
            // current that holds the load (a string's error moves the
            // located point, so the joint's tests see it).
            out.extend(slots.strings_by_load(j - 1));
            out
        }
        ("time", _, None) => slots.in_time(),
        // One string by the clock: its reading, or its zero and scale (a
        // cable that creeps or a drum that warms reads long lengths off
        // more than short ones).
        ("time", _, Some(s)) if s <= m => vec![
            slots.clocked(CorrectionTarget::StringReading, Some(s - 1)),
            slots.clocked(CorrectionTarget::StringZeroScale, Some(s - 1)),
        ],
        ("temperature", _, _) => slots.at_temperature(),
        ("workspace", None, None) => slots.over_workspace(),
        // Or the frame deflecting by where T draws the strings (one
        // string's reading by where T is, with four strings, moves the
        // located point too).
        ("workspace", _, Some(s)) if s <= m => {
            let mut out = slots.by_string_direction(s - 1);
            out.extend(slots.frame_deflection());
            out
        }
        // One string's last change of length: its reading off by the way
        // it last moved (friction in its drum, stretch of its cable).
        ("motion", _, Some(s)) if s <= m => vec![slots.signed(
            (CorrectionTarget::StringReading, Some(s - 1)),
            (CorrectionDriver::StringMove, Some(s - 1)),
        )],
        // Joint j's error by the way it last moved: graded with its own
        // move, or by the direction of its and a neighbour's moves (a
        // drive turning both).
        ("motion", Some(j), None) if j >= 1 && j <= inputs.ctx.n_joints => {
            let mut out = move_families(inputs, j - 1);
            out.extend(slots.by_move_direction(j - 1));
            out.extend(slots.by_load_change(j - 1));
            // Or its play changing during the session.
            out.push(slots.clocked(CorrectionTarget::JointPlay, Some(j - 1)));
            out
        }
        // The move that led to each pose: T off along it by a function of
        // its length (overshoot or lag of an arm not settled at the dwell).
        // Or one string's reading by its own last change: a string that
        // lags or stretches with the way it moved reads off along its own
        // direction, and the located point, which every string's reading
        // makes, follows the move.
        ("motion", _, _) => {
            let mut out = vec![slots.knotted(
                CorrectionTarget::Point,
                None,
                CorrectionDriver::Motion,
                None,
                &JOINT_KNOTS,
            )];
            out.extend((0..m).map(|s| {
                slots.signed(
                    (CorrectionTarget::StringReading, Some(s)),
                    (CorrectionDriver::StringMove, Some(s)),
                )
            }));
            out
        }
        ("configuration", None, None) if m == 0 => slots.by_line_of_sight(),
        ("string", _, Some(s)) if s <= m => slots.by_string_length(s - 1),
        // Only the robot side's excess: no test said what drives it, so
        // any joint's angle as a function of any joint's, and T moved as a
        // function of where it is.
        ("robot", None, None) => slots.on_the_robot_side(),
        _ => Vec::new(),
    };
    out.retain(|f| !f.is_empty());
    out
}

/// The candidate families at each kind of place ([`families`]).
impl Slots<'_> {
    /// At joint `j`'s angle (0-based): an error of any joint's angle (its
    /// own, or another's it is coupled to) as a function of it, and its
    /// own angle periodically (a gear stage turning a non-integer number of
    /// times per joint revolution).
    fn at_joint(&self, j: usize) -> Vec<Vec<Kind>> {
        let mut out: Vec<Vec<Kind>> = (0..self.ctx.n_joints)
            .map(|t| {
                self.knotted(
                    CorrectionTarget::JointAngle,
                    Some(t),
                    CorrectionDriver::JointAngle,
                    Some(j),
                    &JOINT_KNOTS,
                )
            })
            .collect();
        out.push(self.periodic_scan(
            CorrectionTarget::JointAngle,
            Some(j),
            CorrectionDriver::JointAngle,
            Some(j),
        ));
        out
    }

    /// At the clock: T relative to the rig, or one string's zero (a
    /// string's error in time moves the located point too, so every
    /// string's residual follows the clock; cross-validation tells one
    /// string's reading, a third of the columns, from a displacement).
    fn in_time(&self) -> Vec<Vec<Kind>> {
        let m = self.ctx.anchors.len();
        let mut out = vec![
            self.clocked(CorrectionTarget::Point, None),
            self.clocked(CorrectionTarget::InstrumentScale, None),
        ];
        // Or every string's scale at once (sensors sharing one reference
        // that drifts).
        if m > 0 {
            out.push(self.clocked(CorrectionTarget::ReadingScale, None));
        }
        // Or the frame's shape (a frame racking or bowing as it warms,
        // settling unevenly: the anchors move unequally; an instrument
        // turning or stretching its space).
        out.extend(self.rig_shape(CorrectionDriver::Time));
        // Or the tool point in the flange frame (a probe growing with the
        // process's heat, a tool slipping in its holder): T moves as the
        // flange turns, which no function of the clock moving T relative
        // to the rig follows.
        out.push(self.clocked(CorrectionTarget::ToolPoint, None));
        // Or one joint's zero (a re-homing, a lost encoder count, a motor
        // warming): T moves as that joint turns, which no function of the
        // clock alone moving T can follow.
        for t in 0..self.ctx.n_joints {
            out.push(self.clocked(CorrectionTarget::JointAngle, Some(t)));
        }
        for s in 0..m {
            out.push(self.clocked(CorrectionTarget::StringReading, Some(s)));
            // Or its zero and scale (a cable creeping, a drum warming).
            out.push(self.clocked(CorrectionTarget::StringZeroScale, Some(s)));
            // Or a cycle (a sensor's electronics or spool following the
            // cell's heating cycle; a zero that creeps and resets): several
            // cycles need more knots than the poses hold.
            out.push(self.periodic_scan(
                CorrectionTarget::StringReading,
                Some(s),
                CorrectionDriver::Time,
                None,
            ));
        }
        out
    }

    /// At the temperature: T relative to the rig; or the instrument's scale
    /// (a string frame growing with the temperature, a tracker's range with
    /// the air's), the tool point in the flange frame, every string's
    /// scale, or the string frame's (the instrument's) shape.
    fn at_temperature(&self) -> Vec<Vec<Kind>> {
        let readings = (!self.ctx.anchors.is_empty()).then_some(CorrectionTarget::ReadingScale);
        let mut out: Vec<Vec<Kind>> = [
            CorrectionTarget::Point,
            CorrectionTarget::InstrumentScale,
            CorrectionTarget::ToolPoint,
        ]
        .into_iter()
        .chain(readings)
        .map(|target| {
            self.knotted(
                target,
                None,
                CorrectionDriver::Temperature,
                None,
                &CLOCK_KNOTS,
            )
        })
        .collect();
        out.extend(self.rig_shape(CorrectionDriver::Temperature));
        out
    }

    /// The string frame's shape by `driver` (the clock or the
    /// temperature), on a rig of four strings or more (three cannot tell
    /// the frame's shape from T's move), or with point data the measuring
    /// instrument's frame (a camera's extrinsics creeping, a tracker's
    /// stand twisting: the error changes in time by where T is), at
    /// [`RIG_SHAPE_KNOTS`]: nine coefficients a knot, and a frame deforms
    /// slowly.
    fn rig_shape(&self, driver: CorrectionDriver) -> Option<Vec<Kind>> {
        let m = self.ctx.anchors.len();
        (m == 0 || m >= 4).then(|| {
            self.knotted(
                CorrectionTarget::RigShape,
                None,
                driver,
                None,
                &RIG_SHAPE_KNOTS,
            )
        })
    }

    /// The string frame deflected out of its plane by the strings' pull
    /// (a frame bending or twisting under the strings, or on soft legs):
    /// a symmetric compliance between the anchors. Four strings or more:
    /// with three, any reading error is a displacement of the located
    /// point. At most nine strings: beyond, its coefficients pass the
    /// alias check's bound, which would drop a row of them as if it were
    /// a constant ([`own_columns`]).
    fn frame_deflection(&self) -> Option<Vec<Kind>> {
        let m = self.ctx.anchors.len();
        (m >= 4 && m * (m + 1) / 2 <= ALIAS_CHECK_MAX_COLUMNS)
            .then(|| vec![Kind::frame_deflection(m)])
    }

    /// Over the workspace: T's displacement as a function of one
    /// coordinate of where T is, Cartesian or, for an instrument at the
    /// rig's origin, its own angles and distance.
    fn over_workspace(&self) -> Vec<Vec<Kind>> {
        let m = self.ctx.anchors.len();
        let mut out: Vec<Vec<Kind>> = (0..WORKSPACE_COORDINATES)
            .map(|c| {
                self.knotted(
                    CorrectionTarget::Point,
                    None,
                    CorrectionDriver::Workspace,
                    Some(c),
                    &JOINT_KNOTS,
                )
            })
            .collect();
        // Or one string's reading as a function of where T is (its exit
        // walking along its drum as the string pays out, its eyelet's
        // friction by where the string points): with four strings one
        // string's error moves the located point too, so the string is
        // known only by whose reading the field fits.
        for s in 0..m {
            for c in 0..3 {
                out.push(self.knotted(
                    CorrectionTarget::StringReading,
                    Some(s),
                    CorrectionDriver::Workspace,
                    Some(c),
                    &JOINT_KNOTS,
                ));
            }
            // Or its zero and scale by where it points (its exit walking
            // along its drum as it pays out).
            out.push(to_aim(s));
        }
        // Or the string frame deflecting by where T draws the strings.
        out.extend(self.frame_deflection());
        // With point data the rig's origin is the instrument's: its angle
        // and range errors as functions of its own angles and distance, in
        // the directions that turn with them.
        if m == 0 {
            for c in 3..WORKSPACE_COORDINATES {
                out.push(self.knotted(
                    CorrectionTarget::PointSpherical,
                    None,
                    CorrectionDriver::Workspace,
                    Some(c),
                    &JOINT_KNOTS,
                ));
            }
        }
        out
    }

    /// At string `s`'s direction (0-based): its reading by its direction
    /// from its anchor (wrap or friction at its exit, eyelet or pulley),
    /// by the angle from its mean direction over the train poses; or any
    /// string's zero and scale by where it points (with four strings one
    /// string's error moves the located point too, so the string the place
    /// names may be another's).
    fn by_string_direction(&self, s: usize) -> Vec<Vec<Kind>> {
        let mut out = self.by_direction(s);
        out.extend((0..self.ctx.anchors.len()).map(to_aim));
        out
    }

    /// Joint `j`'s (0-based) angle as a periodic function of the direction
    /// of its and a neighbouring joint's last move (one family per
    /// neighbour; [`CorrectionDriver::MoveDirection`]): the play of a drive
    /// that turns both takes the side of a combination of the two moves,
    /// a step round that circle, which the knot counts the scan screens
    /// ([`knots_per_period`]) approximate.
    fn by_move_direction(&self, j: usize) -> Vec<Vec<Kind>> {
        let n = self.ctx.n_joints;
        let turn = std::f64::consts::TAU;
        [j.checked_sub(1), (j + 1 < n).then_some(j)]
            .into_iter()
            .flatten()
            .map(|pair| {
                vec![periodic(
                    (CorrectionTarget::JointAngle, Some(j)),
                    (CorrectionDriver::MoveDirection, Some(pair)),
                    turn,
                    [-turn / 2.0, turn / 2.0],
                    SCAN_KNOTS,
                )]
            })
            .collect()
    }

    /// Where only the robot side's excess placed the remainder: every
    /// joint's angle as a function of every joint's (without the periodic
    /// scans), and T's displacement as a function of each coordinate of
    /// where it is.
    fn on_the_robot_side(&self) -> Vec<Vec<Kind>> {
        let n = self.ctx.n_joints;
        let mut out: Vec<Vec<Kind>> = (0..n)
            .flat_map(|j| {
                (0..n).map(move |t| {
                    self.knotted(
                        CorrectionTarget::JointAngle,
                        Some(t),
                        CorrectionDriver::JointAngle,
                        Some(j),
                        &JOINT_KNOTS,
                    )
                })
            })
            .collect();
        out.extend((0..3).map(|c| {
            self.knotted(
                CorrectionTarget::Point,
                None,
                CorrectionDriver::Workspace,
                Some(c),
                &JOINT_KNOTS,
            )
        }));
        out
    }

    /// Each string's reading as a smooth function of joint `j`'s (0-based)
    /// gravity torque, a family per string; none without link masses.
    fn strings_by_load(&self, j: usize) -> Vec<Vec<Kind>> {
        if !self.ctx.has_masses {
            return vec![];
        }
        (0..self.ctx.anchors.len())
            .map(|s| {
                self.knotted(
                    CorrectionTarget::StringReading,
                    Some(s),
                    CorrectionDriver::GravityTorque,
                    Some(j),
                    &MOVE_KNOTS,
                )
            })
            .collect()
    }

    /// Joint `j`'s (0-based) angle as a smooth function of the change of
    /// its gravity torque over the last move (a drive creeping or winding
    /// up under load lags that change); none without link masses.
    fn by_load_change(&self, j: usize) -> Vec<Vec<Kind>> {
        if !self.ctx.has_masses {
            return vec![];
        }
        vec![self.knotted(
            CorrectionTarget::JointAngle,
            Some(j),
            CorrectionDriver::GravityTorqueChange,
            Some(j),
            &MOVE_KNOTS,
        )]
    }

    /// Point data, placed by the line of sight in the flange frame: the
    /// point off in the instrument's own directions (its range above all)
    /// by one component of that line of sight.
    fn by_line_of_sight(&self) -> Vec<Vec<Kind>> {
        (0..3)
            .map(|c| {
                self.knotted(
                    CorrectionTarget::PointSpherical,
                    None,
                    CorrectionDriver::LineOfSight,
                    Some(c),
                    &JOINT_KNOTS,
                )
            })
            .collect()
    }

    /// At string `s`'s length (0-based): its reading as a function of it,
    /// smooth or periodic (a drum's winding pitch, a spool's eccentricity:
    /// many cycles over the range would need more knots than the poses
    /// hold).
    fn by_string_length(&self, s: usize) -> Vec<Vec<Kind>> {
        vec![
            self.knotted(
                CorrectionTarget::StringReading,
                Some(s),
                CorrectionDriver::StringLength,
                Some(s),
                &JOINT_KNOTS,
            ),
            self.periodic_scan(
                CorrectionTarget::StringReading,
                Some(s),
                CorrectionDriver::StringLength,
                Some(s),
            ),
        ]
    }
}

/// Knot counts of one length's growth in the thermal driver: linear (two
/// knots, as expansion is), or a curve that bends (a warm-up settling).
const LENGTH_KNOTS: [usize; 3] = [2, 3, 4];

/// One family per length of the model ([`Context::lengths`]): that length
/// alone changing as a function of `driver` (the temperature or the
/// clock), what a link that grows unlike the others needs.
///
/// [`Context::lengths`]: crate::physics::effects::Context::lengths
pub(super) fn length_families(inputs: &Inputs, driver: CorrectionDriver) -> Vec<Vec<Kind>> {
    let slots = Slots::of(inputs, &[]);
    inputs
        .ctx
        .lengths
        .iter()
        .map(|&(k, _)| {
            slots.knotted(
                CorrectionTarget::LinkLength,
                Some(k),
                driver,
                None,
                &LENGTH_KNOTS,
            )
        })
        .filter(|f| !f.is_empty())
        .collect()
}

/// The candidates where joint `j` (0-based) kept a backlash: its angle
/// corrected by a smooth function of its signed last move (friction or
/// wind-up that stops a drive short by an amount graded with the move),
/// and, competing with it, T moved along the move that led to the pose by
/// a function of its length (an arm not settled at the dwell, which a
/// backlash also takes part of), at every knot count the train poses allow.
pub(super) fn move_families(inputs: &Inputs, j: usize) -> Vec<Vec<Kind>> {
    let slots = Slots::of(inputs, &[]);
    vec![
        slots.knotted(
            CorrectionTarget::JointAngle,
            Some(j),
            CorrectionDriver::JointMove,
            Some(j),
            &MOVE_KNOTS,
        ),
        slots.knotted(
            CorrectionTarget::Point,
            None,
            CorrectionDriver::Motion,
            None,
            &JOINT_KNOTS,
        ),
    ]
}

/// The candidates of string `s`'s (0-based) reading as a smooth function
/// of its direction from its anchor ([`Slots::by_direction`]), at every
/// knot count the train poses allow: what an anchor step is tested
/// against.
pub(super) fn direction_families(inputs: &Inputs, s: usize) -> Vec<Vec<Kind>> {
    let slots = Slots::of(inputs, &[]);
    slots.by_direction(s)
}

/// The candidates where joint `j` (0-based) kept a compliance: its angle
/// corrected by a smooth function of its gravity torque, and the same
/// jumping where the torque changes sign (a play gravity takes up), at
/// every knot count the train poses allow. Empty without link masses.
pub(super) fn load_families(inputs: &Inputs, j: usize) -> Vec<Vec<Kind>> {
    if !inputs.ctx.has_masses {
        return Vec::new();
    }
    let slots = Slots::of(inputs, &[]);
    let family = slots.signed(
        (CorrectionTarget::JointAngle, Some(j)),
        (CorrectionDriver::GravityTorque, Some(j)),
    );
    vec![family].into_iter().filter(|f| !f.is_empty()).collect()
}

/// Knot counts of a correction by a joint's last move: an odd, saturating
/// shape (a stop short growing with the move, then bounded) needs few.
const MOVE_KNOTS: [usize; 4] = [3, 4, 6, 8];

/// Knots per period of the periodic corrections scanned over their period;
/// the best few periods are tried again at [`PERIODIC_KNOTS`].
const SCAN_KNOTS: usize = 4;
/// Knots per period tried at the best periods of the scan.
const PERIODIC_KNOTS: [usize; 3] = [4, 6, 8];
/// Knots per period tried for a periodic correction by `driver`: a step
/// round the circle of a move's direction (the side a drive turning two
/// joints last turned) needs knots close to its edges, which wherever the
/// edges fall takes more of them than a smooth cycle does.
fn knots_per_period(driver: CorrectionDriver) -> &'static [usize] {
    if driver == CorrectionDriver::MoveDirection {
        &MOVE_DIRECTION_KNOTS
    } else {
        &PERIODIC_KNOTS
    }
}
/// Knots per turn of a move's direction ([`knots_per_period`]).
const MOVE_DIRECTION_KNOTS: [usize; 4] = [4, 8, 12, 16];
/// How many of the scan's best periods (by [`FixedBase::drop_alone`]) are
/// fitted and cross-validated at every knot count.
const SCREENED_PERIODS: usize = 3;

/// A periodic correction of `(target, index)` by `(driver, index)` of
/// `period` with `k` knots evenly spaced over it, fitted where the driver
/// covered `range`.
fn periodic(
    (target, target_index): (CorrectionTarget, Option<usize>),
    (driver, driver_index): (CorrectionDriver, Option<usize>),
    period: f64,
    range: [f64; 2],
    k: usize,
) -> Kind {
    Kind::DataDriven {
        target,
        target_index,
        driver,
        driver_index,
        knots: (0..k).map(|i| period * i as f64 / k as f64).collect(),
        period: Some(period),
        range: Some(range),
        axis: None,
    }
}

/// A family of periodic candidates of one scalar (a joint's angle, a
/// string's reading) screened: the [`SCREENED_PERIODS`]
/// periods whose correction alone would take most from the residual, at
/// every knot count of [`knots_per_period`] (a sinusoid needs few knots, a
/// sharper shape more). Fitting every period scanned beside the whole
/// model would cost a long session seconds.
fn screened(inputs: &Inputs, fixed: &FixedBase, family: &[Kind]) -> Vec<Kind> {
    let Some(first) = family.first() else {
        return vec![];
    };
    let patterns = fixed.pose_patterns(inputs, first);
    let mut by_drop: Vec<(f64, &Kind)> = family
        .iter()
        .map(|k| (fixed.drop_alone(inputs, k, &patterns), k))
        .collect();
    by_drop.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut out = Vec::new();
    for (_, kind) in by_drop.into_iter().take(SCREENED_PERIODS) {
        let Kind::DataDriven {
            target,
            target_index,
            driver,
            driver_index,
            period: Some(p),
            range: Some(r),
            ..
        } = kind
        else {
            continue;
        };
        for &k in knots_per_period(*driver) {
            out.push(periodic(
                (*target, *target_index),
                (*driver, *driver_index),
                *p,
                *r,
                k,
            ));
        }
    }
    out
}

/// `k` knots at quantiles of `values` (their ends the smallest and the
/// largest), distinct; `None` when fewer than two distinct remain.
fn knots_at_quantiles(values: &[f64], k: usize) -> Option<Vec<f64>> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.len() < 2 || k < 2 {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let mut knots: Vec<f64> = (0..k).map(|i| v[(i * (v.len() - 1)) / (k - 1)]).collect();
    knots.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * (1.0 + b.abs()));
    (knots.len() >= 2 && knots.len() == k).then_some(knots)
}

/// The data-driven `kinds` again, each with a jump at each of `at` (see
/// [`with_jumps`]; `values` the driver's at every pose); those where no
/// jump falls inside the driver's range are left out.
fn jumping(kinds: &[Kind], values: &[f64], at: &[f64]) -> Vec<Kind> {
    kinds
        .iter()
        .filter_map(|k| {
            let Kind::DataDriven { knots, .. } = k else {
                return None;
            };
            let knots = with_jumps(knots, values, at)?;
            let mut k = k.clone();
            if let Kind::DataDriven { knots: kk, .. } = &mut k {
                *kk = knots;
            }
            Some(k)
        })
        .collect()
}

/// `knots` (of a function of some driver) with a jump at each of `at`:
/// two knots a quarter and three quarters of the way from the last of
/// `values` (the driver at every pose) at or below the jump to the first
/// above it, so that no pose falls between them. `None` when no jump lies
/// inside the driver's range.
fn with_jumps(knots: &[f64], values: &[f64], at: &[f64]) -> Option<Vec<f64>> {
    let mut out = knots.to_vec();
    let mut jumped = false;
    for &x0 in at {
        let below = values
            .iter()
            .copied()
            .filter(|&v| v <= x0)
            .fold(f64::NEG_INFINITY, f64::max);
        let above = values
            .iter()
            .copied()
            .filter(|&v| v > x0)
            .fold(f64::INFINITY, f64::min);
        if !(below.is_finite() && above.is_finite()) {
            continue;
        }
        let gap = above - below;
        out.retain(|&k| k <= below || k >= above);
        out.push(below + 0.25 * gap);
        out.push(below + 0.75 * gap);
        jumped = true;
    }
    out.sort_by(f64::total_cmp);
    out.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * (1.0 + b.abs()));
    jumped.then_some(out)
}

/// The columns of effect `kind` (starting at `at`) that are fitted beside
/// `base`: those not aliased with it; for a correction of many columns,
/// all but its first knot's (see [`ALIAS_CHECK_MAX_COLUMNS`]).
fn own_columns(a: &DMatrix<f64>, base: &[usize], kind: &Kind, at: usize) -> Vec<usize> {
    own_columns_by(kind, at, |own| unaliased(a, base, own))
}

/// [`own_columns`] with the alias check `unaliased` (of the columns
/// given, in order: those kept).
fn own_columns_by(
    kind: &Kind,
    at: usize,
    unaliased: impl FnOnce(&[usize]) -> Vec<usize>,
) -> Vec<usize> {
    let own: Vec<usize> = (at..at + kind.n_coef()).collect();
    if own.len() <= ALIAS_CHECK_MAX_COLUMNS {
        return unaliased(&own);
    }
    let per_knot = match kind {
        Kind::DataDriven { knots, .. } => kind.n_coef() / knots.len().max(1),
        _ => 1,
    };
    own[per_knot..].to_vec()
}

/// A candidate's linearised fit: the problem it was built on, its normal
/// equations, the columns fitted and their cross-validated SSE.
struct Linearised<'a> {
    problem: EffectProblem<'a>,
    nm: Normals,
    a: DMatrix<f64>,
    b: Vec<f64>,
    rr: f64,
    base: Vec<usize>,
    cols: Vec<usize>,
    cv: f64,
    cv0: f64,
}

/// The candidate `kind` linearised with the geometry and the accepted
/// effects (their rows made once, in `fixed`); `None` when all its columns
/// are aliased or it does not solve.
fn linearise<'a>(
    inputs: &'a Inputs,
    fixed: &FixedBase,
    state: &State,
    kind: &Kind,
) -> Option<Linearised<'a>> {
    let Inputs { obs, ctx, free, .. } = inputs;
    let problem = EffectProblem::of_observations(
        obs,
        ctx,
        obs.train.clone(),
        &state.p,
        free.clone(),
        with_candidate(&state.accepted, kind),
    );
    let nm = fixed.with(inputs, kind);
    let (a, b, rr) = nm.total();
    let held = inputs.held_columns(state.accepted.iter().map(|e| &e.kind).chain([kind]));
    let base: Vec<usize> = (0..fixed.n_base).filter(|c| !held.contains(c)).collect();
    let cols = own_columns(&a, &base, kind, fixed.n_base);
    if cols.is_empty() {
        return None;
    }
    let mut all = base.clone();
    all.extend(&cols);
    let cv = cv_sse(&nm, &a, &b, &all);
    Some(Linearised {
        problem,
        nm,
        a,
        b,
        rr,
        base,
        cols,
        cv,
        cv0: fixed.cv0,
    })
}

/// The cross-validated SSE of [`linearise`] (`None` where it gives
/// none), by block elimination against the base factored once
/// ([`FixedBase::factors`]) rather than from the candidate's whole normal
/// equations: the score every candidate of a place gets.
///
/// A correction by knots (every target but the frame's shape and its
/// deflection) has its blocks from its target's patterns
/// ([`FixedBase::target_patterns`]), kept in `patterns` for the next
/// candidate of the same target (a family's knot counts come together).
fn cross_validated(
    inputs: &Inputs,
    fixed: &FixedBase,
    state: &State,
    kind: &Kind,
    patterns: &mut Option<(Kind, TargetPatterns)>,
) -> Option<f64> {
    let held = inputs.held_columns(state.accepted.iter().map(|e| &e.kind).chain([kind]));
    let base: Vec<usize> = (0..fixed.n_base).filter(|c| !held.contains(c)).collect();
    let factors = fixed.factors(&base);
    let app = match by_knots(kind) {
        Some(probe) => {
            if patterns.as_ref().is_none_or(|(p, _)| *p != probe) {
                let t = fixed.target_patterns(inputs, &probe);
                *patterns = Some((probe, t));
            }
            let (_, t) = patterns.as_ref()?;
            fixed.appended_by_weights(inputs, t, kind)
        }
        None => fixed.appended(inputs, kind),
    };
    // Columns as indices into the candidate's own block.
    let cols = own_columns_by(kind, 0, |own| factors.unaliased(&app, own));
    if cols.is_empty() {
        return None;
    }
    Some(factors.cv_sse(&fixed.nm, &app, &cols))
}

/// What a correction by knots is made of at every pose, whatever its
/// knots (its target and driver; see [`cross_validated`]); `None` for a
/// named effect and for the frame's shape and deflection, whose
/// coefficients are not knots' hat weights times one pattern.
fn by_knots(kind: &Kind) -> Option<Kind> {
    match kind {
        Kind::DataDriven {
            target: CorrectionTarget::RigShape | CorrectionTarget::FrameDeflection,
            ..
        } => None,
        Kind::DataDriven {
            target,
            target_index,
            driver,
            driver_index,
            ..
        } => Some(Kind::DataDriven {
            target: *target,
            target_index: *target_index,
            driver: *driver,
            driver_index: *driver_index,
            knots: vec![],
            period: None,
            range: None,
            axis: None,
        }),
        _ => None,
    }
}

/// The candidates `families` stand for: each family's own, then the
/// aimed ones of each [`to_aim`] placeholder ([`aimed`]), then the periods
/// each periodic scan keeps ([`screened`]), in that order.
fn expanded(inputs: &Inputs, fixed: &FixedBase, families: &[Vec<Kind>]) -> Vec<Kind> {
    let is_scan = |f: &Vec<Kind>| {
        matches!(
            f.first(),
            Some(Kind::DataDriven {
                period: Some(_),
                ..
            })
        )
    };
    let is_aim = |f: &Vec<Kind>| {
        matches!(
            f.first(),
            Some(Kind::DataDriven {
                target: CorrectionTarget::StringZeroScale,
                driver: CorrectionDriver::StringDirection,
                ..
            })
        )
    };
    let mut candidates: Vec<Kind> = families
        .iter()
        .filter(|f| !is_scan(f) && !is_aim(f))
        .flatten()
        .cloned()
        .collect();
    for f in families.iter().filter(|f| is_aim(f)) {
        candidates.extend(f.first().map_or(vec![], |k| aimed(inputs, fixed, k)));
    }
    for f in families.iter().filter(|f| is_scan(f)) {
        candidates.extend(screened(inputs, fixed, f));
    }
    candidates
}

/// The best candidate of `families` by cross-validated SSE, through the
/// held-out gate; kept: its finding written and `state` moved to it.
pub(super) fn try_place(
    inputs: &Inputs,
    state: &mut State,
    families: &[Vec<Kind>],
    place: &Place,
) -> bool {
    // Ranked by cross-validation; only the scores are kept (the normal
    // equations of a long session's many-knot candidates are large), and
    // the best that also solves in full is linearised again.
    let fixed = FixedBase::new(inputs, state);
    let score = |kinds: &mut dyn Iterator<Item = &Kind>| -> Vec<(Kind, f64)> {
        let mut patterns = None;
        kinds
            .filter_map(|k| {
                cross_validated(inputs, &fixed, state, k, &mut patterns).map(|cv| (k.clone(), cv))
            })
            .filter(|(_, cv)| cv.is_finite() && *cv < fixed.cv0)
            .collect()
    };
    let candidates = expanded(inputs, &fixed, families);
    let mut ranked = score(&mut candidates.iter());
    ranked.sort_by(|x, y| x.1.total_cmp(&y.1));
    let Some((kind, lin, (p_new, eff_new, fit))) = ranked.into_iter().find_map(|(k, _)| {
        let l = linearise(inputs, &fixed, state, &k)?;
        let s = stepped(&l)?;
        Some((k, l, s))
    }) else {
        return false;
    };
    let (p_new, eff_new, fit) = refined(inputs, (p_new, eff_new, fit));
    let Inputs { obs, ctx, .. } = inputs;
    let cand = Candidate {
        kind: kind.clone(),
        scanned: 1,
        what: format!("a data-driven correction at the {} place", place.driver),
    };
    let before = Before::now(inputs, state);
    let held = match gates::held_out(
        inputs,
        &before,
        std::slice::from_ref(&cand),
        &p_new,
        &eff_new,
    ) {
        Ok(h) => h,
        Err(turned) => {
            state.notes.extend(turned.note);
            return false;
        }
    };
    let k = eff_new.len() - 1;
    let e = eff_new[k].clone();
    let at: usize = eff_new[..k].iter().map(|e| e.kind.n_coef()).sum();
    let (mag, sig, unit) = magnitude(ctx, obs, &e, &fit.block(at, e.kind.n_coef()));
    let Kind::DataDriven { driver, knots, .. } = &e.kind else {
        return false;
    };
    let usable = compensation_use::words(&e.kind, ctx.anchors.is_empty());
    let shape = match e.kind {
        Kind::DataDriven {
            period: Some(_),
            driver: CorrectionDriver::MoveDirection,
            ..
        } => format!("periodic, {} knots round the turn", knots.len()),
        Kind::DataDriven {
            period: Some(p),
            driver_index,
            ..
        } => format!(
            "periodic, {} knots per period of {} (the period scanned from two to {} cycles over the range)",
            knots.len(),
            crate::physics::effects::correction_driver_amount(*driver, driver_index, p),
            periodogram::MAX_CYCLES
        ),
        // Its knots are the anchors: only the family was chosen.
        Kind::DataDriven {
            target: CorrectionTarget::FrameDeflection,
            ..
        } => format!("{} coefficients", e.kind.n_coef()),
        _ => format!("{} knots", knots.len()),
    };
    let evidence = format!(
        "{shape}, chosen by 5-fold cross-validation on the train poses (cross-validated SSE {:.4} -> {:.4} mm^2 over {} readings); held-out RMS per reading {:.4} -> {:.4} mm (paired z = {:.1}), 3-D {:.4} -> {:.4} mm; {usable}",
        lin.cv0,
        lin.cv,
        lin.nm.rows,
        held.rb,
        held.ra,
        held.gain_z,
        before.test_rms,
        held.test_after,
    );
    state.findings.push(Finding {
        effect: e.kind.name().into(),
        joint: e.kind.joint().map(|j| j + 1),
        sensor: e.kind.sensor().map(|s| s + 1),
        magnitude: mag,
        sigma: sig,
        unit,
        explanation: explanation(ctx, &eff_new[..k], &e.kind),
        evidence,
        test_rms_before_mm: before.test_rms,
        test_rms_after_mm: held.test_after,
        parameters: Some(FindingModel::Effect(EffectParameters::new(e))),
        evidence_plot: evidence_plot(obs, ctx, &p_new, &eff_new, k),
    });
    state.p = p_new;
    state.accepted = eff_new;
    state.final_fit = Some(fit);
    true
}

/// What a kept correction is, in words; one in a slot (target and
/// driver) an earlier round corrected says that the two are one function,
/// their sum (the later round, on what the first left, chose its own
/// knots).
fn explanation(
    ctx: &crate::physics::effects::Context,
    earlier: &[EffectModel],
    kind: &Kind,
) -> String {
    let words = kind.explanation(ctx);
    if earlier
        .iter()
        .any(|e| e.kind.is_data_driven() && super::candidates::same_slot(&e.kind, kind))
    {
        format!(
            "{words}; it adds to an earlier correction of the same target by the same driver: together they are one function of the driver, their sum"
        )
    } else {
        words
    }
}

/// The whole model (`state`'s geometry and effects) refit by one
/// linearised step, with its covariance: every free geometric column and
/// every effect column not aliased with the geometry (the constant part
/// of a correction is a zero offset the geometry holds). What the
/// findings are restated from once a correction is in.
pub(super) fn linear_refit(
    inputs: &Inputs,
    state: &State,
) -> Option<(Vec<f64>, Vec<EffectModel>, FitInfo)> {
    linear_refit_at(inputs, &state.p, &state.accepted)
}

/// [`linear_refit`] from the geometry `p` with `accepted`.
fn linear_refit_at(
    inputs: &Inputs,
    p: &[f64],
    accepted: &[EffectModel],
) -> Option<(Vec<f64>, Vec<EffectModel>, FitInfo)> {
    let Inputs {
        obs,
        ctx,
        free,
        fold_of,
    } = inputs;
    let problem = EffectProblem::of_observations(
        obs,
        ctx,
        obs.train.clone(),
        p,
        free.clone(),
        accepted.to_vec(),
    );
    let x0 = problem.x0();
    let nm = normals(&problem, &x0, fold_of);
    let (a, b, rr) = nm.total();
    let held = inputs.held_columns(accepted.iter().map(|e| &e.kind));
    let base: Vec<usize> = (0..free.len()).filter(|c| !held.contains(c)).collect();
    let mut cols: Vec<usize> = Vec::new();
    let mut at = free.len();
    for e in accepted {
        let mut fixed = base.clone();
        fixed.extend(&cols);
        cols.extend(own_columns(&a, &fixed, &e.kind, at));
        at += e.kind.n_coef();
    }
    stepped(&Linearised {
        problem,
        nm,
        a,
        b,
        rr,
        base,
        cols,
        cv: f64::NAN,
        cv0: f64::NAN,
    })
}

/// The fit `(p, effects, info)` of one linearised step, stepped once more
/// from where it ended when that lowers the train readings' residual: a
/// correction that frees a shape the geometry held (the tool point moving
/// with the clock lets the wrist's offsets trade with it) can move angles
/// far enough that the first step, linearised before it, mispredicts.
fn refined(
    inputs: &Inputs,
    fit: (Vec<f64>, Vec<EffectModel>, FitInfo),
) -> (Vec<f64>, Vec<EffectModel>, FitInfo) {
    let Some(again) = linear_refit_at(inputs, &fit.0, &fit.1) else {
        return fit;
    };
    if train_sse(inputs, &again.0, &again.1) < train_sse(inputs, &fit.0, &fit.1) {
        again
    } else {
        fit
    }
}

/// The train readings' sum of squared residuals of the model `(p,
/// effects)`, evaluated in full (not linearised).
fn train_sse(inputs: &Inputs, p: &[f64], effects: &[EffectModel]) -> f64 {
    let problem = EffectProblem::of_observations(
        inputs.obs,
        &inputs.ctx,
        inputs.obs.train.clone(),
        p,
        vec![],
        effects.to_vec(),
    );
    let mut sse = 0.0;
    problem.residuals(&problem.x0(), |_, r| sse += r * r);
    sse
}

/// One Gauss-Newton step on the base and the candidate's columns from the
/// current fit: the geometry, the accepted effects and the correction
/// jointly, with the covariance of every effect coefficient and the
/// geometric sigmas. The correction is linear in its coefficients and the
/// rest already sits at its optimum, so one step is the fit (an LM refit
/// of up to 200 coefficients over a large session would cost seconds for
/// nothing).
fn stepped(lin: &Linearised) -> Option<(Vec<f64>, Vec<EffectModel>, FitInfo)> {
    let mut all = lin.base.clone();
    all.extend(&lin.cols);
    let (drop, delta) = solve_subset(&lin.a, &lin.b, &all)?;
    let mut x = lin.problem.x0();
    for (k, &c) in all.iter().enumerate() {
        x[c] += delta[k];
    }
    let (p_new, eff_new) = lin.problem.unpack(&x);
    // Covariance: s² (JᵀJ)⁻¹ over the fitted columns, zero for aliased ones.
    let dof = (lin.nm.rows as f64 - all.len() as f64).max(1.0);
    let s2 = ((lin.rr - drop) / dof).max(0.0);
    // Inverted as `solve_subset` solves: scaled to a unit diagonal, with
    // the same tiny jitter, so that what solved also has a covariance.
    let k = all.len();
    let d: Vec<f64> = all
        .iter()
        .map(|&c| lin.a[(c, c)].sqrt().max(1e-300))
        .collect();
    let mut sub = DMatrix::from_fn(k, k, |i, j| lin.a[(all[i], all[j])] / (d[i] * d[j]));
    for i in 0..k {
        sub[(i, i)] += 1e-12;
    }
    let scaled = sub.cholesky()?.inverse();
    let inv = DMatrix::from_fn(k, k, |i, j| scaled[(i, j)] / (d[i] * d[j]));
    let n_free = lin.problem.free.len();
    let n_coef = x.len() - n_free;
    let pos = |c: usize| all.iter().position(|&a| a == c);
    let cov_last = DMatrix::from_fn(n_coef, n_coef, |i, j| {
        match (pos(n_free + i), pos(n_free + j)) {
            (Some(a), Some(b)) => s2 * inv[(a, b)],
            _ => 0.0,
        }
    });
    let sigma_free = (0..n_free)
        .map(|c| pos(c).map_or(0.0, |a| (s2 * inv[(a, a)]).max(0.0).sqrt()))
        .collect();
    Some((
        p_new,
        eff_new,
        FitInfo {
            cov_last,
            sigma_free,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::with_jumps;

    #[test]
    fn a_jump_is_two_knots_between_the_poses_either_side_of_it() {
        let times = [0.0, 10.0, 20.0, 30.0, 40.0];
        let knots = with_jumps(&[0.0, 20.0, 40.0], &times, &[25.0]).unwrap();
        // The last pose before the jump is at 20 s, the first after at 30 s.
        assert_eq!(knots, vec![0.0, 20.0, 22.5, 27.5, 40.0]);
        // A jump outside the session adds nothing.
        assert_eq!(with_jumps(&[0.0, 40.0], &times, &[50.0]), None);
    }
}
