//! Which identifiable parameters to free.
//!
//! With few poses, a model with fewer free parameters can predict better:
//! each parameter the data barely determine carries noise into the
//! prediction of every other pose. The joint parameters form three nested
//! sets, from what a robot's geometry most often gets wrong to what it
//! rarely does: the joint offsets θ ([`FreeSet::Offsets`]); with the link
//! lengths and offsets a and d ([`FreeSet::Lengths`]); every identifiable
//! parameter, the twists α and the parallel-axis β too ([`FreeSet::All`]).
//! The base pose, the tool point and the sensor parameters asked for are
//! free in every set.
//!
//! [`choose`] picks one by K-fold cross-validation on the train poses only
//! (the held-out poses stay unseen): each set is fitted without each fold,
//! the same way as the calibration itself (Levenberg-Marquardt, the
//! undetermined parameters held), and predicts the fold's readings. A
//! smaller set replaces the full one only when it predicts them clearly
//! better ([`CV_MARGIN`]), and the whole test is made only when the train
//! poses are few for the parameters ([`CV_EQUATIONS_PER_PARAMETER`]):
//! sessions with enough poses free every identifiable parameter, as before.

use super::geometric::{distinct_poses, hold_undetermined, run_lm};
use super::identifiability::Selection;
use super::{IdentifyOptions, Method, Observations, Progress};
use crate::error::{Error, Result};
use crate::kinematics::{JointParam, Layout, Params};
use crate::report::{FixedParam, FixedReason, FreeSetChoice, FreeSetScore};
use crate::rng::Rng;

/// The free set asked for (`--free`, a job's `free_set`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FreeSet {
    /// Chosen by cross-validation when the train poses are few, every
    /// identifiable parameter otherwise.
    #[default]
    Auto,
    /// Every identifiable parameter (drawcal's behaviour before the
    /// choice existed).
    All,
    /// The joint offsets θ, the link lengths a and the link offsets d.
    Lengths,
    /// The joint offsets θ alone.
    Offsets,
}

impl FreeSet {
    /// The nested sets, smallest first.
    pub const NESTED: [FreeSet; 3] = [FreeSet::Offsets, FreeSet::Lengths, FreeSet::All];

    /// The name the report, the CLI and a job use (`auto`, `all`,
    /// `lengths`, `offsets`).
    pub fn name(self) -> &'static str {
        match self {
            FreeSet::Auto => "auto",
            FreeSet::All => "all",
            FreeSet::Lengths => "lengths",
            FreeSet::Offsets => "offsets",
        }
    }

    /// The set of a name ([`FreeSet::name`]).
    pub fn parse(name: &str) -> Option<FreeSet> {
        [
            FreeSet::Auto,
            FreeSet::All,
            FreeSet::Lengths,
            FreeSet::Offsets,
        ]
        .into_iter()
        .find(|s| s.name() == name)
    }

    /// What the set frees, in words.
    pub fn describe(self) -> &'static str {
        match self {
            FreeSet::Auto | FreeSet::All => "every identifiable parameter",
            FreeSet::Lengths => "the joint offsets, link lengths and link offsets (θ, a, d)",
            FreeSet::Offsets => "the joint offsets (θ)",
        }
    }

    /// Whether the set frees joint parameters of kind `p`.
    fn frees(self, p: JointParam) -> bool {
        match self {
            FreeSet::Auto | FreeSet::All => true,
            FreeSet::Lengths => matches!(p, JointParam::Theta | JointParam::A | JointParam::D),
            FreeSet::Offsets => p == JointParam::Theta,
        }
    }

    /// The parameters of `free` (identifiable, in priority order) this set
    /// frees: its joint parameters, and every parameter that is not a
    /// joint's.
    pub fn restrict(self, l: Layout, free: &[usize]) -> Vec<usize> {
        free.iter()
            .copied()
            .filter(|&k| k >= l.base() || self.frees(JointParam::ALL[k % 5]))
            .collect()
    }
}

/// Folds of the cross-validation (fewer when there are fewer train poses).
pub const CV_FOLDS: usize = 8;

/// How much better a smaller set must predict the left-out train poses
/// (its cross-validated RMS at most `1 - CV_MARGIN` times the full set's)
/// to replace it: the scores of a few dozen poses scatter by a few per
/// cent between nearly equal models, and the full set is the default that
/// costs nothing when the data determine it.
pub const CV_MARGIN: f64 = 0.05;

