//! The rig's anchors identified with the robot (`identify --rig-anchors`).
//!
//! Anchor coordinates are measured by hand and are off by a millimetre or
//! so. String lengths do not change when every anchor and the robot base
//! move together rigidly, so the anchors are identifiable with the robot
//! only up to that 6-dof motion, which the base pose already carries. The
//! gauge is removed by letting the anchors move only orthogonally to the
//! six infinitesimal rigid motions of rig.json's anchor set: a correction
//! `δ` (3m values) satisfies `Σ δ_k = 0` and `Σ A_k × δ_k = 0`. That is
//! exactly the stationarity condition of the best rigid fit of the
//! corrected anchors onto rig.json's (Kabsch), so the corrected anchors
//! are those whose best rigid fit onto rig.json's is the identity: the rig
//! frame stays rig.json's, the smallest correction is reported, and the
//! rigid part of any error goes to the base pose. A truth is compared in
//! the same gauge by fitting it rigidly onto rig.json's anchors
//! ([`in_gauge`]).
//!
//! The corrections are parametrised by `3m - 6` orthonormal "shape modes"
//! (`δ = N z`), appended to the parameter vector after `r`
//! ([`crate::kinematics::Layout::anchor_mode`]) for the geometric fit only:
//! [`reduce`] then takes them out again (the robot's normal matrix becomes
//! the Schur complement, so its sigmas are the marginal ones, anchors'
//! uncertainty included) and the pipeline re-locates T with the corrected
//! anchors for every step after.

use nalgebra::{DMatrix, Vector3};

use super::identifiability::{self, Selection};
use super::lm::LmResult;
use super::unit_covariance;
use crate::error::{Error, Result};
use crate::kinematics::Layout;
use crate::report::FixedParam;

/// Fewest strings with which the anchors are identifiable with the robot:
/// with three the located point has no redundancy and any anchor error is
/// absorbed by the point.
pub const MIN_STRINGS: usize = 4;

/// Why `--rig-anchors` (a job's `rig_anchors`) cannot run on recordings
/// with `n_strings` string columns (0: measured points), if it cannot.
pub fn refusal(n_strings: usize) -> Option<String> {
    if n_strings == 0 {
        Some(
            "the poses carry measured points (tracker, CMM): there are no anchors to identify"
                .into(),
        )
    } else if n_strings < MIN_STRINGS {
        Some(format!(
            "the rig has {n_strings} strings: the anchors are identifiable with the robot from \
             {MIN_STRINGS} strings up (with fewer the located point absorbs any anchor error)"
        ))
    } else {
        None
    }
}

/// The shape modes of an anchor set: the orthonormal basis `N` (3m × (3m-6))
/// of corrections orthogonal to its six rigid motions.
#[derive(Debug, Clone)]
pub struct AnchorModes {
    /// rig.json's anchors (mm), the modes' origin.
    pub nominal: Vec<Vector3<f64>>,
    /// `N`: column j is mode j, rows `3k..3k+3` anchor k's part.
    pub basis: DMatrix<f64>,
}

