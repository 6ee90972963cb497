//! Whether and where compensation can use a data-driven correction, in
//! words a user acts on: a function of joint angles or of where T is can
//! be applied inside the range the poses covered; a function of this
//! session's clock, temperature or moves describes the session, not a
//! future target; a correction of the readings corrects the measurement,
//! not the robot. Each sentence also says what to check.

use crate::physics::effects::{CorrectionDriver as D, CorrectionTarget as T, Kind};

/// Whether and where compensation can use a data-driven correction `kind`,
/// in words (`point_data`: the session had no strings, so a field over
/// the workspace cannot be told from the instrument's own distortion).
/// Empty for a named effect. The arms are tried in order: the first that
/// matches the correction's target and driver says it.
pub(super) fn words(kind: &Kind, point_data: bool) -> String {
    let Kind::DataDriven {
        target,
        driver,
        target_index,
        driver_index,
        ..
    } = kind
    else {
        return String::new();
    };
    // The session's condition a correction by the clock or the
    // temperature followed.
    let history = if *driver == D::Temperature {
        "temperature"
    } else {
        "clock"
    };
    match (*target, *driver, *target_index, *driver_index) {
        (T::FrameDeflection, ..) => "compensation does not need it: it corrects what the strings read, not where the robot went; the string frame deflects by where T draws the strings (its anchors move unequally with T's position, as a frame bending or twisting under the strings' pull does): stiffen or brace the frame (diagonals, a stiffer corner or post), or lower the strings' spring tension".into(),
        (t, D::Workspace, ..) if t != T::StringReading => in_workspace(kind, point_data),
        (t, D::JointAngle, ..) if t != T::StringReading => by_joint_angles(kind),
        (T::LinkLength, d, i, _) => format!(
            "compensation does not apply it: it follows this session's {} history; {} grew unlike the other lengths: check that link (its material, a motor or drive warming it, a loose joint in it), or calibrate at the temperature the robot works at",
            if d == D::Temperature {
                "temperature"
            } else {
                "clock (a warm-up)"
            },
            crate::physics::effects::length_name(i)
        ),
        (T::InstrumentScale, ..) => "compensation does not need it: it corrects the measuring instrument's scale, not where the robot went; the rig's frame (or a tracker's range, with the air) changed with this session's conditions: hold the instrument's temperature steady, give a tracker the air's temperature and pressure, or measure the rig again at the temperature it is used at".into(),
        (T::ReadingScale, ..) => "compensation does not need it: it corrects what every string read, not where the robot went; all the strings' readings drifted in proportion with this session's conditions, as sensors sharing one reference do (a potentiometers' excitation voltage warming up or wandering, a counter's clock): check the sensors' common supply or reference, let it warm up before measuring, or log it".into(),
        (T::ToolPoint, ..) => format!(
            "compensation cannot use it: the tool point changed with this session's {} (a probe growing with the heat of the process it carries, a tool slipping in its holder or re-seated), which a future target does not carry; check the tool's mounting and its temperature, then measure the tool point again (or re-calibrate) under the conditions it works in",
            history
        ),
        (_, D::LineOfSight, ..) => "compensation does not apply it: it follows how the target faces the instrument, which a target read off its centre by an amount that turns with it gives (a reflector whose vertex is off its sphere's centre, a photogrammetric target seen at steep angles), and which point data alone cannot tell from an error of the robot's that follows the flange's orientation towards the instrument; check the target (replace or characterise it, keep it facing the instrument) and, if the correction stays, measure with another target".into(),
        (T::StringReading, D::GravityTorque, Some(s), Some(j)) => format!(
            "compensation does not need it: it corrects what string {} read, not where the robot went; the reading follows joint {}'s load, as interference from that joint's motor in the string's signal would (it grows with the current that holds the load): route and shield the string's cable away from that motor's, and check its grounding",
            s + 1,
            j + 1
        ),
        (t, D::GravityTorque, ..) if t != T::StringReading => "compensation does not apply it: it follows the joint's gravity load at the target (its angles and the payload), which compensation does not yet evaluate for a data-driven correction; the joint's error is not in proportion to its load as an elastic joint's is: check it for play that gravity takes up or a stiffness that changes with the load".into(),
        (_, D::MoveDirection, ..) => "compensation cannot use it: it depends on the moves that lead to a target, which the program that visits it decides, not the target; the joint's error follows the way it and its neighbour last moved together, as the play or friction of a drive that turns both would (a parallelogram's rod or belt, a coupled wrist): check that drive, or approach every target the same way".into(),
        (_, D::GravityTorqueChange, ..) => "compensation cannot use it: it depends on the load the joint carried at the pose before a target, which the program that visits it decides, not the target; the joint lags the change of its load as a drive that creeps or winds up under load would (a harmonic drive's flexspline relaxing during the dwell, friction holding part of its deflection): dwell longer before measuring, check the drive, or approach every target from the same load".into(),
        (_, D::JointMove, ..) => "compensation cannot use it: it depends on the move that leads to a target, which the program that visits it decides, not the target; the joint stops short by an amount that grows with the move: check its drive for friction or elastic wind-up (a brake dragging, a worn or preloaded gear, a soft coupling), or approach every target with the same move".into(),
        (T::JointPlay, _, Some(t), _) => format!(
            "compensation cannot use it: joint {}'s play changed with this session's {} (grease thinning as the drive warmed up, wear), which a future target does not carry; check that joint's drive for play and wear, warm the robot up before calibrating and before precise work, or approach every target from the same side",
            t + 1,
            history
        ),
        (T::JointAngle, _, Some(t), _) => format!(
            "compensation cannot use it: joint {}'s zero changed with this session's {} (a re-homing, a lost encoder count, a drive warming up), which a future target does not carry; check that joint's homing and encoder, then re-reference its zero or re-calibrate",
            t + 1,
            history
        ),
        (T::StringZeroScale, D::Time, Some(s), _) => format!(
            "compensation does not need it: it corrects what string {} read, not where the robot went; its zero and its scale changed during the session, long lengths more than short ones (a cable creeping under its spring's pull, a drum or cable warming): let the string settle under tension before measuring, check its cable and drum, or log their temperature",
            s + 1
        ),
        (T::RigShape, ..) if point_data => format!(
            "compensation does not need it: it corrects where the measuring instrument saw T, not where the robot went; the instrument's frame changed during the session with its {} by an amount that grows with where T is (a camera's mount or extrinsics creeping, a tracker's stand twisting or its head warming): let the instrument settle after mounting or re-tightening it, check its mount, and measure the robot again once it is stable",
            history
        ),
        (T::RigShape, ..) => format!(
            "compensation does not need it: it corrects what the strings read, not where the robot went; the string frame changed shape during the session with its {} (its anchors moved unequally: a frame racking, bowing or tilting as it warms, a post or a foot settling): brace the frame, let it reach the cell's temperature before measuring, and check its posts and feet",
            history
        ),
        (_, D::Motion, ..) => "compensation cannot use it: it depends on the move that leads to a target, which the program that visits it decides, not the target; T was measured before the arm settled: dwell longer at each pose or approach slower, and check the servo tuning".into(),
        _ if kind.robot_side() => "compensation cannot use it: it is a function of this session's clock or temperature history, not of a future target; find what changed during the session (the stand, the tracker, the temperature of the cell), keep it constant, or re-calibrate when it has settled".into(),
        _ => string_reading(),
    }
}

