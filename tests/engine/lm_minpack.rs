//! drawcal's Levenberg-Marquardt solver (`drawcal::identify::lm`) against
//! MINPACK's reference results on the Moré-Garbow-Hillstrom test problems.
//!
//! Why: identification trusts `lm::minimize` to find the least-squares
//! minimum of a badly scaled, sometimes nearly singular problem. The
//! classic way to check an LM implementation is the one the MINPACK authors
//! used for `lmder` and that ports such as rust-cv/levenberg-marquardt
//! repeat: run the test problems of Moré, Garbow & Hillstrom, "Testing
//! unconstrained optimization software", ACM TOMS 7 (1981) 17-41, from
//! their standard starting points (and 10× / 100× those), and compare the
//! final L2 norm of the residuals and the final x with MINPACK's.
//!
//! The reference figures are MINPACK-1's `lmder1` test-driver output
//! (Garbow, Hillstrom, Moré, Argonne, March 1980; tolerance
//! `sqrt(machine eps)`, `maxfev = 100 (n + 1)`), as reproduced in
//! cminpack's `examples/ref/lmddrv.fortran.ref`. They are printed to eight
//! significant digits, so a norm is compared to 1e-6 relative; a
//! zero-residual problem is only required to reach a norm below 1e-8.
//! Where the minimiser is unique and well determined, x is compared too;
//! where MINPACK's own runs from different starts disagree in x (the
//! Jacobian is singular or nearly so at the minimum) the x tolerance is
//! the spread MINPACK itself shows, and says so.
//!
//! MINPACK's x is only as good as its stopping test (relative reduction
//! `sqrt(eps)` ≈ 1.5e-8 in the sum of squares), which on the flat
//! nonzero-residual problems leaves x off by up to ~3e-4. So those problems
//! are also checked against `x*`, the minimiser computed for this file by
//! Newton's method on `½ Σ r²` (full Hessian) in 50-digit arithmetic
//! (mpmath) from the same data, iterated until the gradient was below 1e-20;
//! each `x*`'s norm agrees with MINPACK's to every printed digit.
//!
//! The problems are written here from the paper's definitions, each with
//! an analytic Jacobian that is checked against central differences at the
//! starting point before the solve. The solver sees them only through the
//! `LeastSquares` trait: the cost `½ Σ r²` and the normal equations `JᵀJ`,
//! `Jᵀr`. It runs with its default tolerances (tighter than MINPACK's
//! `sqrt(eps)`, so it ends at least as close to the minimum) and the
//! iteration limit set to `lmder1`'s function-evaluation limit
//! `100 (n + 1)`; one drawcal iteration costs one residual evaluation, as
//! one MINPACK function evaluation does.
//!
//! Run with `cargo test --test engine lm_minpack -- --nocapture` to see the figures
//! each problem reached.

use drawcal::identify::lm::{LeastSquares, LmResult, LmSettings, Termination, minimize};
use nalgebra::{DMatrix, DVector};

// ---------------------------------------------------------------------------
// Harness
// ---------------------------------------------------------------------------

/// One test problem: `m` residuals in `n` unknowns, with the residual
/// function and its analytic Jacobian (`m × n`, row i = ∂r_i/∂x).
struct Mgh {
    name: &'static str,
    n: usize,
    m: usize,
    residuals: fn(&[f64], &mut [f64]),
    jacobian: fn(&[f64], &mut DMatrix<f64>),
}

impl Mgh {
    /// The residual vector at `x`.
    fn r(&self, x: &[f64]) -> Vec<f64> {
        let mut r = vec![0.0; self.m];
        (self.residuals)(x, &mut r);
        r
    }

    /// The analytic Jacobian at `x`.
    fn j(&self, x: &[f64]) -> DMatrix<f64> {
        let mut j = DMatrix::zeros(self.m, self.n);
        (self.jacobian)(x, &mut j);
        j
    }

    /// The L2 norm of the residuals at `x`, MINPACK's "final l2 norm".
    fn norm(&self, x: &[f64]) -> f64 {
        (2.0 * half_sum_sq(&self.r(x))).sqrt()
    }
}

/// `½ Σ r²`, the cost the trait asks for.
fn half_sum_sq(r: &[f64]) -> f64 {
    0.5 * r.iter().map(|v| v * v).sum::<f64>()
}

impl LeastSquares for Mgh {
    fn n_params(&self) -> usize {
        self.n
    }
    fn n_residuals(&self) -> usize {
        self.m
    }
    fn cost(&self, x: &[f64]) -> f64 {
        half_sum_sq(&self.r(x))
    }
    fn normal_equations(&self, x: &[f64], jtj: &mut DMatrix<f64>, jtr: &mut DVector<f64>) -> f64 {
        let r = self.r(x);
        let j = self.j(x);
        jtj.copy_from(&(j.transpose() * &j));
        jtr.copy_from(&(j.transpose() * DVector::from_column_slice(&r)));
        // Summed exactly as in `cost`, so the solver compares like with like.
        half_sum_sq(&r)
    }
}

