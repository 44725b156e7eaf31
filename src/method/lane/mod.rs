//! One lane: the whole method for one parameter value.
//!
//! Discard `transient` iterations of the reference, the last `align` of
//! them with their Jacobians, which turn the QR frame from I towards the
//! directions of growth without being counted; then run `iterations`
//! iterations, each giving the next reference point and the map's Jacobian
//! there (estimated from perturbed copies, or exact), and accumulate QR. A
//! lane that goes non-finite stops and says so; it never touches another
//! lane.
//!
//! [`MethodSettings`] is what the backends run: its `transient` is the
//! iterations without Jacobians, and its `iterations` begin with the
//! `align` ones, which [`LaneAccumulator`] takes for the frame alone. Every
//! backend gets the alignment that way, by running the settings it is
//! given.
//!
//! The steps, one file each: `settings` (what every lane shares), `settling` (a lane's convergence time),
//! `early_stop` (a basin image's lane stopped on an attractor already known), `plan`
//! (a lane's steps and sub-maps), `driver` (one lane alone), `lockstep`
//! (neighbouring lanes stepped together), `grazing` (the δ ladder of
//! near-grazing iterations), `accumulator` (the sums and the statuses they
//! decide), `uncertainty` (a lane's error estimate) and `result` (what a
//! lane produces).

mod accumulator;
mod driver;
mod early_stop;
mod grazing;
mod lockstep;
mod orbit;
mod plan;
mod result;
mod settings;
mod settling;
mod uncertainty;

pub use crate::perturbation::perturbation_at;
pub use accumulator::{Failure, LaneAccumulator, RESOLUTION_BOUND};
pub use driver::{estimated_iteration, run_lane, Lane};
pub use early_stop::{KnownOrbit, KnownOrbits};
pub use grazing::{estimate_resolving_grazing, is_grazing, reestimate_of, GRAZING_ERROR};
pub use lockstep::run_lanes;
pub use orbit::{return_tolerance, RecentPoints};
pub use plan::{plan_lane, plan_of, LanePlan, MAX_STEPS_PER_PERIOD, MAX_STEP_RATE};
pub use result::{not_run, LaneResult, LaneStatus};
pub use settings::{difference_noise, MethodSettings, Stop, Tangent};
pub use settling::{attractor_tolerance, Settling};
