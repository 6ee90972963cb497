//! Which train poses neighbour which: sorted by a joint angle, the clock,
//! the temperature or a correction's driver, or nearest in joint space or
//! the workspace.

use super::has_temperature;
use super::nearest::{nearest_in_joint_space, nearest_in_time_and_workspace, nearest_in_workspace};
use crate::identify::Observations;
use crate::physics::effects::{Context, CorrectionDriver};

/// The orderings whose neighbours are compared, each a name and its pairs
/// of train poses (positions in `obs.train`): by each joint angle, by time,
/// by temperature when every pose has one, each pose with its nearest
/// neighbour in joint space (the layout [`unexplained_plot`] reads up to
/// here), in the workspace, and in time and the workspace at once.
///
/// [`unexplained_plot`]: crate::physics::evidence::unexplained_plot
pub(super) fn orderings(obs: &Observations, ctx: &Context) -> Vec<(String, Vec<(usize, usize)>)> {
    let n = ctx.n_joints;
    let mut keys: Vec<(String, Vec<f64>)> = (0..n)
        .map(|j| {
            (
                format!("joint {} angle", j + 1),
                obs.train.iter().map(|&i| ctx.poses[i].q_rad[j]).collect(),
            )
        })
        .collect();
    keys.push((
        "time (visiting order)".into(),
        obs.train.iter().map(|&i| ctx.poses[i].time_s).collect(),
    ));
    if has_temperature(obs) {
        keys.push((
            "temperature".into(),
            obs.train
                .iter()
                .map(|&i| obs.data.poses[i].temp_c.unwrap_or(0.0))
                .collect(),
        ));
    }
    // Neighbour pairs per ordering: sorted by one key, and each pose with
    // its nearest neighbour in joint space (the workspace). Poses close in
    // time are usually close in the workspace too (a tour, a raster), so
    // time only wins where it beats the configuration itself.
    let mut pairings: Vec<(String, Vec<(usize, usize)>)> = keys
        .iter()
        .map(|(name, key)| {
            let mut order: Vec<usize> = (0..key.len()).collect();
            order.sort_by(|a, b| key[*a].total_cmp(&key[*b]));
            // Each pose with the next two: a smooth function of the key
            // agrees over both, and the products of pairs that share a
            // pose are still uncorrelated under independent noise.
            let pairs = order
                .windows(2)
                .map(|w| (w[0], w[1]))
                .chain(order.windows(3).map(|w| (w[0], w[2])))
                .collect();
            (name.clone(), pairs)
        })
        .collect();
    pairings.push((
        "the joint configuration (nearest pose in joint space)".into(),
        nearest_in_joint_space(ctx, &obs.train),
    ));
    // Last, T's position: a field over the workspace (a distortion of the
    // measuring device, a compliance of the stand) follows where T is,
    // whatever the joints do to put it there.
    pairings.push((
        "T's position (nearest pose in the workspace)".into(),
        nearest_in_workspace(ctx, &obs.train),
    ));
    // And both: an error changing in time by where T is.
    pairings.push((
        "time and T's position (nearest pose in both)".into(),
        nearest_in_time_and_workspace(ctx, &obs.train),
    ));
    pairings
}

/// What the plain ordering `pk` of [`orderings`] follows, as a place's
/// driver and joint (1-based). The layout: one per joint, time,
/// temperature when recorded (`with_temp`), the configuration, T's
/// position, time and T's position together.
pub(super) fn driver_of(pk: usize, n: usize, with_temp: bool) -> (&'static str, Option<usize>) {
    let t = usize::from(with_temp);
    match pk {
        j if j < n => ("joint", Some(j + 1)),
        j if j == n => ("time", None),
        j if with_temp && j == n + 1 => ("temperature", None),
        j if j == n + 1 + t => ("configuration", None),
        j if j == time_and_workspace_at(n, with_temp) => ("time", None),
        _ => ("workspace", None),
    }
}

/// Where [`orderings`] puts the pairs nearest in time and T's position
/// (after T's position alone): `n` joints, `with_temp` a temperature.
pub(super) fn time_and_workspace_at(n: usize, with_temp: bool) -> usize {
    n + 3 + usize::from(with_temp)
}

/// The train poses (positions in `obs.train`) sorted by the value of a
/// correction's `driver` (with `index`), as the correction sees it.
pub(super) fn train_order(
    obs: &Observations,
    ctx: &Context,
    driver: CorrectionDriver,
    index: usize,
) -> Vec<usize> {
    let v: Vec<f64> = obs
        .train
        .iter()
        .map(|&k| ctx.driver_value(&ctx.poses[k], driver, Some(index), None))
        .collect();
    let mut order: Vec<usize> = (0..v.len()).collect();
    order.sort_by(|a, b| v[*a].total_cmp(&v[*b]));
    order
}
