//! Integrating one map iteration of a flow: classical RK4 with fixed steps,
//! wall impacts located inside the step that crosses the wall, and the
//! closed-form propagator of the impact oscillator that serves as ground truth.

pub mod clock;
pub mod closed_form;
pub mod impact;
pub mod rk4;

pub use impact::{ImpactLocation, Wall};

use crate::system::{FlowSettings, IterationStats};
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
    let steps = settings.steps_per_period;
    let h = period / steps as f64;
    let omega = flow.forcing_frequency();
    let half = cos_sin(0.5 * omega * h);
    let (mut y, mut phase) = (*x, ZERO_PHASE);
    match flow.wall() {
        None => {
            for _ in 0..steps {
                (y, phase) = rk4::step(flow, &phase, &half, &y, h);
            }
        }
        Some(wall) => {
            let location = settings.impact_location;
            for _ in 0..steps {
                (y, phase) =
                    impact::step(flow, &wall, location, omega, &phase, &half, &y, h, stats);
            }
        }
    }
    y
}