/// A correction of what one string read: the measurement's, not the
/// robot's.
fn string_reading() -> String {
    "compensation does not need it: it corrects what a string read, not where the robot went; check that string (its drum, its exit, its mounting)".into()
}

/// A field over the workspace (not of a string's reading): applied inside
/// the region the poses covered.
fn in_workspace(kind: &Kind, point_data: bool) -> String {
    let (lo, hi) = covered(kind);
    let beyond = kind.beyond_range();
    let (lo, hi, unit) = match kind {
        Kind::DataDriven {
            driver_index: Some(3 | 4),
            ..
        } => (lo.to_degrees(), hi.to_degrees(), "deg"),
        _ => (lo, hi, "mm"),
    };
    // Strings that agree place the displacement on the robot's side;
    // one instrument's points cannot.
    let caveat = if point_data {
        "; with point data alone a distortion of the measuring instrument cannot be told from one of the robot: unless the targets were defined with this instrument, measure again from another instrument position before relying on it"
    } else {
        ""
    };
    format!(
        "compensation applies it (a function of where T is), inside the region the poses covered ({lo:.1} to {hi:.1} {unit}; beyond it {beyond}, and compensation warns){caveat}"
    )
}

/// A function of a joint's angle (not of a string's reading): applied
/// inside the range the poses covered.
fn by_joint_angles(kind: &Kind) -> String {
    let (lo, hi) = covered(kind);
    let beyond = kind.beyond_range();
    format!(
        "compensation applies it (a function of joint angles), inside the range the poses covered ({:.1} to {:.1} deg; beyond it {beyond}, and compensation warns)",
        lo.to_degrees(),
        hi.to_degrees()
    )
}

/// The driver's range the fit covered (its first and last knot where the
/// fit did not record it).
fn covered(kind: &Kind) -> (f64, f64) {
    let knots = match kind {
        Kind::DataDriven { knots, .. } => knots.as_slice(),
        _ => &[],
    };
    kind.fitted_range()
        .unwrap_or((knots[0], knots[knots.len() - 1]))
}
