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
//! event:  S = DR + (F⁺ - DR·F⁻) ∇gᵀ / (∇g·F⁻),
//! switch: S = I + (F⁺ - F⁻) ∇gᵀ / (∇g·F⁻),   det S = (∇g·F⁺) / (∇g·F⁻),
//! ```
//!
//! F⁻ the field before the crossing, F⁺ after it (after the reset R, in the
//! new region). A switch whose new field points back into the surface
//! (∇g·F⁺ of the other sign) starts a Filippov sliding motion, which is
//! not integrated yet: the iteration is flagged (`IterationStats::sliding`).

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

/// ln |det S| of an event's crossing at y (on the surface), its state
/// after the reset `after` with Jacobian `dr`, fields `before_field` (F⁻)
/// and `after_field` (F⁺), gradient `gradient` (∇g). -∞ when the reset
/// collapses a direction (det DR = 0).
pub fn event_log_det<const D: usize>(
    dr: &[[f64; D]; D],
    gradient: &[f64; D],
    before_field: &[f64; D],
    after_field: &[f64; D],
) -> f64 {
    let rate: f64 = (0..D).map(|i| gradient[i] * before_field[i]).sum();
    let s = DMatrix::from_fn(D, D, |i, k| {
        let dr_f: f64 = (0..D).map(|m| dr[i][m] * before_field[m]).sum();
        dr[i][k] + (after_field[i] - dr_f) * gradient[k] / rate
    });
    s.determinant().abs().ln()
}
