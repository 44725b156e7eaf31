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

/// How the Jacobian's columns are differenced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Difference {
    /// The paper's scheme: D copies at x + δe_i; error O(δ).
    #[default]
    Forward,
    /// 2D copies at x ± δe_i; error O(δ²), so δ can be larger against
    /// rounding, which is what f32 needs.
    Central,
}

impl Difference {
    pub fn name(self) -> &'static str {
        match self {
            Difference::Forward => "forward",
            Difference::Central => "central",
        }
    }

    /// Perturbed copies per lane.
    pub fn copies(self, dimension: usize) -> usize {
        match self {
            Difference::Forward => dimension,
            Difference::Central => 2 * dimension,
        }
    }
}

/// Estimates DU(x) by central differences:
/// column i ≈ (U(x + δe_i) - U(x - δe_i)) / (δ⁺ + δ⁻), with the steps
/// δ⁺ = (x_i + δ) - x_i and δ⁻ = x_i - (x_i - δ) actually taken.
///
/// A copy that met the wall a different number of times than the reference
/// (`impacts`) crossed a grazing boundary, where the map is not smooth and
/// its difference is O(1) wrong: that column is then differenced on the
/// other side, one-sided against the reference image.
pub fn central_difference<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    x: &[f64; D],
    image: &[f64; D],
    impacts: u32,
    delta: f64,
    stats: &mut IterationStats,
) -> SMatrix<f64, D, D> {
    let mut jacobian = SMatrix::<f64, D, D>::zeros();
    for i in 0..D {
        let (mut plus, mut minus) = (*x, *x);
        plus[i] += delta;
        minus[i] -= delta;
        let (step_plus, step_minus) = (plus[i] - x[i], x[i] - minus[i]);
        let (mut up_stats, mut down_stats) = (IterationStats::default(), IterationStats::default());
        let up = system.iterate(&plus, flow, &mut up_stats);
        let down = system.iterate(&minus, flow, &mut down_stats);
        stats.chattering |= up_stats.chattering || down_stats.chattering;
        let (same_up, same_down) = (up_stats.impacts == impacts, down_stats.impacts == impacts);
        let (a, b, step) = match (same_up, same_down) {
            (false, true) => (image, &down, step_minus),
            (true, false) => (&up, image, step_plus),
            _ => (&up, &down, step_plus + step_minus),
        };
        for k in 0..D {
            jacobian[(k, i)] = (a[k] - b[k]) / step;
        }
    }
    jacobian
}
