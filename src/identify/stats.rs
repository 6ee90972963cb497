//! Error figures: the paper's Tables 3 and 4 (per-axis and 3-D max and mean
//! absolute error) plus RMS.

use nalgebra::Vector3;

use super::report::{AxisStats, ErrorStats};

/// Figures of a set of error vectors (mm).
pub fn error_stats(errors: &[Vector3<f64>]) -> ErrorStats {
    let n = errors.len();
    if n == 0 {
        // No poses, no figures: NaN, written as null, never a perfect 0.
        let none = AxisStats {
            max_abs_mm: f64::NAN,
            mean_abs_mm: f64::NAN,
            rms_mm: f64::NAN,
        };
        return ErrorStats {
            rms_mm: f64::NAN,
            mean_mm: f64::NAN,
            max_mm: f64::NAN,
            x: none,
            y: none,
            z: none,
        };
    }
    let nf = n as f64;
    let axis = |c: usize| {
        let abs: Vec<f64> = errors.iter().map(|e| e[c].abs()).collect();
        AxisStats {
            max_abs_mm: abs.iter().cloned().fold(0.0, f64::max),
            mean_abs_mm: abs.iter().sum::<f64>() / nf,
            rms_mm: (abs.iter().map(|v| v * v).sum::<f64>() / nf).sqrt(),
        }
    };
    let norms: Vec<f64> = errors.iter().map(|e| e.norm()).collect();
    ErrorStats {
        rms_mm: (norms.iter().map(|v| v * v).sum::<f64>() / nf).sqrt(),
        mean_mm: norms.iter().sum::<f64>() / nf,
        max_mm: norms.iter().cloned().fold(0.0, f64::max),
        x: axis(0),
        y: axis(1),
        z: axis(2),
    }
}

/// Median of a slice (NaN-free), 0 when empty.
pub fn median(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_of_known_errors() {
        let e = [Vector3::new(3.0, 4.0, 0.0), Vector3::new(0.0, 0.0, -1.0)];
        let s = error_stats(&e);
        assert_eq!(s.max_mm, 5.0);
        assert_eq!(s.mean_mm, 3.0);
        assert!((s.rms_mm - 13.0f64.sqrt()).abs() < 1e-12);
        assert_eq!(s.z.max_abs_mm, 1.0);
        assert_eq!(s.x.mean_abs_mm, 1.5);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
    }
}
