//! Scoring the candidates of a round: the chi-square drop of adding each
//! one (block elimination of the current columns, so geometry and the
//! accepted effects are refitted alongside), its columns that are not
//! aliased with the current ones, and its Bonferroni threshold.

use nalgebra::DMatrix;

use super::candidates::{Candidate, candidates, same_slot};
use super::normals::{Normals, solve_subset, train_normals, unaliased};
use super::{ALPHA, Inputs, State};
use crate::stats::chi2_quantile_upper;

/// Score of one candidate in one round.
#[derive(Debug, Clone)]
pub(super) struct Scored {
    /// Index into the round's candidates.
    pub(super) idx: usize,
    /// Its unaliased columns (absolute indices).
    pub(super) cols: Vec<usize>,
    /// Drop of the train SSE it buys alone (mm²).
    pub(super) drop: f64,
    pub(super) chi2: f64,
    pub(super) threshold: f64,
    /// Residual variance per reading with the candidate fitted (mm²).
    pub(super) s2: f64,
}

/// One round's linearisation and its scored candidates: what proposals,
/// gates and findings of the round read.
pub(super) struct Scores {
    /// The round's candidates (rejected slots left out).
    pub(super) cands: Vec<Candidate>,
    /// Normal equations of the train poses by fold, and in total.
    pub(super) nm: Normals,
    pub(super) a: DMatrix<f64>,
    pub(super) b: Vec<f64>,
    pub(super) rr: f64,
    /// Columns of the current model: free geometry and accepted effects.
    pub(super) base: Vec<usize>,
    /// SSE drop of the current model's columns.
    pub(super) base_drop: f64,
    /// Tests of the round (the Bonferroni count).
    pub(super) n_tests: usize,
    /// Candidates with unaliased columns, best first: by the chi-square in
    /// excess of its own threshold.
    pub(super) scored: Vec<Scored>,
}

/// The round's scores at the current fit; `None` when nothing is left to
/// try or the current model's normal equations do not solve (the analysis
/// then stops).
pub(super) fn score(inputs: &Inputs, state: &State) -> Option<Scores> {
    let Inputs {
        obs,
        ctx,
        free,
        fold_of,
    } = inputs;
    let cands: Vec<Candidate> = candidates(obs, ctx, &state.accepted)
        .into_iter()
        .filter(|c| !state.rejected.iter().any(|r| same_slot(r, &c.kind)))
        .collect();
    if cands.is_empty() {
        return None;
    }
    let nm = train_normals(
        obs,
        ctx,
        &state.p,
        free,
        &state.accepted,
        cands.iter().map(|c| c.kind.clone()),
        fold_of,
    );
    let (a, b, rr) = nm.total();
    let n_acc: usize = state.accepted.iter().map(|e| e.kind.n_coef()).sum();
    let base: Vec<usize> = (0..free.len() + n_acc).collect();
    let (base_drop, _) = solve_subset(&a, &b, &base)?;
    let n_tests: usize = cands.iter().map(|c| c.scanned).sum();
    let mut scores = Scores {
        cands,
        nm,
        a,
        b,
        rr,
        base,
        base_drop,
        n_tests,
        scored: Vec::new(),
    };
    let mut scored = score_each(&scores);
    // Rank by the chi-square in excess of its own Bonferroni threshold
    // (a penalised likelihood: every block of coefficients pays the
    // look-elsewhere price of its family), so a 3-coefficient scanned
    // change point must explain more than a 1-coefficient constant.
    scored.sort_by(|x, y| (y.chi2 - y.threshold).total_cmp(&(x.chi2 - x.threshold)));
    scores.scored = scored;
    Some(scores)
}

/// Every candidate scored alone over the current model, in candidate
/// order (a candidate whose columns are all aliased is left out).
fn score_each(s: &Scores) -> Vec<Scored> {
    let (a, b, base) = (&s.a, &s.b, &s.base);
    let sse0 = s.rr - s.base_drop;
    let mut scored = Vec::new();
    let mut off = base.len();
    for (ci, c) in s.cands.iter().enumerate() {
        let nc = c.kind.n_coef();
        let own: Vec<usize> = (off..off + nc).collect();
        off += nc;
        let cols = unaliased(a, base, &own);
        if cols.is_empty() {
            continue;
        }
        let mut all_cols = base.clone();
        all_cols.extend(&cols);
        let Some((d, _)) = solve_subset(a, b, &all_cols) else {
            continue;
        };
        let drop = (d - s.base_drop).max(0.0);
        let dof = (s.nm.rows as f64 - all_cols.len() as f64).max(1.0);
        let s2 = ((sse0 - drop) / dof).max(1e-30);
        let chi2 = drop / s2;
        // Bonferroni over every test this round (scanned positions
        // count individually: the look-elsewhere allowance).
        let alpha = ALPHA / s.n_tests as f64;
        let threshold = chi2_quantile_upper(alpha, cols.len());
        scored.push(Scored {
            idx: ci,
            cols,
            drop,
            chi2,
            threshold,
            s2,
        });
    }
    scored
}
