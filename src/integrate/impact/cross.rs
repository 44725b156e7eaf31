//! Crossing a general surface at a located crossing: an event's reset (or
//! the hold it starts, where its crossings accumulate), a switch's new
//! region (or the sliding it starts, where the fields on both sides hold
//! the motion on it), with the iteration's records: the count, and
//! ln |det S| for the volume law.

use crate::integrate::clock::Phase;
use crate::integrate::flow::Flow;
use crate::integrate::iteration::IterationStats;
use crate::integrate::region::SurfaceValues;
use crate::integrate::surface::{self, Surface};

use super::hold::{accumulating, hold_here};

/// Crosses general surface j of `base` at y (on it, at phase `phase`) for a
/// trajectory in `region`: an event's reset, or a switch's flip of the
/// region; counts it and adds ln |det S| to the iteration's volume record.
/// `None` where the crossing cannot be resolved (the iteration is
/// flagged): a reset that leaves the state on or behind its surface, or a
/// switch into sliding.
pub(super) fn cross<const D: usize, F: Flow<D>>(
    base: &F,
    region: &mut u32,
    j: usize,
    phase: &Phase,
    y: &[f64; D],
    h: f64,
    stats: &mut IterationStats,
) -> Option<[f64; D]> {
    let walls = base.walls().len();
    let kind = base.surfaces()[j];
    let before = base.surface_values(surface::sides(*region), phase, y);
    let approach_rate = if surface::is_sliding(*region) {
        surface::rate_along(base, *region, j, phase, y)
    } else {
        before.rate[j]
    };
    let approach = kind.orientation(*region) * approach_rate;
    stats.slowest_impact = stats.slowest_impact.min(approach);
    stats.crossings[walls + j] += 1;
    match kind {
        Surface::Event => reset(base, region, j, phase, y, h, (&before, approach), stats),
        Surface::Switch { bit } => switch(base, region, j, bit, phase, y, approach_rate, stats),
    }
}

/// Event j's reset at y, met at the surfaces' values `before` with the
/// oriented approach rate `approach`; or the hold that starts there.
#[allow(clippy::too_many_arguments)]
fn reset<const D: usize, F: Flow<D>>(
    base: &F,
    region: &mut u32,
    j: usize,
    phase: &Phase,
    y: &[f64; D],
    h: f64,
    (before, approach): (&SurfaceValues, f64),
    stats: &mut IterationStats,
) -> Option<[f64; D]> {
    let walls = base.walls().len();
    if approach <= 0.0 {
        // Met without approaching it: a bounce too short for the step to
        // resolve (the Hermite never dips below the surface), the motion
        // at rest on it. Pressed in, it is held, as a mass touching a stop
        // at rest sticks.
        if let Some(held) = hold_here(base, region, j, phase, y, stats) {
            stats.crossings[walls + j] -= 1;
            return Some(held);
        }
    }
    let (after, dr, reset_rate) = base.reset(j, phase, y);
    let mut now = base.surface_values(*region, phase, &after);
    // The reset may jump across a switch: what follows is that side's
    // field (F⁺ of the saltation below, the rate leaving).
    let from = *region;
    let to = surface::jumped(base.surfaces(), from, before, &now);
    if to != from {
        now = base.surface_values(to, phase, &after);
    }
    // Back where the motion lives (to the location's tolerance: a reset
    // that does not move g leaves it at the root's rounding) and leaving
    // the surface.
    let scale = y.iter().fold(1.0, |m: f64, v| m.max(v.abs()));
    if !(now.g[j] <= 4.0 * f64::EPSILON * scale && now.rate[j] < 0.0) {
        // The reset does not send the motion back where it lives: an
        // approach at the rate's rounding, pressed in, is a motion at rest
        // on the surface (held); else the iteration cannot be trusted.
        if let Some(held) = hold_here(base, region, j, phase, y, stats) {
            return Some(held);
        }
        stats.chattering = true;
        return None;
    }
    if accumulating(base, j, phase, &after, before.rate[j], h) {
        // The crossings accumulate within a sliver of the step: the motion
        // sticks to the surface, which forgets how far from it and how
        // fast towards it the motion was (two directions), and the volume
        // law no longer applies.
        *region = to;
        if let Some(held) = hold_here(base, region, j, phase, &after, stats) {
            return Some(held);
        }
    }
    *region = to;
    stats.log_flux += surface::event_log_det(
        &dr,
        &reset_rate,
        &base.surface_gradient(j, phase, y),
        before.rate[j],
        &base.rhs_in(from, phase, y),
        &base.rhs_in(to, phase, &after),
    );
    if !stats.log_flux.is_finite() {
        stats.rank_loss = stats.rank_loss.max(1);
    }
    Some(after)
}

/// Switch j (region bit `bit`) met at y with the rate `approach_rate`
/// along the field followed so far: the motion slides on it too, where the
/// fields on its two sides hold it there, else goes to the side whose
/// margin ran out.
#[allow(clippy::too_many_arguments)]
fn switch<const D: usize, F: Flow<D>>(
    base: &F,
    region: &mut u32,
    j: usize,
    bit: u32,
    phase: &Phase,
    y: &[f64; D],
    approach_rate: f64,
    stats: &mut IterationStats,
) -> Option<[f64; D]> {
    let walls = base.walls().len();
    // Whether j holds the motion too, beside the switches it may already
    // slide on.
    let Some((plus, minus)) = surface::joining_margins(base, *region, j, bit, phase, y) else {
        stats.sliding = true;
        return None;
    };
    if plus > 0.0 && minus > 0.0 {
        let joined = surface::sliding_on(*region, j);
        let solvable = surface::equivalent(base, joined, phase, y, false).is_some();
        if !solvable || !surface::separable(base, joined, phase, y) {
            // Sliding surfaces whose controls cannot be told apart, or two
            // signs multiplying in the field (the equivalent control of a
            // multi-affine field): not integrated.
            stats.sliding = true;
            return None;
        }
        // Both fields point into the surface (or the stick limit holds the
        // motion): it slides, and forgets how far from the surface it came,
        // one direction per switch it slides on at once; the volume law no
        // longer applies.
        *region = joined;
        let at_once = surface::sliding_set(joined).count_ones();
        stats.rank_loss = stats.rank_loss.max(at_once);
        stats.sliding_phases += 1;
        stats.log_flux = f64::NAN;
        return Some(*y);
    }
    // Not held: the motion goes to the side whose margin ran out. Where
    // that is the side it is on, it only touched the surface (a tangential
    // exit from sliding met again in rounding): no crossing.
    let to_plus = plus <= minus;
    if to_plus == ((*region >> bit) & 1 == 1) {
        stats.crossings[walls + j] -= 1;
        return Some(*y);
    }
    *region ^= 1 << bit;
    let leaving = surface::rate_along(base, *region, j, phase, y);
    if leaving * approach_rate <= 0.0 {
        // The new field points back, yet the stick limit lets go (a limit
        // below Filippov's): the motion cannot be resolved.
        stats.sliding = true;
        return None;
    }
    // det S = (∇g·F⁺)/(∇g·F⁻).
    stats.log_flux += (leaving / approach_rate).ln();
    Some(*y)
}
