//! What every lane of a sweep shares: the method's settings, and the
//! rounding noise of a finite-difference column they imply.

pub use crate::integrate::Stop;
use crate::system::FlowSettings;

use crate::method::jacobian;

/// Where each iteration's Jacobian comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tangent {
    /// The paper's method: forward differences of perturbed copies.
    FiniteDifference,
    /// The closed-form tangent map (the `exact` backend).
    Exact,
}

/// The settings shared by every lane of a sweep.
#[derive(Clone, Debug)]
pub struct MethodSettings {
    /// Iterations of the reference alone, discarded.
    pub transient: usize,
    /// Iterations with Jacobians: the first `align` of them turn the QR
    /// frame only (the scene's transient's last ones), the others are
    /// averaged.
    pub iterations: usize,
    pub align: usize,
    pub initial_state: Vec<f64>,
    /// δ of the perturbed copies, relative to the state's size: the copies
    /// of x_n start at x_n ± δ·max(1, ‖x_n‖∞)·e_i (see [`perturbation_at`]).
    pub perturbation: f64,
    /// Forward (the paper's) or central differences.
    pub difference: jacobian::Difference,
    /// How an iteration is integrated, with the run's stop request
    /// (`flow.stop`), which every lane's iteration loop looks at, and the
    /// step loop within an iteration: a run ends soon after it.
    pub flow: FlowSettings,
    pub tangent: Tangent,
    /// Whether to compute exponents at all (`[output] lyapunov`).
    pub lyapunov: bool,
    /// How many of the last reference points to keep.
    pub bifurcation_points: usize,
    /// The longest orbit period (in map iterations) a lane is tested for.
    pub max_period: usize,
    /// Whether a lane's result keeps its orbit's last points
    /// ([`LaneResult::orbit`](super::LaneResult)): attractors are told apart
    /// and continued by them, periodic orbits traced from them; other runs
    /// need only the period, and at a
    /// million lanes the points would be most of the memory held.
    pub keep_orbit: bool,
    /// Whether a lane keeps its reference's points from its start for its
    /// convergence time ([`LaneResult::settled`](super::LaneResult)): runs
    /// with basin images (`attractors.basins`).
    pub keep_settling: bool,
    /// Early stops (`attractors.early_stop`): a lane whose reference stays
    /// within the attractor tolerance of a known orbit of its value
    /// (`Lane::known`) for this many consecutive transient iterations
    /// stops and takes that orbit; 0: off.
    pub early_stop: usize,
    /// Parts per iteration when the scene fixes them (else [`plan_lane`]'s).
    pub submaps: Option<usize>,
    /// Whether rounding accumulates over the RK4 steps of an iteration (f64),
    /// or is compensated (the f32 kernels' Kahan update): with the number of
    /// steps, sets the smallest contraction the finite difference resolves.
    pub rounding_accumulates: bool,
    /// Keep every iteration's Jacobian in the result (for comparing backends).
    pub keep_jacobians: bool,
    /// The unit roundoff of the arithmetic the images are computed in
    /// (f64::EPSILON, or f32::EPSILON on the GPU's f32 path).
    pub rounding_unit: f64,
}

impl MethodSettings {
    /// The relative rounding noise of a finite-difference column after
    /// `steps` steps ([`difference_noise`] of an image of size 1): the
    /// steps count only where rounding accumulates.
    pub fn column_noise(&self, steps: usize) -> f64 {
        let steps = if self.rounding_accumulates { steps } else { 1 };
        difference_noise(self.rounding_unit, 1.0, steps, self.perturbation)
    }
}

/// The noise in a finite-difference column: the rounding of an image of
/// size `scale`, accumulated over the `steps` of one iteration, over δ.
/// An R_ii near it is mostly rounding.
pub fn difference_noise(unit: f64, scale: f64, steps: usize, delta: f64) -> f64 {
    unit * scale.max(1.0) * (steps as f64).sqrt() / delta
}
