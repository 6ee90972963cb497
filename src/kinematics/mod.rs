//! Kinematics of the measured point: the parameter vector ([`params`]),
//! forward kinematics with analytic derivatives ([`chain`]) and the paper's
//! differential error model, equations (15)-(22) ([`error_model`]); the
//! closed-form inverse kinematics of nominal arms that allow one ([`ik`]).

pub mod chain;
pub mod error_model;
pub mod ik;
pub mod params;

pub use chain::{Chain, Frame, PointJacobian};
pub use params::{JointParam, Layout, Params};

use nalgebra::{Matrix3, Vector3};

/// Rotation `Rz(yaw) Ry(pitch) Rx(roll)` (angles in rad).
pub fn rpy_matrix(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    Matrix3::new(
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    )
}

/// Roll, pitch, yaw (rad) of a rotation, inverse of [`rpy_matrix`].
pub fn matrix_rpy(r: &Matrix3<f64>) -> Vector3<f64> {
    let pitch = (-r[(2, 0)]).clamp(-1.0, 1.0).asin();
    let roll = r[(2, 1)].atan2(r[(2, 2)]);
    let yaw = r[(1, 0)].atan2(r[(0, 0)]);
    Vector3::new(roll, pitch, yaw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_round_trip() {
        let r = rpy_matrix(0.3, -0.4, 2.0);
        let a = matrix_rpy(&r);
        assert!((a - Vector3::new(0.3, -0.4, 2.0)).norm() < 1e-12);
        assert!((r * r.transpose() - Matrix3::identity()).norm() < 1e-12);
    }
}
