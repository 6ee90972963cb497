//! Step 4 of the pipeline: the report, from the observations, the
//! geometric fit and what the physics step found.

use nalgebra::Vector3;

use super::PhysicsOutcome;
use crate::error::{Error, Result};
use crate::identify::lm;
use crate::identify::problem::CalibrationProblem;
use crate::identify::{
    self, Geometric, IdentifyOptions, Method, Observations, identifiability, paper,
};
use crate::kinematics::{JointParam, Params};
use crate::model::Rig;
use crate::model::{Measurement, Split};
use crate::physics::{self, Analysis, Context, EffectModel};
use crate::report::{
    AnchorCorrection, Convergence, ErrorStats, Finding, Identifiability, JointDeviation, Outlier,
    ParamEstimate, PoseResidual, REPORT_FORMAT, Report, RigAnchors, SplitStats, Stats,
};
use crate::stats;

/// The final model: the parameters, their 1-sigma (over the free ones of
/// `selection`), the accepted effects with their context, and its errors
/// at every pose.
struct FinalModel<'g> {
    /// `lm` or `paper`.
    method: &'static str,
    params: Params,
    sigmas: Vec<f64>,
    /// The free parameters and those held (none with the paper's method).
    selection: Option<&'g identifiability::Selection>,
    effects: Option<(Context, Vec<EffectModel>)>,
    /// Model minus measured T at every pose (base frame, mm).
    errors: Vec<Vector3<f64>>,
}

/// The model the report describes: the geometric fit (or the paper's
/// one-step solution), refitted with the effects the physics analysis
/// accepted; and the analysis's findings.
fn final_model<'g>(
    obs: &Observations,
    geo: &'g Geometric,
    opts: &IdentifyOptions,
    paper: &Result<Params>,
    analysis: Option<Analysis>,
) -> Result<(FinalModel<'g>, Vec<Finding>)> {
    let l = obs.chain.layout;
    let all: Vec<usize> = (0..obs.data.poses.len()).collect();
    let mut model = match opts.method {
        Method::Lm => FinalModel {
            method: "lm",
            params: geo.after.clone(),
            sigmas: identify::sigmas(&geo.result.jtj, geo.sigma),
            selection: Some(&geo.selection),
            effects: None,
            errors: obs.errors(&geo.after.values, &all),
        },
        Method::Paper => {
            let p = paper
                .as_ref()
                .map_err(|e| Error::Numerical(format!("paper method: {e}")))?;
            FinalModel {
                method: "paper",
                params: Params {
                    layout: l,
                    values: p.values.clone(),
                },
                sigmas: vec![],
                selection: None,
                effects: None,
                errors: obs.errors(&p.values, &all),
            }
        }
    };
    let Some(an) = analysis else {
        return Ok((model, vec![]));
    };
    if !an.effects.is_empty() {
        // The final model is the geometry refitted with the accepted
        // effects; its errors are what stats.*.after and per_pose report.
        model.errors = physics::errors_with_effects(
            obs,
            &an.context,
            &an.final_params.values,
            &an.effects,
            &all,
        );
        model.params.values = an.final_params.values.clone();
        // Uncertainties of the final model, not of the geometric fit it
        // started from.
        if let Some(s) = an.final_sigmas {
            model.sigmas = s;
        }
        model.effects = Some((an.context, an.effects));
    }
    Ok((model, an.findings))
}

