//! The order the robot visits the chosen poses: a short tour from home.
//!
//! The cost of a move is its slowest joint's travel (the largest joint
//! change, deg), what a move's duration follows. Nearest neighbour from
//! home, then 2-opt on the open path (home fixed first) until no reversal
//! shortens it. [`improve`] then reorders it for another cost (the
//! approach directions backlash needs) within a bound on the travel.

/// Largest joint change between two poses (deg).
pub fn joint_travel_deg(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Total travel of a path from `home` through `poses` in order (deg).
pub fn path_travel_deg(home: &[f64], poses: &[&[f64]]) -> f64 {
    let mut prev = home;
    let mut total = 0.0;
    for q in poses {
        total += joint_travel_deg(prev, q);
        prev = q;
    }
    total
}

/// The visiting order of `poses` (indices) from `home`.
pub fn order(home: &[f64], poses: &[&[f64]]) -> Vec<usize> {
    let n = poses.len();
    let mut left: Vec<usize> = (0..n).collect();
    let mut path = Vec::with_capacity(n);
    let mut cur = home;
    while !left.is_empty() {
        let (pos, _) = left
            .iter()
            .enumerate()
            .map(|(k, &i)| (k, joint_travel_deg(cur, poses[i])))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("non-empty");
        let i = left.swap_remove(pos);
        cur = poses[i];
        path.push(i);
    }
    // 2-opt: reverse path[i..=j] when that shortens the path. Node -1 is
    // home; the path is open at its end.
    let at =
        |path: &[usize], k: isize| -> &[f64] { if k < 0 { home } else { poses[path[k as usize]] } };
    for _ in 0..50 {
        let mut improved = false;
        for i in 0..n {
            for j in i + 1..n {
                let (a, b) = (at(&path, i as isize - 1), at(&path, i as isize));
                let c = at(&path, j as isize);
                let before = joint_travel_deg(a, b)
                    + if j + 1 < n {
                        joint_travel_deg(c, at(&path, j as isize + 1))
                    } else {
                        0.0
                    };
                let after = joint_travel_deg(a, c)
                    + if j + 1 < n {
                        joint_travel_deg(b, at(&path, j as isize + 1))
                    } else {
                        0.0
                    };
                if after < before - 1e-9 {
                    path[i..=j].reverse();
                    improved = true;
                }
            }
        }
        if !improved {
            break;
        }
    }
    path
}

/// Reorder the tour `order` of `poses` from `home` to lower `cost`: segment
/// reversals and single poses moved elsewhere, each kept when it lowers the
/// cost, keeps the travel within `max_travel_deg` and keeps every pose in
/// its `group`'s stretch of the tour (the groups' sequence unchanged);
/// repeated until no move helps or `budget` moves have been tried.
pub fn improve(
    home: &[f64],
    poses: &[&[f64]],
    mut order: Vec<usize>,
    group: &[usize],
    max_travel_deg: f64,
    budget: usize,
    cost: &mut dyn FnMut(&[usize]) -> f64,
) -> Vec<usize> {
    let groups = |o: &[usize]| o.iter().map(|&i| group[i]).collect::<Vec<_>>();
    let shape = groups(&order);
    let mut best = cost(&order);
    let mut spent = 1;
    let n = order.len();
    loop {
        let mut improved = false;
        for i in 0..n {
            for j in i + 1..n {
                for mv in 0..3 {
                    if spent >= budget {
                        return order;
                    }
                    let mut c = order.clone();
                    match mv {
                        0 => c[i..=j].reverse(),
                        1 => {
                            let x = c.remove(i);
                            c.insert(j, x);
                        }
                        _ => {
                            let x = c.remove(j);
                            c.insert(i, x);
                        }
                    }
                    spent += 1;
                    let toured: Vec<&[f64]> = c.iter().map(|&k| poses[k]).collect();
                    if groups(&c) != shape || path_travel_deg(home, &toured) > max_travel_deg {
                        continue;
                    }
                    let v = cost(&c);
                    if v < best - 1e-9 * best.abs().max(1.0) {
                        best = v;
                        order = c;
                        improved = true;
                    }
                }
            }
        }
        if !improved {
            return order;
        }
    }
}

/// A short tour of `refs` from `home` visiting group 0 first, then group
/// 1 from where group 0 ended. With one group: [`order`] itself.
pub(super) fn grouped_tour(home: &[f64], refs: &[&[f64]], group: &[usize]) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::with_capacity(refs.len());
    for g in 0..=1 {
        let idx: Vec<usize> = (0..refs.len()).filter(|&k| group[k] == g).collect();
        if idx.is_empty() {
            continue;
        }
        let start = out.last().map_or(home, |&k| refs[k]);
        let sub: Vec<&[f64]> = idx.iter().map(|&k| refs[k]).collect();
        out.extend(order(start, &sub).into_iter().map(|k| idx[k]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn the_tour_visits_each_pose_once_and_beats_the_given_order() {
        let mut rng = Rng::new(5);
        let poses: Vec<Vec<f64>> = (0..40)
            .map(|_| (0..6).map(|_| rng.range(-150.0, 150.0)).collect())
            .collect();
        let refs: Vec<&[f64]> = poses.iter().map(|p| p.as_slice()).collect();
        let home = [0.0; 6];
        let o = order(&home, &refs);
        let mut seen = o.clone();
        seen.sort();
        assert_eq!(seen, (0..40).collect::<Vec<_>>());
        let toured: Vec<&[f64]> = o.iter().map(|&i| refs[i]).collect();
        let t = path_travel_deg(&home, &toured);
        let given = path_travel_deg(&home, &refs);
        assert!(t < 0.6 * given, "{t} vs {given}");
    }

    #[test]
    fn points_on_a_line_are_visited_in_order() {
        let poses: Vec<Vec<f64>> = [50.0, 10.0, 40.0, 20.0, 30.0]
            .iter()
            .map(|&x| vec![x])
            .collect();
        let refs: Vec<&[f64]> = poses.iter().map(|p| p.as_slice()).collect();
        let o = order(&[0.0], &refs);
        assert_eq!(o, vec![1, 3, 4, 2, 0]);
    }
}