impl AnchorModes {
    /// The modes of `anchors`; an error if they do not span a plane (then
    /// the rigid motions are fewer than six and no basis is defined).
    pub fn new(anchors: &[Vector3<f64>]) -> Result<Self> {
        let m = anchors.len();
        let c = anchors.iter().sum::<Vector3<f64>>() / m.max(1) as f64;
        // Rigid motions of the set: three translations, three rotations
        // about the centroid (the same span as about the origin, better
        // conditioned).
        let mut rigid = DMatrix::<f64>::zeros(3 * m, 6);
        for (k, a) in anchors.iter().enumerate() {
            let v = a - c;
            for i in 0..3 {
                rigid[(3 * k + i, i)] = 1.0;
                let w = Vector3::ith(i, 1.0).cross(&v);
                for r in 0..3 {
                    rigid[(3 * k + r, 3 + i)] = w[r];
                }
            }
        }
        let gram = rigid.transpose() * &rigid;
        let ev = gram.clone().symmetric_eigenvalues();
        let (lo, hi) = ev
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &e| (a.min(e), b.max(e)));
        let Some(inv) = (lo > 1e-12 * hi).then(|| gram.try_inverse()).flatten() else {
            return Err(Error::field(
                "rig_anchors",
                "the anchors are collinear: their rigid motions cannot be told from a \
                 correction",
            ));
        };
        // The projector onto the complement of the rigid motions; its
        // eigenvectors of eigenvalue 1 are the modes.
        let proj = DMatrix::<f64>::identity(3 * m, 3 * m) - &rigid * inv * rigid.transpose();
        let eig = proj.symmetric_eigen();
        let mut cols: Vec<usize> = (0..3 * m).filter(|&i| eig.eigenvalues[i] > 0.5).collect();
        cols.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let basis = DMatrix::from_fn(3 * m, cols.len(), |r, j| eig.eigenvectors[(r, cols[j])]);
        Ok(AnchorModes {
            nominal: anchors.to_vec(),
            basis,
        })
    }

    /// Number of modes, `3m - 6`.
    pub fn len(&self) -> usize {
        self.basis.ncols()
    }

    /// True without modes (never, for four anchors or more).
    pub fn is_empty(&self) -> bool {
        self.basis.ncols() == 0
    }

    /// The anchors at mode coordinates `z` (mm).
    pub fn anchors(&self, z: &[f64]) -> Vec<Vector3<f64>> {
        let d = self.correction(z);
        self.nominal
            .iter()
            .enumerate()
            .map(|(k, a)| a + Vector3::new(d[3 * k], d[3 * k + 1], d[3 * k + 2]))
            .collect()
    }

    /// The correction `N z` (3m values, mm).
    pub fn correction(&self, z: &[f64]) -> Vec<f64> {
        (0..self.basis.nrows())
            .map(|r| (0..self.len()).map(|j| self.basis[(r, j)] * z[j]).sum())
            .collect()
    }

    /// Mode j's move of anchor k (mm per unit of the mode).
    #[inline]
    pub fn column(&self, k: usize, j: usize) -> Vector3<f64> {
        Vector3::new(
            self.basis[(3 * k, j)],
            self.basis[(3 * k + 1, j)],
            self.basis[(3 * k + 2, j)],
        )
    }
}

/// `truth` in the gauge of [`AnchorModes`]: fitted rigidly onto `nominal`
/// (least squares), so that its correction from `nominal` is orthogonal to
/// the rigid motions, as an identified correction is. For tests and
/// simulations that know the true anchors.
pub fn in_gauge(truth: &[Vector3<f64>], nominal: &[Vector3<f64>]) -> Option<Vec<Vector3<f64>>> {
    let (r, t) = super::rigid_fit(truth, nominal)?;
    Some(truth.iter().map(|a| r * a + t).collect())
}

/// One anchor's identified correction.
#[derive(Debug, Clone)]
pub struct AnchorFit {
    /// Corrected anchor (mm, rig frame).
    pub calibrated_mm: Vector3<f64>,
    /// Correction from rig.json's (mm).
    pub correction_mm: Vector3<f64>,
    /// 1-sigma of each coordinate of the correction (mm).
    pub sigma_mm: Vector3<f64>,
    /// How well the data separate this anchor's moves from everything else
    /// fitted: the smallest over x, y, z of the sine the identifiability
    /// analysis uses for a parameter (see [`coordinate_sines`]); 1 for a
    /// move nothing else mimics, under [`identifiability::DEFAULT_TOLERANCE`]
    /// not identifiable.
    pub identifiability: f64,
}

/// The anchors' part of a geometric fit.
#[derive(Debug, Clone)]
pub struct RigFit {
    /// Per anchor, in rig.json's order.
    pub anchors: Vec<AnchorFit>,
    /// Shape modes in all (`3m - 6`).
    pub n_modes: usize,
    /// Shape modes the data determine (the others held at zero, aliased).
    pub n_identified: usize,
    /// The held modes and what they are aliased with.
    pub held: Vec<FixedParam>,
}

impl RigFit {
    /// The corrected anchors.
    pub fn calibrated(&self) -> Vec<Vector3<f64>> {
        self.anchors.iter().map(|a| a.calibrated_mm).collect()
    }
}