/// Equations (three per distinct train pose) per identifiable parameter
/// from which every identifiable parameter is freed without a test: the
/// spread of the extra parameters then adds a few per cent to the
/// prediction error at most (about `k / N` of the noise's variance), less
/// than [`CV_MARGIN`], so no smaller set could pass it except by chance.
pub const CV_EQUATIONS_PER_PARAMETER: usize = 10;

/// Choose the free set for these train poses (see the module's comment):
/// `selection` holds the identifiable parameters, `start` the base and
/// tool fitted on the nominal joints.
pub fn choose(
    obs: &Observations,
    start: &Params,
    selection: &Selection,
    opts: &IdentifyOptions,
    progress: &dyn Progress,
) -> Result<FreeSetChoice> {
    let l = obs.chain.layout;
    let n_all = selection.free.len();
    let plain = |chosen: FreeSet, how: &str, reason: String| FreeSetChoice {
        chosen: chosen.name().into(),
        how: how.into(),
        reason,
        folds: 0,
        candidates: vec![],
    };
    if opts.method == Method::Paper && !matches!(opts.free_set, FreeSet::Auto | FreeSet::All) {
        return Err(Error::field(
            "free_set",
            "the paper's method identifies every parameter in one step; choose a smaller free \
             set with the default method (lm)",
        ));
    }
    if opts.free_set != FreeSet::Auto {
        let set = opts.free_set;
        return Ok(plain(
            set,
            "requested",
            format!(
                "{} freed, as asked (--free {}; {} of the {n_all} identifiable parameters)",
                capitalised(set.describe()),
                set.name(),
                set.restrict(l, &selection.free).len()
            ),
        ));
    }
    if opts.method == Method::Paper {
        return Ok(plain(
            FreeSet::All,
            "not_tried",
            "the paper's method identifies every parameter in one step".into(),
        ));
    }
    // The nested sets that differ: a set equal to the next larger one (no
    // identifiable twist, say) is that one.
    let mut sets: Vec<(FreeSet, Vec<usize>)> = Vec::new();
    for set in FreeSet::NESTED.into_iter().rev() {
        let free = set.restrict(l, &selection.free);
        if sets.last().is_none_or(|(_, larger)| *larger != free) {
            sets.push((set, free));
        }
    }
    sets.reverse();
    if sets.len() == 1 {
        return Ok(plain(
            FreeSet::All,
            "not_tried",
            "no smaller set to try: every identifiable joint parameter is a joint offset".into(),
        ));
    }
    let usable = distinct_poses(obs, &obs.train);
    if 3 * usable >= CV_EQUATIONS_PER_PARAMETER * n_all {
        return Ok(plain(
            FreeSet::All,
            "not_tried",
            format!(
                "{usable} train poses, at least {CV_EQUATIONS_PER_PARAMETER} equations per \
                 identifiable parameter: every one freed without a test"
            ),
        ));
    }
    let folds = folds(&obs.train, opts.seed);
    let mut candidates = Vec::with_capacity(sets.len());
    for (i, (set, free)) in sets.iter().enumerate() {
        progress.update("choosing the free set", i as f64 / sets.len() as f64);
        candidates.push(FreeSetScore {
            name: set.name().into(),
            n_free: free.len(),
            cv_rms_mm: cv_rms(obs, start, free, &folds, opts, progress)?,
        });
    }
    let (chosen, reason) = decide(&sets, &candidates, n_all, CV_MARGIN);
    Ok(FreeSetChoice {
        chosen: chosen.name().into(),
        how: "cross_validation".into(),
        reason,
        folds: folds.len(),
        candidates,
    })
}