/// Checks the analytic Jacobian of `p` at `x` against central differences
/// (step `eps^(1/3) · max(|x_j|, 1)`), entry by entry to 1e-6 relative
/// (absolute below 1).
fn check_jacobian(p: &Mgh, x: &[f64]) {
    let analytic = p.j(x);
    let h_rel = f64::EPSILON.cbrt();
    for col in 0..p.n {
        let h = h_rel * x[col].abs().max(1.0);
        let mut xp = x.to_vec();
        let mut xm = x.to_vec();
        xp[col] += h;
        xm[col] -= h;
        // The step actually taken, after rounding of x ± h.
        let step = xp[col] - xm[col];
        let (rp, rm) = (p.r(&xp), p.r(&xm));
        for row in 0..p.m {
            let fd = (rp[row] - rm[row]) / step;
            let a = analytic[(row, col)];
            assert!(
                (fd - a).abs() <= 1e-6 * a.abs().max(1.0),
                "{}: Jacobian entry ({row}, {col}) at {x:?}: analytic {a:e}, \
                 central difference {fd:e}",
                p.name
            );
        }
    }
}

/// Checks the Jacobian at `x0`, then minimises from there with the
/// default settings and `lmder1`'s limit of `100 (n + 1)` iterations.
/// Also checks that the cost reported after each iteration never rises
/// (LM only accepts steps that lower it). Prints what it reached.
fn solve(p: &Mgh, x0: &[f64]) -> LmResult {
    assert_eq!(x0.len(), p.n);
    check_jacobian(p, x0);
    let settings = LmSettings {
        max_iterations: 100 * (p.n + 1),
        ..LmSettings::default()
    };
    let mut last = p.cost(x0);
    let mut rose = None;
    let result = minimize(p, x0, &settings, |it, cost| {
        if cost > last && rose.is_none() {
            rose = Some((it, last, cost));
        }
        last = cost;
        true
    })
    .unwrap_or_else(|e| panic!("{}: minimize failed: {e}", p.name));
    assert!(rose.is_none(), "{}: cost rose: {rose:?}", p.name);
    let norm = p.norm(&result.x);
    assert!(
        ((2.0 * result.cost).sqrt() - norm).abs() <= 1e-12 * norm.max(1e-300) + 1e-300,
        "{}: reported cost {} does not match the residuals at x (norm {norm})",
        p.name,
        result.cost
    );
    println!(
        "{:<28} from {:?}: norm {:.10e}, {} iterations, {}, x = {:?}",
        p.name,
        x0,
        norm,
        result.iterations,
        result.termination.as_str(),
        result.x
    );
    result
}

/// Asserts the final residual norm equals MINPACK's `reference` to
/// `rel` relative.
fn assert_norm(p: &Mgh, r: &LmResult, reference: f64, rel: f64) {
    let got = p.norm(&r.x);
    assert!(
        (got - reference).abs() <= rel * reference,
        "{}: final L2 norm {got:.10e}, MINPACK {reference:.7e} (relative error {:.2e} > {rel:e})",
        p.name,
        (got - reference).abs() / reference
    );
}

/// Asserts a zero-residual problem reached a norm below `atol`.
fn assert_zero_norm(p: &Mgh, r: &LmResult, atol: f64) {
    let got = p.norm(&r.x);
    assert!(
        got <= atol,
        "{}: final L2 norm {got:e}, expected a zero residual (< {atol:e})",
        p.name
    );
}

/// Asserts every component of `x` is within `rtol · |ref| + atol` of
/// `reference`.
fn assert_x(p: &Mgh, x: &[f64], reference: &[f64], rtol: f64, atol: f64) {
    assert_eq!(x.len(), reference.len());
    for (i, (&got, &want)) in x.iter().zip(reference).enumerate() {
        assert!(
            (got - want).abs() <= rtol * want.abs() + atol,
            "{}: x[{i}] = {got:.10e}, reference {want:.7e} (x = {x:?})",
            p.name
        );
    }
}

/// Asserts the solver stopped on a convergence test, as MINPACK did.
fn assert_converged(p: &Mgh, r: &LmResult) {
    assert_ne!(
        r.termination,
        Termination::MaxIterations,
        "{}: hit the iteration limit ({} iterations), MINPACK converged",
        p.name,
        r.iterations
    );
}

/// `factor` times `x`.
fn scaled(x: &[f64], factor: f64) -> Vec<f64> {
    x.iter().map(|v| v * factor).collect()
}

// ---------------------------------------------------------------------------
// Problems (MGH numbering in brackets; MINPACK test-driver number after)
// ---------------------------------------------------------------------------