/// Take the anchor modes out of a geometric fit over layout `l`: the
/// anchors' corrections with their sigmas (from `sigma² (JᵀWJ)⁻¹` over
/// every free parameter) and identifiability, and the fit reduced to the
/// robot's parameters: `values` truncated, the modes dropped from
/// `selection`, `result.x` and `result.jtj` (which becomes the Schur
/// complement, whose inverse is the robot's block of the full inverse: the
/// robot's sigmas keep the anchors' uncertainty).
pub fn reduce(
    l: Layout,
    modes: &AnchorModes,
    values: &mut Vec<f64>,
    selection: &mut Selection,
    result: &mut LmResult,
    sigma: f64,
) -> RigFit {
    let n = selection.free.len();
    let is_mode = |i: usize| i >= l.len();
    let fa: Vec<usize> = (0..n).filter(|&k| is_mode(selection.free[k])).collect();
    let fr: Vec<usize> = (0..n).filter(|&k| !is_mode(selection.free[k])).collect();
    let z: Vec<f64> = (0..modes.len()).map(|j| values[l.anchor_mode(j)]).collect();
    let delta = modes.correction(&z);
    let cov = unit_covariance(&result.jtj);
    // A free mode's position, for each mode.
    let at: Vec<Option<usize>> = (0..modes.len())
        .map(|j| {
            fa.iter()
                .copied()
                .find(|&k| selection.free[k] == l.anchor_mode(j))
        })
        .collect();
    let sines = coordinate_sines(modes, &at, &result.jtj, cov.as_ref());
    let anchors = modes
        .nominal
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let d = Vector3::new(delta[3 * k], delta[3 * k + 1], delta[3 * k + 2]);
            let sd = Vector3::from_fn(|c, _| {
                let g = mode_row(modes, &at, 3 * k + c, n);
                match &cov {
                    Some(cov) => sigma * g.dot(&(cov * &g)).max(0.0).sqrt(),
                    None => f64::NAN,
                }
            });
            AnchorFit {
                calibrated_mm: a + d,
                correction_mm: d,
                sigma_mm: sd,
                identifiability: (0..3).map(|c| sines[3 * k + c]).fold(1.0, f64::min),
            }
        })
        .collect();
    let held: Vec<FixedParam> = selection
        .fixed
        .iter()
        .filter(|f| f.name.starts_with(Layout::ANCHOR_MODE_PREFIX))
        .cloned()
        .collect();
    selection
        .fixed
        .retain(|f| !f.name.starts_with(Layout::ANCHOR_MODE_PREFIX));
    // The robot block: the Schur complement of the modes' block.
    let sub = |rows: &[usize], cols: &[usize]| {
        DMatrix::from_fn(rows.len(), cols.len(), |i, j| {
            result.jtj[(rows[i], cols[j])]
        })
    };
    let (rr, ra, aa) = (sub(&fr, &fr), sub(&fr, &fa), sub(&fa, &fa));
    result.jtj = match unit_covariance(&aa) {
        Some(aa_inv) if !fa.is_empty() => &rr - &ra * aa_inv * ra.transpose(),
        _ => rr,
    };
    result.x = fr.iter().map(|&k| result.x[k]).collect();
    selection.free = fr.iter().map(|&k| selection.free[k]).collect();
    values.truncate(l.len());
    RigFit {
        anchors,
        n_modes: modes.len(),
        n_identified: fa.len(),
        held,
    }
}

/// Row `r` of `N` (coordinate r's share of each mode) laid out over the
/// `n` free parameters: what a unit move of that coordinate, projected on
/// the gauge, does to them. Held modes count zero.
fn mode_row(
    modes: &AnchorModes,
    at: &[Option<usize>],
    r: usize,
    n: usize,
) -> nalgebra::DVector<f64> {
    let mut g = nalgebra::DVector::zeros(n);
    for (j, a) in at.iter().enumerate() {
        if let Some(k) = a {
            g[*k] = modes.basis[(r, j)];
        }
    }
    g
}

