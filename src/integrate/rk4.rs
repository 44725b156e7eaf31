//! The classical fourth-order Runge–Kutta step (the paper's integrator),
//! the reference for the step program that the generated C and WGSL print
//! (`model::ir::integrator`).

use super::clock::{rotate, Phase};

/// What a step here reads of a flow: its right-hand side F(t, y) at
/// forcing phase `phase` = (cos ωt, sin ωt), and its own whole step where
/// it takes one in a single call. Every `Flow` is one (see `flow`), so
/// that the flows' default steps can call the steps here while nothing
/// here depends on the rest of the trait.
pub trait Field<const D: usize> {
    /// F(t, y) ([`Flow::rhs`](super::Flow::rhs)).
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D];

    /// One RK4 step with the stage phases given
    /// ([`Flow::step_one`](super::Flow::step_one)).
    fn step_one(&self, stages: &[Phase; 3], y: &[f64; D], h: f64) -> [f64; D];
}

/// One RK4 step of size h from y at forcing phase `phase` (= ωt), where
/// `half` is the rotation through ωh/2:
/// k1 = F(t, y), k2 = F(t + h/2, y + h/2·k1), k3 = F(t + h/2, y + h/2·k2),
/// k4 = F(t + h, y + h·k3), y + h/6·(k1 + 2k2 + 2k3 + k4).
/// Returns the new state and the phase at t + h. The flow takes the step
/// ([`Flow::step_one`](super::Flow::step_one)): a compiled model in one native call.
#[inline]
pub fn step<const D: usize, F: Field<D> + ?Sized>(
    flow: &F,
    phase: &Phase,
    half: &Phase,
    y: &[f64; D],
    h: f64,
) -> ([f64; D], Phase) {
    let phases = stage_phases(phase, half);
    (flow.step_one(&phases, y, h), phases[2])
}

/// The forcing phases at t, t + h/2 and t + h, shared by every trajectory
/// that takes the same step.
#[inline]
pub fn stage_phases(phase: &Phase, half: &Phase) -> [Phase; 3] {
    let mid = rotate(phase, half);
    let end = rotate(&mid, half);
    [*phase, mid, end]
}

/// One RK4 step with the stage phases given.
#[inline]
pub fn step_at<const D: usize, F: Field<D> + ?Sized>(
    flow: &F,
    phases: &[Phase; 3],
    y: &[f64; D],
    h: f64,
) -> [f64; D] {
    step_with_stages(flow, phases, y, h).0
}

/// [`step_at`], also returning the four stage states the right-hand side
/// was evaluated at (y, y + h/2·k1, y + h/2·k2, y + h·k3): what a quantity
/// integrated along the step by the same RK4 needs (a quadrature riding
/// along, `integrate::advance_integrating`). Unused, they cost nothing.
#[inline]
pub fn step_with_stages<const D: usize, F: Field<D> + ?Sized>(
    flow: &F,
    phases: &[Phase; 3],
    y: &[f64; D],
    h: f64,
) -> ([f64; D], [[f64; D]; 4]) {
    let [start, mid, end] = phases;
    let h2 = 0.5 * h;
    let k1 = flow.rhs(start, y);
    let y2 = axpy(y, h2, &k1);
    let k2 = flow.rhs(mid, &y2);
    let y3 = axpy(y, h2, &k2);
    let k3 = flow.rhs(mid, &y3);
    let y4 = axpy(y, h, &k3);
    let k4 = flow.rhs(end, &y4);
    let sixth = h / 6.0;
    let next = crate::array::from_fn(|i| y[i] + sixth * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]));
    (next, [*y, y2, y3, y4])
}

/// [`step_at`] for W trajectories held as structure of arrays, each with
/// its own step, given the batch's right-hand side `rhs(s, y)` at stage s
/// (0: the step's start, 1: its middle, 2: its end): every trajectory's
/// arithmetic is exactly `step_at`'s.
#[inline(always)]
pub fn step_batch<const D: usize, const W: usize>(
    mut rhs: impl FnMut(usize, &[[f64; W]; D]) -> [[f64; W]; D],
    y: &[[f64; W]; D],
    h: &[f64; W],
) -> [[f64; W]; D] {
    // Plain loops rather than `array::from_fn`, whose closures the
    // compiler may leave out of line (and out of the vectorised code).
    let mut h2 = [0.0; W];
    let mut sixth = [0.0; W];
    for w in 0..W {
        h2[w] = 0.5 * h[w];
        sixth[w] = h[w] / 6.0;
    }
    let axpy = |a: &[f64; W], k: &[[f64; W]; D]| -> [[f64; W]; D] {
        let mut out = *y;
        for i in 0..D {
            for w in 0..W {
                out[i][w] = y[i][w] + a[w] * k[i][w];
            }
        }
        out
    };
    let k1 = rhs(0, y);
    let k2 = rhs(1, &axpy(&h2, &k1));
    let k3 = rhs(1, &axpy(&h2, &k2));
    let k4 = rhs(2, &axpy(h, &k3));
    let mut out = *y;
    for i in 0..D {
        for w in 0..W {
            out[i][w] = y[i][w] + sixth[w] * (k1[i][w] + 2.0 * (k2[i][w] + k3[i][w]) + k4[i][w]);
        }
    }
    out
}

/// y + a·k
#[inline]
fn axpy<const D: usize>(y: &[f64; D], a: f64, k: &[f64; D]) -> [f64; D] {
    crate::array::from_fn(|i| y[i] + a * k[i])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::clock::{cos_sin, ZERO_PHASE};
    use crate::integrate::Flow;

    struct Decay;
    impl Flow<1> for Decay {
        fn rhs(&self, _phase: &Phase, y: &[f64; 1]) -> [f64; 1] {
            [-y[0]]
        }
    }

    #[test]
    fn one_step_is_the_fourth_order_taylor_polynomial() {
        // For y' = -y, RK4's stability function is 1 - h + h²/2 - h³/6 + h⁴/24.
        let h = 0.1_f64;
        let expected = 1.0 - h + h * h / 2.0 - h.powi(3) / 6.0 + h.powi(4) / 24.0;
        let (y, _) = step(&Decay, &ZERO_PHASE, &cos_sin(0.0), &[1.0], h);
        assert!(
            (y[0] - expected).abs() <= 2.0 * f64::EPSILON,
            "{} vs {expected}",
            y[0]
        );
    }

    /// y' = cos(ωt): the forcing alone, integrated through the phase.
    struct Forcing;
    impl Flow<1> for Forcing {
        fn rhs(&self, phase: &Phase, _y: &[f64; 1]) -> [f64; 1] {
            [phase[0]]
        }
    }

    #[test]
    fn the_phase_is_the_forcing_at_the_stage_times() {
        // ∫ cos(ωt) over [0, h] is sin(ωh)/ω; RK4 is Simpson's rule here.
        let (omega, h) = (0.8_f64, 0.05);
        let (y, end) = step(&Forcing, &ZERO_PHASE, &cos_sin(omega * h / 2.0), &[0.0], h);
        let simpson = h / 6.0 * (1.0 + 4.0 * (omega * h / 2.0).cos() + (omega * h).cos());
        assert!((y[0] - simpson).abs() < 1e-17);
        assert!((end[0] - (omega * h).cos()).abs() < 1e-16);
    }
}
