//! Every attractor at every value: a sweep with many starts per value
//! (`[attractors]`) has its lanes told apart into attractors at each value
//! ([`group`]), each value also started from its neighbours' attractors
//! (continuation), and the attractors matched across values into branches
//! ([`branch`]).
//!
//! Continuation runs in passes over all values at once, so that the lanes
//! of a pass fill the backend together: pass 0 is the scene's own starts;
//! each later pass starts every value from the final states of the
//! attractors that appeared at its neighbours in the pass before, until a
//! pass finds nothing new. A branch that only continuation reaches takes a
//! pass per value it extends over; one the starts already found costs one
//! pass of a lane per neighbour.
//!
//! This module only tells lanes apart and matches them, as pure functions
//! of the lanes' results: [`Found`] takes in each batch of lanes and says
//! which lanes the next pass starts; the driver runs the passes
//! (`crate::driver::continuation`).

pub mod basins;
pub mod branch;
pub mod group;
mod index;

use crate::method::lane::{KnownOrbit, KnownOrbits};
use crate::method::{LaneResult, LaneStatus};
use crate::scene::{Precision, Scene, Seed};
use group::{Member, Rule, ValueAttractors};

/// The attractors of a whole sweep.
#[derive(Clone, Debug)]
pub struct Attractors {
    /// Per point of the grid (first axis fastest), its attractors.
    pub values: Vec<ValueAttractors>,
    /// The scene's starts per value (the continuation seeds come after).
    pub starts: usize,
    /// Branches found.
    pub branches: usize,
    /// Continuation passes run after the scene's starts, and their lanes.
    pub passes: usize,
    pub continued_lanes: usize,
}

impl Attractors {
    /// Values that hold more than one attractor.
    pub fn several(&self) -> usize {
        self.values.iter().filter(|v| v.count() > 1).count()
    }

    /// The branch of the lane that started from `start` at grid point
    /// `point` (`None` for a lone failed lane).
    pub fn branch_of(&self, point: usize, start: usize) -> Option<usize> {
        let value = &self.values[point];
        value
            .of_start
            .get(start)
            .copied()
            .flatten()
            .and_then(|a| value.attractors[a].branch)
    }
}

/// The attractors of a run's lanes held at once (its own lanes, no
/// continuation; `lanes` and their `expected_sums` in the scene's order,
/// computed in `precision`): `None` for a scene without `[attractors]`.
pub fn found_in(
    scene: &Scene,
    lanes: &[LaneResult],
    expected_sums: &[f64],
    precision: Precision,
) -> Option<Attractors> {
    let mut found = Found::new(scene)?;
    found.absorb(scene, lanes, expected_sums, precision);
    Some(found.into_attractors(scene, 0, 0))
}

/// The attractors found so far, value by value: what the continuation
/// passes take each batch of lanes into, and start their next pass from.
pub struct Found {
    values: Vec<ValueAttractors>,
    starts: usize,
    dim: usize,
    /// The attractor each continuation lane was started from, by the
    /// lane's (grid point, start).
    sources: std::collections::HashMap<(usize, usize), (usize, usize)>,
    /// Per grid point, the lanes run in full that found the orbits later
    /// lanes may stop early on ([`Found::known`]), in its order: an
    /// attractor first reached by a lane that stopped early takes its
    /// orbit's lane as its row.
    learned: Vec<Vec<Member>>,
}

impl Found {
    /// None found yet, at any value of `scene` (`None` for a scene without
    /// `[attractors]`).
    pub fn new(scene: &Scene) -> Option<Found> {
        Some(Found {
            values: vec![ValueAttractors::default(); scene.sweep.points()],
            starts: scene.sweep.starts.as_ref()?.states.len(),
            dim: scene.system.dimension(),
            sources: Default::default(),
            learned: Vec::new(),
        })
    }

    /// The periodic orbits found so far that later lanes may stop early on
    /// (see `method::lane::KnownOrbit`), value by value: the attractors
    /// (not lone lanes) whose first lane is `ok` with a period and its
    /// points.
    pub fn known(&self) -> KnownOrbits {
        let per_point = self
            .learnable()
            .map(|members| {
                members
                    .map(|m| KnownOrbit {
                        points: m.lane.orbit.clone(),
                        result: m.lane.clone(),
                    })
                    .collect()
            })
            .collect();
        KnownOrbits { per_point }
    }

