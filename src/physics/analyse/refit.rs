//! The nonlinear refit of geometry and effects together
//! (Levenberg-Marquardt on the train poses), and the covariance it gives
//! the effects' coefficients and the free geometric parameters.

use nalgebra::DMatrix;

use crate::error::Result;
use crate::identify::Observations;
use crate::identify::lm::{self, LeastSquares, LmSettings};
use crate::physics::effects::{Context, EffectModel};
use crate::physics::problem::EffectProblem;

/// A refit: geometric parameters, the effects, their covariance.
pub(super) type Fit = (Vec<f64>, Vec<EffectModel>, FitInfo);

/// Covariance information of a refit.
#[derive(Debug, Clone)]
pub struct FitInfo {
    /// Covariance of the effect coefficients (all effects of the refit, or
    /// one effect's block), internal units.
    pub cov_last: DMatrix<f64>,
    /// 1-sigma of the free geometric parameters (in the order of the
    /// geometric selection's `free`), internal units, from the same fit.
    pub sigma_free: Vec<f64>,
}

impl FitInfo {
    /// The covariance block of `len` coefficients starting at `start`.
    pub(super) fn block(&self, start: usize, len: usize) -> FitInfo {
        FitInfo {
            cov_last: DMatrix::from_fn(len, len, |i, j| {
                let (a, b) = (start + i, start + j);
                if a < self.cov_last.nrows() && b < self.cov_last.ncols() {
                    self.cov_last[(a, b)]
                } else {
                    0.0
                }
            }),
            sigma_free: vec![],
        }
    }
}

/// Geometry (the `free` parameters) and `effects` refitted together on the
/// train poses from `p` and the effects' values, with the covariance of
/// the result: a kept effect's magnitude and sigma come from it.
pub(super) fn refit(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    free: &[usize],
    effects: &[EffectModel],
) -> Result<Fit> {
    let problem = EffectProblem::of_observations(
        obs,
        ctx,
        obs.train.clone(),
        p,
        free.to_vec(),
        effects.to_vec(),
    );
    let res = lm::minimize(&problem, &problem.x0(), &LmSettings::default(), |_, _| true)?;
    let (pn, en) = problem.unpack(&res.x);
    let n = res.x.len();
    let dof = (problem.n_residuals() as f64 - n as f64).max(1.0);
    let s2 = 2.0 * res.cost / dof;
    let nc = problem.n_coef();
    // A coefficient no train pose supports (a backlash's unknown-approach
    // offset whose poses are all held out) has a zero column: scale 1 keeps
    // NaN out of the SVD, which does not terminate on NaN.
    let d: Vec<f64> = (0..n)
        .map(|i| match res.jtj[(i, i)] {
            v if v > 0.0 && v.is_finite() => v.sqrt(),
            _ => 1.0,
        })
        .collect();
    let scaled = DMatrix::from_fn(n, n, |i, j| res.jtj[(i, j)] / (d[i] * d[j]));
    let inv = if scaled.iter().all(|v| v.is_finite()) {
        scaled
            .pseudo_inverse(1e-12)
            .unwrap_or_else(|_| DMatrix::zeros(n, n))
    } else {
        DMatrix::zeros(n, n)
    };
    let cov_last = DMatrix::from_fn(nc, nc, |i, j| {
        let (a, b) = (n - nc + i, n - nc + j);
        s2 * inv[(a, b)] / (d[a] * d[b])
    });
    let sigma_free = (0..n - nc)
        .map(|i| (s2 * inv[(i, i)]).max(0.0).sqrt() / d[i])
        .collect();
    Ok((
        pn,
        en,
        FitInfo {
            cov_last,
            sigma_free,
        },
    ))
}