/// Linear function, full rank [32] (MINPACK 1): r_i = x_i − (2/m) Σx − 1 for
/// i ≤ n, r_i = −(2/m) Σx − 1 after. Minimum x = −1, norm √(m − n).
fn linear_full_rank(m: usize) -> Mgh {
    fn res(x: &[f64], r: &mut [f64]) {
        let m = r.len() as f64;
        let t = 2.0 * x.iter().sum::<f64>() / m + 1.0;
        for (i, ri) in r.iter_mut().enumerate() {
            *ri = x.get(i).copied().unwrap_or(0.0) - t;
        }
    }
    fn jac(_x: &[f64], j: &mut DMatrix<f64>) {
        let m = j.nrows() as f64;
        j.fill(-2.0 / m);
        for k in 0..j.ncols() {
            j[(k, k)] += 1.0;
        }
    }
    Mgh {
        name: "linear full rank",
        n: 5,
        m,
        residuals: res,
        jacobian: jac,
    }
}

/// Rosenbrock [1] (MINPACK 4): r = (10 (x2 − x1²), 1 − x1); start (−1.2, 1).
fn rosenbrock() -> Mgh {
    fn res(x: &[f64], r: &mut [f64]) {
        r[0] = 10.0 * (x[1] - x[0] * x[0]);
        r[1] = 1.0 - x[0];
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        j[(0, 0)] = -20.0 * x[0];
        j[(0, 1)] = 10.0;
        j[(1, 0)] = -1.0;
        j[(1, 1)] = 0.0;
    }
    Mgh {
        name: "rosenbrock",
        n: 2,
        m: 2,
        residuals: res,
        jacobian: jac,
    }
}
const ROSENBROCK_X0: [f64; 2] = [-1.2, 1.0];

/// Helical valley [7] (MINPACK 5): r = (10 (x3 − 10 θ), 10 (√(x1² + x2²) − 1),
/// x3) with 2π θ = atan(x2/x1) (+π when x1 < 0); start (−1, 0, 0).
fn helical_valley() -> Mgh {
    use std::f64::consts::TAU;
    fn res(x: &[f64], r: &mut [f64]) {
        let theta = if x[0] > 0.0 {
            (x[1] / x[0]).atan() / TAU
        } else if x[0] < 0.0 {
            (x[1] / x[0]).atan() / TAU + 0.5
        } else {
            0.25f64.copysign(x[1])
        };
        r[0] = 10.0 * (x[2] - 10.0 * theta);
        r[1] = 10.0 * ((x[0] * x[0] + x[1] * x[1]).sqrt() - 1.0);
        r[2] = x[2];
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        let rho2 = x[0] * x[0] + x[1] * x[1];
        let rho = rho2.sqrt();
        // dθ/dx1 = −x2 / (2π ρ²), dθ/dx2 = x1 / (2π ρ²).
        j[(0, 0)] = 100.0 * x[1] / (TAU * rho2);
        j[(0, 1)] = -100.0 * x[0] / (TAU * rho2);
        j[(0, 2)] = 10.0;
        j[(1, 0)] = 10.0 * x[0] / rho;
        j[(1, 1)] = 10.0 * x[1] / rho;
        j[(1, 2)] = 0.0;
        j[(2, 0)] = 0.0;
        j[(2, 1)] = 0.0;
        j[(2, 2)] = 1.0;
    }
    Mgh {
        name: "helical valley",
        n: 3,
        m: 3,
        residuals: res,
        jacobian: jac,
    }
}
const HELICAL_X0: [f64; 3] = [-1.0, 0.0, 0.0];

/// Powell singular [13] (MINPACK 6): r = (x1 + 10 x2, √5 (x3 − x4),
/// (x2 − 2 x3)², √10 (x1 − x4)²); start (3, −1, 0, 1). Minimum 0 at the
/// origin, where the Jacobian has rank 2.
fn powell_singular() -> Mgh {
    fn res(x: &[f64], r: &mut [f64]) {
        r[0] = x[0] + 10.0 * x[1];
        r[1] = 5f64.sqrt() * (x[2] - x[3]);
        r[2] = (x[1] - 2.0 * x[2]).powi(2);
        r[3] = 10f64.sqrt() * (x[0] - x[3]).powi(2);
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        j.fill(0.0);
        let a = x[1] - 2.0 * x[2];
        let b = x[0] - x[3];
        j[(0, 0)] = 1.0;
        j[(0, 1)] = 10.0;
        j[(1, 2)] = 5f64.sqrt();
        j[(1, 3)] = -(5f64.sqrt());
        j[(2, 1)] = 2.0 * a;
        j[(2, 2)] = -4.0 * a;
        j[(3, 0)] = 2.0 * 10f64.sqrt() * b;
        j[(3, 3)] = -2.0 * 10f64.sqrt() * b;
    }
    Mgh {
        name: "powell singular",
        n: 4,
        m: 4,
        residuals: res,
        jacobian: jac,
    }
}
const POWELL_X0: [f64; 4] = [3.0, -1.0, 0.0, 1.0];

