//! Structure periodic in a driver (a string's length: a drum's winding
//! pitch, a spool's eccentricity): the periods sought, and the test that
//! finds one. The locator (`physics::unexplained`) tests a string's
//! residual against them; the data-driven correction
//! (`physics::analyse`) scans the same periods, so what was located is
//! what can be modelled.
//!
//! Neighbours in the driver agree only while the period is long against
//! their spacing, and a piecewise-linear correction needs knots for every
//! cycle: a periodic error of many short cycles escapes both.

/// Fewest cycles over the range the poses cover: below two, the smooth
/// (non-periodic) tests and corrections already see it.
const MIN_CYCLES: f64 = 2.0;
/// Most cycles over the range: past this a cycle holds too few poses.
pub const MAX_CYCLES: f64 = 64.0;
/// Frequency steps per inverse range: a period off by half a step is out
/// of phase by an eighth of a cycle at the ends of the range.
const STEPS_PER_CYCLE: f64 = 4.0;

/// The periods sought in a driver that took `values`: frequencies evenly
/// spaced (four steps per inverse range) from two to [`MAX_CYCLES`]
/// cycles over their range. Empty when the values have no range.
///
/// ```
/// use drawcal::physics::periodogram::scanned_periods;
/// let p = scanned_periods(&[0.0, 100.0]);
/// assert_eq!(p[0], 50.0); // two cycles over the range
/// assert!((p[p.len() - 1] - 100.0 / 64.0).abs() < 1e-9);
/// ```
pub fn scanned_periods(values: &[f64]) -> Vec<f64> {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let range = hi - lo;
    if !(range > 0.0) {
        return vec![];
    }
    let step = 1.0 / (STEPS_PER_CYCLE * range);
    let steps = ((MAX_CYCLES - MIN_CYCLES) * STEPS_PER_CYCLE).round() as usize;
    (0..=steps)
        .map(|i| 1.0 / (MIN_CYCLES / range + i as f64 * step))
        .collect()
}

/// The strongest sinusoid in `y` as a function of `x` over the
/// [`scanned_periods`] of `x`: its period and the chance that noise alone
/// gives one as strong at any of them (Bonferroni over the periods tried).
///
/// Per period, `y` is fitted by a constant and a sine and cosine; the
/// F-statistic of the two against what is left has, for independent
/// Gaussian noise, the exact tail `(1 + 2F/d)^(-d/2)` with `d = n - 3`.
/// `None` with fewer than eight values or no range.
///
/// ```
/// use drawcal::physics::periodogram::strongest_period;
/// let x: Vec<f64> = (0..200).map(|i| 300.0 + 2.0 * i as f64 + 0.3 * (i % 7) as f64).collect();
/// let y: Vec<f64> = x.iter().enumerate()
///     .map(|(i, v)| 0.05 * (2.0 * std::f64::consts::PI * v / 37.0).sin() + 0.02 * ((i * 7919 % 97) as f64 / 97.0 - 0.5))
///     .collect();
/// let (period, p) = strongest_period(&x, &y).unwrap();
/// assert!((period - 37.0).abs() < 1.0 && p < 1e-6, "{period} {p}");
/// ```
pub fn strongest_period(x: &[f64], y: &[f64]) -> Option<(f64, f64)> {
    let n = x.len().min(y.len());
    if n < 8 {
        return None;
    }
    let periods = scanned_periods(&x[..n]);
    let mean = y[..n].iter().sum::<f64>() / n as f64;
    let yc: Vec<f64> = y[..n].iter().map(|v| v - mean).collect();
    let total: f64 = yc.iter().map(|v| v * v).sum();
    if periods.is_empty() || total <= 0.0 {
        return None;
    }
    let d = (n - 3) as f64;
    let mut best: Option<(f64, f64)> = None;
    for &period in &periods {
        let explained = sinusoid_explained(&x[..n], &yc, period);
        let rest = (total - explained).max(1e-300);
        let f = (explained / 2.0) / (rest / d);
        if best.is_none_or(|(_, bf)| f > bf) {
            best = Some((period, f));
        }
    }
    let (period, f) = best?;
    let p = (1.0 + 2.0 * f / d).powf(-d / 2.0) * periods.len() as f64;
    Some((period, p.min(1.0)))
}

/// Sum of squares of centred `yc` explained by a constant, a sine and a
/// cosine of `x` at `period` (beyond the constant alone).
fn sinusoid_explained(x: &[f64], yc: &[f64], period: f64) -> f64 {
    let w = 2.0 * std::f64::consts::PI / period;
    // Normal equations of [1, s, c] on the centred y (whose sum is zero).
    let (mut s1, mut c1, mut ss, mut sc, mut cc, mut ys, mut yc_) =
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let n = x.len() as f64;
    for (&xi, &yi) in x.iter().zip(yc) {
        let (s, c) = (w * xi).sin_cos();
        s1 += s;
        c1 += c;
        ss += s * s;
        sc += s * c;
        cc += c * c;
        ys += yi * s;
        yc_ += yi * c;
    }
    // Sine and cosine with their means removed (the constant's share).
    let (a11, a12, a22) = (ss - s1 * s1 / n, sc - s1 * c1 / n, cc - c1 * c1 / n);
    let det = a11 * a22 - a12 * a12;
    if det <= 1e-12 * (a11 * a22).max(1e-300) {
        return 0.0;
    }
    let b1 = (a22 * ys - a12 * yc_) / det;
    let b2 = (a11 * yc_ - a12 * ys) / det;
    b1 * ys + b2 * yc_
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pseudo-random uniform values in [-0.5, 0.5) (a fixed LCG: no
    /// dependency for a test).
    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    #[test]
    fn explained_share_matches_a_least_squares_fit() {
        let x: Vec<f64> = (0..50).map(|i| i as f64 * 1.7).collect();
        let e = noise(50, 3);
        let y: Vec<f64> = x
            .iter()
            .zip(&e)
            .map(|(v, e)| 0.4 * (v / 5.0).sin() - 0.2 * (v / 5.0).cos() + 0.1 * e + 3.0)
            .collect();
        let mean = y.iter().sum::<f64>() / 50.0;
        let yc: Vec<f64> = y.iter().map(|v| v - mean).collect();
        let period = 2.0 * std::f64::consts::PI * 5.0;
        let a = nalgebra::DMatrix::from_fn(50, 3, |i, j| match j {
            0 => 1.0,
            1 => (x[i] / 5.0).sin(),
            _ => (x[i] / 5.0).cos(),
        });
        let b = nalgebra::DVector::from_vec(yc.clone());
        let sol = a.clone().svd(true, true).solve(&b, 1e-12).unwrap();
        let fitted = &a * sol;
        let want: f64 = fitted.iter().map(|v| v * v).sum();
        let got = sinusoid_explained(&x, &yc, period);
        assert!((got - want).abs() < 1e-9 * want, "{got} {want}");
    }

    #[test]
    fn noise_alone_rarely_passes_a_thousandth() {
        // 400 sessions of pure noise at a realistic size: the Bonferroni
        // chance must not be optimistic (at most a few below 1e-2).
        let mut below = 0;
        for seed in 0..400 {
            let x: Vec<f64> = noise(120, 1000 + seed)
                .iter()
                .map(|v| 600.0 + 400.0 * v)
                .collect();
            let y = noise(120, 5000 + seed);
            let (_, p) = strongest_period(&x, &y).unwrap();
            if p < 1e-2 {
                below += 1;
            }
        }
        assert!(below <= 12, "{below} of 400 below 1e-2");
    }
}
