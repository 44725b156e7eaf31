//! Resolving one RK4 step that meets a wall or a surface: every crossing
//! inside it in the order they happen, each located on the RK4 solution of
//! the field in force (`locate`) and applied (a wall's rebound here, a
//! general surface's crossing in `cross`), the rest of the step
//! integrated again after each; a held or sliding motion handed to `hold`
//! or `slide`; and a mass at rest on a wall, stuck there while pressed in.
//! (Sticking on a wall and resolving a step call each other, a release
//! going on as a free step: they live together here.)

use std::ops::ControlFlow;

use crate::integrate::clock::{cos_sin, rotate, Phase};
use crate::integrate::flow::{Flow, InRegion};
use crate::integrate::iteration::{ImpactLocation, IterationStats};
use crate::integrate::locate::{locate, locate_linear, locate_newton, SubStep};
use crate::integrate::rk4;
use crate::integrate::surface::{self, Surface};
use crate::integrate::wall::{may_reach, Wall};

use super::cross::cross;
use super::hold::{hold_step, Hold, ACCUMULATION_FRACTION};
use super::slide::{slide, Slid};

/// More impacts than this inside one RK4 step mean impacts accumulate
/// faster than the accumulation test below catches; the step then stops
/// resolving them and flags the iteration (chattering).
pub const MAX_IMPACTS_PER_STEP: u32 = 64;

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
/// wall (an excursion between the ends, the stop test [`may_reach`]).
#[inline]
pub fn reaches_wall<const D: usize>(wall: &Wall, y: &[f64; D], h: f64, y1: &[f64; D]) -> bool {
    may_reach(
        wall.gap(y),
        wall.speed(y),
        wall.gap(y1),
        wall.speed(y1),
        h,
        true,
    )
}

/// Where the resolution of a step stands: `done` of it taken, the
/// trajectory at (phase, y), and y1 the plain RK4 image of the rest of the
/// step in the field now in force.
struct Progress<const D: usize> {
    done: f64,
    phase: Phase,
    y: [f64; D],
    y1: [f64; D],
}

impl<const D: usize> Progress<D> {
    /// `s` further into the step, at y.
    fn advance(&mut self, omega: f64, s: f64, y: [f64; D]) {
        self.done += s;
        self.phase = rotate(&self.phase, &cos_sin(omega * s));
        self.y = y;
    }
}

/// What stays the same along one step's resolution: the system, how
/// crossings are located, the forcing's ω and the step's size.
struct Resolving<'a, F> {
    base: &'a F,
    location: ImpactLocation,
    omega: f64,
    h: f64,
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
    let step = Resolving {
        base,
        location,
        omega,
        h,
    };
    let mut at = Progress {
        done: 0.0,
        phase: *phase,
        y: *y,
        y1,
    };
    for _ in 0..MAX_IMPACTS_PER_STEP {
        let next = if let Some(j) = surface::held_on(*region) {
            step.held(j, region, &mut at, stats)
        } else if surface::is_sliding(*region) {
            step.sliding(region, &mut at, stats)
        } else {
            step.free(region, &mut at, stats)
        };
        if let ControlFlow::Break(y_end) = next {
            return y_end;
        }
    }
    step.too_many(region, &at, stats)
}