/// Per anchor coordinate (3m values), the identifiability analysis's sine
/// of its move: for a unit direction `g` of the free parameters,
/// `1 / sqrt(gᵀHg · gᵀH⁻¹g)`, which for a parameter's own axis is the sine
/// of its Jacobian column to the span of the others
/// ([`identifiability::undetermined`]'s test). Here `g` is the coordinate's
/// move projected on the gauge and normalised, so the others are the
/// robot's parameters and the anchors' moves orthogonal to it; the value
/// does not depend on how the robot's parameters are scaled. 0 when the
/// move is held or nothing can be inverted.
pub fn coordinate_sines(
    modes: &AnchorModes,
    at: &[Option<usize>],
    jtj: &DMatrix<f64>,
    cov: Option<&DMatrix<f64>>,
) -> Vec<f64> {
    let n = jtj.nrows();
    (0..modes.basis.nrows())
        .map(|r| {
            let g = mode_row(modes, at, r, n);
            let norm = g.norm();
            match cov {
                Some(cov) if norm > 1e-9 => {
                    let g = g / norm;
                    let v = g.dot(&(jtj * &g)) * g.dot(&(cov * &g));
                    if v > 0.0 {
                        (1.0 / v.sqrt()).min(1.0)
                    } else {
                        0.0
                    }
                }
                _ => 0.0,
            }
        })
        .collect()
}

/// What a constant error of rig.json's anchors would explain of a fit made
/// with them: [`probe`]'s answer.
#[derive(Debug, Clone)]
pub struct Probe {
    /// Held-out 3-D RMS (mm, robot base frame) with the anchors fitted with
    /// the robot: T located again with them at every test pose.
    pub test_rms_mm: f64,
    /// The largest anchor correction (mm) and its anchor (0-based).
    pub largest_mm: f64,
    /// Which anchor that is.
    pub largest_anchor: usize,
    /// Residual scale of the train readings with the anchors fitted (mm):
    /// the string noise, when the anchors explain the strings.
    pub sigma_mm: f64,
}

/// Refit `values` (the geometric fit over `free`, on `obs`'s train poses)
/// with the anchors' shape modes free too, and measure the held-out error
/// with the anchors so found: whether the strings disagree the way a
/// constant anchor error explains (the pipeline then proposes
/// `--rig-anchors`). `None` with fewer than [`MIN_STRINGS`] strings, no
/// test poses, or a fit that does not converge.
pub fn probe(obs: &super::Observations, values: &[f64], free: &[usize]) -> Option<Probe> {
    let l = obs.chain.layout;
    if l.n_strings < MIN_STRINGS || obs.test.is_empty() || values.len() != l.len() {
        return None;
    }
    let modes = AnchorModes::new(&obs.anchors).ok()?;
    let mut full = values.to_vec();
    full.extend(std::iter::repeat_n(0.0, modes.len()));
    let mut f = free.to_vec();
    f.extend((0..modes.len()).map(|j| l.anchor_mode(j)));
    let problem = super::problem::CalibrationProblem::new(
        obs.chain,
        obs.anchors.clone(),
        obs.train_poses(),
        full,
        f,
    )
    .with_anchor_modes(modes.clone());
    let fit = super::lm::minimize(
        &problem,
        &problem.x0(),
        &super::lm::LmSettings::default(),
        |_, _| true,
    )
    .ok()?;
    let p = problem.expand(&fit.x);
    let n = super::lm::LeastSquares::n_residuals(&problem) as f64;
    let sigma_mm = (2.0 * fit.cost / (n - fit.x.len() as f64).max(1.0)).sqrt();
    let z = &p[l.len()..];
    let anchors = modes.anchors(z);
    let b = l.base();
    let rb = crate::kinematics::rpy_matrix(p[b + 3], p[b + 4], p[b + 5]);
    let mut errors = Vec::with_capacity(obs.test.len());
    for &i in &obs.test {
        let crate::model::Measurement::Strings(readings) = &obs.data.poses[i].measurement else {
            return None;
        };
        // With the string offsets fitted beside the anchors, as the
        // pipeline locates T after a rig calibration.
        let dist: Vec<f64> = readings
            .iter()
            .enumerate()
            .map(|(k, v)| v + obs.rig.r_mm + p[l.string_offset(k)])
            .collect();
        let at = crate::measure::locate(&anchors, &dist, Some(&obs.measured[i])).ok()?;
        let (_, t) = obs.chain.point(
            &p,
            &obs.data.poses[i].q_rad,
            crate::kinematics::chain::OutputFrame::Rig,
        );
        errors.push(rb.transpose() * (t - at.point));
    }
    let (largest_anchor, largest_mm) = anchors
        .iter()
        .zip(&modes.nominal)
        .map(|(a, n)| (a - n).norm())
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    Some(Probe {
        test_rms_mm: crate::stats::rms_norm(&errors),
        largest_mm,
        largest_anchor,
        sigma_mm,
    })
}

