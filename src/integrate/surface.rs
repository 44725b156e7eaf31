//! Event surfaces of any shape, g(y) = 0, beyond the walls: events, whose
//! reset maps the state where g crosses 0 from below, and switches, across
//! which the field itself changes (the piecewise-smooth systems of dry
//! friction and piecewise stiffness).
//!
//! A switch splits phase space into regions, one bit per switch (set on the
//! side where its g > 0), and each region has its own smooth field. The
//! integrator never evaluates a side from the raw state inside a step: a
//! trajectory carries its region, every step integrates one region's field
//! ([`InRegion`]), and a step whose end lies across a surface (or whose
//! rate ∇g·F turns inside it, an excursion across and back) is cut at the
//! crossing, located on the integrator's own solution as impacts are
//! (Newton on re-stepped RK4, `impact::newton_in_bracket`).
//!
//! Each crossing multiplies phase-space volume by |det S|, S the saltation
//! matrix, which the sum rule needs (added to `IterationStats::log_flux`):
//!
//! ```text
//! event:  S = DR + (F⁺ - DR·F⁻ - ∂R/∂t) ∇gᵀ / (∇g·F⁻ + ∂g/∂t),
//! switch: S = I + (F⁺ - F⁻) ∇gᵀ / (∇g·F⁻),   det S = (∇g·F⁺) / (∇g·F⁻),
//! ```
//!
//! F⁻ the field before the crossing, F⁺ after it (after the reset R, in the
//! new region).
//!
//! **Sliding.** Where the fields on both sides point into a switch (the
//! rates a = ∇g·F on the negative side and b on the positive side with
//! a > 0 > b), the motion slides on it with Filippov's convex combination
//! F_s = F_a + α(F_b - F_a), α = a/(a - b), which keeps ∇g·F_s = 0: a mass
//! stuck to a belt under dry friction. With the mean rate m = (a + b)/2
//! (the rate without the discontinuity) and the half jump (a - b)/2, the
//! motion slides while |m| < L and leaves towards the side m points to when
//! |m| reaches L. Filippov's L is the half jump itself; a switch's stick
//! limit gives a larger L (static friction above kinetic), and then a
//! trajectory arriving with |m| < L sticks as well. A sliding phase
//! forgets the distance to the surface: the map loses a rank
//! (`IterationStats::rank_loss`), and the volume law does not apply to it
//! (its record becomes NaN).

use nalgebra::DMatrix;

use super::clock::Phase;
use super::{Flow, Wall};

/// General surfaces a flow may have (events and switches together).
pub const MAX_SURFACES: usize = 4;

/// What crossing a surface does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    /// An event: the motion lives where g ≤ 0; where g crosses 0 from
    /// below, the reset maps the state.
    Event,
    /// Switch number `bit` of the field: no reset, the trajectory's region
    /// flips that bit.
    Switch { bit: u32 },
}

/// Region bits from this one up mark a trajectory sliding on a switch:
/// bit `SLIDING + j` for surface j; the bits below are the sides.
pub const SLIDING: u32 = 16;

/// The side bits of a region (what a flow's fields are indexed by).
#[inline(always)]
pub fn sides(region: u32) -> u32 {
    region & ((1 << SLIDING) - 1)
}

/// The surface a trajectory in `region` slides on, if any.
#[inline(always)]
pub fn sliding(region: u32) -> Option<usize> {
    let s = region >> SLIDING;
    (s != 0).then(|| s.trailing_zeros() as usize)
}

/// The region of a trajectory sliding on surface j from `region`'s sides.
pub fn sliding_on(region: u32, j: usize) -> u32 {
    sides(region) | 1 << (SLIDING + j as u32)
}

/// The fields on either side of switch `bit` (its bit cleared, and set)
/// at y, for a trajectory whose other sides are `sides`.
fn either_side<const D: usize, F: Flow<D>>(
    flow: &F,
    sides: u32,
    bit: u32,
    phase: &Phase,
    y: &[f64; D],
) -> ([f64; D], [f64; D]) {
    (
        flow.rhs_in(sides & !(1 << bit), phase, y),
        flow.rhs_in(sides | 1 << bit, phase, y),
    )
}

