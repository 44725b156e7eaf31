//! A system of map dimension D as the method iterates it: the [`System`]
//! trait, one map iteration x_{n+1} = U(x_n) and what the lane plans it
//! by, with the helpers a flow's [`SystemInfo`](super::SystemInfo) and
//! its lanes are built from.

use nalgebra::SMatrix;

use super::info::Params;
use crate::integrate::clock::Phase;
use crate::integrate::{Flow, FlowSettings, IterationStats, Part};

/// Every coordinate of a map image that does not exist: a Poincaré map's
/// trajectory that never came back to its section within the return bound.
/// Not finite, so the lane fails as on any non-finite point, and
/// [`is_no_return`] tells the two apart for its status.
pub const NO_RETURN: f64 = f64::INFINITY;

/// Whether `x` is the image of no return ([`NO_RETURN`]) rather than a
/// point that blew up.
pub fn is_no_return(x: &[f64]) -> bool {
    !x.is_empty() && x.iter().all(|&v| v == NO_RETURN)
}

/// A system of map dimension `D`.
pub trait System<const D: usize>: Sized + Send + Sync {
    /// Builds the system from checked parameter values.
    fn new(params: &Params) -> Self;

    /// The time T of one map iteration (exponents are per unit time: ln R_ii / T).
    fn period(&self) -> f64;

    /// One map iteration x_{n+1} = U(x_n).
    fn iterate(&self, x: &[f64; D], flow: &FlowSettings, stats: &mut IterationStats) -> [f64; D];

    /// One map iteration of several trajectories (a reference and its
    /// perturbed copies); a flow integrates them in lockstep
    /// ([`crate::integrate::time_map_many`]).
    fn iterate_many(&self, ys: &mut [[f64; D]], flow: &FlowSettings, stats: &mut [IterationStats]) {
        for (y, st) in ys.iter_mut().zip(stats.iter_mut()) {
            *y = self.iterate(y, flow, st);
        }
    }

    /// One map iteration of trajectory k of `systems[k]`, for every k (the
    /// references of neighbouring lanes of a sweep in their transient, or
    /// their references and copies while they average); a flow steps them
    /// as batches across lanes ([`crate::integrate::time_map_lanes`]).
    fn iterate_lanes(
        systems: &[&Self],
        xs: &mut [[f64; D]],
        flow: &FlowSettings,
        stats: &mut [IterationStats],
    ) {
        for ((system, x), st) in systems.iter().zip(xs.iter_mut()).zip(stats) {
            *x = system.iterate(x, flow, st);
        }
    }

    /// Whether neighbouring lanes may average in lockstep, their references
    /// and copies stepped together by [`iterate_lanes`](Self::iterate_lanes)
    /// (`method::lane::run_lanes`): where that gives every trajectory the
    /// bits and statistics [`part_many`](Self::part_many) gives it over the
    /// whole iteration, and runs faster. A time map of a flow whose
    /// divergence is not integrated along the reference does.
    fn averages_across_lanes(&self) -> bool {
        false
    }

    /// [`iterate_many`](Self::iterate_many) for one part of the iteration,
    /// from the forcing phase `phase` at its start (advanced to its end).
    /// Only flows have parts; a map is always whole.
    fn part_many(
        &self,
        ys: &mut [[f64; D]],
        flow: &FlowSettings,
        part: Part,
        _phase: &mut Phase,
        stats: &mut [IterationStats],
    ) {
        assert_eq!(part, Part::WHOLE, "a map iteration has no parts");
        self.iterate_many(ys, flow, stats);
    }

    /// One map iteration (or part of one) with its exact Jacobian, where a
    /// closed form exists (`SystemInfo::has_exact`).
    fn iterate_exact(
        &self,
        _x: &[f64; D],
        _part: Part,
        _stats: &mut IterationStats,
    ) -> Option<([f64; D], SMatrix<f64, D, D>)> {
        None
    }

    /// The largest |eigenvalue| of the flow's linearisation, an estimate
    /// over the region the orbit visits (0 for a map). RK4's step h must
    /// keep h·rate small: stable below 2.78, accurate to a relative 1e-6 in
    /// the fastest exponent near 0.1.
    fn stiffness(&self) -> f64 {
        0.0
    }

    /// An estimate of the fastest contraction rate, -λ_min (0 for a map):
    /// sets how many parts an iteration needs (see [`Part`]).
    fn contraction(&self) -> f64 {
        0.0
    }

    /// One iteration's image with its tangent map pushed onto `factors` as
    /// a product of D×D factors (first applied first), where the system
    /// estimates it itself rather than by the method's perturbed copies
    /// per part (a Poincaré map, see `system::section`); `None` otherwise.
    fn tangent_factors(
        &self,
        _x: &[f64; D],
        _flow: &FlowSettings,
        _delta: f64,
        _difference: crate::perturbation::Difference,
        _stats: &mut IterationStats,
        _factors: &mut Vec<SMatrix<f64, D, D>>,
    ) -> Option<[f64; D]> {
        None
    }

    /// Brings a map point to its canonical form at the end of an iteration:
    /// a model's angles into [-π, π) (see `model::Model::angles`); nothing
    /// for most systems.
    fn wrap(&self, _x: &mut [f64; D]) {}

    /// The map's first point from the scene's initial state: the state
    /// itself, or for a Poincaré map the first crossing of its section from
    /// a point of the flow (NaN where there is none).
    fn start(&self, initial: &[f64], _flow: &FlowSettings) -> [f64; D] {
        crate::array::from_fn(|i| initial[i])
    }

    /// The stiffness and contraction ([`stiffness`](Self::stiffness),
    /// [`contraction`](Self::contraction)) the lane's plan uses, given where
    /// it starts (`initial`, the scene's initial state) and the requested
    /// steps: by default the system's own estimates.
    fn time_scales(&self, _initial: &[f64], _flow: &FlowSettings) -> (f64, f64) {
        (self.stiffness(), self.contraction())
    }

    /// Whether a trajectory may start at y: not behind a wall. A perturbed
    /// copy of a reference within δ of the wall would start behind it.
    fn admits(&self, _y: &[f64; D]) -> bool {
        true
    }
}

/// [`System::iterate_lanes`] of a flow: its time-T maps stepped as one batch.
pub fn time_map_lanes<const D: usize, S: System<D> + Flow<D>>(
    systems: &[&S],
    xs: &mut [[f64; D]],
    flow: &FlowSettings,
    stats: &mut [IterationStats],
) {
    let periods: Vec<f64> = systems.iter().map(|s| s.period()).collect();
    crate::integrate::time_map_lanes(systems, xs, &periods, flow, stats);
}

/// [`SystemInfo::period`](super::SystemInfo::period) from the system's own
/// [`System::period`].
pub fn period_of<const D: usize, S: System<D>>(params: &Params) -> f64 {
    S::new(params).period()
}

/// [`SystemInfo::forcing_frequency`](super::SystemInfo::forcing_frequency)
/// from the flow's own [`Flow::forcing_frequency`].
pub fn forcing_of<const D: usize, S: System<D> + Flow<D>>(params: &Params) -> f64 {
    S::new(params).forcing_frequency()
}