/// Whether a sine of [`coordinate_sines`] marks an anchor as determined.
pub fn identified(sine: f64) -> bool {
    sine > identifiability::DEFAULT_TOLERANCE
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rig4() -> Vec<Vector3<f64>> {
        vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.0, 900.0, 0.0),
            Vector3::new(1200.0, 0.0, 0.0),
            Vector3::new(1200.0, 900.0, 0.0),
        ]
    }

    #[test]
    fn modes_are_orthonormal_and_orthogonal_to_rigid_motions() {
        let a = rig4();
        let m = AnchorModes::new(&a).unwrap();
        assert_eq!(m.len(), 6);
        let g = m.basis.transpose() * &m.basis;
        assert!((g - DMatrix::<f64>::identity(6, 6)).norm() < 1e-9);
        // Every mode: Σ δ_k = 0 and Σ A_k × δ_k = 0.
        for j in 0..m.len() {
            let (mut s, mut w) = (Vector3::zeros(), Vector3::zeros());
            for (k, ak) in a.iter().enumerate() {
                s += m.column(k, j);
                w += ak.cross(&m.column(k, j));
            }
            assert!(s.norm() < 1e-9 && w.norm() < 1e-6, "{s:?} {w:?}");
        }
    }

    #[test]
    fn a_truth_in_the_gauge_is_what_the_modes_can_reach() {
        // An anchor error plus a rigid motion: in the gauge, the rigid
        // part is gone and the rest is in the span of the modes.
        let a = rig4();
        let m = AnchorModes::new(&a).unwrap();
        let bump = [
            Vector3::new(0.5, -1.0, 0.3),
            Vector3::new(-0.2, 0.8, 1.5),
            Vector3::new(1.1, 0.4, -0.6),
            Vector3::new(-0.7, -1.2, 0.9),
        ];
        let rot = nalgebra::Rotation3::from_euler_angles(0.01, -0.02, 0.015);
        let t = Vector3::new(5.0, -3.0, 2.0);
        let truth: Vec<_> = a
            .iter()
            .zip(&bump)
            .map(|(a, b)| rot * (a + b) + t)
            .collect();
        let g = in_gauge(&truth, &a).unwrap();
        let d: Vec<f64> = g
            .iter()
            .zip(&a)
            .flat_map(|(g, a)| (g - a).iter().copied().collect::<Vec<_>>())
            .collect();
        let d = nalgebra::DVector::from_vec(d);
        let z = m.basis.transpose() * &d;
        let back = &m.basis * &z;
        assert!((back - &d).norm() < 1e-9 * (1.0 + d.norm()));
        // The bump projected on the modes is what remains (to first order
        // in the rotation).
        let bump =
            nalgebra::DVector::from_iterator(12, bump.iter().flat_map(|b| b.iter().copied()));
        let proj = &m.basis * (m.basis.transpose() * bump);
        assert!((proj - d).norm() < 0.05);
    }

    #[test]
    fn refuses_three_strings_and_points_by_name() {
        assert!(refusal(4).is_none());
        assert!(refusal(3).unwrap().contains("3 strings"));
        assert!(refusal(0).unwrap().contains("measured points"));
        let collinear: Vec<_> = (0..4)
            .map(|k| Vector3::new(100.0 * k as f64, 0.0, 0.0))
            .collect();
        assert!(AnchorModes::new(&collinear).is_err());
    }
}