    /// The first lanes of [`Found::known`]'s orbits, value by value.
    fn learnable(&self) -> impl Iterator<Item = impl Iterator<Item = &Member>> {
        let dim = self.dim;
        self.values.iter().map(move |value| {
            value
                .attractors
                .iter()
                .filter(move |a| {
                    let lane = &a.first.lane;
                    !a.is_lone()
                        && lane.status == LaneStatus::Ok
                        && lane
                            .orbit_period
                            .is_some_and(|p| p > 0 && lane.orbit.len() == p * dim)
                })
                .map(|a| &a.first)
        })
    }

    /// Takes the orbits `learning` found (its [`Found::known`]) as those
    /// this one's lanes may stop early on; `learning`'s lanes count for
    /// nothing here.
    pub fn learn_from(&mut self, learning: &Found) {
        self.learned = learning
            .learnable()
            .map(|members| members.cloned().collect())
            .collect();
    }

    /// The attractors found, matched into branches.
    pub fn into_attractors(
        mut self,
        scene: &Scene,
        passes: usize,
        continued_lanes: usize,
    ) -> Attractors {
        let n1 = scene.sweep.first.values.len();
        let branches = branch::assign(&mut self.values, n1, self.dim);
        Attractors {
            values: self.values,
            starts: self.starts,
            branches,
            passes,
            continued_lanes,
        }
    }

    /// Adds a batch's lanes (with their expected sums, computed in
    /// `precision`) to their values' attractors; returns the attractors
    /// that are new, as (grid point, index).
    pub fn absorb(
        &mut self,
        batch: &Scene,
        lanes: &[LaneResult],
        expected_sums: &[f64],
        precision: Precision,
    ) -> Vec<(usize, usize)> {
        let rule = Rule::new(self.dim, precision.rounding_unit());
        let mut new = Vec::new();
        for (j, lane) in lanes.iter().enumerate() {
            let point = batch.sweep.point_of(batch.sweep_lane(j));
            let start = batch.lane_start(j);
            // Not a motion: no attractor's row, and no share of the basins.
            if lane.status == LaneStatus::Inadmissible {
                self.values[point].inadmissible.push(start);
                continue;
            }
            let member = Member {
                start,
                lane: LaneResult {
                    bifurcation: Vec::new(),
                    jacobians: Vec::new(),
                    ..lane.clone()
                },
                expected_sum: expected_sums[j],
            };
            let (index, is_new) = self.values[point].join(member, start < self.starts, rule);
            if is_new {
                self.take_learned_row(point, index);
            }
            if let Some(&(from, attractor)) = self.sources.get(&(point, start)) {
                self.values[point].links.push((index, from, attractor));
            }
            if is_new && !self.values[point].attractors[index].is_lone() {
                new.push((point, index));
            }
        }
        new
    }

    /// Where a new attractor's first lane stopped early, the lane run in
    /// full that found its orbit becomes its row (the stopped lane carries
    /// that lane's orbit, to the bit).
    fn take_learned_row(&mut self, point: usize, index: usize) {
        let first = &self.values[point].attractors[index].first;
        if !matches!(first.lane.status, LaneStatus::EarlyStop { .. }) {
            return;
        }
        let learned = self.learned.get(point).and_then(|members| {
            members
                .iter()
                .find(|m| m.lane.orbit == first.lane.orbit)
                .cloned()
        });
        if let Some(learned) = learned {
            self.values[point].attractors[index].first = learned;
        }
    }

    /// The lanes of the next continuation pass: each attractor of
    /// `frontier` started at its neighbours along the first axis (the next
    /// value up, the one before down) from its final state, where that
    /// state may start a lane there.
    pub fn seeds(
        &mut self,
        scene: &Scene,
        frontier: &[(usize, usize)],
        continuation: crate::scene::Continuation,
    ) -> Vec<Seed> {
        let n1 = scene.sweep.first.values.len();
        let states = scene.integration.initial_state.len();
        let mut next_start: Vec<usize> = self.values.iter().map(|v| v.of_start.len()).collect();
        let mut seeds = Vec::new();
        for &(point, index) in frontier {
            let orbit = &self.values[point].attractors[index].first.lane.orbit;
            if orbit.len() < states {
                continue;
            }
            let state = orbit[orbit.len() - states..].to_vec();
            let i = point % n1;
            let up = (continuation.up() && i + 1 < n1).then_some(point + 1);
            let down = (continuation.down() && i > 0).then(|| point - 1);
            for target in up.into_iter().chain(down) {
                let params = scene.params_at_point(target);
                if (scene.system.check_state)(&params, &state).is_err() {
                    continue;
                }
                let start = next_start[target].max(self.starts);
                next_start[target] = start + 1;
                self.sources.insert((target, start), (point, index));
                seeds.push(Seed {
                    point: target,
                    start,
                    state: state.clone(),
                });
            }
        }
        seeds
    }
}
