//! Building a compensator: from two robots, or from a calibration report
//! after checking what compensation relies on in it (a report may have been
//! edited by hand).

use std::sync::{Arc, OnceLock};

use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::kinematics::Params;
use crate::kinematics::chain::Chain;
use crate::kinematics::ik::ClosedFormIk;
use crate::model::Robot;
use crate::physics::{JointEffects, WorkspaceField};
use crate::report::Report;

use super::Compensator;
use super::conditions::{Thermal, has_time_thermal, thermal_of};
use super::reach::Reach;

impl Compensator {
    /// From the nominal and calibrated models (robot.json form).
    pub fn new(nominal: &Robot, calibrated: &Robot) -> Result<Self> {
        if nominal.dof() != calibrated.dof() || nominal.convention != calibrated.convention {
            return Err(Error::field(
                "calibrated_robot",
                "does not match the nominal robot's joints or convention",
            ));
        }
        let chain = Chain::new(nominal.convention, nominal.dof(), 0);
        let (nominal_p, calibrated_p) = (Params::of_robot(nominal), Params::of_robot(calibrated));
        Ok(Compensator {
            chain,
            reach_nominal: Reach::of(&chain, &nominal_p.values),
            reach_calibrated: OnceLock::new(),
            nominal: nominal_p,
            calibrated: calibrated_p,
            limits_rad: calibrated
                .joints
                .iter()
                .map(|j| (j.q_min_deg.to_radians(), j.q_max_deg.to_radians()))
                .collect(),
            joint_effects: None,
            workspace_field: None,
            thermal: None,
            temp_c: None,
            time_thermal: false,
            ik: ClosedFormIk::from_robot(nominal).map(Arc::new),
            closed_form: true,
            tolerance_mm: 1e-3,
            tolerance_rad: 1e-6,
            max_joint_change_deg: super::DEFAULT_MAX_JOINT_CHANGE_DEG,
            tool_difference_mm: (Vector3::from(nominal.tool_point_mm)
                - Vector3::from(calibrated.tool_point_mm))
            .norm(),
            max_iterations: 50,
        })
    }

    /// From a calibration report, with the robot-side effects its physics
    /// analysis accepted (a compliant joint's correction depends on the pose).
    /// A temperature-driven thermal expansion is kept and applied at its
    /// reference temperature (multiplier 0, the geometry as calibrated):
    /// use [`Compensator::at_temperature`] for the temperature the robot
    /// runs at. A time-driven one is left out (see the module docs).
    pub fn from_report(report: &Report) -> Result<Self> {
        check_report(report)?;
        let mut comp = Self::new(&report.nominal_robot, &report.calibrated_robot)?;
        if let Some(info) = thermal_of(report) {
            comp.thermal = Some(Arc::new(Thermal {
                info,
                lengths: crate::physics::effects::nominal_lengths(&report.nominal_robot),
                reference_values: comp.calibrated.values.clone(),
            }));
            comp.temp_c = Some(info.reference_temp_c);
        }
        comp.time_thermal = has_time_thermal(report);
        comp.joint_effects =
            JointEffects::new(&report.findings, &report.nominal_robot).map(Arc::new);
        let base = &report.base_in_rig;
        let [roll, pitch, yaw] = base.rpy_deg.map(f64::to_radians);
        comp.workspace_field = WorkspaceField::new(
            &report.findings,
            crate::kinematics::rpy_matrix(roll, pitch, yaw),
            Vector3::from(base.xyz_mm),
        )
        .map(Arc::new);
        Ok(comp)
    }
}

/// What compensation relies on in a report, checked before any index is
/// used: both robots valid, and every finding but `unexplained` carrying an
/// effect model that fits the robot (or compensation would drop it).
fn check_report(report: &Report) -> Result<()> {
    for (field, robot) in [
        ("nominal_robot", &report.nominal_robot),
        ("calibrated_robot", &report.calibrated_robot),
    ] {
        robot
            .validate()
            .map_err(|e| Error::field(field, e.to_string()))?;
    }
    let robot = &report.nominal_robot;
    let has_masses = robot.links.as_ref().is_some_and(|l| l.len() == robot.dof());
    for (i, f) in report.findings.iter().enumerate() {
        // `unexplained` has no model; every other finding must carry
        // one that fits the robot, or compensation would drop it.
        if f.effect == "unexplained" {
            continue;
        }
        let field = || format!("findings[{i}].parameters");
        let e = f
            .effect_model()
            .ok_or_else(|| Error::field(field(), format!("{}: no effect model", f.effect)))?;
        e.check(robot.dof(), has_masses)
            .map_err(|m| Error::field(field(), m))?;
    }
    Ok(())
}
