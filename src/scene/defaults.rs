//! The values a scene gets for the keys it leaves out, each with the
//! measurement that chose it.

use crate::error::{Error, Result};

/// Default RK4 steps per map period: the first step count on the measured
/// Pareto front (docs/BENCHMARKS.md) below 1e-8 with newton location and
/// central differences at δ = 1e-6, 2.3e-9 in 0.23 s on the bench's 17
/// values; 1800, the paper's, is 3.7 times slower there for no gain (the
/// seed's scene keeps it, to reproduce the paper). Lanes whose fastest time
/// scale needs more get more (`method::lane::plan_lane`).
pub const DEFAULT_STEPS_PER_PERIOD: usize = 450;
pub const DEFAULT_TRANSIENT: usize = 500;
/// Default `align`: the transient's last tenth, rounded up, so that any
/// transient aligns at least once (a transient of 5 with none left a
/// 20-iteration average of the over-damped oscillator 58% off, the frame's
/// start in it). The frame Q starts from a
/// fixed frame (`method::qr::generic_frame`), and its projection onto the
/// directions of growth stays in the sums of
/// ln R_ii, a bias of O(1/N) over N averaged iterations (3e-4 per unit time
/// on the friction belt at η = 0.6, N = 300); turned by the Jacobians of
/// the transient's last iterations first, the frame starts the window
/// aligned, and on a periodic orbit the bias then vanishes with the
/// window a multiple of the orbit's period. The frame converges at the
/// rate of the gaps between exponents, so a tenth of the default 500 is
/// ample for the gaps this tool meets, for a twentieth of a run's work.
pub const DEFAULT_ALIGN_FRACTION: usize = 10;
pub const DEFAULT_ITERATIONS: usize = 1000;
/// Default δ in f64, for central differences (error O(δ²) against rounding
/// ε·√steps/δ, optimum near ε^(1/3)): on the measured front at 450 to 1800
/// steps (docs/BENCHMARKS.md), 30 to 200 times more accurate on the periodic
/// points than δ = 1e-8. Near-grazing iterations, where a large δ would
/// leave the linear regime, are re-estimated down a ladder of smaller δ
/// (`method::lane::estimate_resolving_grazing`).
pub const DEFAULT_PERTURBATION_F64: f64 = 1e-6;
/// Default δ in f32 (on the GPU, with central differences), relative to
/// max(1, ‖x‖∞) like every δ: the compensated f32 images carry about 1e-7
/// relative error, so δ must be large, and the O(δ²) error of central
/// differences allows it. Measured on lavapipe over 512 η in [0.5, 1.5] of the
/// seed's scene, the largest sum-rule error is 1.5e-4, 6.3e-5, 4.8e-4 and
/// 7.9e-4 at δ = 2e-4, 5e-4, 1e-3 and 2e-3: rounding limits small δ; above
/// 5e-4 a lane of the chaotic window, whose copies graze where the
/// reference does not, limits large δ, and the host re-estimates ever more
/// grazing iterations (93, 381, 813 and 7455). 5e-4's gain did not pay
/// for four times the re-estimations (docs/BENCHMARKS.md, "f32's
/// perturbation δ").
pub const DEFAULT_PERTURBATION_F32: f64 = 2e-4;
/// Default number of sweep values a GPU run recomputes on the CPU.
pub const DEFAULT_VALIDATE: usize = 4;
/// Evenly spaced values when a sweep gives `from` and `to` but no `count`.
pub const DEFAULT_COUNT: usize = 101;

/// A count's value: the scene's, at least 1, or `default`.
pub(super) fn positive(key: &str, value: Option<usize>, default: usize) -> Result<usize> {
    match value {
        Some(0) => Err(Error::invalid(key, "must be at least 1, got 0")),
        Some(v) => Ok(v),
        None => Ok(default),
    }
}