/// How far a sliding motion on switch j (bit `bit`) at y is from leaving
/// it: (L - m, L + m), the first ≤ 0 where it leaves to the positive side,
/// the second to the negative side (see the module's docs).
pub fn stick_margins<const D: usize, F: Flow<D>>(
    flow: &F,
    sides: u32,
    j: usize,
    bit: u32,
    phase: &Phase,
    y: &[f64; D],
) -> (f64, f64) {
    let (lo, hi) = either_side(flow, sides, bit, phase, y);
    let n = flow.surface_gradient(j, phase, y);
    let a: f64 = (0..D).map(|i| n[i] * lo[i]).sum();
    let b: f64 = (0..D).map(|i| n[i] * hi[i]).sum();
    let m = 0.5 * (a + b);
    let limit = flow.stick_limit(j, y).unwrap_or(0.5 * (a - b));
    (limit - m, limit + m)
}

/// A flow sliding on switch j: Filippov's field F_a + α(F_b - F_a) with
/// α = a/(a - b), whose rate along ∇g is 0.
pub struct Sliding<'a, F> {
    pub flow: &'a F,
    pub sides: u32,
    pub surface: usize,
    pub bit: u32,
}

impl<const D: usize, F: Flow<D>> Flow<D> for Sliding<'_, F> {
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        let (lo, hi) = either_side(self.flow, self.sides, self.bit, phase, y);
        let n = self.flow.surface_gradient(self.surface, phase, y);
        let a: f64 = (0..D).map(|i| n[i] * lo[i]).sum();
        let b: f64 = (0..D).map(|i| n[i] * hi[i]).sum();
        let alpha = a / (a - b);
        std::array::from_fn(|i| lo[i] + alpha * (hi[i] - lo[i]))
    }

    fn forcing_frequency(&self) -> f64 {
        self.flow.forcing_frequency()
    }
}

/// g of every surface at one state, and its rate ∇g·F along a region's
/// field (only the first `surfaces().len()` are meaningful).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfaceValues {
    pub g: [f64; MAX_SURFACES],
    pub rate: [f64; MAX_SURFACES],
}

impl Surface {
    /// The orientation of g for a trajectory in `region`: +1 where the
    /// crossing to watch for is g rising through 0 (an event, or a switch
    /// whose side is the negative one), -1 where it is g falling.
    #[inline]
    pub fn orientation(self, region: u32) -> f64 {
        match self {
            Surface::Switch { bit } if (region >> bit) & 1 == 1 => -1.0,
            _ => 1.0,
        }
    }
}

/// The region of y: bit b set where switch b's g > 0.
pub fn region_of<const D: usize, F: Flow<D>>(flow: &F, phase: &Phase, y: &[f64; D]) -> u32 {
    if flow.surfaces().is_empty() {
        return 0;
    }
    let values = flow.surface_values(0, phase, y);
    let mut region = 0;
    for (j, s) in flow.surfaces().iter().enumerate() {
        if let Surface::Switch { bit } = s {
            if values.g[j] > 0.0 {
                region |= 1 << bit;
            }
        }
    }
    region
}

/// A flow in one region of its switches: the one smooth field a step of
/// that region integrates.
pub struct InRegion<'a, F> {
    pub flow: &'a F,
    pub region: u32,
}

impl<const D: usize, F: Flow<D>> Flow<D> for InRegion<'_, F> {
    #[inline(always)]
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        self.flow.rhs_in(self.region, phase, y)
    }

    fn forcing_frequency(&self) -> f64 {
        self.flow.forcing_frequency()
    }

    fn walls(&self) -> &[Wall] {
        self.flow.walls()
    }
}

/// Whether a step from values `before` to `after` (oriented by the
/// trajectory's region) may cross surface j: its end lies across, or its
/// rate turns from approaching to leaving inside the step.
#[inline]
pub fn may_cross(kind: Surface, region: u32, before: (f64, f64), after: (f64, f64)) -> bool {
    let o = kind.orientation(region);
    o * after.0 > 0.0 || (o * before.1 > 0.0 && o * after.1 < 0.0)
}

/// ln |det S| of an event's crossing: the reset's Jacobian `dr` and rate
/// `reset_rate` (∂R/∂t), the fields `before_field` (F⁻) and `after_field`
/// (F⁺), the surface's gradient ∇g and its rate along F⁻, `rate` = ∇g·F⁻ +
/// ∂g/∂t. -∞ when the reset collapses a direction (det DR = 0).
pub fn event_log_det<const D: usize>(
    dr: &[[f64; D]; D],
    reset_rate: &[f64; D],
    gradient: &[f64; D],
    rate: f64,
    before_field: &[f64; D],
    after_field: &[f64; D],
) -> f64 {
    let s = DMatrix::from_fn(D, D, |i, k| {
        let dr_f: f64 = (0..D).map(|m| dr[i][m] * before_field[m]).sum();
        dr[i][k] + (after_field[i] - dr_f - reset_rate[i]) * gradient[k] / rate
    });
    s.determinant().abs().ln()
}
