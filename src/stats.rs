//! Small statistics shared by every layer: the median, the RMS, and the
//! distribution quantiles of the significance tests (no statistics crate:
//! the approximations below are accurate to well under 1% in the tails
//! used, far finer than the thresholds need).

use nalgebra::Vector3;

/// Median of `values` (the mean of the middle two for an even count); NaN
/// when empty, so that a missing figure never reads as a perfect 0.
pub fn median(values: &[f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
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

/// Root mean square of `values`; NaN when empty.
pub fn rms(values: &[f64]) -> f64 {
    rms_of(values.iter().map(|v| v * v), values.len())
}

/// Root mean square of the lengths of `errors` (the 3-D RMS, mm); NaN when
/// empty.
pub fn rms_norm(errors: &[Vector3<f64>]) -> f64 {
    rms_of(errors.iter().map(|v| v.norm_squared()), errors.len())
}

fn rms_of(squares: impl Iterator<Item = f64>, n: usize) -> f64 {
    if n == 0 {
        return f64::NAN;
    }
    (squares.sum::<f64>() / n as f64).sqrt()
}

/// Standard normal quantile (Acklam's rational approximation, relative error
/// below 1.2e-9).
pub fn normal_quantile(p: f64) -> f64 {
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    const A: [f64; 6] = [
        -3.969683028665376e+01,
        2.209460984245205e+02,
        -2.759285104469687e+02,
        1.383577518672690e+02,
        -3.066479806614716e+01,
        2.506628277459239e+00,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e+01,
        1.615858368580409e+02,
        -1.556989798598866e+02,
        6.680131188771972e+01,
        -1.328068155288572e+01,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-03,
        -3.223964580411365e-01,
        -2.400758277161838e+00,
        -2.549732539343734e+00,
        4.374664141464968e+00,
        2.938163982698783e+00,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-03,
        3.224671290700398e-01,
        2.445134137142996e+00,
        3.754408661907416e+00,
    ];
    let plow = 0.02425;
    if p < plow {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - plow {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -normal_quantile(1.0 - p)
    }
}

/// Standard normal upper tail `P(Z > z)`, from the complementary error
/// function's Chebyshev fit (fractional error below 1.2e-7 everywhere, so
/// also in the far tail where `1 - cdf` would cancel).
pub fn normal_upper_tail(z: f64) -> f64 {
    let x = z / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.5 * x.abs());
    const C: [f64; 10] = [
        -1.26551223,
        1.00002368,
        0.37409196,
        0.09678418,
        -0.18628806,
        0.27886807,
        -1.13520398,
        1.48851587,
        -0.82215223,
        0.17087277,
    ];
    let poly = C.iter().rev().fold(0.0, |acc, c| acc * t + c);
    let erfc_abs = t * (-x * x + poly).exp();
    let erfc = if x >= 0.0 { erfc_abs } else { 2.0 - erfc_abs };
    0.5 * erfc
}

/// Chi-square statistic `x` with `k` degrees of freedom as a standard normal
/// score (Wilson-Hilferty cube-root transform).
pub fn chi2_z(x: f64, k: usize) -> f64 {
    let k = k.max(1) as f64;
    let v = 2.0 / (9.0 * k);
    ((x.max(0.0) / k).cbrt() - (1.0 - v)) / v.sqrt()
}

/// Upper `alpha` quantile of chi-square with `k` degrees of freedom
/// (Wilson-Hilferty).
pub fn chi2_quantile_upper(alpha: f64, k: usize) -> f64 {
    let kf = k.max(1) as f64;
    let v = 2.0 / (9.0 * kf);
    let z = normal_quantile(1.0 - alpha);
    kf * (1.0 - v + z * v.sqrt()).powi(3)
}

/// Upper `alpha` quantile of the F distribution with `d1` and `d2` degrees
/// of freedom (Paulson's approximation: Wilson-Hilferty applied to the
/// ratio of the two chi-squares; within about 1 % for `d2 >= 10`).
pub fn f_quantile_upper(alpha: f64, d1: usize, d2: usize) -> f64 {
    let (e, c) = (
        2.0 / (9.0 * d1.max(1) as f64),
        2.0 / (9.0 * d2.max(1) as f64),
    );
    let (a, b) = (1.0 - c, 1.0 - e);
    let z = normal_quantile(1.0 - alpha);
    // (a u - b)^2 = z^2 (c u^2 + e) for u = F^(1/3), the larger root.
    let qa = a * a - z * z * c;
    let disc = (a * b).powi(2) - qa * (b * b - z * z * e);
    if qa <= 0.0 || disc < 0.0 {
        return f64::INFINITY;
    }
    ((a * b + disc.sqrt()) / qa).powi(3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_tables() {
        assert!((normal_quantile(0.975) - 1.959964).abs() < 1e-5);
        assert!((normal_quantile(0.001) + 3.090232).abs() < 1e-5);
        // chi2(1) upper 1e-3: 10.83; chi2(3) upper 0.01: 11.34
        assert!((chi2_quantile_upper(1e-3, 1) - 10.83).abs() < 0.4);
        assert!((chi2_quantile_upper(0.01, 3) - 11.34).abs() < 0.1);
        assert!(
            (chi2_z(chi2_quantile_upper(1e-4, 2), 2) - normal_quantile(1.0 - 1e-4)).abs() < 1e-9
        );
    }

    #[test]
    fn the_normal_tail_inverts_the_quantile() {
        assert!((normal_upper_tail(0.0) - 0.5).abs() < 1e-7);
        assert!((normal_upper_tail(1.959964) - 0.025).abs() < 1e-7);
        assert!((normal_upper_tail(-1.959964) - 0.975).abs() < 1e-7);
        for p in [1e-3, 1e-4, 1.7e-4, 1e-6, 1e-9] {
            let q = normal_upper_tail(normal_quantile(1.0 - p));
            assert!((q / p - 1.0).abs() < 1e-5, "{p}: {q}");
        }
    }

    #[test]
    fn f_quantiles_match_tables() {
        // F upper 0.001 (10, 20): 5.075; 0.01 (5, 10): 5.636; 0.05 (60, 120): 1.429.
        for (alpha, d1, d2, table) in [
            (1e-3, 10, 20, 5.075),
            (1e-2, 5, 10, 5.636),
            (5e-2, 60, 120, 1.429),
        ] {
            let f = f_quantile_upper(alpha, d1, d2);
            assert!(
                (f / table - 1.0).abs() < 0.03,
                "F({alpha}; {d1}, {d2}) = {f}, table {table}"
            );
        }
    }

    #[test]
    fn median_and_rms_of_known_values() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
        assert_eq!(rms(&[3.0, -4.0, 0.0, 0.0]), 2.5);
        assert!(rms(&[]).is_nan());
        let e = [Vector3::new(3.0, 4.0, 0.0), Vector3::new(0.0, 0.0, -1.0)];
        assert!((rms_norm(&e) - 13.0f64.sqrt()).abs() < 1e-12);
        assert!(rms_norm(&[]).is_nan());
    }
}