/// The set the scores choose, and why in one sentence. From the full set
/// down, a smaller set replaces the current one when it predicts the
/// left-out poses clearly better ([`CV_MARGIN`]) than the current one: a
/// smaller model has to earn its place against the larger one it would
/// replace, not only against the full one. When the full set cannot be
/// fitted without a fold, the smaller sets that can compete alone.
fn decide(
    sets: &[(FreeSet, Vec<usize>)],
    scores: &[FreeSetScore],
    n_all: usize,
    margin: f64,
) -> (FreeSet, String) {
    let listed = scores
        .iter()
        .map(|s| format!("{} {:.4} mm", s.name, s.cv_rms_mm))
        .collect::<Vec<_>>()
        .join(", ");
    let last = scores.len() - 1;
    let mut current = last;
    for i in (0..last).rev() {
        let (now, then) = (scores[i].cv_rms_mm, scores[current].cv_rms_mm);
        if now.is_finite() && (!then.is_finite() || now < (1.0 - margin) * then) {
            current = i;
        }
    }
    let all = scores[last].cv_rms_mm;
    let chosen = &scores[current];
    if current == last {
        let why = if all.is_finite() {
            format!(
                "no smaller set predicted the left-out train poses {:.0} % better than the \
                 larger one ({listed})",
                100.0 * margin
            )
        } else {
            format!("no set could be fitted without each fold's poses ({listed})")
        };
        return (FreeSet::All, why);
    }
    let gain = if all.is_finite() {
        format!(
            "{:.0} % better than every identifiable parameter ({n_all})",
            100.0 * (1.0 - chosen.cv_rms_mm / all)
        )
    } else {
        format!(
            "while every identifiable parameter ({n_all}) cannot be fitted without a fold's poses"
        )
    };
    (
        sets[current].0,
        format!(
            "with these few train poses, freeing only {} ({} parameters) predicted the left-out \
             train poses {gain}, each smaller set more than {:.0} % better than the larger one \
             it replaces ({listed})",
            sets[current].0.describe(),
            chosen.n_free,
            100.0 * margin
        ),
    )
}

/// Hold at nominal what the chosen set does not free (reason
/// [`FixedReason::FreeSet`]).
pub fn apply(choice: &FreeSetChoice, l: Layout, selection: &mut Selection) {
    let set = FreeSet::parse(&choice.chosen).unwrap_or(FreeSet::All);
    let kept = set.restrict(l, &selection.free);
    for &k in selection.free.iter().filter(|k| !kept.contains(k)) {
        selection.fixed.push(FixedParam {
            name: l.name(k),
            aliased_with: vec![],
            reason: FixedReason::FreeSet,
        });
    }
    selection.free = kept;
}

/// The train poses dealt into at most [`CV_FOLDS`] folds after a seeded
/// shuffle (recordings are often in an order that follows one joint).
fn folds(train: &[usize], seed: u64) -> Vec<Vec<usize>> {
    let mut order = train.to_vec();
    Rng::new(seed).shuffle(&mut order);
    let k = CV_FOLDS.min(order.len());
    (0..k)
        .map(|f| {
            let mut fold: Vec<usize> = order.iter().skip(f).step_by(k).copied().collect();
            fold.sort_unstable();
            fold
        })
        .collect()
}

/// Cross-validated RMS (mm) of the readings of the train poses when each
/// fold is predicted by the fit of `free` on the other folds; NaN when a
/// fold leaves too few poses to fit them (as few equations as
/// parameters).
fn cv_rms(
    obs: &Observations,
    start: &Params,
    free: &[usize],
    folds: &[Vec<usize>],
    opts: &IdentifyOptions,
    progress: &dyn Progress,
) -> Result<f64> {
    let mut start_values = start.values.clone();
    if let (Some(m), true) = (&obs.anchor_modes, opts.rig_anchors) {
        start_values.extend(std::iter::repeat_n(0.0, m.len()));
    }
    let (mut sum, mut n) = (0.0, 0usize);
    let mut r = Vec::new();
    for fold in folds {
        let fit: Vec<usize> = obs
            .train
            .iter()
            .copied()
            .filter(|i| fold.binary_search(i).is_err())
            .collect();
        if 3 * distinct_poses(obs, &fit) <= free.len() {
            return Ok(f64::NAN);
        }
        // A fit that fails (diverges, or the solver gives up) leaves this
        // set unscored, not the calibration refused: the full set is then
        // what the calibration tries, as before the choice existed.
        let values = match fit_on(obs, &fit, &start_values, free, opts, progress) {
            Ok(v) => v,
            Err(Error::Cancelled) => return Err(Error::Cancelled),
            Err(_) => return Ok(f64::NAN),
        };
        let p = obs.problem_on(fold, values, vec![]);
        for pose in &p.poses {
            p.pose_residuals(&p.full, pose, &mut r);
            sum += r.iter().map(|v| v * v).sum::<f64>();
            n += r.len();
        }
    }
    Ok(if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    })
}

