//! A value's lanes told apart into attractors: two lanes are on one
//! attractor when their orbits coincide, a periodic orbit by its points, an
//! aperiodic one by the region its points cover and the signs of its
//! exponents.

use super::index::{self, Candidates, Index};
use crate::method::lane::attractor_tolerance;
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
    /// The convergence times of the scene's starts that ended on it
    /// (`LaneResult::settled`, where the lanes kept them), in the order
    /// they came.
    pub settling: Vec<usize>,
    /// The branch it belongs to across values (see `branch`); `None` for
    /// a failed lane's own row, and until branches are matched.
    pub branch: Option<usize>,
}

impl Attractor {
    /// The mean, median and largest convergence time of its starts (see
    /// [`Attractor::settling`]): `None` when none kept one. The median of
    /// an even count is the mean of the middle two.
    pub fn convergence(&self) -> Option<(f64, f64, usize)> {
        let mut times = self.settling.clone();
        times.sort_unstable();
        let n = times.len();
        let largest = *times.last()?;
        let mean = times.iter().map(|&t| t as f64).sum::<f64>() / n as f64;
        let median = if n % 2 == 1 {
            times[n / 2] as f64
        } else {
            0.5 * (times[n / 2 - 1] + times[n / 2]) as f64
        };
        Some((mean, median, largest))
    }

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
    /// The attractor tolerance of the run's arithmetic
    /// ([`attractor_tolerance`]).
    pub fn new(dim: usize, rounding_unit: f64) -> Rule {
        Rule {
            dim,
            tolerance: attractor_tolerance(rounding_unit),
        }
    }
}

/// The attractors of one value, as its lanes arrive.
#[derive(Clone, Debug, Default)]
pub struct ValueAttractors {
    pub attractors: Vec<Attractor>,
    /// The attractor each lane ended on, by the lane's start.
    pub of_start: Vec<Option<usize>>,
    /// The starts outside the admissible states (not run), in order.
    pub inadmissible: Vec<usize>,
    /// Continuation's evidence: (attractor here, neighbouring point, its
    /// attractor) when a lane started from that attractor's final state
    /// ended on this one.
    pub links: Vec<(usize, usize, usize)>,
    /// What the matching reads of each attractor's first lane, by index
    /// (see [`Shape`]): kept, not recomputed for every lane that arrives.
    shapes: Vec<Shape>,
    /// Where the attractors lie, so that a lane is tested only against
    /// those it may be on.
    index: Index,
}

/// What [`same_attractor`] reads of a lane beyond its period and points,
/// computed once per lane: the signs of its exponents, the box around its
/// points and the largest |x| among them. Min, max and comparisons are
/// exact, so the cached values give the same answers, to the bit, as
/// folding the points again at every comparison; matching a lane against
/// N attractors then costs N boxes, not N passes over their points.
#[derive(Clone, Debug)]
struct Shape {
    signs: Vec<i8>,
    /// (low, high) of each coordinate of the points.
    bounds: Vec<(f64, f64)>,
    /// max(1, |x|∞) over the points.
    scale: f64,
}

impl Shape {
    /// The index's view of the shape.
    fn region(&self) -> index::Shape<'_> {
        index::Shape {
            signs: &self.signs,
            bounds: &self.bounds,
            scale: self.scale,
        }
    }

    fn of(lane: &LaneResult, dim: usize) -> Shape {
        Shape {
            signs: signs(&lane.exponents),
            bounds: (0..dim).map(|i| bounds(lane, dim, i)).collect(),
            scale: lane.orbit.iter().fold(1.0_f64, |m, v| m.max(v.abs())),
        }
    }
}

