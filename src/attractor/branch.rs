//! Attractors matched across neighbouring values into branches, the ids
//! the same along a branch. An attractor continues one at the value before
//! it that continuation links it to (a lane started from one ended on the
//! other), or, without such a link, the nearest one within a small
//! distance: a branch moves continuously with the parameter.

use super::group::{box_gap, points, relative_distance, scale, ValueAttractors};
use crate::method::LaneResult;

/// The largest distance (relative to max(1, |x|∞)) between an attractor
/// and the one it continues at the neighbouring value, without a
/// continuation link. A branch moves a little from one value to the next;
/// an orbit a quarter of the state's scale away is another attractor,
/// reached by a jump.
pub const MAX_BRANCH_STEP: f64 = 0.25;

/// The same with a continuation link: near a fold a branch moves fast (the
/// seed's impacting orbit moves by 0.3 between η = 0.575 and 0.58 of a
/// 0.005 step), but a link across the state's whole scale is a jump to
/// another attractor where the first ended.
pub const MAX_LINKED_STEP: f64 = 1.0;

/// The distance between two attractors' orbits: between periodic ones the
/// Hausdorff distance of their points (a period-doubled orbit is near the
/// one it came from), otherwise the gap between the boxes around them.
pub fn distance(a: &LaneResult, b: &LaneResult, dim: usize) -> f64 {
    match (a.orbit_period, b.orbit_period) {
        (Some(_), Some(_)) => {
            let one_way = |a: &LaneResult, b: &LaneResult| {
                points(a, dim).fold(0.0_f64, |m, x| {
                    m.max(points(b, dim).fold(f64::INFINITY, |n, y| n.min(relative_distance(x, y))))
                })
            };
            one_way(a, b).max(one_way(b, a))
        }
        _ => box_gap(a, b, dim) / scale(a, b),
    }
}

/// Gives every attractor (not the lone failed lanes) a branch: along the
/// first axis, within each row of the second, pairs of the value before
/// and this value are matched, linked ones first and then the closest
/// first, each attractor at most once; an attractor left unmatched starts
/// a new branch. Returns the number of branches. `values` are the grid's
/// points, first axis fastest.
pub fn assign(values: &mut [ValueAttractors], first_len: usize, dim: usize) -> usize {
    let mut branches = 0;
    for g in 0..values.len() {
        let mut pairs: Vec<(bool, f64, usize, usize)> = Vec::new();
        if g % first_len > 0 {
            let (before, here) = (&values[g - 1], &values[g]);
            for (i, a) in before.attractors.iter().enumerate() {
                for (j, b) in here.attractors.iter().enumerate() {
                    if a.branch.is_none() || b.is_lone() {
                        continue;
                    }
                    let linked =
                        here.links.contains(&(j, g - 1, i)) || before.links.contains(&(i, g, j));
                    let d = distance(&a.first.lane, &b.first.lane, dim);
                    let limit = if linked {
                        MAX_LINKED_STEP
                    } else {
                        MAX_BRANCH_STEP
                    };
                    if d <= limit {
                        // Linked pairs sort first.
                        pairs.push((!linked, d, i, j));
                    }
                }
            }
        }
        pairs.sort_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)));
        let mut taken_before = Vec::new();
        for (_, _, i, j) in pairs {
            if taken_before.contains(&i) || values[g].attractors[j].branch.is_some() {
                continue;
            }
            taken_before.push(i);
            values[g].attractors[j].branch = values[g - 1].attractors[i].branch;
        }
        for attractor in &mut values[g].attractors {
            if attractor.branch.is_none() && !attractor.is_lone() {
                attractor.branch = Some(branches);
                branches += 1;
            }
        }
    }
    branches
}
