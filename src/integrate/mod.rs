//! Integrating one map iteration of a flow: classical RK4 with fixed steps,
//! wall impacts located inside the step that crosses the wall, and the
//! closed-form propagator of the impact oscillator that serves as ground truth.

pub mod clock;
pub mod closed_form;
pub mod impact;
pub mod rk4;

pub use impact::{ImpactLocation, Wall};

use crate::system::{FlowSettings, IterationStats, Part};
use clock::{cos_sin, Phase, ZERO_PHASE};

/// A flow y' = F(t, y) in D dimensions, possibly forced, possibly with a wall.
///
/// Time enters only through the forcing phase (cos ωt, sin ωt), which every
/// map iteration restarts at ωt = 0 (see [`clock`]): exact for a forcing of
/// period T, and no time variable can drift over long runs.
pub trait Flow<const D: usize>: Sync {
    /// The right-hand side F(t, y), given phase = (cos ωt, sin ωt).
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D];

    /// ω of the forcing; 0 for an autonomous flow.
    fn forcing_frequency(&self) -> f64 {
        0.0
    }

    /// The rigid wall acting on coordinate 0 (position) with coordinate 1 its
    /// velocity, if the system has one.
    fn wall(&self) -> Option<Wall> {
        None
    }
}

/// The time-T map of a flow: `steps` RK4 steps of h = T/steps from t = 0,
/// with every wall impact located and applied inside its step.
pub fn time_map<const D: usize, F: Flow<D>>(
    flow: &F,
    x: &[f64; D],
    period: f64,
    settings: &FlowSettings,
    stats: &mut IterationStats,
) -> [f64; D] {
    let mut ys = [*x];
    time_map_many(flow, &mut ys, period, settings, std::slice::from_mut(stats));
    ys[0]
}

/// [`time_map`] of several trajectories at once (a reference and its
/// perturbed copies), in lockstep: each step's forcing phases are computed
/// once, and the trajectories' independent RK4 chains interleave, which is
/// what keeps a core busy (one chain alone waits on its own latencies). Each
/// trajectory's arithmetic is exactly what it would be alone.
pub fn time_map_many<const D: usize, F: Flow<D>>(
    flow: &F,
    ys: &mut [[f64; D]],
    period: f64,
    settings: &FlowSettings,
    stats: &mut [IterationStats],
) {
    let mut phase = ZERO_PHASE;
    part_map_many(flow, ys, period, settings, Part::WHOLE, &mut phase, stats);
}

/// Part `part` of the time-T map (its share of the period's RK4 steps),
/// from the forcing phase `phase` at the part's start, which it advances to
/// the part's end. The parts of a period, run in order with the phase
/// passed on, do exactly the arithmetic of the whole [`time_map_many`].
pub fn part_map_many<const D: usize, F: Flow<D>>(
    flow: &F,
    ys: &mut [[f64; D]],
    period: f64,
    settings: &FlowSettings,
    part: Part,
    phase: &mut Phase,
    stats: &mut [IterationStats],
) {
    let steps = settings.steps_per_period;
    let h = period / steps as f64;
    let omega = flow.forcing_frequency();
    let half = cos_sin(0.5 * omega * h);
    let wall = flow.wall();
    let location = settings.impact_location;
    for _ in part.steps(steps) {
        let phases = rk4::stage_phases(phase, &half);
        for (y, st) in ys.iter_mut().zip(stats.iter_mut()) {
            if let Some(w) = wall.as_ref().filter(|w| impact::at_rest_on(w, y)) {
                *y = impact::stuck_step(flow, w, location, omega, phase, h, st);
                continue;
            }
            let y1 = rk4::step_at(flow, &phases, y, h);
            *y = match &wall {
                Some(w) if impact::reaches_wall(w, y, &y1) => {
                    impact::resolve(flow, w, location, omega, phase, y, h, y1, st)
                }
                _ => y1,
            };
        }
        *phase = phases[2];
    }
}