/// Freudenstein-Roth [2] (MINPACK 7): r1 = −13 + x1 + ((5 − x2) x2 − 2) x2,
/// r2 = −29 + x1 + ((x2 + 1) x2 − 14) x2; start (0.5, −2). Global minimum 0
/// at (5, 4); local minimum norm 6.9988752 at (11.41…, −0.8968…).
fn freudenstein_roth() -> Mgh {
    fn res(x: &[f64], r: &mut [f64]) {
        r[0] = -13.0 + x[0] + ((5.0 - x[1]) * x[1] - 2.0) * x[1];
        r[1] = -29.0 + x[0] + ((x[1] + 1.0) * x[1] - 14.0) * x[1];
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        j[(0, 0)] = 1.0;
        j[(0, 1)] = (10.0 - 3.0 * x[1]) * x[1] - 2.0;
        j[(1, 0)] = 1.0;
        j[(1, 1)] = (3.0 * x[1] + 2.0) * x[1] - 14.0;
    }
    Mgh {
        name: "freudenstein-roth",
        n: 2,
        m: 2,
        residuals: res,
        jacobian: jac,
    }
}
const FREUDENSTEIN_X0: [f64; 2] = [0.5, -2.0];

/// Bard [8] (MINPACK 8): r_i = y_i − (x1 + u_i / (v_i x2 + w_i x3)) with
/// u_i = i, v_i = 16 − i, w_i = min(u_i, v_i); start (1, 1, 1).
fn bard() -> Mgh {
    const Y: [f64; 15] = [
        0.14, 0.18, 0.22, 0.25, 0.29, 0.32, 0.35, 0.39, 0.37, 0.58, 0.73, 0.96, 1.34, 2.10, 4.39,
    ];
    fn uvw(i: usize) -> (f64, f64, f64) {
        let u = (i + 1) as f64;
        let v = (15 - i) as f64;
        (u, v, u.min(v))
    }
    fn res(x: &[f64], r: &mut [f64]) {
        for (i, ri) in r.iter_mut().enumerate() {
            let (u, v, w) = uvw(i);
            *ri = Y[i] - (x[0] + u / (v * x[1] + w * x[2]));
        }
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        for i in 0..15 {
            let (u, v, w) = uvw(i);
            let d2 = (v * x[1] + w * x[2]).powi(2);
            j[(i, 0)] = -1.0;
            j[(i, 1)] = u * v / d2;
            j[(i, 2)] = u * w / d2;
        }
    }
    Mgh {
        name: "bard",
        n: 3,
        m: 15,
        residuals: res,
        jacobian: jac,
    }
}
const BARD_X0: [f64; 3] = [1.0, 1.0, 1.0];

/// Kowalik-Osborne [15] (MINPACK 9): r_i = y_i − x1 (u_i² + u_i x2) /
/// (u_i² + u_i x3 + x4); start (0.25, 0.39, 0.415, 0.39).
fn kowalik_osborne() -> Mgh {
    const U: [f64; 11] = [
        4.0, 2.0, 1.0, 0.5, 0.25, 0.167, 0.125, 0.1, 0.0833, 0.0714, 0.0625,
    ];
    const Y: [f64; 11] = [
        0.1957, 0.1947, 0.1735, 0.1600, 0.0844, 0.0627, 0.0456, 0.0342, 0.0323, 0.0235, 0.0246,
    ];
    fn res(x: &[f64], r: &mut [f64]) {
        for (i, ri) in r.iter_mut().enumerate() {
            let u = U[i];
            *ri = Y[i] - x[0] * u * (u + x[1]) / (u * (u + x[2]) + x[3]);
        }
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        for i in 0..11 {
            let u = U[i];
            let num = u * (u + x[1]);
            let den = u * (u + x[2]) + x[3];
            j[(i, 0)] = -num / den;
            j[(i, 1)] = -x[0] * u / den;
            j[(i, 2)] = x[0] * num * u / (den * den);
            j[(i, 3)] = x[0] * num / (den * den);
        }
    }
    Mgh {
        name: "kowalik-osborne",
        n: 4,
        m: 11,
        residuals: res,
        jacobian: jac,
    }
}
const KOWALIK_X0: [f64; 4] = [0.25, 0.39, 0.415, 0.39];