/// The parameters fitted on the poses `fit` the way the calibration fits
/// them: Levenberg-Marquardt on `free`, then the undetermined ones held.
fn fit_on(
    obs: &Observations,
    fit: &[usize],
    start: &[f64],
    free: &[usize],
    opts: &IdentifyOptions,
    progress: &dyn Progress,
) -> Result<Vec<f64>> {
    let stage = "choosing the free set";
    let mut problem = obs.problem_on(fit, start.to_vec(), free.to_vec());
    let mut result = run_lm(&problem, progress, stage)?;
    let mut selection = Selection {
        free: free.to_vec(),
        fixed: vec![],
        condition_number: f64::NAN,
    };
    let before = Params {
        layout: obs.chain.layout,
        values: start.to_vec(),
    };
    hold_undetermined(
        obs,
        fit,
        opts,
        &before,
        &mut selection,
        &mut problem,
        &mut result,
        progress,
    )?;
    let values = problem.expand(&result.x);
    if values.iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical(
            "the cross-validation of the free set diverged".into(),
        ));
    }
    Ok(values)
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().chain(c).collect())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scores(cv: [f64; 3]) -> (Vec<(FreeSet, Vec<usize>)>, Vec<FreeSetScore>) {
        let sets = FreeSet::NESTED
            .iter()
            .zip([9, 15, 21])
            .map(|(&s, n)| (s, (0..n).collect()))
            .collect();
        let scores = FreeSet::NESTED
            .iter()
            .zip(cv)
            .zip([9, 15, 21])
            .map(|((s, cv_rms_mm), n_free)| FreeSetScore {
                name: s.name().into(),
                n_free,
                cv_rms_mm,
            })
            .collect();
        (sets, scores)
    }

    fn chosen(cv: [f64; 3]) -> FreeSet {
        let (sets, s) = scores(cv);
        decide(&sets, &s, 21, CV_MARGIN).0
    }

    #[test]
    fn a_smaller_set_must_beat_the_one_it_replaces_by_the_margin() {
        // Within the margin of the full set: the full set stays.
        assert_eq!(chosen([0.97, 0.96, 1.0]), FreeSet::All);
        // The lengths clearly better; the offsets not clearly better still.
        assert_eq!(chosen([0.88, 0.90, 1.0]), FreeSet::Lengths);
        // Both steps clear the margin.
        assert_eq!(chosen([0.80, 0.90, 1.0]), FreeSet::Offsets);
        // The lengths no better, the offsets clearly better than all.
        assert_eq!(chosen([0.90, 0.99, 1.0]), FreeSet::Offsets);
        // The full set could not be fitted without a fold.
        assert_eq!(chosen([0.93, 0.95, f64::NAN]), FreeSet::Lengths);
        assert_eq!(chosen([f64::NAN, f64::NAN, f64::NAN]), FreeSet::All);
        let (sets, s) = scores([0.80, 0.90, 1.0]);
        let why = decide(&sets, &s, 21, CV_MARGIN).1;
        assert!(why.contains("20 % better"), "{why}");
    }

    #[test]
    fn nested_sets_keep_what_is_not_a_joint_parameter() {
        let l = Layout {
            n_joints: 2,
            n_strings: 4,
        };
        let free: Vec<usize> = (0..l.len()).collect();
        let off = FreeSet::Offsets.restrict(l, &free);
        assert_eq!(
            off.iter().filter(|&&k| k < l.base()).count(),
            2,
            "one θ per joint"
        );
        // Base, tool, string offsets and r all stay.
        assert!(off.ends_with(&(l.base()..l.len()).collect::<Vec<_>>()));
        let len = FreeSet::Lengths.restrict(l, &free);
        assert_eq!(len.iter().filter(|&&k| k < l.base()).count(), 6);
        assert_eq!(FreeSet::All.restrict(l, &free), free);
        for s in [
            FreeSet::Auto,
            FreeSet::All,
            FreeSet::Lengths,
            FreeSet::Offsets,
        ] {
            assert_eq!(FreeSet::parse(s.name()), Some(s));
        }
    }
}
