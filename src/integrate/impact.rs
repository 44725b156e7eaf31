//! Crossings inside an RK4 step: wall impacts, and the general surfaces of
//! `integrate::surface` (events, switches, sliding), in one loop.
//!
//! A rigid wall (a stop) at X = X_w acts on one coordinate of a flow (a
//! position X) whose rate is another coordinate (its velocity V = X'),
//! from one side. A step that reaches a wall or crosses a surface is split:
//! integrate to the crossing, apply it (the reset V → -e·V with X = X_w
//! exactly, an event's reset, a switch's new region, or the start of a
//! sliding phase), then integrate the rest of the step, and look again, so
//! several crossings in one step, on one surface or several, work and no
//! step ends behind a wall or integrates across a switch.

use super::clock::{cos_sin, rotate, Phase};
use super::flow::{EventHoldValues, Flow, InRegion};
use super::iteration::{ImpactLocation, IterationStats};
use super::rk4;
use super::surface::{self, Surface};

// A wall as data and the turn bound moved below the `Flow` trait
// (`wall`); here under their old paths, which the generated code and the
// GPU host name.
pub use super::wall::{may_turn_past, Wall, MAX_WALLS, TURN_REACH};

/// More impacts than this inside one RK4 step mean impacts accumulate
/// faster than the accumulation test below catches; the step then stops
/// resolving them and flags the iteration (chattering).
pub const MAX_IMPACTS_PER_STEP: u32 = 64;

/// An impact whose remaining accumulation (the geometric sequence of ever
/// smaller bounces under a force pressing towards the wall) would last less
/// than this fraction of a step is the onset of sticking: the sequence is
/// summed in closed form instead of bounce by bounce.
const ACCUMULATION_FRACTION: f64 = 1e-3;

/// The wall of `walls` that y rests on, if any: the sticking state, X = X_w and V = 0.
#[inline]
pub fn resting_on<const D: usize>(walls: &[Wall], y: &[f64; D]) -> Option<usize> {
    walls
        .iter()
        .position(|w| y[w.coordinate] == w.position && y[w.velocity] == 0.0)
}

/// The acceleration towards the wall of state y (at rest on it) at
/// `phase`: > 0 presses the mass into the wall (it sticks), ≤ 0 lets it
/// leave.
#[inline]
fn pressing<const D: usize, F: Flow<D>>(flow: &F, wall: &Wall, phase: &Phase, y: &[f64; D]) -> f64 {
    wall.side * flow.rhs(phase, y)[wall.velocity]
}

/// The flow with a mass held at rest on a wall: its position and velocity
/// do not move, the other coordinates follow the flow.
struct Held<'a, F> {
    flow: &'a F,
    wall: Wall,
}

impl<const D: usize, F: Flow<D>> Flow<D> for Held<'_, F> {
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        let mut f = self.flow.rhs(phase, y);
        f[self.wall.coordinate] = 0.0;
        f[self.wall.velocity] = 0.0;
        f
    }
}

/// One step of size h from rest on wall `stuck` of `walls`: the mass stays
/// there while the force presses it into the wall (the other coordinates
/// move on) and leaves when the force reverses (the sticking model). The
/// iteration's Jacobian loses the rank of the mass's position and velocity:
/// after release they depend on the forcing, not on where the mass came
/// from (with two coordinates, the whole state).
#[allow(clippy::too_many_arguments)]
pub fn stuck_step<const D: usize, F: Flow<D>>(
    base: &F,
    region: &mut u32,
    stuck: usize,
    location: ImpactLocation,
    omega: f64,
    phase: &Phase,
    y: &[f64; D],
    h: f64,
    stats: &mut IterationStats,
) -> [f64; D] {
    let flow = &InRegion {
        flow: base,
        region: *region,
    };
    let walls = base.walls();
    let wall = &walls[stuck];
    let rest = wall.on_wall(*y, 0.0);
    let at = |s: f64| rotate(phase, &cos_sin(omega * s));
    if pressing(flow, wall, phase, &rest) <= 0.0 {
        // Not pressed: a free departure from rest, like any other step.
        let (y1, _) = rk4::step(flow, phase, &cos_sin(0.5 * omega * h), &rest, h);
        return resolve(base, region, location, omega, phase, &rest, h, y1, stats);
    }
    stats.rank_loss = stats.rank_loss.max(2.min(D as u32));
    let held = Held { flow, wall: *wall };
    // The state held for s into the step (with two coordinates, `rest`
    // itself: RK4 adds zeros).
    let held_for = |s: f64| -> [f64; D] {
        if D == 2 {
            rest
        } else {
            rk4::step(&held, phase, &cos_sin(0.5 * omega * s), &rest, s).0
        }
    };
    let end = held_for(h);
    if pressing(flow, wall, &at(h), &end) > 0.0 {
        return end;
    }
    // The force reverses inside the step: bisect for the release.
    let (mut lo, mut hi) = (0.0, h);
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        if pressing(flow, wall, &at(mid), &held_for(mid)) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= f64::EPSILON * h {
            break;
        }
    }
    let release = at(hi);
    let rest_of_step = h - hi;
    let from = held_for(hi);
    let (y1, _) = rk4::step(
        flow,
        &release,
        &cos_sin(0.5 * omega * rest_of_step),
        &from,
        rest_of_step,
    );
    resolve(
        base,
        region,
        location,
        omega,
        &release,
        &from,
        rest_of_step,
        y1,
        stats,
    )
}

/// One RK4 step of size h from y at forcing phase `phase` (`half` rotates
/// through ωh/2) of a flow with walls alone, with every impact inside it
/// applied. Returns the state and the phase at the end of the step.
#[allow(clippy::too_many_arguments)]
pub fn step<const D: usize, F: Flow<D>>(
    flow: &F,
    location: ImpactLocation,
    omega: f64,
    phase: &Phase,
    half: &Phase,
    y: &[f64; D],
    h: f64,
    stats: &mut IterationStats,
) -> ([f64; D], Phase) {
    debug_assert!(flow.surfaces().is_empty());
    let (y1, end) = rk4::step(flow, phase, half, y, h);
    if !flow.walls().iter().any(|w| reaches_wall(w, y, h, &y1)) {
        return (y1, end);
    }
    let y1 = resolve(flow, &mut 0, location, omega, phase, y, h, y1, stats);
    (y1, end)
}

/// Whether a step of size h from y to y1 may contain an impact: it ends
/// beyond the wall, or the velocity turns inside it within reach of the
/// wall (an excursion between the ends, [`may_turn_past`]).
#[inline]
pub fn reaches_wall<const D: usize>(wall: &Wall, y: &[f64; D], h: f64, y1: &[f64; D]) -> bool {
    let (g0, s0, g1, s1) = (wall.gap(y), wall.speed(y), wall.gap(y1), wall.speed(y1));
    g1 > 0.0 || (s0 > 0.0 && s1 < 0.0 && may_turn_past(g0, s0, g1, s1, h))
}