impl<F> Resolving<'_, F> {
    /// Held on event j: the rest of the step on its surface, unless the
    /// field lets go of the motion inside it.
    fn held<const D: usize>(
        &self,
        j: usize,
        region: &mut u32,
        at: &mut Progress<D>,
        stats: &mut IterationStats,
    ) -> ControlFlow<[f64; D]>
    where
        F: Flow<D>,
    {
        let (base, omega, h) = (self.base, self.omega, self.h);
        match hold_step(base, j, omega, &at.phase, &at.y, h - at.done, stats) {
            Hold::Through(y_end) => ControlFlow::Break(y_end),
            Hold::Releases(s, y_free) => {
                *region &= !(1 << (surface::HELD + j as u32));
                at.advance(omega, s, y_free);
                at.y1 = field_step(base, *region, omega, &at.phase, &at.y, h - at.done);
                ControlFlow::Continue(())
            }
        }
    }

    /// On one switch or several: the rest of the step slides, unless the
    /// motion leaves one of them or meets another.
    fn sliding<const D: usize>(
        &self,
        region: &mut u32,
        at: &mut Progress<D>,
        stats: &mut IterationStats,
    ) -> ControlFlow<[f64; D]>
    where
        F: Flow<D>,
    {
        let (base, omega, h) = (self.base, self.omega, self.h);
        let (phase0, y0) = (at.phase, at.y);
        let (s, y_at) = match slide(
            base,
            region,
            self.location,
            omega,
            &phase0,
            &y0,
            h - at.done,
            stats,
        ) {
            Slid::Through(y_end) => return ControlFlow::Break(y_end),
            Slid::Leaves(s, y_exit) => (s, y_exit),
            Slid::Meets(k, s, yc) => {
                let phase_c = rotate(&phase0, &cos_sin(omega * s));
                match cross(base, region, k, &phase_c, &yc, h, stats) {
                    Some(after) => (s, after),
                    // Not resolved (flagged): the rest of the step in the
                    // field now in force.
                    None => {
                        let rest = field_step(base, *region, omega, &phase_c, &yc, h - at.done - s);
                        return ControlFlow::Break(rest);
                    }
                }
            }
        };
        at.advance(omega, s, y_at);
        if !surface::is_sliding(*region) {
            at.y1 = field_step(base, *region, omega, &at.phase, &at.y, h - at.done);
        }
        ControlFlow::Continue(())
    }

    /// In a region's field: the first wall or surface met in the rest of
    /// the step, crossed; or the step's end, where none is.
    fn free<const D: usize>(
        &self,
        region: &mut u32,
        at: &mut Progress<D>,
        stats: &mut IterationStats,
    ) -> ControlFlow<[f64; D]>
    where
        F: Flow<D>,
    {
        let Some((j, s, yc)) = self.first_met(*region, at) else {
            return ControlFlow::Break(at.y1);
        };
        let (base, omega, h) = (self.base, self.omega, self.h);
        let phase_c = rotate(&at.phase, &cos_sin(omega * s));
        at.done += s;
        let walls = base.walls();
        if j < walls.len() {
            return self.impact(j, region, (phase_c, yc), at, stats);
        }
        // A general surface.
        match cross(base, region, j - walls.len(), &phase_c, &yc, h, stats) {
            Some(after) => {
                at.phase = phase_c;
                at.y = after;
                // A constrained motion: the loop's top slides, or holds,
                // the rest of the step.
                if !surface::is_constrained(*region) {
                    at.y1 = field_step(base, *region, omega, &at.phase, &at.y, h - at.done);
                }
                ControlFlow::Continue(())
            }
            // Not resolved (flagged): the rest of the step in the field
            // now in force.
            None => {
                ControlFlow::Break(field_step(base, *region, omega, &phase_c, &yc, h - at.done))
            }
        }
    }

    /// The first wall or surface met in the rest of the step, from `at`
    /// in `region`'s field: its index (walls first), offset and state.
    fn first_met<const D: usize>(
        &self,
        region: u32,
        at: &Progress<D>,
    ) -> Option<(usize, f64, [f64; D])>
    where
        F: Flow<D>,
    {
        let (base, omega) = (self.base, self.omega);
        let walls = base.walls();
        let surfaces = base.surfaces();
        let flow = &InRegion { flow: base, region };
        let sub = SubStep { flow, omega };
        let (phase0, y0, y1) = (&at.phase, &at.y, &at.y1);
        let rest = self.h - at.done;
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
                match self.location {
                    ImpactLocation::Linear => locate_linear(wall, y0, rest, y1),
                    ImpactLocation::Newton => locate_newton(&sub, wall, phase0, y0, rest, y1),
                },
            );
        }
        if surfaces.is_empty() {
            return first;
        }
        let end = rotate(phase0, &cos_sin(omega * rest));
        let before = base.surface_values(region, phase0, y0);
        let after = base.surface_values(region, &end, y1);
        for (j, &kind) in surfaces.iter().enumerate() {
            let o = kind.orientation(region);
            // At s into the rest of the step: a surface may move with the
            // forcing.
            let values_at = |s: f64, y: &[f64; D]| {
                base.surface_values(region, &rotate(phase0, &cos_sin(omega * s)), y)
            };
            let distance = |s: f64, y: &[f64; D]| o * values_at(s, y).g[j];
            let rate = |s: f64, y: &[f64; D]| o * values_at(s, y).rate[j];
            let (start, end) = (
                (o * before.g[j], o * before.rate[j]),
                (o * after.g[j], o * after.rate[j]),
            );
            // A turn out of reach of the surface cannot cross it (the stop
            // test, as the step loops find, `surface::may_cross`); a step
            // that ends beyond, or whose distance is NaN, goes on to the
            // location.
            if end.0 <= 0.0 && !may_reach(start.0, start.1, end.0, end.1, rest, true) {
                continue;
            }
            earliest(
                walls.len() + j,
                locate(
                    &sub,
                    self.location,
                    phase0,
                    y0,
                    rest,
                    y1,
                    start,
                    end,
                    kind == Surface::Event,
                    distance,
                    rate,
                ),
            );
        }
        first
    }

    /// Wall j met at (phase_c, yc), `at.done` into the step: the rebound,
    /// or the mass stuck to the wall where it arrives at rest or its
    /// bounces accumulate.
    fn impact<const D: usize>(
        &self,
        j: usize,
        region: &mut u32,
        (phase_c, yc): (Phase, [f64; D]),
        at: &mut Progress<D>,
        stats: &mut IterationStats,
    ) -> ControlFlow<[f64; D]>
    where
        F: Flow<D>,
    {
        let (base, omega, h) = (self.base, self.omega, self.h);
        let wall = &base.walls()[j];
        let speed = wall.speed(&yc);
        let stuck = |region: &mut u32, stats: &mut IterationStats| {
            stuck_step(
                base,
                region,
                j,
                self.location,
                omega,
                &phase_c,
                &yc,
                h - at.done,
                stats,
            )
        };
        if speed <= 0.0 {
            // Reaching the wall without approaching it: the mass arrives at
            // rest, pressed into the wall. It sticks.
            return ControlFlow::Break(stuck(region, stats));
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
            return ControlFlow::Break(stuck(region, stats));
        }
        at.phase = phase_c;
        at.y = wall.on_wall(yc, -rebound);
        let surfaces = base.surfaces();
        if !surfaces.is_empty() {
            // The rebound may jump across a switch (a velocity reversed
            // across a friction's slip): the field after it is that side's.
            *region = surface::jumped(
                surfaces,
                *region,
                &base.surface_values(*region, &at.phase, &yc),
                &base.surface_values(*region, &at.phase, &at.y),
            );
        }
        at.y1 = field_step(base, *region, omega, &at.phase, &at.y, h - at.done);
        ControlFlow::Continue(())
    }

    /// More crossings in the step than [`MAX_IMPACTS_PER_STEP`]. Bounces
    /// this dense under a force pressing into the wall are a mass
    /// effectively at rest (with e = 1 and damping their heights shrink
    /// only harmonically, never summing to a finite time): it sticks.
    /// Otherwise the iteration cannot be trusted.
    fn too_many<const D: usize>(
        &self,
        region: &mut u32,
        at: &Progress<D>,
        stats: &mut IterationStats,
    ) -> [f64; D]
    where
        F: Flow<D>,
    {
        let (base, omega, h) = (self.base, self.omega, self.h);
        let walls = base.walls();
        for (j, wall) in walls.iter().enumerate() {
            if at.y[wall.coordinate] == wall.position
                && pressing(
                    &flow_in(base, *region),
                    wall,
                    &at.phase,
                    &wall.on_wall(at.y, 0.0),
                ) > 0.0
            {
                let rest = h - at.done;
                return stuck_step(
                    base,
                    region,
                    j,
                    self.location,
                    omega,
                    &at.phase,
                    &at.y,
                    rest,
                    stats,
                );
            }
        }
        stats.chattering = true;
        walls.iter().fold(at.y1, |y, w| clamp_to_wall(w, y))
    }
}

fn flow_in<F>(flow: &F, region: u32) -> InRegion<'_, F> {
    InRegion { flow, region }
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

fn clamp_to_wall<const D: usize>(wall: &Wall, y: [f64; D]) -> [f64; D] {
    if wall.gap(&y) > 0.0 {
        wall.on_wall(y, wall.speed(&y).min(0.0))
    } else {
        y
    }
}
