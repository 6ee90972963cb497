//! Levenberg-Marquardt on the normal equations, with MINPACK-style column
//! scaling.
//!
//! Written here rather than taken from a crate because identification needs
//! three things the crates do not give together: accumulation of `JᵀWJ` pose
//! by pose without storing J (the 11,911-pose grid would need 36k × 45
//! doubles per iteration otherwise), per-pose robust weights, and the final
//! normal matrix for covariance and identifiability.

use nalgebra::{DMatrix, DVector};

use crate::error::{Error, Result};

/// A weighted least-squares problem `min ½ Σ w r(x)²`.
pub trait LeastSquares {
    /// Number of unknowns.
    fn n_params(&self) -> usize;
    /// Number of residuals.
    fn n_residuals(&self) -> usize;
    /// The cost `½ Σ w r²` at `x`.
    fn cost(&self, x: &[f64]) -> f64;
    /// The cost, and `JᵀWJ` and `JᵀWr` written into `jtj` and `jtr`
    /// (overwritten, full symmetric).
    fn normal_equations(&self, x: &[f64], jtj: &mut DMatrix<f64>, jtr: &mut DVector<f64>) -> f64;
}

/// Solver settings.
#[derive(Debug, Clone, Copy)]
pub struct LmSettings {
    /// Maximum accepted-or-rejected iterations.
    pub max_iterations: usize,
    /// Stop when the relative cost reduction falls below this.
    pub ftol: f64,
    /// Stop when the scaled step falls below this relative to the scaled x.
    pub xtol: f64,
}

impl Default for LmSettings {
    fn default() -> Self {
        LmSettings {
            max_iterations: 200,
            ftol: 1e-12,
            xtol: 1e-10,
        }
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// The cost stopped decreasing.
    CostConverged,
    /// The step became negligible.
    StepConverged,
    /// The gradient vanished.
    GradientZero,
    /// The iteration limit was reached.
    MaxIterations,
}

impl Termination {
    /// Text for the report.
    pub fn as_str(self) -> &'static str {
        match self {
            Termination::CostConverged => "cost converged",
            Termination::StepConverged => "step converged",
            Termination::GradientZero => "gradient zero",
            Termination::MaxIterations => "iteration limit reached",
        }
    }
}

/// Solution and the normal equations at it.
#[derive(Debug, Clone)]
pub struct LmResult {
    /// The solution.
    pub x: Vec<f64>,
    /// `½ Σ w r²` at the solution.
    pub cost: f64,
    /// `JᵀWJ` at the solution.
    pub jtj: DMatrix<f64>,
    /// Iterations used.
    pub iterations: usize,
    /// Why it stopped.
    pub termination: Termination,
}