/// Applies every crossing inside the step [0, h] from (phase, y) of a
/// trajectory in region `region` (which it updates), whose plain RK4 image
/// y1 reaches a wall ([`reaches_wall`]) or a surface
/// ([`surface::may_cross`]), in the order they happen: impacts, event
/// resets, and switches of the field, each located on the RK4 solution of
/// the field in force.
#[allow(clippy::too_many_arguments)]
pub fn resolve<const D: usize, F: Flow<D>>(
    base: &F,
    region: &mut u32,
    location: ImpactLocation,
    omega: f64,
    phase: &Phase,
    y: &[f64; D],
    h: f64,
    y1: [f64; D],
    stats: &mut IterationStats,
) -> [f64; D] {
    let walls = base.walls();
    let surfaces = base.surfaces();
    // Sub-steps from (phase0, y0), `done` into the step.
    let (mut done, mut phase0, mut y0, mut y1) = (0.0, *phase, *y, y1);
    for _ in 0..MAX_IMPACTS_PER_STEP {
        if let Some(j) = surface::held_on(*region) {
            // Held on event j: the rest of the step on its surface, unless
            // the field lets go of the motion inside it.
            match hold_step(base, j, omega, &phase0, &y0, h - done, stats) {
                Hold::Through(y_end) => return y_end,
                Hold::Releases(s, y_free) => {
                    *region &= !(1 << (surface::HELD + j as u32));
                    done += s;
                    phase0 = rotate(&phase0, &cos_sin(omega * s));
                    y0 = y_free;
                    y1 = field_step(base, *region, omega, &phase0, &y0, h - done);
                    continue;
                }
            }
        }
        if surface::is_sliding(*region) {
            // On one switch or several: the rest of the step slides, unless
            // the motion leaves one of them or meets another.
            let (s, y_at) =
                match slide(base, region, location, omega, &phase0, &y0, h - done, stats) {
                    Slid::Through(y_end) => return y_end,
                    Slid::Leaves(s, y_exit) => (s, y_exit),
                    Slid::Meets(k, s, yc) => {
                        let phase_c = rotate(&phase0, &cos_sin(omega * s));
                        match cross(base, region, k, &phase_c, &yc, h, stats) {
                            Some(after) => (s, after),
                            // Not resolved (flagged): the rest of the step in
                            // the field now in force.
                            None => {
                                return field_step(
                                    base,
                                    *region,
                                    omega,
                                    &phase_c,
                                    &yc,
                                    h - done - s,
                                )
                            }
                        }
                    }
                };
            done += s;
            phase0 = rotate(&phase0, &cos_sin(omega * s));
            y0 = y_at;
            if !surface::is_sliding(*region) {
                y1 = field_step(base, *region, omega, &phase0, &y0, h - done);
            }
            continue;
        }
        let flow = &InRegion {
            flow: base,
            region: *region,
        };
        let sub = SubStep { flow, omega };
        let rest = h - done;
        // The first wall or surface met in the rest of the step: its index
        // (walls first), offset and state.
        let mut first: Option<(usize, f64, [f64; D])> = None;
        let mut earliest = |j: usize, hit: Option<(f64, [f64; D])>| {
            if let Some((s, yc)) = hit {
                if first.is_none_or(|(_, earliest, _)| s < earliest) {
                    first = Some((j, s, yc));
                }
            }
        };
        for (j, wall) in walls.iter().enumerate() {
            earliest(
                j,
                match location {
                    ImpactLocation::Linear => locate_linear(wall, &y0, rest, &y1),
                    ImpactLocation::Newton => locate_newton(&sub, wall, &phase0, &y0, rest, &y1),
                },
            );
        }
        if !surfaces.is_empty() {
            let end = rotate(&phase0, &cos_sin(omega * rest));
            let before = base.surface_values(*region, &phase0, &y0);
            let after = base.surface_values(*region, &end, &y1);
            for (j, &kind) in surfaces.iter().enumerate() {
                let o = kind.orientation(*region);
                // At s into the rest of the step: a surface may move with
                // the forcing.
                let at = |s: f64, y: &[f64; D]| {
                    base.surface_values(*region, &rotate(&phase0, &cos_sin(omega * s)), y)
                };
                let distance = |s: f64, y: &[f64; D]| o * at(s, y).g[j];
                let rate = |s: f64, y: &[f64; D]| o * at(s, y).rate[j];
                let (start, end) = (
                    (o * before.g[j], o * before.rate[j]),
                    (o * after.g[j], o * after.rate[j]),
                );
                // A turn out of reach of the surface cannot cross it (as
                // the step loops find, `surface::may_cross`).
                if end.0 <= 0.0 && !may_turn_past(start.0, start.1, end.0, end.1, rest) {
                    continue;
                }
                earliest(
                    walls.len() + j,
                    locate(
                        &sub,
                        location,
                        &phase0,
                        &y0,
                        rest,
                        &y1,
                        start,
                        end,
                        kind == Surface::Event,
                        distance,
                        rate,
                    ),
                );
            }
        }
        let Some((j, s, yc)) = first else {
            return y1;
        };
        let phase_c = rotate(&phase0, &cos_sin(omega * s));
        done += s;
        if j >= walls.len() {
            // A general surface.
            let j = j - walls.len();
            match cross(base, region, j, &phase_c, &yc, h, stats) {
                Some(after) => {
                    phase0 = phase_c;
                    y0 = after;
                    if surface::is_constrained(*region) {
                        // The loop's top slides, or holds, the rest of
                        // the step.
                        continue;
                    }
                    let flow = &InRegion {
                        flow: base,
                        region: *region,
                    };
                    y1 = rk4::step(
                        flow,
                        &phase0,
                        &cos_sin(0.5 * omega * (h - done)),
                        &y0,
                        h - done,
                    )
                    .0;
                    continue;
                }
                // Not resolved (flagged): the rest of the step in the field now in force.
                None => {
                    let flow = &InRegion {
                        flow: base,
                        region: *region,
                    };
                    return rk4::step(
                        flow,
                        &phase_c,
                        &cos_sin(0.5 * omega * (h - done)),
                        &yc,
                        h - done,
                    )
                    .0;
                }
            }
        }
        let wall = &walls[j];
        let speed = wall.speed(&yc);
        if speed <= 0.0 {
            // Reaching the wall without approaching it: the mass arrives at
            // rest, pressed into the wall. It sticks.
            return stuck_step(
                base,
                region,
                j,
                location,
                omega,
                &phase_c,
                &yc,
                h - done,
                stats,
            );
        }
        stats.slowest_impact = stats.slowest_impact.min(speed);
        stats.impacts += 1;
        stats.crossings[j] += 1;
        let rebound = wall.restitution * speed;
        let push = pressing(
            &flow_in(base, *region),
            wall,
            &phase_c,
            &wall.on_wall(yc, 0.0),
        );
        // e = 0 stops the mass dead; a rebound whose bounces accumulate (the
        // flight time 2v/a shrinks by e each bounce, summing to
        // 2v/(a(1 - e))) within a sliver of the step ends at rest as well.
        if rebound == 0.0
            || (push > 0.0
                && 2.0 * rebound / (push * (1.0 - wall.restitution)) < ACCUMULATION_FRACTION * h)
        {
            stats.rank_loss = stats.rank_loss.max(1);
            return stuck_step(
                base,
                region,
                j,
                location,
                omega,
                &phase_c,
                &yc,
                h - done,
                stats,
            );
        }
        phase0 = phase_c;
        y0 = wall.on_wall(yc, -rebound);
        if !surfaces.is_empty() {
            // The rebound may jump across a switch (a velocity reversed
            // across a friction's slip): the field after it is that side's.
            *region = surface::jumped(
                surfaces,
                *region,
                &base.surface_values(*region, &phase0, &yc),
                &base.surface_values(*region, &phase0, &y0),
            );
        }
        y1 = SubStep {
            flow: &flow_in(base, *region),
            omega,
        }
        .step(&phase0, &y0, h - done)
        .0;
    }
    // Bounces this dense under a force pressing into the wall are a mass
    // effectively at rest (with e = 1 and damping their heights shrink only
    // harmonically, never summing to a finite time): it sticks. Otherwise
    // the iteration cannot be trusted.
    for (j, wall) in walls.iter().enumerate() {
        if y0[wall.coordinate] == wall.position
            && pressing(
                &flow_in(base, *region),
                wall,
                &phase0,
                &wall.on_wall(y0, 0.0),
            ) > 0.0
        {
            return stuck_step(
                base,
                region,
                j,
                location,
                omega,
                &phase0,
                &y0,
                h - done,
                stats,
            );
        }
    }
    stats.chattering = true;
    walls.iter().fold(y1, |y, w| clamp_to_wall(w, y))
}

