//! What one map iteration is, to the integrator: how it is integrated
//! ([`FlowSettings`], [`ImpactLocation`]), which share of it a call takes
//! ([`Part`]), and what happened on the way ([`IterationStats`]). The
//! method reads these; the systems fill them.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use serde::Deserialize;

use super::region::MAX_SURFACES;
use super::wall::MAX_WALLS;

/// Crossings counted apart per iteration: the walls', then the general
/// surfaces' (the output's event columns).
pub const MAX_EVENTS: usize = MAX_WALLS + MAX_SURFACES;

/// Located events (wall impacts, crossings of events and switches) one
/// trajectory may meet in one call of the step loop: a map iteration, or
/// one of its sub-maps where it is cut into parts. Past it the trajectory
/// ends non-finite with [`IterationStats::too_many_events`] set, and its
/// lane stops with `too-many-events(iteration=k)`.
///
/// Why a bound at all: energy pumped in between events faster than they
/// take it out (an impact pair under negative damping, ζ = -3000) shortens
/// the flight between impacts to about -ln(e)/(2|ζ|) without ever putting
/// 64 in one step, so the lane settled at 4.2e5 located impacts per period,
/// ten seconds an iteration, and ran on for hours. Why this value: the
/// shipped scenes average at most 6 events per period (belt-into-stop;
/// measured on every scene's reduced run, `.ci/same-outputs` sizes), and
/// an accumulation of impacts to rest is some hundred (e = 0.8 down to
/// rounding); 1e4 leaves them a wide margin, while a lane past it stops
/// within about a quarter of a second a trajectory (some 25 µs a located
/// event).
pub const MAX_EVENTS_PER_ITERATION: u32 = 10_000;

/// RK4 steps a step loop takes between two looks at [`Stop`]: at most
/// some hundredths of a second of a batch of trajectories (the native
/// loops take some ten nanoseconds a trajectory-step), and a look costs
/// nothing beside them.
pub const STEPS_BETWEEN_STOP_LOOKS: usize = 1 << 16;

/// How one flow iteration is integrated (the part of `[integration]` a system sees).
#[derive(Clone, Debug)]
pub struct FlowSettings {
    pub steps_per_period: usize,
    pub impact_location: ImpactLocation,
    /// The run's stop request: the step loop looks at it as a call begins
    /// and every [`STEPS_BETWEEN_STOP_LOOKS`] steps, and ends the call
    /// where it is set, so that one long iteration does not hold a
    /// stopped run.
    pub stop: Stop,
}

/// A request, from outside a run (a front end's Ctrl-C), that it end early.
/// A stopped run's lanes are not results: the backends return
/// `Error::Stopped` and nothing is written, so an iteration cut short
/// where it was asked is never read.
#[derive(Clone, Debug, Default)]
pub struct Stop(Arc<AtomicBool>);

impl Stop {
    /// Asks every run holding this flag to end.
    pub fn request(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    pub fn requested(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// How the impact time inside a crossing step is found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ImpactLocation {
    /// The paper's recipe: linear interpolation of the state between the two
    /// ends of the crossing step. Error O(h²) in t_c.
    Linear,
    /// Re-step to the event: Newton iteration on s ↦ X(RK4(t, y, s)) - X_w,
    /// started from the root of the cubic Hermite interpolant, so the impact
    /// lies on the RK4 solution itself (error O(h⁴), that of RK4). Also finds
    /// an excursion past the wall between two step ends (the velocity turns
    /// inside the step and RK4 re-stepped to the Hermite peak is beyond the wall).
    #[default]
    Newton,
}

impl ImpactLocation {
    pub fn name(self) -> &'static str {
        match self {
            ImpactLocation::Linear => "linear",
            ImpactLocation::Newton => "newton",
        }
    }
}

/// Part `index` of `count` equal parts of one map iteration: a sub-map.
/// Over a long period a strongly contracting direction shrinks below what a
/// finite difference (or even a product of exact tangent maps) resolves, so
/// the method estimates the map as the composition of its parts, re-seeding
/// the perturbations and accumulating QR at each (see `method::lane`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Part {
    pub index: usize,
    pub count: usize,
}

impl Part {
    pub const WHOLE: Part = Part { index: 0, count: 1 };

    /// This part's share of `total` RK4 steps.
    pub fn steps(&self, total: usize) -> std::ops::Range<usize> {
        total * self.index / self.count..total * (self.index + 1) / self.count
    }

    /// This part's time span within a period (the last one ends at `period` exactly).
    pub fn span(&self, period: f64) -> (f64, f64) {
        let at = |k: usize| {
            if k == self.count {
                period
            } else {
                period * k as f64 / self.count as f64
            }
        };
        (at(self.index), at(self.index + 1))
    }