impl ValueAttractors {
    /// Adds a lane (`sampled`: one of the scene's starts, which count for
    /// the basins): joins the attractor its orbit coincides with, or
    /// begins a new one. Returns the attractor's index and whether it is
    /// new.
    pub fn join(&mut self, member: Member, sampled: bool, rule: Rule) -> (usize, bool) {
        let start = member.start;
        let settled = member.lane.settled.filter(|_| sampled);
        while self.shapes.len() < self.attractors.len() {
            let first = &self.attractors[self.shapes.len()].first.lane;
            self.shapes.push(Shape::of(first, rule.dim));
        }
        self.catch_up_index(rule);
        let shape = Shape::of(&member.lane, rule.dim);
        let lone = is_lone(&member.lane.status);
        let test = |&i: &usize| {
            matches(
                &self.attractors[i].first.lane,
                &self.shapes[i],
                &member.lane,
                &shape,
                rule,
            )
        };
        let found = match self.index.candidates(
            &member.lane,
            &shape.region(),
            rule.dim,
            rule.tolerance,
            lone,
        ) {
            Candidates::Some(list) => list.iter().copied().find(|i| test(i)),
            Candidates::All => (0..self.attractors.len()).find(|i| test(i)),
        };
        let (index, new) = match found {
            Some(i) => (i, false),
            None => {
                let i = self.attractors.len();
                self.index.insert(
                    i,
                    &member.lane,
                    &shape.region(),
                    rule.dim,
                    rule.tolerance,
                    lone,
                );
                self.shapes.push(shape);
                self.attractors.push(Attractor {
                    first: member,
                    starts: 0,
                    lanes: 0,
                    settling: Vec::new(),
                    branch: None,
                });
                (self.attractors.len() - 1, true)
            }
        };
        let attractor = &mut self.attractors[index];
        attractor.lanes += 1;
        attractor.starts += usize::from(sampled);
        attractor.settling.extend(settled);
        if self.of_start.len() <= start {
            self.of_start.resize(start + 1, None);
        }
        self.of_start[start] = Some(index);
        (index, new)
    }

    /// Files the attractors not yet in the index (those added to
    /// `attractors` directly).
    fn catch_up_index(&mut self, rule: Rule) {
        while self.index.indexed < self.attractors.len() {
            let i = self.index.indexed;
            let lane = &self.attractors[i].first.lane;
            self.index.insert(
                i,
                lane,
                &self.shapes[i].region(),
                rule.dim,
                rule.tolerance,
                is_lone(&lane.status),
            );
        }
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
    matches(a, &Shape::of(a, rule.dim), b, &Shape::of(b, rule.dim), rule)
}

/// [`same_attractor`] of `a` and `b` with their shapes computed already:
/// the same tests in the same order, the points' folds read from the
/// shapes.
fn matches(a: &LaneResult, sa: &Shape, b: &LaneResult, sb: &Shape, rule: Rule) -> bool {
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
            sa.signs == sb.signs
                && gap(&sa.bounds, &sb.bounds) <= tolerance * sa.scale.max(sb.scale)
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
    let box_of = |lane| -> Vec<(f64, f64)> { (0..dim).map(|i| bounds(lane, dim, i)).collect() };
    gap(&box_of(a), &box_of(b))
}

/// (low, high) of coordinate `i` over a lane's points.
fn bounds(lane: &LaneResult, dim: usize, i: usize) -> (f64, f64) {
    points(lane, dim).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
        (lo.min(x[i]), hi.max(x[i]))
    })
}