/// Meyer [10] (MINPACK 10): r_i = x1 exp(x2 / (t_i + x3)) − y_i with
/// t_i = 45 + 5 i; start (0.02, 4000, 250). Very badly scaled.
fn meyer() -> Mgh {
    const Y: [f64; 16] = [
        34780.0, 28610.0, 23650.0, 19630.0, 16370.0, 13720.0, 11540.0, 9744.0, 8261.0, 7030.0,
        6005.0, 5147.0, 4427.0, 3820.0, 3307.0, 2872.0,
    ];
    fn t(i: usize) -> f64 {
        45.0 + 5.0 * (i + 1) as f64
    }
    fn res(x: &[f64], r: &mut [f64]) {
        for (i, ri) in r.iter_mut().enumerate() {
            *ri = x[0] * (x[1] / (t(i) + x[2])).exp() - Y[i];
        }
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        for i in 0..16 {
            let d = t(i) + x[2];
            let e = (x[1] / d).exp();
            j[(i, 0)] = e;
            j[(i, 1)] = x[0] * e / d;
            j[(i, 2)] = -x[0] * e * x[1] / (d * d);
        }
    }
    Mgh {
        name: "meyer",
        n: 3,
        m: 16,
        residuals: res,
        jacobian: jac,
    }
}
const MEYER_X0: [f64; 3] = [0.02, 4000.0, 250.0];

/// Box three-dimensional [12] (MINPACK 12), m = 10: r_i = exp(−t_i x1) −
/// exp(−t_i x2) − x3 (exp(−t_i) − exp(−10 t_i)), t_i = 0.1 i; start
/// (0, 10, 20). Zero minima at (1, 10, 1), (10, 1, −1) and on x1 = x2,
/// x3 = 0; MINPACK reaches (1, 10, 1).
fn box_3d() -> Mgh {
    fn res(x: &[f64], r: &mut [f64]) {
        for (i, ri) in r.iter_mut().enumerate() {
            let t = 0.1 * (i + 1) as f64;
            *ri = (-t * x[0]).exp() - (-t * x[1]).exp() - x[2] * ((-t).exp() - (-10.0 * t).exp());
        }
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        for i in 0..j.nrows() {
            let t = 0.1 * (i + 1) as f64;
            j[(i, 0)] = -t * (-t * x[0]).exp();
            j[(i, 1)] = t * (-t * x[1]).exp();
            j[(i, 2)] = -((-t).exp() - (-10.0 * t).exp());
        }
    }
    Mgh {
        name: "box 3-d",
        n: 3,
        m: 10,
        residuals: res,
        jacobian: jac,
    }
}
const BOX_X0: [f64; 3] = [0.0, 10.0, 20.0];

/// Jennrich-Sampson [6] (MINPACK 13), m = 10: r_i = 2 + 2 i − (exp(i x1) +
/// exp(i x2)); start (0.3, 0.4). Minimum at x1 = x2 = 0.2578, where the
/// two Jacobian columns coincide.
fn jennrich_sampson() -> Mgh {
    fn res(x: &[f64], r: &mut [f64]) {
        for (i, ri) in r.iter_mut().enumerate() {
            let k = (i + 1) as f64;
            *ri = 2.0 + 2.0 * k - ((k * x[0]).exp() + (k * x[1]).exp());
        }
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        for i in 0..j.nrows() {
            let k = (i + 1) as f64;
            j[(i, 0)] = -k * (k * x[0]).exp();
            j[(i, 1)] = -k * (k * x[1]).exp();
        }
    }
    Mgh {
        name: "jennrich-sampson",
        n: 2,
        m: 10,
        residuals: res,
        jacobian: jac,
    }
}
const JENNRICH_X0: [f64; 2] = [0.3, 0.4];

/// Brown-Dennis [16] (MINPACK 14), m = 20: r_i = (x1 + t_i x2 − exp t_i)² +
/// (x3 + x4 sin t_i − cos t_i)², t_i = i / 5; start (25, 5, −5, −1).
fn brown_dennis() -> Mgh {
    fn res(x: &[f64], r: &mut [f64]) {
        for (i, ri) in r.iter_mut().enumerate() {
            let t = (i + 1) as f64 / 5.0;
            let a = x[0] + t * x[1] - t.exp();
            let b = x[2] + t.sin() * x[3] - t.cos();
            *ri = a * a + b * b;
        }
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        for i in 0..j.nrows() {
            let t = (i + 1) as f64 / 5.0;
            let a = x[0] + t * x[1] - t.exp();
            let b = x[2] + t.sin() * x[3] - t.cos();
            j[(i, 0)] = 2.0 * a;
            j[(i, 1)] = 2.0 * a * t;
            j[(i, 2)] = 2.0 * b;
            j[(i, 3)] = 2.0 * b * t.sin();
        }
    }
    Mgh {
        name: "brown-dennis",
        n: 4,
        m: 20,
        residuals: res,
        jacobian: jac,
    }
}
const BROWN_DENNIS_X0: [f64; 4] = [25.0, 5.0, -5.0, -1.0];

