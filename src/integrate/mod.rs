//! Integrating one map iteration of a flow: classical RK4 with fixed steps,
//! wall impacts located inside the step that crosses the wall, and the
//! closed-form propagator of the impact oscillator that serves as ground truth.

#[path = "closed_form_stub.rs"]
pub mod closed_form;
pub mod impact;
pub mod rk4;

pub use impact::{ImpactLocation, Wall};

use crate::system::{FlowSettings, IterationStats};

/// A flow y' = F(t, y) in D dimensions, possibly with a wall.
///
/// Time is local to the map iteration: every iteration starts at t = 0, which
/// is exact for a forcing of period T and keeps the forcing phase from
/// drifting over long runs.
pub trait Flow<const D: usize>: Sync {
    /// The right-hand side F(t, y).
    fn rhs(&self, t: f64, y: &[f64; D]) -> [f64; D];

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
    let mut y = *x;
    match flow.wall() {
        None => {
            for k in 0..steps {
                // t from k·h rather than by summation, so no rounding accumulates in it.
                y = rk4::step(flow, k as f64 * h, &y, h);
            }
        }
        Some(wall) => {
            for k in 0..steps {
                y = impact::step(
                    flow,
                    &wall,
                    settings.impact_location,
                    k as f64 * h,
                    &y,
                    h,
                    stats,
                );
            }
        }
    }
    y
}
