//! Least-squares multilateration: the point whose distances to the anchors
//! best match the string lengths, with its covariance and, with more than
//! three strings, a consistency residual.

use nalgebra::{Matrix3, Vector3};

use crate::error::{Error, Result};

/// A located point.
#[derive(Debug, Clone, PartialEq)]
pub struct Located {
    /// T in the rig frame (mm).
    pub point: Vector3<f64>,
    /// Per-string residual `|T - A_k| - (l_k + r)` at the solution (mm).
    pub residuals_mm: Vec<f64>,
    /// `(GᵀG)⁻¹` with G the unit anchor-to-T directions: the point
    /// covariance per unit string variance (mm²/mm²).
    pub cov_unit: Matrix3<f64>,
}

impl Located {
    /// RMS string residual (mm), zero with three strings.
    pub fn consistency_rms_mm(&self) -> f64 {
        (self.residuals_mm.iter().map(|r| r * r).sum::<f64>() / self.residuals_mm.len() as f64)
            .sqrt()
    }
}

/// The point at distances `dist_mm[k]` from `anchors[k]`. With coplanar
/// anchors (the paper's rig) there are two mirror solutions; `side` picks the
/// one nearer to it (default: the +normal side, as the paper's z >= 0).
pub fn locate(
    anchors: &[Vector3<f64>],
    dist_mm: &[f64],
    side: Option<&Vector3<f64>>,
) -> Result<Located> {
    let m = anchors.len();
    if m < 3 || dist_mm.len() != m {
        return Err(Error::InsufficientData(format!(
            "{} distances for {m} anchors: need 3 or more, one each",
            dist_mm.len()
        )));
    }
    let start = linear_start(anchors, dist_mm, side)?;
    let mut p = start;
    // Gauss-Newton on the distances; converges in a handful of steps from
    // the linear start.
    for _ in 0..30 {
        let mut gtg = Matrix3::zeros();
        let mut gtr = Vector3::zeros();
        for k in 0..m {
            let v = p - anchors[k];
            let n = v.norm().max(1e-9);
            let u = v / n;
            let r = n - dist_mm[k];
            gtg += u * u.transpose();
            gtr += u * r;
        }
        let step = match gtg.try_inverse() {
            Some(inv) => inv * gtr,
            None => {
                return Err(Error::Numerical(
                    "multilateration: the strings do not fix the point".into(),
                ));
            }
        };
        p -= step;
        if step.norm() < 1e-10 {
            break;
        }
    }
    let mut gtg = Matrix3::zeros();
    let mut residuals_mm = Vec::with_capacity(m);
    for k in 0..m {
        let v = p - anchors[k];
        let u = v / v.norm();
        gtg += u * u.transpose();
        residuals_mm.push(v.norm() - dist_mm[k]);
    }
    let cov_unit = gtg
        .try_inverse()
        .ok_or_else(|| Error::Numerical("multilateration: singular geometry".into()))?;
    Ok(Located {
        point: p,
        residuals_mm,
        cov_unit,
    })
}

/// True when the anchors lie in one plane (the paper's rig): every point
/// then has a mirror image across that plane at the same distances.
pub fn coplanar(anchors: &[Vector3<f64>]) -> bool {
    spread_frame(anchors).2
}

/// The eigen-decomposition of the anchors' spread about their centroid,
/// with its axes ordered from the strongest spread down, and whether the
/// weakest is nil (coplanar anchors).
fn spread_frame(
    anchors: &[Vector3<f64>],
) -> (
    nalgebra::SymmetricEigen<f64, nalgebra::U3>,
    [usize; 3],
    bool,
) {
    let mut cov = Matrix3::zeros();
    let centroid = anchors.iter().sum::<Vector3<f64>>() / anchors.len().max(1) as f64;
    for a in anchors {
        let v = a - centroid;
        cov += v * v.transpose();
    }
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
    let spread = eig.eigenvalues[order[0]].max(1e-12);
    let coplanar = eig.eigenvalues[order[2]] < 1e-6 * spread;
    (eig, order, coplanar)
}

