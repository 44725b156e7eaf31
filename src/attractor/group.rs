//! A value's lanes told apart into attractors: two lanes are on one
//! attractor when their orbits coincide, a periodic orbit by its points, an
//! aperiodic one by the region its points cover and the signs of its
//! exponents.

use crate::method::lane::return_tolerance;
use crate::method::{LaneResult, LaneStatus};

/// One lane of a value as the grouping keeps it: its result without the
/// bifurcation points and Jacobians (those go to the files as they come).
#[derive(Clone, Debug)]
pub struct Member {
    /// The lane's start among its value's (the scene's starts first, then
    /// the continuation seeds).
    pub start: usize,
    pub lane: LaneResult,
    pub expected_sum: f64,
}

/// An attractor found at one value, or a lane that failed, on its own.
#[derive(Clone, Debug)]
pub struct Attractor {
    /// The lane that found it first: its exponents, orbit and status are
    /// the attractor's row.
    pub first: Member,
    /// The scene's starts (random, grid or list) that ended on it: its
    /// basin, as a count.
    pub starts: usize,
    /// Every lane that ended on it, continuation seeds included.
    pub lanes: usize,
    /// The branch it belongs to across values (see `branch`); `None` for
    /// a failed lane's own row, and until branches are matched.
    pub branch: Option<usize>,
}

impl Attractor {
    /// Whether this row is one lane that failed or whose motion the method
    /// does not resolve (diverged, stuck, chattering, sliding): such a lane
    /// keeps its status and is never merged with another.
    pub fn is_lone(&self) -> bool {
        is_lone(&self.first.lane.status)
    }
}

fn is_lone(status: &LaneStatus) -> bool {
    status.is_failure()
        || matches!(
            status,
            LaneStatus::Chattering { .. }
                | LaneStatus::Sliding { .. }
                | LaneStatus::Collapsed { .. }
        )
}

/// What decides that two lanes of a value are on one attractor.
#[derive(Clone, Copy, Debug)]
pub struct Rule {
    /// The dimension of the map's points.
    pub dim: usize,
    /// The relative distance within which two lanes' orbit points are one
    /// point.
    pub tolerance: f64,
}

impl Rule {
    /// Ten times the return test's tolerance in the run's arithmetic: each
    /// lane's own points settle within that of their orbit, so two lanes'
    /// points within twice it.
    pub fn new(dim: usize, rounding_unit: f64) -> Rule {
        Rule {
            dim,
            tolerance: 10.0 * return_tolerance(rounding_unit),
        }
    }
}

/// The attractors of one value, as its lanes arrive.
#[derive(Clone, Debug, Default)]
pub struct ValueAttractors {
    pub attractors: Vec<Attractor>,
    /// The attractor each lane ended on, by the lane's start.
    pub of_start: Vec<Option<usize>>,
    /// Continuation's evidence: (attractor here, neighbouring point, its
    /// attractor) when a lane started from that attractor's final state
    /// ended on this one.
    pub links: Vec<(usize, usize, usize)>,
}

impl ValueAttractors {
    /// Adds a lane (`sampled`: one of the scene's starts, which count for
    /// the basins): joins the attractor its orbit coincides with, or
    /// begins a new one. Returns the attractor's index and whether it is
    /// new.
    pub fn join(&mut self, member: Member, sampled: bool, rule: Rule) -> (usize, bool) {
        let start = member.start;
        let found = self
            .attractors
            .iter()
            .position(|a| same_attractor(&a.first.lane, &member.lane, rule));
        let (index, new) = match found {
            Some(i) => (i, false),
            None => {
                self.attractors.push(Attractor {
                    first: member,
                    starts: 0,
                    lanes: 0,
                    branch: None,
                });
                (self.attractors.len() - 1, true)
            }
        };
        let attractor = &mut self.attractors[index];
        attractor.lanes += 1;
        attractor.starts += usize::from(sampled);
        if self.of_start.len() <= start {
            self.of_start.resize(start + 1, None);
        }
        self.of_start[start] = Some(index);
        (index, new)
    }

    /// Attractors proper (not lone failed lanes).
    pub fn count(&self) -> usize {
        self.attractors.iter().filter(|a| !a.is_lone()).count()
    }
}

/// Whether two lanes of one value ended on one attractor: the same period
/// and each point of one within `tolerance` (relative to max(1, |x|∞)) of
/// a point of the other; or both aperiodic, with the same signs of
/// exponents and regions (the boxes around their points) that overlap.
pub fn same_attractor(a: &LaneResult, b: &LaneResult, rule: Rule) -> bool {
    if is_lone(&a.status) || is_lone(&b.status) || a.orbit.is_empty() || b.orbit.is_empty() {
        return false;
    }
    let (dim, tolerance) = (rule.dim, rule.tolerance);
    match (a.orbit_period, b.orbit_period) {
        (Some(p), Some(q)) => {
            p == q
                && points(a, dim)
                    .all(|x| points(b, dim).any(|y| relative_distance(x, y) <= tolerance))
        }
        (None, None) => {
            signs(&a.exponents) == signs(&b.exponents)
                && box_gap(a, b, dim) <= tolerance * scale(a, b)
        }
        _ => false,
    }
}

pub(super) fn points(lane: &LaneResult, dim: usize) -> impl Iterator<Item = &[f64]> + Clone {
    lane.orbit.chunks_exact(dim)
}

/// |x - y|∞ / max(1, |x|∞, |y|∞).
pub(super) fn relative_distance(x: &[f64], y: &[f64]) -> f64 {
    let scale = x.iter().chain(y).fold(1.0_f64, |m, v| m.max(v.abs()));
    x.iter()
        .zip(y)
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()))
        / scale
}

/// max(1, |x|∞) over both lanes' points.
pub(super) fn scale(a: &LaneResult, b: &LaneResult) -> f64 {
    a.orbit
        .iter()
        .chain(&b.orbit)
        .fold(1.0_f64, |m, v| m.max(v.abs()))
}

/// The gap between the boxes around two lanes' points, in the max norm
/// (0 when they overlap).
pub(super) fn box_gap(a: &LaneResult, b: &LaneResult, dim: usize) -> f64 {
    let bounds = |lane: &LaneResult, i: usize| {
        points(lane, dim).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x[i]), hi.max(x[i]))
        })
    };
    (0..dim).fold(0.0_f64, |gap, i| {
        let (alo, ahi) = bounds(a, i);
        let (blo, bhi) = bounds(b, i);
        gap.max(alo - bhi).max(blo - ahi)
    })
}

/// The signs of the exponents (+1, 0, -1), an exponent within a hundredth
/// of the largest magnitude counting as 0: chaotic (+, -) and
/// quasi-periodic (0, -) motions in one region are different attractors.
fn signs(exponents: &[f64]) -> Vec<i8> {
    let largest = exponents.iter().fold(0.0_f64, |m, e| m.max(e.abs()));
    exponents
        .iter()
        .map(|&e| {
            if e.abs() <= 1e-2 * largest {
                0
            } else if e > 0.0 {
                1
            } else {
                -1
            }
        })
        .collect()
}
