//! The perturbation estimate of the map's Jacobian (the paper's eq. 6):
//! column i of DU(x_n) ≈ (U(x_n + δ·e_i) - U(x_n)) / δ.
//!
//! The perturbed copies restart from x_n every iteration, so they never
//! separate far enough to leave the linear regime, and a copy crossing a
//! discontinuity (an impact) needs no special linearisation.

use nalgebra::SMatrix;

use crate::system::{FlowSettings, IterationStats, System};

/// Estimates DU(x) by forward differences, given the reference image U(x).
///
/// The step actually taken is (x_i + δ) - x_i, not δ: the two differ by the
/// rounding of x_i + δ, which would otherwise bias every column by up to
/// ulp(x_i)/δ.
pub fn forward_difference<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    x: &[f64; D],
    image: &[f64; D],
    delta: f64,
    stats: &mut IterationStats,
) -> SMatrix<f64, D, D> {
    let mut jacobian = SMatrix::<f64, D, D>::zeros();
    for i in 0..D {
        let mut shifted = *x;
        shifted[i] += delta;
        let step = shifted[i] - x[i];
        let mut copy_stats = IterationStats::default();
        let moved = system.iterate(&shifted, flow, &mut copy_stats);
        stats.chattering |= copy_stats.chattering;
        for k in 0..D {
            jacobian[(k, i)] = (moved[k] - image[k]) / step;
        }
    }
    jacobian
}