/// Build the report of a calibration.
pub fn report(
    obs: &Observations,
    geo: &Geometric,
    opts: &IdentifyOptions,
    physics: PhysicsOutcome,
    warnings: Vec<String>,
) -> Result<Report> {
    let (robot, data) = (obs.robot, obs.data);
    let l = obs.chain.layout;
    let string_sigma = obs
        .string_sigma()
        .or_else(|| (l.n_strings > 0).then_some(geo.sigma));
    let paper = paper::one_step(obs, &geo.before);
    let physics_notes = physics.notes();
    let confirmation = physics.confirmation;
    let (model, findings) = final_model(obs, geo, opts, &paper, physics.analysis)?;
    let all: Vec<usize> = (0..data.poses.len()).collect();
    let eb = obs.errors(&geo.before.values, &all);
    let paper_stats = match (&paper, opts.method) {
        (Ok(p), Method::Lm) => Some(obs.stats_of(&eb, &obs.errors(&p.values, &all))),
        _ => None,
    };
    let train_problem = obs.problem(model.params.values.clone(), vec![]);
    let after = &model.params;
    let identifiability = Identifiability {
        // Every parameter considered, held by request or not.
        n_candidates: identify::candidates(
            l,
            &IdentifyOptions {
                hold: vec![],
                ..opts.clone()
            },
        )
        .iter()
        // The anchors' shape modes are counted in `rig_anchors`.
        .filter(|&&k| k < l.len())
        .count(),
        n_identified: model
            .selection
            .map(|s| s.free.len())
            .unwrap_or(5 * l.n_joints),
        condition_number: geo.selection.condition_number,
        fixed: model.selection.map(|s| s.fixed.clone()).unwrap_or_default(),
    };
    let (deviations, parameters) = deviations_and_estimates(obs, geo, &model);
    let (rig_anchors, calibrated_rig) = match rig_report(obs, geo, after) {
        Some((a, r)) => (Some(a), Some(r)),
        None => (None, None),
    };
    Ok(Report {
        rig_anchors,
        calibrated_rig,
        format: REPORT_FORMAT.into(),
        method: model.method.into(),
        robust: opts.robust,
        nominal_robot: robot.clone(),
        calibrated_robot: after.to_robot(robot, &format!("{} (calibrated)", robot.name)),
        base_in_rig: after.base(),
        tool_point_mm: after.tool(),
        deviations,
        parameters,
        fixed: identifiability
            .fixed
            .iter()
            .map(|f| f.name.clone())
            .collect(),
        identifiability,
        free_set: Some(geo.free_set.clone()),
        stats: Stats {
            confirmation: (!confirmation.is_empty()).then(|| SplitStats {
                n: confirmation.len(),
                before: ErrorStats::of(&confirmation.iter().map(|&i| eb[i]).collect::<Vec<_>>()),
                after: ErrorStats::of(
                    &confirmation
                        .iter()
                        .map(|&i| model.errors[i])
                        .collect::<Vec<_>>(),
                ),
            }),
            ..obs.stats_of(&eb, &model.errors)
        },
        paper_stats,
        noise_floor_mm: obs.noise_floor(string_sigma),
        expected_test_rms_mm: obs.expected_test_rms(
            &geo.after.values,
            &geo.selection.free,
            &geo.result.jtj,
            string_sigma,
        ),
        flange_orientation_sigma_deg: (opts.method == Method::Lm)
            .then_some(geo.flange_orientation_sigma_rad)
            .flatten()
            .map(f64::to_degrees),
        string_sigma_mm: string_sigma,
        held_out: obs.test.iter().map(|&i| data.poses[i].id.clone()).collect(),
        split_source: obs.split_source(opts),
        outliers: outliers(obs, &train_problem, &after.values),
        convergence: Convergence {
            iterations: geo.result.iterations,
            termination: geo.result.termination.as_str().into(),
            residual_rms_mm: (2.0 * geo.result.cost
                / lm::LeastSquares::n_residuals(&train_problem).max(1) as f64)
                .sqrt(),
        },
        closed_form_vs_lsq: identify::closed_form_comparison(obs),
        per_pose: per_pose(obs, &train_problem, &model, &eb, &confirmation),
        findings,
        physics: physics.run,
        physics_notes,
        warnings,
        extra_poses: None,
        verdict: None,
    })
}

/// The anchors' corrections and the calibrated rig (rig.json's, with the
/// identified anchors and the final model's base pose), when the anchors
/// were identified.
fn rig_report(obs: &Observations, geo: &Geometric, after: &Params) -> Option<(RigAnchors, Rig)> {
    let fit = geo.rig.as_ref()?;
    let modes = obs.anchor_modes.as_ref()?;
    let arr = |v: &Vector3<f64>| [v.x, v.y, v.z];
    let anchors = fit
        .anchors
        .iter()
        .zip(&modes.nominal)
        .enumerate()
        .map(|(k, (a, nominal))| AnchorCorrection {
            anchor: obs.rig.sensor_name(k),
            nominal_mm: arr(nominal),
            calibrated_mm: arr(&a.calibrated_mm),
            correction_mm: arr(&a.correction_mm),
            correction_mm_sigma: arr(&a.sigma_mm),
            identifiability: a.identifiability,
            identified: identify::rig::identified(a.identifiability),
        })
        .collect();
    let mut rig = obs.rig.clone();
    rig.anchors_mm = fit.anchors.iter().map(|a| arr(&a.calibrated_mm)).collect();
    rig.base_in_rig = Some(after.base());
    Some((
        RigAnchors {
            gauge: RigAnchors::GAUGE.into(),
            n_modes: fit.n_modes,
            n_identified: fit.n_identified,
            held: fit.held.clone(),
            anchors,
        },
        rig,
    ))
}

