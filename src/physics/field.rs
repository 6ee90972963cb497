//! A data-driven field over the workspace, as compensation uses it: the
//! calibration found T displaced by `f(where T is)` in the rig's frame
//! (`Kind::DataDriven` with target `Point` and driver `Workspace`), so a
//! target is reached by aiming the calibrated model at the target minus
//! that displacement. The field is smooth and fractions of a millimetre,
//! so evaluating it at the target rather than at the aimed point changes
//! the aim by its slope times itself (micrometres).

use nalgebra::{Matrix3, Vector3};

use super::effects::{
    CorrectionDriver, CorrectionTarget, EffectModel, Kind, hat_weights, point_frame,
    workspace_coordinate,
};
use super::effects_of;
use crate::report::Finding;

/// The workspace corrections a calibration accepted, with the base pose
/// that takes a target from the robot's base frame to the rig's.
#[derive(Debug, Clone)]
pub struct WorkspaceField {
    corrections: Vec<EffectModel>,
    base_rotation: Matrix3<f64>,
    base_translation_mm: Vector3<f64>,
}

impl WorkspaceField {
    /// The field of `findings`, with the calibrated base pose in the rig
    /// (`base_rotation`, `base_translation_mm`); `None` when no workspace
    /// correction was accepted.
    pub fn new(
        findings: &[Finding],
        base_rotation: Matrix3<f64>,
        base_translation_mm: Vector3<f64>,
    ) -> Option<Self> {
        let corrections: Vec<EffectModel> = effects_of(findings)
            .into_iter()
            .filter(|e| {
                matches!(
                    e.kind,
                    Kind::DataDriven {
                        target: CorrectionTarget::Point | CorrectionTarget::PointSpherical,
                        driver: CorrectionDriver::Workspace,
                        ..
                    }
                )
            })
            .collect();
        (!corrections.is_empty()).then_some(WorkspaceField {
            corrections,
            base_rotation,
            base_translation_mm,
        })
    }

    /// Where to aim the calibrated model (robot base frame, mm) so that T
    /// lands on `target_mm`, and a warning when the target lies outside
    /// the range of a coordinate the field was fitted on (there it is held
    /// at its end value, an extrapolation no pose supports).
    pub fn aim(&self, target_mm: &Vector3<f64>) -> (Vector3<f64>, Option<String>) {
        let at_rig = self.base_rotation * target_mm + self.base_translation_mm;
        let mut shift_rig = Vector3::zeros();
        let mut outside = Vec::new();
        for e in &self.corrections {
            let Kind::DataDriven {
                target,
                driver_index: Some(c),
                knots,
                period,
                ..
            } = &e.kind
            else {
                continue;
            };
            let x = workspace_coordinate(&at_rig, *c);
            let frame = point_frame(*target, &at_rig);
            for (k, w) in hat_weights(knots, *period, x) {
                for (axis, dir) in frame.iter().enumerate() {
                    shift_rig += w * e.coef.get(3 * k + axis).copied().unwrap_or(0.0) * dir;
                }
            }
            let Some((lo, hi)) = e.kind.fitted_range() else {
                continue;
            };
            if x < lo || x > hi {
                let angle = matches!(c, 3 | 4);
                let (x, lo, hi, unit) = if angle {
                    (x.to_degrees(), lo.to_degrees(), hi.to_degrees(), "deg")
                } else {
                    (x, lo, hi, "mm")
                };
                outside.push(format!(
                    "warning: the target's {} is {x:.1} {unit}, outside {lo:.1} to {hi:.1} {unit}, the range the data-driven correction over the workspace was fitted on; {}",
                    super::effects::correction_driver_words(CorrectionDriver::Workspace, Some(*c))
                        .trim_start_matches("T's "),
                    e.kind.beyond_range()
                ));
            }
        }
        let aimed = target_mm - self.base_rotation.transpose() * shift_rig;
        (aimed, (!outside.is_empty()).then(|| outside.join("; ")))
    }
}