    /// The parts of one iteration, in order.
    pub fn all(count: usize) -> impl Iterator<Item = Part> {
        (0..count).map(move |index| Part { index, count })
    }
}

/// What happened during one map iteration of one trajectory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationStats {
    /// Wall impacts during the iteration.
    pub impacts: u32,
    /// The crossings of each wall of the flow, in its order, then of each
    /// general surface (events and switches).
    pub crossings: [u32; MAX_EVENTS],
    /// An integration step needed more impacts than the bound allows, or the
    /// mass was pressed into the wall: the iteration is not trustworthy.
    pub chattering: bool,
    /// The trajectory met more than [`MAX_EVENTS_PER_ITERATION`] located
    /// events in the step loop's call: it was ended there, non-finite.
    pub too_many_events: bool,
    /// A sliding motion that is not integrated (a wall or an event met
    /// while sliding, switches whose signs multiply in the field, a stick
    /// limit below Filippov's, or sliding on two switches at once in the
    /// exact propagator): the iteration is not trustworthy.
    pub sliding: bool,
    /// Dimensions the iteration collapsed: 1 after an impact with e = 0 (the
    /// velocity is forgotten), D after sticking (the state on release depends
    /// on the forcing alone). The map's Jacobian then has rank D - rank_loss
    /// and the last rank_loss exponents are -∞.
    pub rank_loss: u32,
    /// Sliding phases the iteration entered (one per switch a motion
    /// began to slide on): each collapses one direction where it
    /// happens, so together they bound the map's rank loss from above
    /// (`rank_loss`, the most switches slid on at once, bounds it from
    /// below; phases one after the other on two switches collapse two
    /// directions where the switches' motions are independent, one where
    /// the flow couples them). See `LaneAccumulator`.
    pub sliding_phases: u32,
    /// The slowest approach speed of the iteration's impacts (infinite
    /// without impacts): a slow impact is near grazing.
    pub slowest_impact: f64,
    /// Of a Jacobian estimate: how far the perturbed copies left the linear
    /// regime, as the largest relative difference between a copy's slowest
    /// impact speed and the reference's (infinite when a column's copies
    /// met the wall a different number of times on both sides), or, for
    /// central differences, the copies' asymmetry |U₊ + U₋ - 2U₀| / |U₊ - U₋|
    /// where that is larger (`jacobian::Copies::difference`). A finite
    /// difference is off by about this fraction (forward) or its square
    /// (central).
    pub nonlinearity: f64,
    /// Of a Jacobian estimate: re-estimated over a ladder of smaller δ
    /// because `nonlinearity` was too large for the Jacobian's conditioning
    /// (a grazing iteration).
    pub grazing: bool,
    /// Of a grazing iteration: the error left in ln R_ii of the chosen
    /// estimate, measured as the change between neighbouring rungs of the
    /// ladder (0 for other iterations).
    pub grazing_error: f64,
    /// The time the iteration took, where it is not the system's period
    /// (a Poincaré section's return time); 0 otherwise.
    pub time: f64,
    /// ln |F_k(start) / F_k(end)| of a section map on state k, plus
    /// ∫ div F dt along the reference where div F depends on the state,
    /// plus ln |det S| of every crossing of a general surface: the
    /// iteration's ln |det| beyond what the system's expected sum has
    /// (the determinant is exp(∫ div F dt)·F_k(start)/F_k(end)·Π det S);
    /// 0 otherwise.
    pub log_flux: f64,
}

impl IterationStats {
    /// Adds a part's statistics to its iteration's.
    pub fn merge(&mut self, part: &IterationStats) {
        self.impacts += part.impacts;
        for (c, p) in self.crossings.iter_mut().zip(part.crossings) {
            *c += p;
        }
        self.chattering |= part.chattering;
        self.too_many_events |= part.too_many_events;
        self.rank_loss = self.rank_loss.max(part.rank_loss);
        self.sliding_phases += part.sliding_phases;
        self.slowest_impact = self.slowest_impact.min(part.slowest_impact);
        self.nonlinearity = self.nonlinearity.max(part.nonlinearity);
        self.grazing |= part.grazing;
        self.grazing_error += part.grazing_error;
        self.time += part.time;
        self.log_flux += part.log_flux;
        self.sliding |= part.sliding;
    }
}

impl Default for IterationStats {
    fn default() -> Self {
        IterationStats {
            impacts: 0,
            crossings: [0; MAX_EVENTS],
            sliding: false,
            chattering: false,
            too_many_events: false,
            rank_loss: 0,
            sliding_phases: 0,
            slowest_impact: f64::INFINITY,
            nonlinearity: 0.0,
            grazing: false,
            grazing_error: 0.0,
            time: 0.0,
            log_flux: 0.0,
        }
    }
}