/// Minimise from `x0`. `on_iteration` is called after each iteration with
/// the iteration number and cost; returning `false` cancels.
pub fn minimize<P: LeastSquares + ?Sized>(
    problem: &P,
    x0: &[f64],
    settings: &LmSettings,
    mut on_iteration: impl FnMut(usize, f64) -> bool,
) -> Result<LmResult> {
    let n = problem.n_params();
    let mut x = x0.to_vec();
    let mut jtj = DMatrix::zeros(n, n);
    let mut g = DVector::zeros(n);
    let mut cost = problem.normal_equations(&x, &mut jtj, &mut g);
    if !cost.is_finite() {
        return Err(Error::Numerical(
            "the starting point gives a non-finite residual".into(),
        ));
    }
    if n == 0 {
        return Ok(LmResult {
            x,
            cost,
            jtj,
            iterations: 0,
            termination: Termination::GradientZero,
        });
    }
    // Column scales, never decreasing (MINPACK): the step is measured in
    // units where every parameter moves T alike.
    let mut diag: Vec<f64> = (0..n).map(|i| jtj[(i, i)].sqrt().max(1e-12)).collect();
    let mut mu = 1e-3;
    let mut nu = 2.0;
    let mut termination = Termination::MaxIterations;
    let mut iterations = 0;
    let mut a = DMatrix::zeros(n, n);
    while iterations < settings.max_iterations {
        iterations += 1;
        for i in 0..n {
            diag[i] = diag[i].max(jtj[(i, i)].sqrt());
        }
        let gmax = (0..n)
            .map(|i| g[i].abs() / (diag[i] * (2.0 * cost).sqrt().max(1e-300)))
            .fold(0.0, f64::max);
        if gmax < 1e-14 {
            termination = Termination::GradientZero;
            break;
        }
        a.copy_from(&jtj);
        for i in 0..n {
            a[(i, i)] += mu * diag[i] * diag[i];
        }
        let step = match a.clone().cholesky() {
            Some(ch) => ch.solve(&(-&g)),
            None => {
                mu *= nu;
                nu *= 2.0;
                continue;
            }
        };
        let x_new: Vec<f64> = x.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
        let cost_new = problem.cost(&x_new);
        // Predicted reduction of the quadratic model.
        let predicted = -(step.dot(&g) + 0.5 * step.dot(&(&jtj * &step)));
        let actual = cost - cost_new;
        let rho = if predicted > 0.0 {
            actual / predicted
        } else {
            -1.0
        };
        let scaled_step = (0..n)
            .map(|i| (diag[i] * step[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        let scaled_x = (0..n).map(|i| (diag[i] * x[i]).powi(2)).sum::<f64>().sqrt();
        if cost_new.is_finite() && rho > 0.0 {
            x = x_new;
            let old = cost;
            cost = problem.normal_equations(&x, &mut jtj, &mut g);
            mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
            nu = 2.0;
            if !on_iteration(iterations, cost) {
                return Err(Error::Cancelled);
            }
            if (old - cost) <= settings.ftol * old {
                termination = Termination::CostConverged;
                break;
            }
            if scaled_step <= settings.xtol * (scaled_x + settings.xtol) {
                termination = Termination::StepConverged;
                break;
            }
        } else {
            mu *= nu;
            nu *= 2.0;
            if !on_iteration(iterations, cost) {
                return Err(Error::Cancelled);
            }
            if scaled_step <= settings.xtol * (scaled_x + settings.xtol) || mu > 1e20 {
                termination = Termination::StepConverged;
                break;
            }
        }
    }
    Ok(LmResult {
        x,
        cost,
        jtj,
        iterations,
        termination,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as least squares: r = (10 (y - x²), 1 - x), minimum (1, 1).
    struct Rosenbrock;
    impl LeastSquares for Rosenbrock {
        fn n_params(&self) -> usize {
            2
        }
        fn n_residuals(&self) -> usize {
            2
        }
        fn cost(&self, x: &[f64]) -> f64 {
            let r0 = 10.0 * (x[1] - x[0] * x[0]);
            let r1 = 1.0 - x[0];
            0.5 * (r0 * r0 + r1 * r1)
        }
        fn normal_equations(
            &self,
            x: &[f64],
            jtj: &mut DMatrix<f64>,
            jtr: &mut DVector<f64>,
        ) -> f64 {
            let r = [10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]];
            let j = DMatrix::from_row_slice(2, 2, &[-20.0 * x[0], 10.0, -1.0, 0.0]);
            jtj.copy_from(&(j.transpose() * &j));
            jtr.copy_from(&(j.transpose() * DVector::from_row_slice(&r)));
            0.5 * (r[0] * r[0] + r[1] * r[1])
        }
    }

    #[test]
    fn solves_rosenbrock_from_minpack_start() {
        // MINPACK's test start (-1.2, 1).
        let r = minimize(&Rosenbrock, &[-1.2, 1.0], &LmSettings::default(), |_, _| {
            true
        })
        .unwrap();
        assert!(
            (r.x[0] - 1.0).abs() < 1e-9 && (r.x[1] - 1.0).abs() < 1e-9,
            "{:?}",
            r.x
        );
        assert!(r.cost < 1e-20);
    }

    #[test]
    fn cancels() {
        let r = minimize(&Rosenbrock, &[-1.2, 1.0], &LmSettings::default(), |_, _| {
            false
        });
        assert!(matches!(r, Err(Error::Cancelled)));
    }
}