/// Osborne 1 [17] (MINPACK 17): r_i = y_i − (x1 + x2 exp(−t_i x4) +
/// x3 exp(−t_i x5)), t_i = 10 (i − 1); start (0.5, 1.5, −1, 0.01, 0.02).
fn osborne1() -> Mgh {
    const Y: [f64; 33] = [
        0.844, 0.908, 0.932, 0.936, 0.925, 0.908, 0.881, 0.850, 0.818, 0.784, 0.751, 0.718, 0.685,
        0.658, 0.628, 0.603, 0.580, 0.558, 0.538, 0.522, 0.506, 0.490, 0.478, 0.467, 0.457, 0.448,
        0.438, 0.431, 0.424, 0.420, 0.414, 0.411, 0.406,
    ];
    fn res(x: &[f64], r: &mut [f64]) {
        for (i, ri) in r.iter_mut().enumerate() {
            let t = 10.0 * i as f64;
            *ri = Y[i] - (x[0] + x[1] * (-t * x[3]).exp() + x[2] * (-t * x[4]).exp());
        }
    }
    fn jac(x: &[f64], j: &mut DMatrix<f64>) {
        for i in 0..33 {
            let t = 10.0 * i as f64;
            let e4 = (-t * x[3]).exp();
            let e5 = (-t * x[4]).exp();
            j[(i, 0)] = -1.0;
            j[(i, 1)] = -e4;
            j[(i, 2)] = -e5;
            j[(i, 3)] = t * x[1] * e4;
            j[(i, 4)] = t * x[2] * e5;
        }
    }
    Mgh {
        name: "osborne 1",
        n: 5,
        m: 33,
        residuals: res,
        jacobian: jac,
    }
}
const OSBORNE1_X0: [f64; 5] = [0.5, 1.5, -1.0, 0.01, 0.02];

// ---------------------------------------------------------------------------
// Tests. MINPACK figures: lmddrv.fortran.ref (see the module comment).
// ---------------------------------------------------------------------------

#[test]
fn linear_full_rank_m10() {
    // MINPACK: norm 2.2360680e+00 (= √5), x = −1, info 3.
    let p = linear_full_rank(10);
    let r = solve(&p, &[1.0; 5]);
    assert_converged(&p, &r);
    assert_norm(&p, &r, 2.2360680e+00, 1e-6);
    assert_norm(&p, &r, 5f64.sqrt(), 1e-12);
    assert_x(&p, &r.x, &[-1.0; 5], 0.0, 1e-9);
}

#[test]
fn linear_full_rank_m50() {
    // MINPACK: norm 6.7082039e+00 (= √45), x = −1, info 3.
    let p = linear_full_rank(50);
    let r = solve(&p, &[1.0; 5]);
    assert_converged(&p, &r);
    assert_norm(&p, &r, 6.7082039e+00, 1e-6);
    assert_norm(&p, &r, 45f64.sqrt(), 1e-12);
    assert_x(&p, &r.x, &[-1.0; 5], 0.0, 1e-9);
}

#[test]
fn rosenbrock_from_1x_10x_100x() {
    // MINPACK: norm 0 at (1, 1) from all three (info 4, 2, 2).
    let p = rosenbrock();
    for factor in [1.0, 10.0, 100.0] {
        let r = solve(&p, &scaled(&ROSENBROCK_X0, factor));
        assert_converged(&p, &r);
        assert_zero_norm(&p, &r, 1e-8);
        assert_x(&p, &r.x, &[1.0, 1.0], 0.0, 1e-8);
    }
}

#[test]
fn helical_valley_from_1x_10x_100x() {
    // MINPACK: norms 9.9365231e-17, 1.0446727e-19, 3.4526556e-29 at
    // (1, 0, 0) (info 2 each).
    let p = helical_valley();
    for factor in [1.0, 10.0, 100.0] {
        let r = solve(&p, &scaled(&HELICAL_X0, factor));
        assert_converged(&p, &r);
        assert_zero_norm(&p, &r, 1e-8);
        assert_x(&p, &r.x, &[1.0, 0.0, 0.0], 0.0, 1e-8);
    }
}

#[test]
fn powell_singular_from_1x_10x() {
    // MINPACK: norm 3.3916607e-167 from 1× (stopped by maxfev, info 5:
    // convergence to the singular minimum is only linear) and
    // 3.6588477e-37 from 10× (info 4). x → 0.
    //
    // drawcal converges linearly as well, then stalls near a norm of
    // 5e-19: it solves the normal equations, whose condition number is that
    // of J squared, and J's smallest singular values shrink with x. (MINPACK
    // factors J itself.) It never meets a convergence test and stops at the
    // iteration limit, which MINPACK also did from 1×; so the termination
    // is not asserted, only that the residual is zero.
    let p = powell_singular();
    for factor in [1.0, 10.0] {
        let r = solve(&p, &scaled(&POWELL_X0, factor));
        assert_zero_norm(&p, &r, 1e-8);
        // r3, r4 are quadratic in x, so a norm of 1e-8 only pins x to ~1e-4.
        assert_x(&p, &r.x, &[0.0; 4], 0.0, 1e-4);
    }
}