/// A start from the linearised equations `2(A_k - A_0)·p = |A_k|² - |A_0|²
/// - d_k² + d_0²`. When the anchors are coplanar the normal component comes
/// from the first sphere instead.
fn linear_start(
    anchors: &[Vector3<f64>],
    d: &[f64],
    side: Option<&Vector3<f64>>,
) -> Result<Vector3<f64>> {
    let a0 = anchors[0];
    // Orthonormal frame of the anchors' spread: e1, e2 span the plane of
    // the strongest spread, e3 its normal.
    let (eig, order, coplanar) = spread_frame(anchors);
    let mut rows: Vec<(Vector3<f64>, f64)> = Vec::new();
    for k in 1..anchors.len() {
        let ak = anchors[k];
        rows.push((
            2.0 * (ak - a0),
            ak.norm_squared() - a0.norm_squared() - d[k] * d[k] + d[0] * d[0],
        ));
    }
    if !coplanar {
        let mut ata = Matrix3::zeros();
        let mut atb = Vector3::zeros();
        for (a, b) in &rows {
            ata += a * a.transpose();
            atb += a * *b;
        }
        return ata
            .try_inverse()
            .map(|inv| inv * atb)
            .ok_or_else(|| Error::Numerical("multilateration: degenerate anchors".into()));
    }
    let e1 = eig.eigenvectors.column(order[0]).into_owned();
    let e2 = eig.eigenvectors.column(order[1]).into_owned();
    let mut n = eig.eigenvectors.column(order[2]).into_owned();
    // In-plane solve for (u, v) with p = a0 + u e1 + v e2 + w n.
    let (mut s11, mut s12, mut s22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (a, b) in &rows {
        let (x, y) = (a.dot(&e1), a.dot(&e2));
        let rhs = b - a.dot(&a0);
        s11 += x * x;
        s12 += x * y;
        s22 += y * y;
        b1 += x * rhs;
        b2 += y * rhs;
    }
    let det = s11 * s22 - s12 * s12;
    if det.abs() < 1e-12 * (s11 * s22).max(1e-300) {
        return Err(Error::Numerical(
            "multilateration: degenerate anchors".into(),
        ));
    }
    let u = (s22 * b1 - s12 * b2) / det;
    let v = (s11 * b2 - s12 * b1) / det;
    let in_plane = u * e1 + v * e2;
    let w = (d[0] * d[0] - in_plane.norm_squared()).max(0.0).sqrt();
    // Paper's convention: z along x_AC × (A→D side), i.e. the anchors'
    // right-handed normal; a side hint overrides it.
    let paper_normal =
        (anchors[2.min(anchors.len() - 1)] - a0).cross(&(anchors[anchors.len() - 1] - a0));
    if paper_normal.dot(&n) < 0.0 {
        n = -n;
    }
    let plus = a0 + in_plane + w * n;
    let minus = a0 + in_plane - w * n;
    Ok(match side {
        Some(h) if (minus - h).norm() < (plus - h).norm() => minus,
        _ => plus,
    })
}

/// The string noise (1 sigma, mm) implied by the strings' redundancy: with
/// m > 3 strings each located point leaves m - 3 degrees of freedom, so
/// `σ² = Σ residual² / Σ (m - 3)`. `None` with three strings.
pub fn string_sigma(located: &[Located]) -> Option<f64> {
    let mut ss = 0.0;
    let mut dof = 0usize;
    for l in located {
        let m = l.residuals_mm.len();
        if m > 3 {
            ss += l.residuals_mm.iter().map(|r| r * r).sum::<f64>();
            dof += m - 3;
        }
    }
    (dof > 0).then(|| (ss / dof as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn anchors() -> Vec<Vector3<f64>> {
        vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(3.5, 898.9, 0.0),
            Vector3::new(1200.0, 0.0, 0.0),
            Vector3::new(1202.3, 900.7, 0.0),
        ]
    }

    #[test]
    fn recovers_point_coplanar_and_3d() {
        let t = Vector3::new(420.0, 310.0, 555.0);
        let a = anchors();
        let d: Vec<f64> = a.iter().map(|x| (t - x).norm()).collect();
        let l = locate(&a, &d, None).unwrap();
        assert!((l.point - t).norm() < 1e-8);
        assert!(l.consistency_rms_mm() < 1e-8);
        let mut a3 = a.clone();
        a3[3].z = 400.0;
        let d3: Vec<f64> = a3.iter().map(|x| (t - x).norm()).collect();
        assert!((locate(&a3, &d3, None).unwrap().point - t).norm() < 1e-8);
        // Three anchors: mirror picked by the side hint.
        let below = Vector3::new(420.0, 310.0, -555.0);
        let d2: Vec<f64> = a[..3].iter().map(|x| (below - x).norm()).collect();
        let l = locate(&a[..3], &d2, Some(&Vector3::new(0.0, 0.0, -100.0))).unwrap();
        assert!((l.point - below).norm() < 1e-6);
    }

    #[test]
    fn string_sigma_estimates_noise() {
        let a = anchors();
        let mut rng = crate::rng::Rng::new(5);
        let mut located = Vec::new();
        for _ in 0..3000 {
            let t = Vector3::new(
                rng.range(200.0, 1000.0),
                rng.range(100.0, 800.0),
                rng.range(200.0, 700.0),
            );
            let d: Vec<f64> = a
                .iter()
                .map(|x| (t - x).norm() + 0.02 * rng.normal())
                .collect();
            located.push(locate(&a, &d, None).unwrap());
        }
        let s = string_sigma(&located).unwrap();
        assert!((s - 0.02).abs() < 0.002, "{s}");
    }
}