fn flow_in<F>(flow: &F, region: u32) -> InRegion<'_, F> {
    InRegion { flow, region }
}

/// Crosses general surface j of `base` at y (on it, at phase `phase`) for a
/// trajectory in `region`: an event's reset, or a switch's flip of the
/// region; counts it and adds ln |det S| to the iteration's volume record.
/// `None` where the crossing cannot be resolved (the iteration is
/// flagged): a reset that leaves the state on or behind its surface, or a
/// switch into sliding.
fn cross<const D: usize, F: Flow<D>>(
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
        Surface::Event => {
            if approach <= 0.0 {
                // Met without approaching it: a bounce too short for the
                // step to resolve (the Hermite never dips below the
                // surface), the motion at rest on it. Pressed in, it is
                // held, as a mass touching a stop at rest sticks.
                if let Some(held) = hold_here(base, region, j, phase, y, stats) {
                    stats.crossings[walls + j] -= 1;
                    return Some(held);
                }
            }
            let (after, dr, reset_rate) = base.reset(j, phase, y);
            let mut now = base.surface_values(*region, phase, &after);
            // The reset may jump across a switch: what follows is that
            // side's field (F⁺ of the saltation below, the rate leaving).
            let from = *region;
            let to = surface::jumped(base.surfaces(), from, &before, &now);
            if to != from {
                now = base.surface_values(to, phase, &after);
            }
            // Back where the motion lives (to the location's tolerance:
            // a reset that does not move g leaves it at the root's
            // rounding) and leaving the surface.
            let scale = y.iter().fold(1.0, |m: f64, v| m.max(v.abs()));
            if !(now.g[j] <= 4.0 * f64::EPSILON * scale && now.rate[j] < 0.0) {
                // The reset does not send the motion back where it lives:
                // an approach at the rate's rounding, pressed in, is a
                // motion at rest on the surface (held); else the
                // iteration cannot be trusted.
                if let Some(held) = hold_here(base, region, j, phase, y, stats) {
                    return Some(held);
                }
                stats.chattering = true;
                return None;
            }
            if accumulating(base, j, phase, &after, before.rate[j], h) {
                // The crossings accumulate within a sliver of the step: the
                // motion sticks to the surface, which forgets how far from
                // it and how fast towards it the motion was (two
                // directions), and the volume law no longer applies.
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
        Surface::Switch { bit } => {
            // Whether j holds the motion too, beside the switches it may
            // already slide on.
            let Some((plus, minus)) = surface::joining_margins(base, *region, j, bit, phase, y)
            else {
                stats.sliding = true;
                return None;
            };
            if plus > 0.0 && minus > 0.0 {
                let joined = surface::sliding_on(*region, j);
                let solvable = surface::equivalent(base, joined, phase, y, false).is_some();
                if !solvable || !surface::separable(base, joined, phase, y) {
                    // Sliding surfaces whose controls cannot be told
                    // apart, or two signs multiplying in the field (the
                    // equivalent control of a multi-affine field): not
                    // integrated.
                    stats.sliding = true;
                    return None;
                }
                // Both fields point into the surface (or the stick limit
                // holds the motion): it slides, and forgets how far from
                // the surface it came, one direction per switch it slides
                // on at once; the volume law no longer applies.
                *region = joined;
                let at_once = surface::sliding_set(joined).count_ones();
                stats.rank_loss = stats.rank_loss.max(at_once);
                stats.sliding_phases += 1;
                stats.log_flux = f64::NAN;
                return Some(*y);
            }
            // Not held: the motion goes to the side whose margin ran out.
            // Where that is the side it is on, it only touched the surface
            // (a tangential exit from sliding met again in rounding): no
            // crossing.
            let to_plus = plus <= minus;
            if to_plus == ((*region >> bit) & 1 == 1) {
                stats.crossings[walls + j] -= 1;
                return Some(*y);
            }
            *region ^= 1 << bit;
            let leaving = surface::rate_along(base, *region, j, phase, y);
            if leaving * approach_rate <= 0.0 {
                // The new field points back, yet the stick limit lets go
                // (a limit below Filippov's): the motion cannot be resolved.
                stats.sliding = true;
                return None;
            }
            // det S = (∇g·F⁺)/(∇g·F⁻).
            stats.log_flux += (leaving / approach_rate).ln();
            Some(*y)
        }
    }
}

/// Holds a motion at y, at rest on event j's surface, where the free field
/// presses it in: the held state, with the trajectory's region and the
/// iteration's record marked.
fn hold_here<const D: usize, F: Flow<D>>(
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
fn accumulating<const D: usize, F: Flow<D>>(
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
    let w: [f64; D] = std::array::from_fn(|i| if v.pushed[i] { 0.0 } else { v.gradient[i] });
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
    std::array::from_fn(|i| if v.pushed[i] { v.rate_gradient[i] } else { 0.0 })
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
        std::array::from_fn(|i| f[i] + lambda * u[i])
    }

    fn forcing_frequency(&self) -> f64 {
        self.flow.forcing_frequency()
    }

    fn walls(&self) -> &[Wall] {
        self.flow.walls()
    }
}

/// How a held step ends.
enum Hold<const D: usize> {
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
fn hold_step<const D: usize, F: Flow<D>>(
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

/// One RK4 step of s from (phase, y) in the field a trajectory in
/// `region` follows: its region's, or the sliding field.
fn field_step<const D: usize, F: Flow<D>>(
    base: &F,
    region: u32,
    omega: f64,
    phase: &Phase,
    y: &[f64; D],
    s: f64,
) -> [f64; D] {
    if surface::is_sliding(region) {
        let flow = &surface::Sliding::new(base, region);
        SubStep { flow, omega }.step(phase, y, s).0
    } else {
        SubStep {
            flow: &flow_in(base, region),
            omega,
        }
        .step(phase, y, s)
        .0
    }
}

/// How a sliding sub-step ended ([`slide`]).
enum Slid<const D: usize> {
    /// Still sliding at the end of the step, at this state.
    Through([f64; D]),
    /// Left a switch (its region updated) after this offset, at this state.
    Leaves(f64, [f64; D]),
    /// Met switch k, which it does not slide on, after this offset, at
    /// this state (on k's surface), still sliding on the others.
    Meets(usize, f64, [f64; D]),
}

/// Slides on the switches of `region`'s sliding set (a trajectory on
/// their surfaces at y, phase `phase`) for up to `h`, along the
/// equivalent control's field ([`surface::Equivalent`]). Another switch
/// met on the way is located as any crossing is (on RK4 re-stepped along
/// the sliding field) and handed back; an exit (a stick margin of a
/// sliding switch reaching 0) before it is bisected on the same re-steps,
/// and the region leaves that switch to the side whose margin ran out,
/// the others still sliding.
#[allow(clippy::too_many_arguments)]
fn slide<const D: usize, F: Flow<D>>(
    base: &F,
    region: &mut u32,
    location: ImpactLocation,
    omega: f64,
    phase: &Phase,
    y: &[f64; D],
    h: f64,
    stats: &mut IterationStats,
) -> Slid<D> {
    let (sides, set) = (surface::sides(*region), surface::sliding_set(*region));
    let surfaces = base.surfaces();
    let sliding = surface::Sliding::new(base, *region);
    let sub = SubStep {
        flow: &sliding,
        omega,
    };
    let phase_at = |s: f64| rotate(phase, &cos_sin(omega * s));
    let margins = |phase_s: &Phase, y_s: &[f64; D]| {
        surface::equivalent_on(base, &sliding.set, phase_s, y_s, true)
            .map_or([(f64::NAN, f64::NAN); surface::MAX_SURFACES], |e| e.margins)
    };
    let at = |s: f64| -> ([f64; D], [(f64, f64); surface::MAX_SURFACES]) {
        let y_s = sub.step(phase, y, s).0;
        (y_s, margins(&phase_at(s), &y_s))
    };
    // Every sliding switch still held.
    let holds = |m: &[(f64, f64); surface::MAX_SURFACES]| {
        (0..surfaces.len())
            .filter(|&j| set >> j & 1 == 1)
            .all(|j| m[j].0 > 0.0 && m[j].1 > 0.0)
    };
    let (end, end_margins) = at(h);
    // An event or a wall met while sliding would need a motion along the
    // surfaces and into them at once, which is not integrated: the
    // iteration says so rather than step through it.
    let end_phase = phase_at(h);
    let (before, after) = (
        base.surface_values(sides, phase, y),
        base.surface_values(sides, &end_phase, &end),
    );
    // The first other switch met, located on the sliding field.
    let mut first: Option<(usize, f64, [f64; D])> = None;
    let others = surfaces
        .iter()
        .enumerate()
        .filter(|&(k, _)| set >> k & 1 == 0);
    for (k, &kind) in others {
        let o = kind.orientation(sides);
        if kind == Surface::Event {
            if o * before.g[k] <= 0.0 && o * after.g[k] > 0.0 {
                stats.sliding = true;
            }
            continue;
        }
        let distance = |s: f64, y: &[f64; D]| o * base.surface_values(sides, &phase_at(s), y).g[k];
        let rate =
            |s: f64, y: &[f64; D]| o * surface::rate_along(base, *region, k, &phase_at(s), y);
        let (start, stop) = (
            (o * before.g[k], rate(0.0, y)),
            (o * after.g[k], rate(h, &end)),
        );
        if !(stop.0 > 0.0 || (start.1 > 0.0 && stop.1 < 0.0)) {
            continue;
        }
        let hit = locate(
            &sub, location, phase, y, h, &end, start, stop, false, distance, rate,
        );
        if let Some((s, yc)) = hit {
            if first.is_none_or(|(_, earliest, _)| s < earliest) {
                first = Some((k, s, yc));
            }
        }
    }
    if base.walls().iter().any(|w| w.gap(&end) > 0.0) {
        stats.sliding = true;
    }
    let (horizon, state, margins_there) = match first {
        Some((_, s, yc)) => (s, yc, margins(&phase_at(s), &yc)),
        None => (h, end, end_margins),
    };
    if holds(&margins_there) {
        return match first {
            Some((k, s, yc)) => Slid::Meets(k, s, yc),
            None => Slid::Through(end),
        };
    }
    let (mut lo, mut hi) = (0.0, horizon);
    let (mut exit, mut m) = (state, margins_there);
    while hi - lo > f64::EPSILON * h {
        let mid = 0.5 * (lo + hi);
        let (y_mid, m_mid) = at(mid);
        if holds(&m_mid) {
            lo = mid;
        } else {
            (hi, exit, m) = (mid, y_mid, m_mid);
        }
    }
    // It leaves the switch whose margin ran out (the most out, where two
    // did within the bisection), to the side whose margin that is.
    let (j, bit) = surfaces
        .iter()
        .enumerate()
        .filter_map(|(j, s)| match s {
            Surface::Switch { bit } if set >> j & 1 == 1 => Some((j, *bit)),
            _ => None,
        })
        .min_by(|&(p, _), &(q, _)| {
            let out = |j: usize| {
                if m[j].0.is_nan() {
                    f64::NEG_INFINITY
                } else {
                    m[j].0.min(m[j].1)
                }
            };
            out(p).total_cmp(&out(q))
        })
        .expect("a sliding trajectory slides on a switch");
    *region = surface::leaving(*region, j, bit, m[j].0 <= m[j].1);
    Slid::Leaves(hi, exit)
}

/// Locates the crossing of a general surface inside the step [0, h] from
/// (phase0, y0) to y1, given its oriented distance and rate (> 0 beyond
/// and approaching) at both ends, as [`locate_newton`] locates an impact:
/// the root of the Hermite interpolant, then Newton on re-stepped RK4; an
/// excursion across and back inside the step is found at the Hermite peak.
#[allow(clippy::too_many_arguments)]
fn locate<const D: usize, F: Flow<D>>(
    sub: &SubStep<F>,
    location: ImpactLocation,
    phase0: &Phase,
    y0: &[f64; D],
    h: f64,
    y1: &[f64; D],
    start: (f64, f64),
    end: (f64, f64),
    rebounding: bool,
    distance: impl Fn(f64, &[f64; D]) -> f64,
    rate: impl Fn(f64, &[f64; D]) -> f64,
) -> Option<(f64, [f64; D])> {
    if location == ImpactLocation::Linear {
        if end.0 <= 0.0 {
            return None;
        }
        let theta = (-start.0 / (end.0 - start.0)).clamp(0.0, 1.0);
        return Some((
            theta * h,
            std::array::from_fn(|i| y0[i] + theta * (y1[i] - y0[i])),
        ));
    }
    let hermite = Hermite::new(start.0, start.1, end.0, end.1, h);
    let scale = y0.iter().fold(1.0, |m: f64, v| m.max(v.abs()));
    if rebounding && end.0 > 0.0 && start.0 >= 0.0 && start.1 < 0.0 {
        // Just reset onto an event's surface (g at its rounding, ≥ 0) and
        // leaving it, the motion comes back within the step (a bounce
        // shorter than a step, as bounces accumulating are): the crossing
        // from below is the one after the trough, not the rounding at 0.
        let trough = Hermite::new(-start.0, -start.1, -end.0, -end.1, h).peak()?;
        if hermite.value(trough) >= 0.0 {
            // No flight at all: it meets the surface at once, at rest
            // relative to it (its crossings accumulate there).
            let s = trough * h;
            return Some((s, sub.step(phase0, y0, s).0));
        }
        return Some(newton_from(
            |s| sub.step(phase0, y0, s).0,
            distance,
            rate,
            scale,
            trough * h,
            h,
            hermite.first_root(trough, 1.0) * h,
        ));
    }
    let (hi, guess) = if end.0 > 0.0 {
        (h, hermite.first_root(0.0, 1.0))
    } else if start.1 > 0.0 && end.1 < 0.0 {
        // An excursion no deeper than the location's own tolerance is a
        // touch in rounding (a motion leaving a sliding surface
        // tangentially), not a crossing.
        let peak = hermite.peak()?;
        if distance(peak * h, &sub.step(phase0, y0, peak * h).0) <= 4.0 * f64::EPSILON * scale {
            return None;
        }
        (peak * h, hermite.first_root(0.0, peak))
    } else {
        return None;
    };
    Some(newton_in_bracket(
        |s| sub.step(phase0, y0, s).0,
        distance,
        rate,
        scale,
        hi,
        guess * h,
    ))
}

/// RK4 steps of any size s from a given phase: the re-steps of impact location.
struct SubStep<'a, F> {
    flow: &'a F,
    omega: f64,
}

impl<F> SubStep<'_, F> {
    fn step<const D: usize>(&self, phase: &Phase, y: &[f64; D], s: f64) -> ([f64; D], Phase)
    where
        F: Flow<D>,
    {
        rk4::step(self.flow, phase, &cos_sin(0.5 * self.omega * s), y, s)
    }
}

fn clamp_to_wall<const D: usize>(wall: &Wall, y: [f64; D]) -> [f64; D] {
    if wall.gap(&y) > 0.0 {
        wall.on_wall(y, wall.speed(&y).min(0.0))
    } else {
        y
    }
}

/// The paper's location: the crossing fraction of a straight line between the
/// step's ends, and the state interpolated linearly there.
fn locate_linear<const D: usize>(
    wall: &Wall,
    y0: &[f64; D],
    h: f64,
    y1: &[f64; D],
) -> Option<(f64, [f64; D])> {
    if wall.gap(y1) <= 0.0 {
        return None;
    }
    let c = wall.coordinate;
    let theta = ((wall.position - y0[c]) / (y1[c] - y0[c])).clamp(0.0, 1.0);
    Some((
        theta * h,
        std::array::from_fn(|i| y0[i] + theta * (y1[i] - y0[i])),
    ))
}

/// Re-steps RK4 from (phase0, y0) to the impact: returns the offset s into
/// the step and the state RK4 reaches there, X(s) = X_w to rounding.
fn locate_newton<const D: usize, F: Flow<D>>(
    sub: &SubStep<F>,
    wall: &Wall,
    phase0: &Phase,
    y0: &[f64; D],
    h: f64,
    y1: &[f64; D],
) -> Option<(f64, [f64; D])> {
    let hermite = Hermite::new(
        wall.gap(y0),
        wall.speed(y0),
        wall.gap(y1),
        wall.speed(y1),
        h,
    );
    // The bracket [lo, hi] of s: g(lo) <= 0 < g(hi), g(s) = the gap of RK4(y0, s).
    let (hi, guess) = if wall.gap(y1) > 0.0 {
        (h, hermite.first_root(0.0, 1.0))
    } else if wall.speed(y0) > 0.0
        && wall.speed(y1) < 0.0
        && may_turn_past(
            wall.gap(y0),
            wall.speed(y0),
            wall.gap(y1),
            wall.speed(y1),
            h,
        )
    {
        // Both ends short of the wall, but the velocity turns inside the
        // step within reach of it: an excursion past the wall in between is
        // a (near-grazing) impact. The Hermite interpolant locates the peak
        // well (X is flat there) but its value is off by O(h⁴); RK4 decides
        // whether the peak is beyond the wall.
        let peak = hermite.peak()?;
        if wall.gap(&sub.step(phase0, y0, peak * h).0) <= 0.0 {
            return None;
        }
        (peak * h, hermite.first_root(0.0, peak))
    } else {
        return None;
    };
    Some(newton_in_bracket(
        |s| sub.step(phase0, y0, s).0,
        |_, y| wall.gap(y),
        |_, y| wall.speed(y),
        wall.position,
        hi,
        guess * h,
    ))
}

/// Safeguarded Newton on a crossing: g(s) = distance(at(s)), with g'(s) ≈
/// rate(at(s)), in the bracket [0, hi] from s, bisecting whenever Newton
/// would leave the bracket; g is resolved to 4 ulp of `scale` (where the
/// surface lies). `at(s)` is RK4 re-stepped from the step's start, so the
/// crossing lies on the integrator's own solution. The impact's and the
/// Poincaré section's location.
pub(crate) fn newton_in_bracket<const D: usize>(
    at: impl Fn(f64) -> [f64; D],
    distance: impl Fn(f64, &[f64; D]) -> f64,
    rate: impl Fn(f64, &[f64; D]) -> f64,
    scale: f64,
    hi: f64,
    s: f64,
) -> (f64, [f64; D]) {
    newton_from(at, distance, rate, scale, 0.0, hi, s)
}

/// [`newton_in_bracket`] in the bracket [lo, hi].
fn newton_from<const D: usize>(
    at: impl Fn(f64) -> [f64; D],
    distance: impl Fn(f64, &[f64; D]) -> f64,
    rate: impl Fn(f64, &[f64; D]) -> f64,
    scale: f64,
    mut lo: f64,
    mut hi: f64,
    mut s: f64,
) -> (f64, [f64; D]) {
    let tolerance = 4.0 * f64::EPSILON * scale.abs().max(1.0);
    let mut y = at(s);
    for _ in 0..32 {
        let g = distance(s, &y);
        if g.abs() <= tolerance {
            break;
        }
        if g > 0.0 {
            hi = s;
        } else {
            lo = s;
        }
        let newton = s - g / rate(s, &y);
        s = if newton > lo && newton < hi && newton.is_finite() {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo <= f64::EPSILON * hi.abs() {
            break;
        }
        y = at(s);
    }
    (s, y)
}

/// The cubic Hermite interpolant of g = X - X_w over one step, in θ ∈ [0, 1],
/// from the values and derivatives (velocities) at both ends.
pub(crate) struct Hermite {
    c: [f64; 4],
}

impl Hermite {
    pub(crate) fn new(g0: f64, v0: f64, g1: f64, v1: f64, h: f64) -> Self {
        let (d0, d1) = (v0 * h, v1 * h);
        // g(θ) = c0 + c1 θ + c2 θ² + c3 θ³
        let c2 = 3.0 * (g1 - g0) - 2.0 * d0 - d1;
        let c3 = 2.0 * (g0 - g1) + d0 + d1;
        Hermite {
            c: [g0, d0, c2, c3],
        }
    }

    fn value(&self, th: f64) -> f64 {
        let c = &self.c;
        c[0] + th * (c[1] + th * (c[2] + th * c[3]))
    }

    fn slope(&self, th: f64) -> f64 {
        let c = &self.c;
        c[1] + th * (2.0 * c[2] + th * 3.0 * c[3])
    }

    /// Where the slope turns from positive to negative inside (0, 1), given
    /// slope(0) > 0 > slope(1): the quadratic slope a·θ² + b·θ + c then has
    /// exactly one root there, found in closed form with the root formula
    /// that does not cancel (q = -(b + sign(b)·√disc)/2, roots q/a and
    /// c/q). Safeguarded Newton from the midpoint, stopped only when an
    /// iterate repeated, took 25 iterations on average (up to 64: near the
    /// root the slope's rounding moves each step by a few ulps, and the
    /// bracket closed by bisection): at one call per oscillation and
    /// trajectory, 7 percent of the CPU path's time on a 200-step sweep
    /// of the seed's oscillator. Twin of `hermite_peak`.
    fn peak(&self) -> Option<f64> {
        if !(self.slope(0.0) > 0.0 && self.slope(1.0) < 0.0) {
            return None;
        }
        let (a, b, c) = (3.0 * self.c[3], 2.0 * self.c[2], self.c[1]);
        let root = (b * b - 4.0 * a * c).max(0.0).sqrt();
        // b >= 0: a < -b - c < 0 (the slope at 1), so q < 0 and the root
        // in (0, 1) is q/a (c/q < 0). b < 0: q > 0 and c/q is the smaller
        // positive root (or the only one).
        let th = if b >= 0.0 {
            -0.5 * (b + root) / a
        } else {
            c / (-0.5 * (b - root))
        };
        Some(th.clamp(0.0, 1.0))
    }

    /// The first upward root of the cubic in [a, b] (g(a) <= 0 < g(b)), by
    /// bisection refined with Newton; used only as Newton's starting guess.
    pub(crate) fn first_root(&self, mut a: f64, mut b: f64) -> f64 {
        let mut th =
            a + (b - a) * (-self.value(a) / (self.value(b) - self.value(a))).clamp(0.0, 1.0);
        for _ in 0..8 {
            let g = self.value(th);
            if g > 0.0 {
                b = th;
            } else {
                a = th;
            }
            let next = th - g / self.slope(th);
            th = if next > a && next < b {
                next
            } else {
                0.5 * (a + b)
            };
        }
        th
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::clock::ZERO_PHASE;

    /// An autonomous step: ω = 0, the phase never moves.
    fn step_at<const D: usize, F: Flow<D>>(
        flow: &F,
        wall: &Wall,
        location: ImpactLocation,
        y: &[f64; D],
        h: f64,
        stats: &mut IterationStats,
    ) -> [f64; D] {
        step(
            &Walled { flow, wall: *wall },
            location,
            0.0,
            &ZERO_PHASE,
            &ZERO_PHASE,
            y,
            h,
            stats,
        )
        .0
    }

    /// A flow with one wall added.
    struct Walled<'a, F> {
        flow: &'a F,
        wall: Wall,
    }

    impl<const D: usize, F: Flow<D>> Flow<D> for Walled<'_, F> {
        fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
            self.flow.rhs(phase, y)
        }

        fn walls(&self) -> &[Wall] {
            std::slice::from_ref(&self.wall)
        }
    }

    /// X'' = a > 0: a ball thrown at a ceiling by constant gravity. RK4 is
    /// exact on quadratics, so the only error left is the impact location.
    struct Gravity {
        a: f64,
    }

    impl Flow<2> for Gravity {
        fn rhs(&self, _phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            [y[1], self.a]
        }
    }

    /// The bouncing ball in closed form from rest at distance d below the wall.
    fn bouncing(a: f64, d: f64, e: f64, t: f64) -> ([f64; 2], u32) {
        let mut t_hit = (2.0 * d / a).sqrt();
        if t < t_hit {
            return ([-d + 0.5 * a * t * t, a * t], 0);
        }
        let mut v = a * t_hit;
        let mut impacts = 0;
        loop {
            impacts += 1;
            v *= e;
            let flight = 2.0 * v / a;
            if t < t_hit + flight {
                let s = t - t_hit;
                return ([-v * s + 0.5 * a * s * s, -v + a * s], impacts);
            }
            t_hit += flight;
        }
    }

    #[test]
    fn several_impacts_in_one_step_are_all_applied() {
        let (a, d, e) = (9.81, 0.5, 0.6);
        let flow = Gravity { a };
        let wall = Wall::above(0.0, e);
        // One step long enough for four impacts.
        let h = 1.2;
        let (expected, impacts) = bouncing(a, d, e, h);
        assert!(
            impacts >= 4,
            "the test needs several impacts, got {impacts}"
        );
        let mut stats = IterationStats::default();
        let y = step_at(
            &flow,
            &wall,
            ImpactLocation::Newton,
            &[-d, 0.0],
            h,
            &mut stats,
        );
        assert_eq!(stats.impacts, impacts);
        assert!(!stats.chattering);
        assert!((y[0] - expected[0]).abs() < 1e-12, "{y:?} vs {expected:?}");
        assert!((y[1] - expected[1]).abs() < 1e-12, "{y:?} vs {expected:?}");
    }

    #[test]
    fn no_step_ends_behind_the_wall() {
        let flow = Gravity { a: 9.81 };
        for location in [ImpactLocation::Newton, ImpactLocation::Linear] {
            for e in [1.0, 0.9, 0.5] {
                let wall = Wall::above(0.0, e);
                let (mut t, mut y) = (0.0, [-1.0, 0.0]);
                let mut stats = IterationStats::default();
                let h = 0.0137;
                while t < 2.0 {
                    y = step_at(&flow, &wall, location, &y, h, &mut stats);
                    t += h;
                    assert!(
                        y[0] <= 0.0,
                        "{location:?}, e = {e}: x = {} behind the wall at t = {t}",
                        y[0]
                    );
                }
                assert!(stats.impacts > 0);
            }
        }
    }

    /// X'' = -X: a free oscillation whose top is at amplitude A.
    struct Harmonic;

    impl Flow<2> for Harmonic {
        fn rhs(&self, _phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            [y[1], -y[0]]
        }
    }

    #[test]
    fn an_excursion_past_the_wall_between_step_ends_is_an_impact() {
        // x(t) = cos(t - 0.1): the peak at t = 0.1 lies inside the step
        // [0, 0.2], whose ends are both at cos(0.1) = 0.995 < 1 - 1e-6 = the
        // wall (RK4's error over the half step is about 1e-8).
        let wall = Wall::above(1.0 - 1e-6, 1.0);
        let y0 = [0.1_f64.cos(), 0.1_f64.sin()];
        let mut stats = IterationStats::default();
        let y = step_at(
            &Harmonic,
            &wall,
            ImpactLocation::Newton,
            &y0,
            0.2,
            &mut stats,
        );
        assert_eq!(stats.impacts, 1, "the near-grazing impact was stepped over");
        assert!(y[0] <= wall.position);
        // The paper's linear location only looks at the step ends and misses it.
        let mut linear = IterationStats::default();
        step_at(
            &Harmonic,
            &wall,
            ImpactLocation::Linear,
            &y0,
            0.2,
            &mut linear,
        );
        assert_eq!(linear.impacts, 0);
    }

    /// X'' = -X - k·X³: a stiffening spring, whose turns are not those of
    /// a harmonic.
    struct Stiffening {
        k: f64,
    }

    impl Flow<2> for Stiffening {
        fn rhs(&self, _phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            [y[1], -y[0] - self.k * y[0] * y[0] * y[0]]
        }
    }

    #[test]
    fn a_step_s_cubic_rises_at_most_half_the_turn_reach_above_its_ends() {
        // The bound behind `may_turn_past`: any cubic Hermite interpolant
        // whose slope turns from + to - stays below max(g0, g1) +
        // (4/27)·h·(s0 - s1), half of TURN_REACH's; tight for ends level
        // with each other (the peak of g0 = g1 = 0, s0 = -s1 is exactly
        // h·s0/4 < (8/27)·h·s0).
        let mut tightest: f64 = 0.0;
        for i in 0..20_000 {
            let u = |k: usize| ((i * 7919 + k * 104_729) % 10_007) as f64 / 10_007.0;
            let (g0, g1) = (
                -u(1) * [1e-3, 0.1, 3.0][i % 3],
                -u(2) * [1e-3, 0.1, 3.0][i % 3],
            );
            let (s0, s1) = (1e-3 + 10.0 * u(3), -1e-3 - 10.0 * u(4));
            let h = [1e-3, 0.03, 0.3][(i / 3) % 3] * (0.5 + u(5));
            let hermite = Hermite::new(g0, s0, g1, s1, h);
            let Some(th) = hermite.peak() else { continue };
            let rise = hermite.value(th) - g0.max(g1);
            let bound = 0.5 * TURN_REACH * h * (s0 - s1);
            assert!(rise <= bound * (1.0 + 1e-12), "{rise:e} > {bound:e}");
            tightest = tightest.max(rise / bound);
        }
        assert!(
            tightest > 0.5,
            "the bound is not tested near its edge: {tightest}"
        );
    }

    #[test]
    fn a_turn_out_of_reach_never_passes_the_wall() {
        // What `may_turn_past` leaves out, the re-step to the Hermite peak
        // (which decides) never finds beyond the wall: turns of a harmonic
        // and a stiffening oscillation, 12 to 6000 steps per cycle, with
        // the wall placed just out of reach, where the step's cubic falls
        // short by half the reach and RK4 would need to overshoot it by
        // that much.
        let mut tested = 0;
        for i in 0..40_000 {
            let u = |k: usize| ((i * 7919 + k * 104_729) % 10_007) as f64 / 10_007.0;
            let amplitude = 0.05 + 5.0 * u(1);
            let k = [0.0, 0.5, 3.0][i % 3];
            let per_cycle = [20.0, 50.0, 200.0, 1800.0, 3600.0][i % 5];
            // Per cycle of the motion: the spring's frequency at this
            // amplitude, to first order (1 + (3/4)·k·A²)^½.
            let omega = (1.0 + 0.75 * k * amplitude * amplitude).sqrt();
            let h = std::f64::consts::TAU / omega / per_cycle * (0.6 + u(2));
            // A step starting before the peak X = amplitude (V = 0), by up
            // to one step.
            let flow = Stiffening { k };
            let back = h * u(3);
            let mut y0 = [amplitude, 0.0];
            // Reached backwards: the state `back` before the peak.
            let reversed = rk4::step(&Reversed(&flow), &ZERO_PHASE, &ZERO_PHASE, &y0, back).0;
            y0 = reversed;
            let y1 = rk4::step(&flow, &ZERO_PHASE, &ZERO_PHASE, &y0, h).0;
            let (s0, s1) = (y0[1], y1[1]);
            if !(s0 > 0.0 && s1 < 0.0) {
                continue;
            }
            let reach = TURN_REACH * h * (s0 - s1);
            let highest = y0[0].max(y1[0]);
            // Just out of reach, by a thousandth to a tenth of it.
            let wall = Wall::above(highest + reach * (1.001 + 0.1 * u(4)), 1.0);
            let (g0, g1) = (wall.gap(&y0), wall.gap(&y1));
            assert!(!may_turn_past(g0, s0, g1, s1, h), "{i}");
            let hermite = Hermite::new(g0, s0, g1, s1, h);
            let peak = hermite.peak().expect("the slope turns");
            let at_peak = rk4::step(&flow, &ZERO_PHASE, &ZERO_PHASE, &y0, peak * h).0;
            assert!(
                wall.gap(&at_peak) <= -0.25 * reach,
                "{i}: RK4's peak {:e} short of the wall, the reach {reach:e}",
                -wall.gap(&at_peak)
            );
            tested += 1;
        }
        assert!(tested > 30_000, "{tested} turns");
    }

    #[test]
    fn a_turn_out_of_reach_never_crosses_a_curved_moving_surface() {
        // `surface::may_cross`'s reach, on a surface curved in the state
        // and moving with the time, g = x + 0.3·x² + b·cos(w·t) - c, whose
        // rate along the motion is (1 + 0.6·x)·v - b·w·sin(w·t): along
        // harmonic and stiffening oscillations, 20 to 1000 steps per
        // cycle, the first step in which the rate turns, with the surface
        // placed just out of reach; the re-step to the Hermite peak (which
        // decides) never comes within a quarter of the reach.
        use crate::integrate::surface::{self, Surface};
        let mut tested = 0;
        for i in 0..4000 {
            let u = |k: usize| ((i * 7919 + k * 104_729) % 10_007) as f64 / 10_007.0;
            let k = [0.0, 0.5, 3.0][i % 3];
            let amplitude = 0.05 + 3.0 * u(1);
            let omega = (1.0 + 0.75 * k * amplitude * amplitude).sqrt();
            let per_cycle = [20.0, 50.0, 200.0, 1000.0][i % 4];
            let h = std::f64::consts::TAU / omega / per_cycle * (0.6 + u(2));
            let (b, w) = (0.3 * u(5), 0.2 + 2.0 * u(6));
            let value = |t: f64, y: &[f64; 2]| y[0] + 0.3 * y[0] * y[0] + b * (w * t).cos();
            let rate = |t: f64, y: &[f64; 2]| (1.0 + 0.6 * y[0]) * y[1] - b * w * (w * t).sin();
            let flow = Stiffening { k };
            let angle = std::f64::consts::TAU * u(3);
            let (mut t0, mut y0) = (
                10.0 * u(4),
                [amplitude * angle.cos(), amplitude * angle.sin()],
            );
            for _ in 0..(3.0 * per_cycle) as usize {
                let y1 = rk4::step(&flow, &ZERO_PHASE, &ZERO_PHASE, &y0, h).0;
                let (r0, r1) = (rate(t0, &y0), rate(t0 + h, &y1));
                if !(r0 > 0.0 && r1 < 0.0) {
                    (t0, y0) = (t0 + h, y1);
                    continue;
                }
                let reach = TURN_REACH * h * (r0 - r1);
                let highest = value(t0, &y0).max(value(t0 + h, &y1));
                let c = highest + reach * (1.001 + 0.1 * u(7));
                let (g0, g1) = (value(t0, &y0) - c, value(t0 + h, &y1) - c);
                assert!(
                    !surface::may_cross(Surface::Event, 0, (g0, r0), (g1, r1), h),
                    "{i}"
                );
                let peak = Hermite::new(g0, r0, g1, r1, h)
                    .peak()
                    .expect("the slope turns");
                let at_peak = rk4::step(&flow, &ZERO_PHASE, &ZERO_PHASE, &y0, peak * h).0;
                let g = value(t0 + peak * h, &at_peak) - c;
                assert!(
                    g <= -0.25 * reach,
                    "{i}: RK4's peak {:e} short of the surface, the reach {reach:e}",
                    -g
                );
                tested += 1;
                break;
            }
        }
        assert!(tested > 3000, "{tested} turns");
    }

    /// A flow run backwards in time.
    struct Reversed<'a, F>(&'a F);

    impl<F: Flow<2>> Flow<2> for Reversed<'_, F> {
        fn rhs(&self, phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            let [a, b] = self.0.rhs(phase, y);
            [-a, -b]
        }
    }

    #[test]
    fn a_mass_pressed_onto_the_wall_sticks() {
        // e = 0: the velocity dies at the first impact and gravity keeps
        // the ball on the wall: it rests there, and the step says the
        // state has forgotten where it came from.
        let wall = Wall::above(0.0, 0.0);
        let mut stats = IterationStats::default();
        let y = step_at(
            &Gravity { a: 1.0 },
            &wall,
            ImpactLocation::Newton,
            &[-0.1, 0.0],
            2.0,
            &mut stats,
        );
        assert!(!stats.chattering);
        assert_eq!(stats.impacts, 1);
        assert_eq!(stats.rank_loss, 2);
        assert_eq!(y, [0.0, 0.0]);
    }

    #[test]
    fn the_hermite_peak_is_the_slope_s_root_to_rounding() {
        // Steps across a turning point of a motion with harmonics, from
        // 50 to 3600 steps per cycle: the closed form against bisection on
        // the slope carried to the last bit. The slope's own rounding,
        // about ε·|slope(0)| against a curvature of its size, moves a root
        // by a few ε: that is the bound (measured: 1.5ε).
        let mut worst: f64 = 0.0;
        for i in 0..4000 {
            let u = |k: usize| ((i * 7919 + k * 104_729) % 10_007) as f64 / 10_007.0;
            let amplitude = 0.1 + 3.0 * u(1);
            let h = std::f64::consts::TAU / [50.0, 200.0, 1800.0, 3600.0][i % 4] * (0.6 + u(2));
            let t0 = h * u(3);
            let x = |t: f64| amplitude * ((t - t0).cos() + 0.1 * (3.0 * (t - t0)).cos());
            let v = |t: f64| -amplitude * ((t - t0).sin() + 0.3 * (3.0 * (t - t0)).sin());
            let hermite = Hermite::new(x(0.0) - 2.0, v(0.0), x(h) - 2.0, v(h), h);
            let Some(th) = hermite.peak() else { continue };
            let (mut a, mut b) = (0.0_f64, 1.0_f64);
            while b - a > f64::EPSILON {
                let mid = 0.5 * (a + b);
                if hermite.slope(mid) > 0.0 {
                    a = mid;
                } else {
                    b = mid;
                }
            }
            worst = worst.max((th - 0.5 * (a + b)).abs());
        }
        assert!(worst <= 4.0 * f64::EPSILON, "{worst:e}");
    }
}
