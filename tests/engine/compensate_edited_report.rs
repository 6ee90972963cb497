//! A report edited by hand (or damaged) before `drawcal compensate` reads
//! it: every index compensation relies on is checked first, and a bad one
//! is an error naming the field, never a panic or a silently dropped
//! effect. Found by a fuzzing run: a finding's joint index past the
//! robot's joints, joint limits in the wrong order, 13+ joints or none all
//! panicked inside compensation.

use crate::common;

use drawcal::compensate::Compensator;
use drawcal::model::{Target, TargetKind};
use drawcal::report::Report;

/// The report of er3a_compliance_j2: one finding, joint 2 compliance.
fn report() -> Report {
    let (robot, rig, data) = common::load("er3a_compliance_j2");
    let rep = common::identify_default(&robot, &rig, &data);
    assert_eq!(rep.findings[0].effect, "joint_compliance");
    rep
}

/// `Compensator::from_report` on `rep` as JSON edited by `edit`: the
/// error's text, or `None` when it accepted the report (then one target
/// must compensate without a panic).
fn read_edited(rep: &Report, edit: impl Fn(&mut serde_json::Value)) -> Option<String> {
    let mut v = serde_json::to_value(rep).unwrap();
    edit(&mut v);
    let edited = match Report::from_json(&v.to_string()) {
        Ok(r) => r,
        Err(e) => return Some(e.to_string()),
    };
    match Compensator::from_report(&edited) {
        Err(e) => Some(e.to_string()),
        Ok(c) => {
            let t = Target {
                target: "t".into(),
                kind: TargetKind::Joints {
                    q_deg: vec![10.0, 20.0, 30.0, 40.0, 50.0, 60.0],
                },
            };
            let _ = c.compensate(&t, false);
            None
        }
    }
}

#[test]
fn bad_indices_and_robots_are_named_errors() {
    let rep = report();
    for (what, edit, field) in [
        (
            "a finding's joint past the robot's",
            Box::new(|v: &mut serde_json::Value| {
                v["findings"][0]["parameters"]["joint_index"] = 99.into()
            }) as Box<dyn Fn(&mut serde_json::Value)>,
            "findings[0].parameters",
        ),
        (
            "a backlash on joint 99",
            Box::new(|v: &mut serde_json::Value| {
                v["findings"][0]["parameters"] =
                    serde_json::json!({"kind": "backlash", "joint_index": 99, "coef": [1e-3, 0.0]})
            }),
            "findings[0].parameters",
        ),
        (
            "a coefficient too few",
            Box::new(
                |v: &mut serde_json::Value| v["findings"][0]["parameters"] = serde_json::json!({"kind": "joint_periodic", "joint_index": 1, "harmonic": 1, "coef": [1e-3]}),
            ),
            "findings[0].parameters",
        ),
        (
            "a mass-free compliance on a robot with link masses",
            Box::new(|v: &mut serde_json::Value| {
                v["findings"][0]["parameters"]["regressors"] = serde_json::json!([6]);
            }),
            "findings[0].parameters",
        ),
        (
            "a model that does not parse (compensation would drop it)",
            Box::new(|v: &mut serde_json::Value| {
                v["findings"][0]["parameters"]["joint_index"] = "2".into();
            }),
            "findings[0].parameters",
        ),
        (
            "joint limits in the wrong order",
            Box::new(|v: &mut serde_json::Value| {
                v["calibrated_robot"]["joints"][2]["q_min_deg"] = 100.0.into();
                v["calibrated_robot"]["joints"][2]["q_max_deg"] = (-100.0).into();
            }),
            "calibrated_robot",
        ),
        (
            "no joints",
            Box::new(|v: &mut serde_json::Value| {
                v["nominal_robot"]["joints"] = serde_json::json!([]);
                v["calibrated_robot"]["joints"] = serde_json::json!([]);
            }),
            "nominal_robot",
        ),
        (
            "fourteen joints",
            Box::new(|v: &mut serde_json::Value| {
                for k in ["nominal_robot", "calibrated_robot"] {
                    let j0 = v[k]["joints"][0].clone();
                    let joints = v[k]["joints"].as_array_mut().unwrap();
                    joints.extend(std::iter::repeat_n(j0, 8));
                }
            }),
            "nominal_robot",
        ),
    ] {
        let e = read_edited(&rep, edit).unwrap_or_else(|| panic!("{what}: accepted"));
        assert!(e.starts_with(field), "{what}: {e}");
    }
    // Every joint index in range is accepted, every one past it refused.
    for j in 0..9 {
        let r = read_edited(&rep, |v| {
            v["findings"][0]["parameters"]["joint_index"] = j.into()
        });
        assert_eq!(r.is_none(), j < 6, "joint_index {j}: {r:?}");
    }
}
