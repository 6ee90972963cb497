//! What a kept proposal reports: one finding per member, with its
//! magnitude, the evidence that kept it (the scores and gates of its
//! round), the doubts the data leave (an implausible thermal growth, a
//! twin that explains as much), the model compensation needs and its
//! evidence plot.

use super::candidates::Candidate;
use super::gates::Before;
use super::magnitude::{magnitude, warm_up_growth};
use super::proposals::Proposal;
use super::scoring::{Scored, Scores};
use super::trial::Kept;
use super::{Inputs, State};
use crate::physics::effects::{Context, EffectModel, Kind, ThermalDriver};
use crate::physics::evidence::evidence_plot;
use crate::physics::unexplained::robot_side_share;
use crate::report::{EffectParameters, Finding, FindingModel};

/// Another candidate explaining at least this share of a kept effect's
/// chi-square drop on its own is named beside it as indistinguishable.
const TWIN_SHARE: f64 = 0.98;
/// Largest growth of a metal arm's links over a session that thermal
/// expansion explains: about 20 K on aluminium (23 ppm/K) or 40 K on steel.
const MAX_THERMAL_GROWTH_PPM: f64 = 500.0;

/// The findings of the kept proposal `prop` (members `cs`, refit `kept`),
/// appended to `state` in the order `kept.stages` gives; `state` is still
/// the model before it (the residual's side is that model's).
pub(super) fn write(
    inputs: &Inputs,
    scores: &Scores,
    before: &Before,
    prop: &Proposal,
    cs: &[Candidate],
    kept: &Kept,
    state: &mut State,
) {
    let Inputs { obs, ctx, .. } = inputs;
    let round = Round {
        ctx,
        scores,
        before,
        prop,
        cs,
        kept,
    };
    let n_old = state.accepted.len();
    let n_acc_coef: usize = state.accepted.iter().map(|e| e.kind.n_coef()).sum();
    let (rs, _) = robot_side_share(obs, &state.p);
    for (stage, &mi) in kept.stages.order.iter().enumerate() {
        let e = kept.eff_new[n_old + mi].clone();
        let nc = e.kind.n_coef();
        let coef_at = n_acc_coef + cs[..mi].iter().map(|c| c.kind.n_coef()).sum::<usize>();
        let info = kept.fit.block(coef_at, nc);
        let (mag, sig, unit) = magnitude(ctx, obs, &e, &info);
        let evidence = round.evidence(mi, &e, side(rs, &e));
        let params = finding_parameters(ctx, &e);
        state.findings.push(Finding {
            effect: e.kind.name().into(),
            joint: e.kind.acting_joint().map(|j| j + 1),
            sensor: e.kind.sensor().map(|k| k + 1),
            magnitude: mag,
            sigma: sig,
            unit,
            explanation: e.kind.explanation(ctx),
            evidence,
            test_rms_before_mm: kept.stages.rms[stage],
            test_rms_after_mm: kept.stages.rms[stage + 1],
            parameters: Some(FindingModel::Effect(params)),
            evidence_plot: evidence_plot(obs, ctx, &kept.p_new, &kept.eff_new, n_old + mi),
        });
    }
}

/// What the round that kept a proposal measured, as its findings quote it.
struct Round<'a> {
    ctx: &'a Context,
    scores: &'a Scores,
    before: &'a Before,
    prop: &'a Proposal,
    cs: &'a [Candidate],
    kept: &'a Kept,
}

/// Where the residual an effect explains lives, from the share `rs` of
/// the string residual that one displacement of T explains (none without
/// a redundant string).
fn side(rs: Option<f64>, e: &EffectModel) -> String {
    match rs {
        Some(v) if e.kind.robot_side() => format!(
            "; the residual it explains is robot-side (all strings agree on one displacement of T: {:.0}% of the residual energy)",
            100.0 * v
        ),
        Some(v) => format!(
            "; the residual it explains is sensor-side (the strings disagree with any single point: {:.0}% of the residual energy)",
            100.0 * (1.0 - v)
        ),
        None => String::new(),
    }
}

