//! A motion held on an event's surface (a ball locked onto a vibrating
//! table): entering the hold where the event's crossings accumulate or the
//! motion arrives at rest pressed in, the held flow (the free field plus
//! the constraint force that keeps g and ġ at 0), and the release where
//! the field stops pressing.

use crate::integrate::clock::Phase;
use crate::integrate::flow::{EventHoldValues, Flow};
use crate::integrate::iteration::IterationStats;
use crate::integrate::locate::SubStep;
use crate::integrate::surface::{self, Surface};
use crate::integrate::wall::Wall;

/// An impact whose remaining accumulation (the geometric sequence of ever
/// smaller bounces under a force pressing towards the wall) would last less
/// than this fraction of a step is the onset of sticking: the sequence is
/// summed in closed form instead of bounce by bounce.
pub(super) const ACCUMULATION_FRACTION: f64 = 1e-3;

/// Holds a motion at y, at rest on event j's surface, where the free field
/// presses it in: the held state, with the trajectory's region and the
/// iteration's record marked.
pub(super) fn hold_here<const D: usize, F: Flow<D>>(
    base: &F,
    region: &mut u32,
    j: usize,
    phase: &Phase,
    y: &[f64; D],
    stats: &mut IterationStats,
) -> Option<[f64; D]> {
    let pressed = base.event_hold(j, phase, y)?.pressing > 0.0;
    let held = onto_hold(base, j, phase, y).filter(|_| pressed)?;
    *region |= 1 << (surface::HELD + j as u32);
    stats.rank_loss = stats.rank_loss.max(2);
    stats.log_flux = f64::NAN;
    Some(held)
}

/// Whether event j's crossings accumulate after a reset to `after` that
/// came in at rate `approach` (> 0): the rebound leaves at rate r = -ġ⁺
/// against a free g̈ > 0 that brings the motion back after 2r/g̈, each
/// flight shorter by the ratio e = r/approach, all of them within
/// 2r/(g̈(1 - e)), which is below a sliver of the step, as a stop's
/// bounces (`ACCUMULATION_FRACTION`). Never where the flow cannot hold the
/// motion on the surface.
pub(super) fn accumulating<const D: usize, F: Flow<D>>(
    base: &F,
    j: usize,
    phase: &Phase,
    after: &[f64; D],
    approach: f64,
    h: f64,
) -> bool {
    let Some(v) = base.event_hold(j, phase, after) else {
        return false;
    };
    let rebound = -v.rate;
    let e = rebound / approach;
    v.pressing > 0.0
        && (rebound <= 0.0
            || (e < 1.0 && 2.0 * rebound / (v.pressing * (1.0 - e)) < ACCUMULATION_FRACTION * h))
}

/// y moved onto event j's surface with no rate through it (g = 0 along the
/// states the reset leaves, then ġ = 0 along those it changes): the held
/// motion's constraints, kept to rounding at every step. `None` where the
/// surface's rates give no direction to move along.
fn onto_hold<const D: usize, F: Flow<D>>(
    base: &F,
    j: usize,
    phase: &Phase,
    y: &[f64; D],
) -> Option<[f64; D]> {
    let mut y = *y;
    let v = base.event_hold(j, phase, &y)?;
    let w: [f64; D] = crate::array::from_fn(|i| if v.pushed[i] { 0.0 } else { v.gradient[i] });
    let ww: f64 = w.iter().map(|a| a * a).sum();
    if ww > 0.0 {
        for i in 0..D {
            y[i] -= v.g * w[i] / ww;
        }
    }
    let v = base.event_hold(j, phase, &y)?;
    let u = pushing(&v);
    let uu: f64 = u.iter().zip(&v.rate_gradient).map(|(a, b)| a * b).sum();
    if uu == 0.0 {
        return None;
    }
    for i in 0..D {
        y[i] -= v.rate * u[i] / uu;
    }
    Some(y)
}

/// The direction the constraint force of a hold pushes in: ∇ġ on the
/// states the reset changes (for a ball on a table, its velocity).
fn pushing<const D: usize>(v: &EventHoldValues<D>) -> [f64; D] {
    crate::array::from_fn(|i| if v.pushed[i] { v.rate_gradient[i] } else { 0.0 })
}

/// The flow of a motion held on event j's surface: the free field plus
/// the constraint force λ·u along [`pushing`]'s u, λ such that g̈ = 0
/// (ġ stays 0, so g does).
struct HeldOnEvent<'a, F> {
    flow: &'a F,
    j: usize,
}

impl<const D: usize, F: Flow<D>> Flow<D> for HeldOnEvent<'_, F> {
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        let f = self.flow.rhs_in(0, phase, y);
        let Some(v) = self.flow.event_hold(self.j, phase, y) else {
            return f;
        };
        let u = pushing(&v);
        let uu: f64 = u.iter().zip(&v.rate_gradient).map(|(a, b)| a * b).sum();
        let lambda = -v.pressing / uu;
        crate::array::from_fn(|i| f[i] + lambda * u[i])
    }

    fn forcing_frequency(&self) -> f64 {
        self.flow.forcing_frequency()
    }

    fn walls(&self) -> &[Wall] {
        self.flow.walls()
    }
}

/// How a held step ends.
pub(super) enum Hold<const D: usize> {
    /// Still held at the end of the step, at this state.
    Through([f64; D]),
    /// Let go after this offset, at this state (on the surface, the free
    /// field pulling away).
    Releases(f64, [f64; D]),
}

/// Holds a motion on event j's surface (at y, phase `phase`) for up to
/// `h`; where the free field stops pressing it in (g̈ turns negative), the
/// release is located by bisection on the held motion (re-stepped RK4) and
/// taken just past the root, where the field pulls away. Another surface
/// crossed meanwhile is not integrated: the iteration is flagged.
pub(super) fn hold_step<const D: usize, F: Flow<D>>(
    base: &F,
    j: usize,
    omega: f64,
    phase: &Phase,
    y: &[f64; D],
    h: f64,
    stats: &mut IterationStats,
) -> Hold<D> {
    // An iteration with a held phase has forgotten the two directions
    // through the surface (however the phase began: a hold entered in an
    // earlier iteration goes on here), and the volume law does not apply.
    stats.rank_loss = stats.rank_loss.max(2);
    stats.log_flux = f64::NAN;
    let held = HeldOnEvent { flow: base, j };
    let sub = SubStep { flow: &held, omega };
    let at = |s: f64| -> ([f64; D], Phase) {
        let (y1, end) = sub.step(phase, y, s);
        (onto_hold(base, j, &end, &y1).unwrap_or(y1), end)
    };
    let pressing =
        |y: &[f64; D], end: &Phase| base.event_hold(j, end, y).map_or(-1.0, |v| v.pressing);
    let (y1, end) = at(h);
    let others = |end: &Phase, y1: &[f64; D]| {
        let values = base.surface_values(0, end, y1);
        base.surfaces()
            .iter()
            .enumerate()
            .any(|(k, &kind)| k != j && kind == Surface::Event && values.g[k] > 0.0)
            || base.walls().iter().any(|w| w.gap(y1) > 0.0)
    };
    if pressing(&y1, &end) >= 0.0 {
        if others(&end, &y1) {
            stats.chattering = true;
        }
        return Hold::Through(y1);
    }
    // pressing(0) > 0 (held), pressing(h) < 0: bisect to the release.
    let (mut lo, mut hi) = (0.0, h);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        let (ym, em) = at(mid);
        if pressing(&ym, &em) >= 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let (y_free, end) = at(hi);
    if others(&end, &y_free) {
        stats.chattering = true;
    }
    Hold::Releases(hi, y_free)
}
