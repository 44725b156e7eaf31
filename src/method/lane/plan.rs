//! A lane's plan, made from its system's time scales before it runs: the
//! RK4 steps per period and the sub-maps an iteration is cut into.

use crate::system::{Params, System};

use super::settings::MethodSettings;

/// RK4 step times the system's stiffness above which a lane's steps are
/// raised: RK4 is stable up to 2.78, and at 0.1 the fastest mode's
/// per-step growth factor is right to a relative (0.1)⁴/120 ≈ 1e-6.
pub const MAX_STEP_RATE: f64 = 0.1;
/// RK4 steps per map period above which a lane is not run: one lane would
/// take hours (η = 1e-9 of the seed's oscillator, a period of 6e9 natural
/// time units, needs 6e10), and the clock and step counters lose their
/// resolution. Such a lane says `too-many-steps`.
pub const MAX_STEPS_PER_PERIOD: usize = 100_000_000;

/// Relative rounding noise allowed in a part's most contracted column.
/// Its bias in an exponent is about PART_NOISE²/2 per part's time.
const PART_NOISE: f64 = 1e-2;

/// How one lane's iterations are cut, from its system's time scales.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LanePlan {
    /// RK4 steps per period: the requested ones, or more where the
    /// requested step would leave the fastest time scale unresolved (stiff
    /// damping; a natural period far shorter than the forcing period).
    pub steps_per_period: usize,
    /// Parts per iteration (sub-maps, see [`Part`]): enough that the
    /// fastest contraction over one part stays above the finite
    /// difference's rounding noise by a factor 1/`PART_NOISE`.
    pub parts: usize,
}

impl LanePlan {
    /// Whether a lane may run on this plan (see [`MAX_STEPS_PER_PERIOD`]).
    pub fn affordable(&self) -> bool {
        self.steps_per_period <= MAX_STEPS_PER_PERIOD
    }
}

/// The plan of a lane of system `S` (see [`LanePlan`]).
pub fn plan_lane<const D: usize, S: System<D>>(system: &S, settings: &MethodSettings) -> LanePlan {
    let period = system.period();
    let requested = settings.flow.steps_per_period;
    let (stiffness, contraction) = system.time_scales(&settings.initial_state, &settings.flow);
    let needed = (period * stiffness / MAX_STEP_RATE).ceil();
    // A plan over MAX_STEPS_PER_PERIOD is not run (`LanePlan::affordable`);
    // `as` saturates an infinite or overflowing need.
    let steps_per_period = if needed > requested as f64 {
        needed as usize
    } else {
        requested
    };
    let contraction = period * contraction;
    let parts = if let Some(fixed) = settings.submaps {
        fixed.clamp(1, steps_per_period)
    } else if settings.lyapunov && contraction > 0.0 {
        let noise = settings.column_noise(steps_per_period);
        // ln of the contraction one part may have; at least e, so that the
        // parts never outnumber |λ_min|·T.
        let allowed = (PART_NOISE / noise).ln().max(1.0);
        ((contraction / allowed).ceil() as usize).clamp(1, steps_per_period)
    } else {
        1
    };
    LanePlan {
        steps_per_period,
        parts,
    }
}

/// [`plan_lane`] from parameter values (`dispatch::Runner::plan`).
pub fn plan_of<const D: usize, S: System<D>>(
    params: &Params,
    settings: &MethodSettings,
) -> LanePlan {
    plan_lane(&S::new(params), settings)
}
