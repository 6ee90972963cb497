//! The paper's identification as published: the linearised error model
//! (equations 15-25) at the nominal parameters, one Moore-Penrose
//! pseudo-inverse step (equation 39) on the located points expressed in the
//! robot base frame. The base pose and tool point come from the "before"
//! fit. As in the paper's Table 2, Hayati's β is a parameter only where a
//! joint's axis is nominally parallel to the next one's; elsewhere it would
//! duplicate the DH parameters.

use nalgebra::{DMatrix, DVector, Vector3};

use super::Observations;
use crate::error::{Error, Result};
use crate::kinematics::chain::OutputFrame;
use crate::kinematics::error_model::paper_columns;
use crate::kinematics::{JointParam, Params};
use crate::model::Convention;

/// One pseudo-inverse step from `before` (nominal joints, fitted base and
/// tool) on the train poses.
pub fn one_step(obs: &Observations, before: &Params) -> Result<Params> {
    let chain = obs.chain;
    let l = chain.layout;
    let n = 5 * l.n_joints;
    let cols_used: Vec<usize> = (0..n)
        .filter(|&j| j % 5 != 4 || beta_applies(before, j / 5))
        .collect();
    let (rb, tb) = before.base_rt();
    let rows = 3 * obs.train.len();
    let mut a = DMatrix::zeros(rows, cols_used.len());
    let mut b = DVector::zeros(rows);
    let mut jac = chain.new_jacobian();
    for (k, &i) in obs.train.iter().enumerate() {
        let pose = &obs.data.poses[i];
        // The least-squares point: the paper's closed form fails outright
        // for points behind anchor A (see `closed_form_comparison`), and the
        // method under test here is the identification, not the location.
        let measured_rig = obs.measured[i];
        let measured: Vector3<f64> = rb.transpose() * (measured_rig - tb);
        let cols = if chain.convention == Convention::Dh {
            paper_columns(&chain, &before.values, &pose.q_rad, OutputFrame::Base)
        } else {
            chain.point_jacobian(&before.values, &pose.q_rad, OutputFrame::Base, &mut jac);
            jac.d_params[..n].to_vec()
        };
        let (_, nominal) = chain.point(&before.values, &pose.q_rad, OutputFrame::Base);
        for c in 0..3 {
            for (j, &col) in cols_used.iter().enumerate() {
                a[(3 * k + c, j)] = cols[col][c];
            }
            b[3 * k + c] = measured[c] - nominal[c];
        }
    }
    // Moore-Penrose with the usual tolerance max(m, n) · eps · σ_max. When A
    // is tall, a QR first reduces it to its square R (same singular
    // values), so the SVD is of a k × k matrix rather than of A itself;
    // with fewer train rows than columns the SVD of A itself gives the
    // minimum-norm step.
    let k = cols_used.len();
    let solve = |m: DMatrix<f64>, rhs: DVector<f64>| {
        let svd = m.svd(true, true);
        let smax = svd.singular_values.iter().cloned().fold(0.0, f64::max);
        let tol = rows.max(k) as f64 * f64::EPSILON * smax;
        svd.solve(&rhs, tol)
            .map_err(|e| Error::Numerical(e.to_string()))
    };
    let x = if rows >= k {
        let qr = a.qr();
        let mut qtb = b;
        qr.q_tr_mul(&mut qtb);
        solve(qr.r(), qtb.rows(0, k).into_owned())?
    } else {
        solve(a, b)?
    };
    let mut out = before.clone();
    for (j, &col) in cols_used.iter().enumerate() {
        out.values[col] += x[j];
    }
    Ok(out)
}

/// Hayati's rule: β belongs to joint j when its axis is nominally parallel
/// to joint j+1's (DH twist 0 or 180°).
fn beta_applies(p: &Params, j: usize) -> bool {
    j + 1 < p.layout.n_joints && p.joint(j, JointParam::Alpha).sin().abs() < 1e-6
}