/// The gap between two boxes, each (low, high) per coordinate, in the max
/// norm (0 when they overlap).
fn gap(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0_f64, |gap, (&(alo, ahi), &(blo, bhi))| {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::lane::LanePlan;

    /// The matching as it was, every fold over the points redone at every
    /// comparison: the reference the kept shapes must agree with.
    fn same_attractor_by_points(a: &LaneResult, b: &LaneResult, rule: Rule) -> bool {
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
                let bounds = |lane: &LaneResult, i: usize| {
                    points(lane, dim).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                        (lo.min(x[i]), hi.max(x[i]))
                    })
                };
                let gap = (0..dim).fold(0.0_f64, |gap, i| {
                    let (alo, ahi) = bounds(a, i);
                    let (blo, bhi) = bounds(b, i);
                    gap.max(alo - bhi).max(blo - ahi)
                });
                signs(&a.exponents) == signs(&b.exponents) && gap <= tolerance * scale(a, b)
            }
            _ => false,
        }
    }

    fn lane(orbit: Vec<f64>, period: Option<usize>, exponents: Vec<f64>) -> LaneResult {
        LaneResult {
            exponents,
            impacts_per_period: 0.0,
            crossings_per_period: [0.0; crate::integrate::MAX_EVENTS],
            period: 1.0,
            orbit_period: period,
            orbit,
            settled: None,
            orbit_term: 0.0,
            bifurcation: Vec::new(),
            jacobians: Vec::new(),
            grazing: 0,
            grazing_bound: 0.0,
            error: 0.0,
            plan: LanePlan {
                steps_per_period: 100,
                parts: 1,
            },
            status: LaneStatus::Ok,
        }
    }

    /// Lanes of every kind the matching tells apart: periodic orbits of a
    /// few periods, some on one orbit within the tolerance; aperiodic
    /// regions that overlap, touch or lie apart, of either sign pattern,
    /// NaN points among them; failed and empty lanes.
    fn assorted(n: usize, points: usize, rng: &mut fastrand::Rng) -> Vec<LaneResult> {
        (0..n)
            .map(|k| {
                let centre = [rng.usize(0..6) as f64 * 0.75, rng.usize(0..3) as f64];
                match k % 7 {
                    0 | 1 => {
                        let p = 1 + rng.usize(0..3);
                        let jitter = if rng.bool() { 1e-12 } else { 1e-3 };
                        let orbit = (0..p)
                            .flat_map(|j| [centre[0] + j as f64, centre[1] + jitter * rng.f64()])
                            .collect();
                        lane(orbit, Some(p), vec![-0.1, -0.5])
                    }
                    2 => lane(Vec::new(), None, vec![0.1, -0.5]),
                    _ => {
                        let width = 0.1 + 0.4 * rng.f64();
                        let mut orbit: Vec<f64> = (0..points)
                            .flat_map(|_| {
                                [centre[0] + width * rng.f64(), centre[1] + width * rng.f64()]
                            })
                            .collect();
                        if k % 11 == 0 {
                            orbit[1] = f64::NAN;
                        }
                        let mut result =
                            lane(orbit, None, vec![[0.1, 0.0][k % 2], -0.5 - rng.f64()]);
                        if k % 13 == 0 {
                            result.status = LaneStatus::NonFinite { iteration: 3 };
                        }
                        result
                    }
                }
            })
            .collect()
    }

    /// Each lane's attractor by the scan as it was: the first attractor
    /// whose first lane matches, else a new one.
    fn grouped_by_points(lanes: &[LaneResult], rule: Rule) -> Vec<usize> {
        let mut firsts: Vec<&LaneResult> = Vec::new();
        lanes
            .iter()
            .map(|l| {
                match firsts
                    .iter()
                    .position(|a| same_attractor_by_points(a, l, rule))
                {
                    Some(i) => i,
                    None => {
                        firsts.push(l);
                        firsts.len() - 1
                    }
                }
            })
            .collect()
    }

    fn grouped(lanes: &[LaneResult], rule: Rule) -> ValueAttractors {
        let mut value = ValueAttractors::default();
        for (start, l) in lanes.iter().enumerate() {
            let member = Member {
                start,
                lane: l.clone(),
                expected_sum: 0.0,
            };
            value.join(member, true, rule);
        }
        value
    }

    #[test]
    fn kept_shapes_group_lanes_as_the_folds_over_their_points_did() {
        let rule = Rule {
            dim: 2,
            tolerance: 1e-9,
        };
        for seed in 0..20 {
            let mut rng = fastrand::Rng::with_seed(seed);
            let lanes = assorted(300, 1 + rng.usize(0..40), &mut rng);
            let value = grouped(&lanes, rule);
            let kept: Vec<usize> = value.of_start.iter().map(|a| a.unwrap()).collect();
            assert_eq!(kept, grouped_by_points(&lanes, rule), "seed {seed}");
            assert!(
                value.attractors.len() > 10,
                "seed {seed}: a trivial grouping"
            );
            for (i, j) in [(0, 1), (3, 4), (5, 10), (12, 13)] {
                assert_eq!(
                    same_attractor(&lanes[i], &lanes[j], rule),
                    same_attractor_by_points(&lanes[i], &lanes[j], rule)
                );
            }
        }
    }

    /// Lanes made to test the index's bounds: orbits of 1 to 3
    /// coordinates at magnitudes from 1 to 1e9, points placed at the
    /// tolerance's edge (just within, just beyond) of one another and
    /// across powers of two, boxes from a point to 1e6 wide, some apart by
    /// the tolerance, and points that are NaN or infinite.
    fn edges(n: usize, dim: usize, tolerance: f64, rng: &mut fastrand::Rng) -> Vec<LaneResult> {
        let magnitudes = [0.3, 1.0, 2.0, 1023.9, 1024.1, 7.5e5, 1e9];
        let mut made: Vec<LaneResult> = Vec::new();
        for k in 0..n {
            let near = !made.is_empty() && rng.u8(0..3) > 0;
            let base: Vec<f64> = if near {
                let other = &made[rng.usize(0..made.len())];
                let mut x: Vec<f64> = other.orbit.iter().take(dim).copied().collect();
                x.resize(dim, 0.0);
                x
            } else {
                let m = magnitudes[rng.usize(0..magnitudes.len())];
                (0..dim).map(|_| m * (2.0 * rng.f64() - 1.0)).collect()
            };
            let scale = base.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
            let edge = [0.0, 0.5, 0.999_999_999_9, 1.0, 1.000_000_000_1, 2.0, 3.0][rng.usize(0..7)];
            let shift = |v: f64, rng: &mut fastrand::Rng| {
                let sign = if rng.bool() { 1.0 } else { -1.0 };
                v + sign * edge * tolerance * scale
            };
            let mut l = if k % 3 == 0 {
                let width = [0.0, 1e-12, 1e-3, 1.0, 1e6][rng.usize(0..5)];
                let points = 1 + rng.usize(0..6);
                let corner: Vec<f64> = base.iter().map(|&v| shift(v, rng)).collect();
                let orbit = (0..points)
                    .flat_map(|_| {
                        corner
                            .iter()
                            .map(|&c| c + width * rng.f64())
                            .collect::<Vec<_>>()
                    })
                    .collect();
                lane(orbit, None, vec![[0.1, 0.0][rng.usize(0..2)], -0.5])
            } else {
                let p = 1 + rng.usize(0..2);
                let orbit: Vec<f64> = (0..p)
                    .flat_map(|j| {
                        base.iter()
                            .map(|&v| shift(v + j as f64 * 3.0 * tolerance * scale, rng))
                            .collect::<Vec<_>>()
                    })
                    .collect();
                lane(orbit, Some(p), vec![-0.1, -0.5])
            };
            match rng.u8(0..40) {
                0 => l.orbit[0] = f64::NAN,
                1 => l.orbit[0] = f64::INFINITY,
                2 => {
                    let last = l.orbit.len() - 1;
                    l.orbit[last] = f64::NEG_INFINITY
                }
                3 if dim > 1 => l.orbit.truncate(dim - 1),
                4 => l.orbit.clear(),
                5 => l.status = LaneStatus::NonFinite { iteration: 1 },
                _ => {}
            }
            made.push(l);
        }
        made
    }

    /// The index proposes every attractor the test accepts: each lane
    /// joins the attractor it joined when compared with all, at the edges
    /// of the tolerance, of the grids' cells and magnitudes, and with
    /// points that are not finite; and for tolerances the index does not
    /// serve (compared with all).
    #[test]
    fn indexed_matching_groups_lanes_as_comparing_each_with_all() {
        for seed in 0..60 {
            let mut rng = fastrand::Rng::with_seed(seed);
            let dim = 1 + (seed as usize % 3);
            for tolerance in [1e-9, 1e-5, 6e-4, 0.3, 0.0] {
                let rule = Rule { dim, tolerance };
                let lanes = edges(400, dim, tolerance.max(1e-7), &mut rng);
                let value = grouped(&lanes, rule);
                let kept: Vec<usize> = value.of_start.iter().map(|a| a.unwrap()).collect();
                let reference = grouped_by_points(&lanes, rule);
                assert_eq!(
                    kept, reference,
                    "seed {seed}, dim {dim}, tolerance {tolerance}"
                );
                let joined = kept.iter().enumerate().filter(|&(i, &a)| a != i).count();
                assert!(
                    tolerance == 0.0 || joined > 20,
                    "seed {seed}: too few lanes joined another ({joined})"
                );
            }
        }
    }

    /// 20 000 lanes that never settled, each on a region of its own, and
    /// 20 000 periodic ones on 2 000 orbits: the index keeps the matching
    /// about linear (comparing each with all would be 2·10^8 tests).
    #[test]
    fn many_distinct_attractors_are_told_apart_in_about_linear_time() {
        let rule = Rule {
            dim: 2,
            tolerance: 1e-5,
        };
        let mut rng = fastrand::Rng::with_seed(7);
        let mut lanes: Vec<LaneResult> = (0..20_000)
            .map(|_| {
                let (x, v) = (6.0 * rng.f64() - 3.0, 6.0 * rng.f64() - 3.0);
                let orbit = (0..50)
                    .flat_map(|j| [x + j as f64 * 1e-7, v + j as f64 * 1e-7])
                    .collect();
                lane(orbit, None, vec![0.0, -0.5])
            })
            .collect();
        lanes.extend((0..20_000).map(|k| {
            let o = (k % 2_000) as f64 * 1e-3;
            lane(vec![o, 1.0, o, -1.0], Some(2), vec![-0.1, -0.5])
        }));
        let now = std::time::Instant::now();
        let value = grouped(&lanes, rule);
        let took = now.elapsed();
        assert_eq!(value.attractors.len(), 22_000);
        assert!(took.as_secs_f64() < 2.0, "{took:?}");
        // A sample checked against comparing with all.
        let sample: Vec<LaneResult> = lanes[..2_000]
            .iter()
            .chain(&lanes[20_000..22_000])
            .cloned()
            .collect();
        let kept: Vec<usize> = grouped(&sample, rule)
            .of_start
            .iter()
            .map(|a| a.unwrap())
            .collect();
        assert_eq!(kept, grouped_by_points(&sample, rule));
    }

    /// Thousands of lanes that never settled (aperiodic, each on a region
    /// of its own): the matching as it was against the kept shapes, timed.
    #[test]
    fn lanes_that_never_settle_are_matched_without_refolding_their_points() {
        let rule = Rule {
            dim: 2,
            tolerance: 1e-9,
        };
        let (n, points) = (2000, 200);
        let lanes: Vec<LaneResult> = (0..n)
            .map(|k| {
                let orbit = (0..points)
                    .flat_map(|j| [k as f64 * 10.0 + j as f64 * 1e-3, 0.5])
                    .collect();
                lane(orbit, None, vec![0.1, -0.5])
            })
            .collect();
        let before = std::time::Instant::now();
        let reference = grouped_by_points(&lanes, rule);
        let folded = before.elapsed();
        let now = std::time::Instant::now();
        let value = grouped(&lanes, rule);
        let kept = now.elapsed();
        assert_eq!(value.attractors.len(), n);
        let of_start: Vec<usize> = value.of_start.iter().map(|a| a.unwrap()).collect();
        assert_eq!(of_start, reference);
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr(),
            "{n} lanes of {points} points, none settled: folding the points {:.2} s, kept shapes {:.3} s",
            folded.as_secs_f64(),
            kept.as_secs_f64()
        );
        assert!(kept < folded, "{kept:?} against {folded:?}");
    }
}