impl Round<'_> {
    /// The evidence of member `mi` (refitted as `e`): its score and the
    /// round's gates, then any doubt and twin, so that a reader sees why it
    /// was kept and what the data cannot tell.
    fn evidence(&self, mi: usize, e: &EffectModel, side: String) -> String {
        let Round {
            ctx,
            scores,
            before,
            prop,
            cs,
            kept,
        } = self;
        let c = &cs[mi];
        let s = &scores.scored[prop.members[mi].0];
        let joint = if cs.len() == 1 {
            String::new()
        } else {
            let other = &cs[1 - mi];
            format!(
                ", tested jointly with {} ({}): chi-square {:.1} given it; the pair beats either alone on the held-out readings (paired z >= {:.1})",
                other.kind.name(),
                other.what,
                prop.members[mi].1,
                kept.stages.pair_z.unwrap_or(f64::NAN)
            )
        };
        let h = &kept.held;
        let evidence = format!(
            "residual correlates with {}: adding it drops chi-square by {:.1} on {} coefficient(s) (threshold {:.1}, {} candidate tests{}){}, explaining {:.0}% of the remaining train residual; 5-fold cross-validated SSE {:.4} -> {:.4} mm^2; held-out RMS per reading {:.4} -> {:.4} mm (paired z = {:.1}){}",
            c.what,
            s.chi2,
            s.cols.len(),
            s.threshold,
            scores.n_tests,
            match &c.kind {
                Kind::ThermalExpansion { tau_h: Some(_), .. } => {
                    ", time constant scanned"
                }
                k if k.change_time_s().is_some() => {
                    ", change point scanned; figures at the nearest grid point, before refinement"
                }
                _ => "",
            },
            joint,
            100.0 * s.drop / scores.rr.max(1e-30),
            before.cv0,
            kept.cv1,
            h.rb,
            h.ra,
            h.gain_z,
            side
        );
        let evidence = match thermal_doubt(ctx, e) {
            Some(doubt) => format!("{evidence}; {doubt}"),
            None => evidence,
        };
        let twins = indistinguishable(&scores.scored, &scores.cands, &prop.members, &e.kind, s);
        if twins.is_empty() {
            evidence
        } else {
            format!(
                "{evidence}; indistinguishable on this data from {}: it explains as much of the train residual (the two models predict nearly the same errors at these poses), so the name is the better-scoring of equals",
                twins.join(" or ")
            )
        }
    }
}

/// Other candidates of this round on the same joint or sensor that explain
/// on their own at least [`TWIN_SHARE`] of what the kept effect `kind`
/// (scored as `kept`) explains, one per effect, described: a positioner
/// whose gravity torque is a pure sinusoid of the joint makes compliance
/// and a once-per-turn error the same model, and the name is then a choice
/// the finding must own up to. `members` are the kept proposal's.
fn indistinguishable(
    scored: &[Scored],
    cands: &[Candidate],
    members: &[(usize, f64)],
    kind: &Kind,
    kept: &Scored,
) -> Vec<String> {
    let mut out: Vec<&Candidate> = Vec::new();
    for o in scored {
        let c = &cands[o.idx];
        let k = &c.kind;
        let member = members.iter().any(|m| scored[m.0].idx == o.idx);
        let twin = !member
            && (k.joint().is_some() || k.sensor().is_some())
            && k.name() != kind.name()
            && k.joint() == kind.joint()
            && k.sensor() == kind.sensor()
            && o.drop >= TWIN_SHARE * kept.drop;
        // One per effect (a step scanned over the session would otherwise
        // be listed at every position).
        if twin && !out.iter().any(|x| x.kind.name() == k.name()) {
            out.push(c);
        }
    }
    out.iter()
        .map(|c| format!("{} ({})", c.kind.name(), c.what))
        .collect()
}

/// A doubt to state with a thermal finding whose growth over the session
/// is beyond what a metal arm's thermal expansion gives: the fit holds, the
/// name may not (an instrument whose scale drifted as it warmed up looks
/// the same).
fn thermal_doubt(ctx: &Context, e: &EffectModel) -> Option<String> {
    let Kind::ThermalExpansion { tau_h, .. } = e.kind else {
        return None;
    };
    let (lo, hi) = ctx
        .poses
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.thermal), hi.max(p.thermal))
        });
    let span = match tau_h {
        Some(tau) => warm_up_growth(ctx, tau),
        None => hi - lo,
    };
    let growth_ppm = (e.coef.first()? * span * 1e6).abs();
    (growth_ppm > MAX_THERMAL_GROWTH_PPM).then(|| {
        format!(
            "doubt: a growth of {growth_ppm:.0} ppm over the session is more than a metal arm's thermal expansion gives (12-23 ppm/K; {MAX_THERMAL_GROWTH_PPM:.0} ppm is 20-40 K): check the temperature record, or an instrument whose scale drifted as it warmed up"
        )
    })
}

/// What a named finding records of its effect: the model, and what
/// compensation needs beside it (the payload a compliance was fitted
/// around and whether a payload changes it, as compensation decides it;
/// the temperature a thermal expansion scales from).
fn finding_parameters(ctx: &Context, e: &EffectModel) -> EffectParameters {
    let mut p = EffectParameters::new(e.clone());
    // A compliance says whether a payload changes it, either way; every
    // other effect a payload loads says so (EffectModel::payload_matters).
    if matches!(e.kind, Kind::JointCompliance { .. }) || e.payload_matters(ctx.n_joints) {
        p.reference_payload_kg = ctx.payload_ref_kg;
        p.payload_matters = Some(e.payload_matters(ctx.n_joints));
    }
    if let Kind::ThermalExpansion { driver, .. } = e.kind {
        p.reference = Some("driver zero at the first pose (temperature, time or row)".into());
        if driver == ThermalDriver::Temperature {
            p.reference_temp_c = ctx.temp_ref_c;
        }
    }
    p
}
