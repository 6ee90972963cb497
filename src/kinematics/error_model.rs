//! The paper's differential error model, equations (15)-(22): how small
//! deviations of one link's (a, α, d, θ, β) move and turn its frame, and,
//! chained through the arm (equation 24), the point T.
//!
//! The identification itself uses the exact Jacobian of [`super::chain`];
//! this module exists for the paper's one-step method and as an independent
//! check of that Jacobian (the tests compare the two).

use nalgebra::Vector3;

use super::chain::{Chain, OutputFrame};
use crate::model::Convention;

/// Differential translation `d_i` and rotation `δ_i` of link frame i, in
/// frame i, for deviations `[Δa, Δα, Δd, Δθ, Δβ]` (mm, rad) of a DH link
/// with twist `alpha` and Hayati angle `beta` (rad), length `a` (mm).
pub fn link_differential(
    a: f64,
    alpha: f64,
    beta: f64,
    dev: [f64; 5],
) -> (Vector3<f64>, Vector3<f64>) {
    let [da, dal, dd, dth, dbe] = dev;
    let (sa, ca) = alpha.sin_cos();
    let (sb, cb) = beta.sin_cos();
    // (15)-(17)
    let delta = Vector3::new(
        -ca * sb * dth + cb * dal,
        sa * dth + dbe,
        ca * cb * dth + sb * dal,
    );
    // (18)-(20)
    let d = Vector3::new(
        cb * da - ca * sb * dd + a * sb * sa * dth,
        sa * dd + a * ca * dth,
        sb * da + ca * cb * dd - a * cb * sa * dth,
    );
    (d, delta)
}

/// Columns of the paper's linear error model for the 5n joint parameters at
/// one pose: `dT = Σ_i R_i (d_i + δ_i × T_i)` (equation 24 restricted to the
/// position of T), with `T_i` the point in link frame i. DH convention only.
pub fn paper_columns(chain: &Chain, p: &[f64], q: &[f64], frame: OutputFrame) -> Vec<Vector3<f64>> {
    assert_eq!(
        chain.convention,
        Convention::Dh,
        "the paper's error model is written for DH links"
    );
    let frames = chain.link_frames(p, q, frame);
    let (_, point) = chain.point(p, q, frame);
    let n = chain.layout.n_joints;
    let mut cols = Vec::with_capacity(5 * n);
    for (j, f) in frames.iter().enumerate() {
        let k = 5 * j;
        let t_local = f.r.transpose() * (point - f.o);
        for e in 0..5 {
            let mut dev = [0.0; 5];
            dev[e] = 1.0;
            let (d, delta) = link_differential(p[k], p[k + 1], p[k + 4], dev);
            cols.push(f.r * (d + delta.cross(&t_local)));
        }
    }
    cols
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::{Chain, Params};
    use crate::model::{BasePose, Rig, Robot};
    use nalgebra::{Matrix4, Rotation3, Translation3};

    fn link(a: f64, al: f64, d: f64, th: f64, be: f64) -> Matrix4<f64> {
        Rotation3::from_axis_angle(&Vector3::z_axis(), th).to_homogeneous()
            * Translation3::new(0.0, 0.0, d).to_homogeneous()
            * Translation3::new(a, 0.0, 0.0).to_homogeneous()
            * Rotation3::from_axis_angle(&Vector3::x_axis(), al).to_homogeneous()
            * Rotation3::from_axis_angle(&Vector3::y_axis(), be).to_homogeneous()
    }

    #[test]
    fn equations_15_to_20_match_differentiated_link() {
        // T^-1 dT must be the skew/translation operator of equation (14).
        let (a, al, d, th, be) = (275.0, -0.3, 12.0, 0.7, 0.05);
        let t0 = link(a, al, d, th, be);
        let inv = t0.try_inverse().unwrap();
        for e in 0..5 {
            let h = 1e-6;
            // parameter order in dev: a, alpha, d, theta, beta
            let mut v = [a, al, d, th, be];
            v[e] += h;
            let tp = link(v[0], v[1], v[2], v[3], v[4]);
            v[e] -= 2.0 * h;
            let tm = link(v[0], v[1], v[2], v[3], v[4]);
            let op = inv * (tp - tm) / (2.0 * h);
            let mut dev = [0.0; 5];
            dev[e] = 1.0;
            let (dd, delta) = link_differential(a, al, be, dev);
            let ours = Matrix4::new(
                0.0, -delta.z, delta.y, dd.x, delta.z, 0.0, -delta.x, dd.y, -delta.y, delta.x, 0.0,
                dd.z, 0.0, 0.0, 0.0, 0.0,
            );
            assert!(
                (op - ours).norm() < 1e-6,
                "parameter {e}: fd {op} eq {ours}"
            );
        }
    }

    #[test]
    fn paper_model_equals_chain_jacobian() {
        let robot =
            Robot::from_json(include_str!("../../tests/data/ur5_geometric/robot.json")).unwrap();
        let rig = Rig::from_json(include_str!("../../tests/data/ur5_geometric/rig.json")).unwrap();
        let mut p = Params::nominal(
            &robot,
            &BasePose {
                xyz_mm: [700.0, 500.0, -100.0],
                rpy_deg: [1.0, 2.0, 170.0],
            },
            &rig,
            4,
        );
        p.values[4] = 0.01; // a non-zero beta on joint 1
        p.values[9] = -0.02;
        let chain = Chain::new(Convention::Dh, 6, 4);
        let mut jac = chain.new_jacobian();
        for q in [
            [0.1, -1.0, 0.5, 0.2, 1.1, -0.4],
            [2.0, -0.3, -1.2, 0.9, -0.6, 0.3],
        ] {
            chain.point_jacobian(&p.values, &q, OutputFrame::Rig, &mut jac);
            let cols = paper_columns(&chain, &p.values, &q, OutputFrame::Rig);
            for (i, c) in cols.iter().enumerate() {
                assert!(
                    (c - jac.d_params[i]).norm() < 1e-9,
                    "{}: paper {c:?} chain {:?}",
                    chain.layout.name(i),
                    jac.d_params[i]
                );
            }
        }
    }
}
