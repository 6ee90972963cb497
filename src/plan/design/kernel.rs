//! The products the selection repeats for every candidate at every step
//! (`State::update`, `State::refresh`): a candidate's rows times a few
//! columns, arranged so that several sums are in flight at once and the
//! compiler can vectorise them.
//!
//! Each output is still summed term by term in the order of the plain dot
//! product, from `-0.0` as `Iterator::sum` starts, so the results are the
//! plain formulas' to the bit (tested below): a faster selection chooses
//! the same poses, and a plan without a payload writes the same targets.

/// `out[a·w + t] = Σ_k rows[a·p + k] · cols[k·w + t]`, `k` in order, for
/// each row `a` of `rows` (`p` values each, row-major) and each column `t`
/// of `cols` (`p × w`, row-major): the dot product of row `a` with column
/// `t`, summed as `Iterator::sum` sums it. The columns go in blocks of eight (then four,
/// two, one), whose sums stay in registers.
pub(super) fn rows_times(rows: &[f64], p: usize, cols: &[f64], w: usize, out: &mut [f64]) {
    assert!(cols.len() >= p * w && out.len() >= rows.len() / p * w);
    for (row, o) in rows.chunks_exact(p).zip(out.chunks_exact_mut(w)) {
        let mut c0 = 0;
        while c0 + 8 <= w {
            block::<8>(row, cols, w, c0, o);
            c0 += 8;
        }
        for b in [4, 2, 1] {
            if c0 + b <= w {
                match b {
                    4 => block::<4>(row, cols, w, c0, o),
                    2 => block::<2>(row, cols, w, c0, o),
                    _ => block::<1>(row, cols, w, c0, o),
                }
                c0 += b;
            }
        }
    }
}

/// Columns `c0..c0 + B` of one row of [`rows_times`].
#[inline(always)]
fn block<const B: usize>(row: &[f64], cols: &[f64], w: usize, c0: usize, o: &mut [f64]) {
    let mut acc = [-0.0f64; B];
    for (k, &x) in row.iter().enumerate() {
        let c: &[f64; B] = cols[k * w + c0..k * w + c0 + B]
            .try_into()
            .expect("B columns");
        for (s, &v) in acc.iter_mut().zip(c) {
            *s += x * v;
        }
    }
    o[c0..c0 + B].copy_from_slice(&acc);
}

/// `t[k·r + a] = rows[a·p + k]`: the `r = t.len() / p` rows of `p` values
/// each as columns, the shape `rows_times` takes its columns in.
pub(super) fn transpose(rows: &[f64], p: usize, t: &mut [f64]) {
    let r = t.len() / p;
    for (k, tk) in t.chunks_exact_mut(r).enumerate() {
        for (a, v) in tk.iter_mut().enumerate() {
            *v = rows[a * p + k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// The plain dot product the selection's formulas are written with:
    /// `Σ_k a[k] · b[k]`, `k` in order.
    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    /// Every output equals the plain dot product bit for bit, zeros' signs
    /// included, over shapes with and without a remainder.
    #[test]
    fn rows_times_is_the_plain_dot_product_to_the_bit() {
        let mut rng = Rng::new(11);
        for (n_rows, p, w) in [(4, 31, 8), (3, 7, 6), (8, 31, 4), (1, 1, 1), (5, 40, 31)] {
            let mut rows: Vec<f64> = (0..n_rows * p).map(|_| rng.normal() * 1e3).collect();
            let mut cols: Vec<f64> = (0..p * w).map(|_| rng.normal() * 1e-3).collect();
            // Exact zeros, negative zeros and a whole zero row.
            rows[0] = -0.0;
            cols[w.min(p * w - 1)] = 0.0;
            rows[(n_rows - 1) * p..].iter_mut().for_each(|v| *v = -0.0);
            let mut out = vec![f64::NAN; n_rows * w];
            rows_times(&rows, p, &cols, w, &mut out);
            for a in 0..n_rows {
                for t in 0..w {
                    let col: Vec<f64> = (0..p).map(|k| cols[k * w + t]).collect();
                    let want = dot(&rows[a * p..(a + 1) * p], &col);
                    assert_eq!(
                        out[a * w + t].to_bits(),
                        want.to_bits(),
                        "{n_rows}x{p}x{w} at {a},{t}"
                    );
                }
            }
        }
    }
}