/// Per joint, the deviations from nominal with their 1-sigma; and every
/// identified parameter with its value, deviation and 1-sigma.
fn deviations_and_estimates(
    obs: &Observations,
    geo: &Geometric,
    model: &FinalModel,
) -> (Vec<JointDeviation>, Vec<ParamEstimate>) {
    let l = obs.chain.layout;
    let after = &model.params;
    let mut sigma_of = vec![None; l.len()];
    if let Some(sel) = model.selection {
        for (k, &i) in sel.free.iter().enumerate() {
            sigma_of[i] = model.sigmas.get(k).copied();
        }
    }
    // `nominal` carries the fitted "before" base pose, so base deviations
    // are from that fit, the rest from nominal.
    let nominal = Params::nominal(obs.robot, &geo.before.base(), obs.rig, l.n_strings);
    let unit = |i: usize| {
        if l.is_angle(i) {
            (f64::to_degrees as fn(f64) -> f64, "deg")
        } else {
            (std::convert::identity as fn(f64) -> f64, "mm")
        }
    };
    let deviations = (0..l.n_joints)
        .map(|j| {
            let dev = |p: JointParam| {
                let i = l.joint(j, p);
                let (conv, _) = unit(i);
                (
                    conv(after.values[i] - nominal.values[i]),
                    sigma_of[i].map(conv),
                )
            };
            let (a, a_s) = dev(JointParam::A);
            let (al, al_s) = dev(JointParam::Alpha);
            let (d, d_s) = dev(JointParam::D);
            let (th, th_s) = dev(JointParam::Theta);
            let (be, be_s) = dev(JointParam::Beta);
            JointDeviation {
                joint: j + 1,
                a_mm: a,
                a_mm_sigma: a_s,
                alpha_deg: al,
                alpha_deg_sigma: al_s,
                d_mm: d,
                d_mm_sigma: d_s,
                theta_offset_deg: th,
                theta_offset_deg_sigma: th_s,
                beta_deg: be,
                beta_deg_sigma: be_s,
            }
        })
        .collect();
    let estimates = model
        .selection
        .map(|sel| {
            sel.free
                .iter()
                .map(|&i| {
                    let (conv, u) = unit(i);
                    ParamEstimate {
                        name: l.name(i),
                        value: conv(after.values[i]),
                        deviation: conv(after.values[i] - nominal.values[i]),
                        sigma: sigma_of[i].map(conv).unwrap_or(f64::NAN),
                        unit: u.into(),
                    }
                })
                .collect()
        })
        .unwrap_or_default();
    (deviations, estimates)
}

/// Train poses far beyond the robust residual scale of the final model.
fn outliers(obs: &Observations, train_problem: &CalibrationProblem, p: &[f64]) -> Vec<Outlier> {
    let res = identify::pose_rms(train_problem, p);
    let scale = 1.4826 * stats::median(&res);
    obs.train
        .iter()
        .zip(&res)
        .filter(|(_, e)| scale > 0.0 && **e > 4.0 * scale)
        .map(|(&i, &e)| Outlier {
            pose: obs.data.poses[i].id.clone(),
            residual_mm: e,
            score: e / scale,
        })
        .collect()
}

/// Every pose's errors before and after, with its string residuals (of
/// the final model, effects included when any were accepted, as the
/// physics fit defines them).
fn per_pose(
    obs: &Observations,
    train_problem: &CalibrationProblem,
    model: &FinalModel,
    eb: &[Vector3<f64>],
    confirmation: &[usize],
) -> Vec<PoseResidual> {
    let ea = &model.errors;
    let data = obs.data;
    let l = obs.chain.layout;
    let after = &model.params.values;
    let test_set: std::collections::HashSet<usize> = obs.test.iter().copied().collect();
    let mut r = Vec::new();
    (0..data.poses.len())
        .map(|i| {
            let strings_mm = (l.n_strings > 0).then(|| {
                match (&model.effects, &data.poses[i].measurement) {
                    (Some((ctx, effects)), Measurement::Strings(readings)) => {
                        let (t, dl) = physics::problem::EffectProblem::model_point(
                            &obs.chain,
                            ctx,
                            after,
                            effects,
                            i,
                            &data.poses[i].q_rad,
                        );
                        r.clear();
                        r.extend((0..l.n_strings).map(|k| {
                            crate::measure::string_residual_mm(
                                (t - obs.anchors[k]).norm(),
                                after[l.r()],
                                after[l.n_geometric() + k],
                                dl[k],
                                readings[k],
                            )
                        }));
                    }
                    _ => train_problem.pose_residuals(after, &data.poses[i], &mut r),
                }
                r.clone()
            });
            PoseResidual {
                pose: data.poses[i].id.clone(),
                split: if test_set.contains(&i) {
                    Split::Test
                } else {
                    Split::Train
                },
                confirmation: confirmation.binary_search(&i).is_ok(),
                before_mm: eb[i].into(),
                after_mm: ea[i].into(),
                strings_mm,
            }
        })
        .collect()
}