#[test]
fn freudenstein_roth_from_1x_10x_100x() {
    // MINPACK: norm 6.9988752e+00 from all three, at the local minimum
    // (11.412484, −0.89682791) (1×), (11.413005, −0.89679604) (10×),
    // (11.412782, −0.89680511) (100×), info 1 each; not the global
    // minimum 0 at (5, 4). The local minimiser is flat along one
    // direction: MINPACK's three x differ by 5e-5 relative. drawcal reaches
    // the same local minimum from all three starts.
    let p = freudenstein_roth();
    for factor in [1.0, 10.0, 100.0] {
        let r = solve(&p, &scaled(&FREUDENSTEIN_X0, factor));
        assert_converged(&p, &r);
        assert_norm(&p, &r, 6.9988752e+00, 1e-6);
        assert_x(&p, &r.x, &[11.412484, -0.89682791], 1e-4, 0.0);
        // x* = (11.4127789869021, −0.896805253274477), norm 6.99887517242878.
        assert_x(&p, &r.x, &[11.4127789869021, -0.896805253274477], 1e-6, 0.0);
    }
}

#[test]
fn bard_from_1x() {
    // MINPACK: norm 9.0635960e-02 at (8.2410577e-02, 1.1330367, 2.3436946),
    // info 1.
    let p = bard();
    let r = solve(&p, &BARD_X0);
    assert_converged(&p, &r);
    assert_norm(&p, &r, 9.0635960e-02, 1e-6);
    assert_x(&p, &r.x, &[8.2410577e-02, 1.1330367, 2.3436946], 1e-6, 0.0);
    // x* = (0.0824105597497889, 1.13303609202972, 2.34369517864254).
    assert_x(
        &p,
        &r.x,
        &[0.0824105597497889, 1.13303609202972, 2.34369517864254],
        1e-6,
        0.0,
    );
}

#[test]
fn bard_from_10x() {
    // MINPACK: norm 4.1747687e+00 at (8.4066667e-01, −1.5884803e+08,
    // −1.6437867e+08), info 1: from 10× the iterates run off to the
    // degenerate minimum at infinity. As x2, x3 → −∞ the model term
    // vanishes, so x1 → mean(y) = 12.61 / 15 and the norm → ‖y − mean(y)‖;
    // only those are determined.
    let p = bard();
    let r = solve(&p, &scaled(&BARD_X0, 10.0));
    assert_converged(&p, &r);
    assert_norm(&p, &r, 4.1747687e+00, 1e-6);
    assert_x(&p, &r.x[..1], &[8.4066667e-01], 1e-6, 0.0);
    assert_x(&p, &r.x[..1], &[12.61 / 15.0], 1e-7, 0.0);
    assert!(
        r.x[1] < -1e6 && r.x[2] < -1e6,
        "bard from 10×: expected x2, x3 → −∞, x = {:?}",
        r.x
    );
}

#[test]
fn kowalik_osborne_from_1x() {
    // MINPACK: norm 1.7535838e-02 at (1.9280781e-01, 1.9126265e-01,
    // 1.2305280e-01, 1.3605322e-01), info 1. That x is 1e-4 (x2) from x*:
    // the minimum is flat, and MINPACK's own run from 100×, which ran out
    // of evaluations near it, ends 1.2e-4 away the other way (1.9124024e-01).
    // drawcal, with its tighter ftol, ends within 1e-6 of x*.
    let p = kowalik_osborne();
    let r = solve(&p, &KOWALIK_X0);
    assert_converged(&p, &r);
    assert_norm(&p, &r, 1.7535838e-02, 1e-6);
    assert_x(
        &p,
        &r.x,
        &[1.9280781e-01, 1.9126265e-01, 1.2305280e-01, 1.3605322e-01],
        2e-4,
        0.0,
    );
    // x* = (0.192806934579, 0.191282328734, 0.123056506926, 0.136062330684).
    assert_x(
        &p,
        &r.x,
        &[
            0.192806934579,
            0.191282328734,
            0.123056506926,
            0.136062330684,
        ],
        1e-6,
        0.0,
    );
}

