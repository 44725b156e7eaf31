//! Early stops: a lane of a basin image whose reference has come within
//! the attractor tolerance of a point of an attractor already known at its
//! value, and stayed within it for `k` consecutive iterations of the
//! transient, stops there and takes that attractor.
//!
//! The known attractors are periodic orbits that lanes run in full found
//! first (`attractor::Found::known`); a stable orbit's neighbourhood of
//! that size lies in its basin (the seed's critical shocks at η = 0.6 are
//! above 0.1 of the box, the tolerance 1e-5 of the state), so a start that
//! has stayed in it does not leave. The stopped lane's numbers (exponents,
//! impacts, orbit) are its attractor's lane's, and its status says so
//! ([`LaneStatus::EarlyStop`]); its own are its convergence time, taken
//! over its points up to the stop against the known orbit (the points
//! after it stay within the tolerance), and its last reference points.

use super::result::{LaneResult, LaneStatus};
use super::settling::{relative_distance, Settling};

/// A periodic orbit a value's lanes may stop early on: its points (D
/// numbers each) and the result of the lane that found it.
#[derive(Clone, Debug)]
pub struct KnownOrbit {
    pub points: Vec<f64>,
    pub result: LaneResult,
}

/// The known orbits of every point of the sweep's grid.
#[derive(Clone, Debug, Default)]
pub struct KnownOrbits {
    pub per_point: Vec<Vec<KnownOrbit>>,
}

/// A lane's watch over its reference: which known orbit its points lie
/// near, and for how many consecutive iterations.
pub struct Watch<'a> {
    known: &'a [KnownOrbit],
    needed: usize,
    tolerance: f64,
    /// The orbit the last points lie near, and how many of them.
    near: Option<usize>,
    run: usize,
}

impl<'a> Watch<'a> {
    /// A watch that stops after `needed` consecutive points within
    /// `tolerance` of one of `known`: `None` when there is nothing to
    /// watch (no orbit known, or `needed` 0: early stops off).
    pub fn new(known: &'a [KnownOrbit], needed: usize, tolerance: f64) -> Option<Watch<'a>> {
        (needed > 0 && !known.is_empty()).then_some(Watch {
            known,
            needed,
            tolerance,
            near: None,
            run: 0,
        })
    }

    /// Takes the reference's next point: the known orbit to stop on, once
    /// `needed` consecutive points have been within the tolerance of one of
    /// its points.
    pub fn sees(&mut self, x: &[f64]) -> Option<&'a KnownOrbit> {
        let tolerance = self.tolerance;
        let near = self.known.iter().position(|o| {
            o.points
                .chunks_exact(x.len())
                .any(|y| relative_distance(x, y) <= tolerance)
        });
        match near {
            Some(j) if self.near == Some(j) => self.run += 1,
            Some(_) => self.run = 1,
            None => self.run = 0,
        }
        self.near = near;
        let j = near.filter(|_| self.run >= self.needed)?;
        Some(&self.known[j])
    }
}

/// The result of a lane that stopped early on `orbit` after transient
/// iteration `iteration` (counted from 0, the first), with its points
/// from the start `settling`: the orbit's lane's numbers, its own
/// convergence time and its last `bifurcation_points` points.
pub fn stopped<const D: usize>(
    orbit: &KnownOrbit,
    iteration: usize,
    settling: &Settling<D>,
    tolerance: f64,
    bifurcation_points: usize,
) -> LaneResult {
    LaneResult {
        settled: settling.time(Some(&orbit.points), 0, tolerance),
        bifurcation: settling.last(bifurcation_points),
        jacobians: Vec::new(),
        status: LaneStatus::EarlyStop { iteration },
        ..orbit.result.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::lane::LanePlan;

    fn known(points: Vec<f64>) -> KnownOrbit {
        KnownOrbit {
            points,
            result: LaneResult {
                exponents: vec![-0.05, -0.05],
                impacts_per_period: 0.0,
                crossings_per_period: [0.0; crate::integrate::MAX_EVENTS],
                period: 1.0,
                orbit_period: Some(1),
                orbit: Vec::new(),
                settled: None,
                orbit_term: 0.0,
                bifurcation: Vec::new(),
                jacobians: Vec::new(),
                grazing: 0,
                grazing_bound: 0.0,
                error: 0.0,
                plan: LanePlan {
                    steps_per_period: 10,
                    parts: 1,
                },
                status: LaneStatus::Ok,
            },
        }
    }

    /// Three points in a row near the second orbit stop the lane; a point
    /// away, or one near the other orbit, starts the count again.
    #[test]
    fn consecutive_points_near_one_orbit_stop_the_lane() {
        let orbits = [known(vec![0.0, 0.0]), known(vec![1.0, 1.0, 2.0, 2.0])];
        let mut watch = Watch::new(&orbits, 3, 1e-5).unwrap();
        let near = [1.0 + 5e-6, 1.0];
        let other = [2.0, 2.0 - 1e-5];
        let first = [0.0, 5e-6];
        for x in [near, other, [0.5, 0.5], near, first, near, other] {
            assert!(watch.sees(&x).is_none());
        }
        let stop = watch.sees(&near).unwrap();
        assert_eq!(stop.points, orbits[1].points);
        assert!(Watch::new(&orbits, 0, 1e-5).is_none());
        assert!(Watch::new(&[], 3, 1e-5).is_none());
    }

    /// A stopped lane keeps its own convergence time and last points, the
    /// orbit's numbers and the status that says so.
    #[test]
    fn a_stopped_lane_has_its_own_time_and_the_orbit_s_numbers() {
        let orbit = known(vec![2.0]);
        let mut settling = Settling::<1>::default();
        for x in [5.0, 3.0, 2.0 + 1e-6, 2.0, 2.0] {
            settling.push(&[x]);
        }
        let lane = stopped(&orbit, 3, &settling, 1e-5, 2);
        assert_eq!(lane.settled, Some(2));
        assert_eq!(lane.bifurcation, [2.0, 2.0]);
        assert_eq!(lane.status, LaneStatus::EarlyStop { iteration: 3 });
        assert_eq!(lane.exponents, orbit.result.exponents);
    }
}