#[test]
fn meyer_from_1x() {
    // MINPACK: norm 9.3779451e+00 at (5.6096365e-03, 6.1813463e+03,
    // 3.4522363e+02), info 3, after 126 function evaluations. (From 10×
    // MINPACK fails, norm 7.95e+02 at maxfev, so that start has no
    // reference and is not tested.)
    let p = meyer();
    let r = solve(&p, &MEYER_X0);
    assert_converged(&p, &r);
    assert_norm(&p, &r, 9.3779451e+00, 1e-6);
    assert_x(
        &p,
        &r.x,
        &[5.6096365e-03, 6.1813463e+03, 3.4522363e+02],
        1e-6,
        0.0,
    );
    // x* = (0.00560963647102805, 6181.34634628637, 345.223634624136).
    assert_x(
        &p,
        &r.x,
        &[0.00560963647102805, 6181.34634628637, 345.223634624136],
        1e-6,
        0.0,
    );
}

#[test]
fn box_3d_from_1x() {
    // MINPACK: norm 2.8529818e-16 at (1, 10, 1), info 2.
    let p = box_3d();
    let r = solve(&p, &BOX_X0);
    assert_converged(&p, &r);
    assert_zero_norm(&p, &r, 1e-8);
    assert_x(&p, &r.x, &[1.0, 10.0, 1.0], 1e-6, 0.0);
}

#[test]
fn jennrich_sampson_from_1x() {
    // MINPACK: norm 1.1151779e+01 at (2.5781993e-01, 2.5782998e-01),
    // info 1. The minimiser is on x1 = x2 (the problem is symmetric), where
    // the two Jacobian columns coincide; MINPACK's x is 2e-5 off it.
    let p = jennrich_sampson();
    let r = solve(&p, &JENNRICH_X0);
    assert_converged(&p, &r);
    assert_norm(&p, &r, 1.1151779e+01, 1e-6);
    assert_x(&p, &r.x, &[2.5781993e-01, 2.5782998e-01], 1e-4, 0.0);
    // x* = (0.257825213670364, 0.257825213670364), norm 11.1517793358556.
    assert_x(&p, &r.x, &[0.257825213670364; 2], 1e-6, 0.0);
}

#[test]
fn brown_dennis_from_1x_10x() {
    // MINPACK: norm 2.9295429e+02 (1×) and 2.9295427e+02 (10×), info 1,
    // at (−1.1591245e+01, 1.3202486e+01, −4.0357490e-01, 2.3673619e-01)
    // and (−1.1595927e+01, 1.3204187e+01, −4.0341736e-01, 2.3677114e-01):
    // its runs agree to 1e-7 in the norm but only to ~4e-4 in x, and each
    // is up to 3.4e-4 from x*. The minimum is flat along (x3, x4): drawcal
    // ends with the norm of x* to 1e-10 but x3, x4 up to 2.5e-5 from it, so
    // x* is asserted to 1e-4 here.
    let p = brown_dennis();
    let minpack = [
        (
            1.0,
            2.9295429e+02,
            [-1.1591245e+01, 1.3202486e+01, -4.0357490e-01, 2.3673619e-01],
        ),
        (
            10.0,
            2.9295427e+02,
            [-1.1595927e+01, 1.3204187e+01, -4.0341736e-01, 2.3677114e-01],
        ),
    ];
    for (factor, norm, x) in minpack {
        let r = solve(&p, &scaled(&BROWN_DENNIS_X0, factor));
        assert_converged(&p, &r);
        assert_norm(&p, &r, norm, 1e-6);
        assert_x(&p, &r.x, &x, 1e-3, 0.0);
        // x* = (−11.5944399047622, 13.2036300512072, −0.40343948817686,
        // 0.236778774455736), norm 292.954265417584.
        assert_x(
            &p,
            &r.x,
            &[
                -11.5944399047622,
                13.2036300512072,
                -0.40343948817686,
                0.236778774455736,
            ],
            1e-4,
            0.0,
        );
    }
}

#[test]
fn osborne1_from_1x() {
    // MINPACK: norm 7.3924926e-03 at (3.7541005e-01, 1.9358465e+00,
    // −1.4646868e+00, 1.2867534e-02, 2.2122701e-02), info 1.
    let p = osborne1();
    let r = solve(&p, &OSBORNE1_X0);
    assert_converged(&p, &r);
    assert_norm(&p, &r, 7.3924926e-03, 1e-6);
    assert_x(
        &p,
        &r.x,
        &[
            3.7541005e-01,
            1.9358465e+00,
            -1.4646868e+00,
            1.2867534e-02,
            2.2122701e-02,
        ],
        1e-6,
        0.0,
    );
    // x* = (0.375410052106952, 1.93584691271237, −1.46468713661342,
    // 0.0128675346400573, 0.0221226996616726).
    assert_x(
        &p,
        &r.x,
        &[
            0.375410052106952,
            1.93584691271237,
            -1.46468713661342,
            0.0128675346400573,
            0.0221226996616726,
        ],
        1e-6,
        0.0,
    );
}
