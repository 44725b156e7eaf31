//! A motion sliding on one switch or several, along the equivalent
//! control's field (`surface::Equivalent`), for the rest of a step: the
//! other switches it meets, located as any crossing is on RK4 re-stepped
//! along the sliding field, and its exit where a stick margin runs out.

use crate::integrate::clock::{cos_sin, rotate, Phase};
use crate::integrate::flow::Flow;
use crate::integrate::iteration::{ImpactLocation, IterationStats};
use crate::integrate::locate::{locate, SubStep};
use crate::integrate::region::SurfaceValues;
use crate::integrate::surface::{self, Surface, MAX_SURFACES};
use crate::integrate::wall::may_reach;

/// How a sliding sub-step ended ([`slide`]).
pub(super) enum Slid<const D: usize> {
    /// Still sliding at the end of the step, at this state.
    Through([f64; D]),
    /// Left a switch (its region updated) after this offset, at this state.
    Leaves(f64, [f64; D]),
    /// Met switch k, which it does not slide on, after this offset, at
    /// this state (on k's surface), still sliding on the others.
    Meets(usize, f64, [f64; D]),
}

/// The stick margins (L - m, L + m) of every surface at one state (those
/// of the sliding switches only are meaningful).
type Margins = [(f64, f64); MAX_SURFACES];

/// Slides on the switches of `region`'s sliding set (a trajectory on
/// their surfaces at y, phase `phase`) for up to `h`, along the
/// equivalent control's field ([`surface::Equivalent`]). Another switch
/// met on the way is located as any crossing is (on RK4 re-stepped along
/// the sliding field) and handed back; an exit (a stick margin of a
/// sliding switch reaching 0) before it is bisected on the same re-steps,
/// and the region leaves that switch to the side whose margin ran out,
/// the others still sliding.
#[allow(clippy::too_many_arguments)]
pub(super) fn slide<const D: usize, F: Flow<D>>(
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
            .map_or([(f64::NAN, f64::NAN); MAX_SURFACES], |e| e.margins)
    };
    let at = |s: f64| -> ([f64; D], Margins) {
        let y_s = sub.step(phase, y, s).0;
        (y_s, margins(&phase_at(s), &y_s))
    };
    // Every sliding switch still held.
    let holds = |m: &Margins| {
        (0..surfaces.len())
            .filter(|&j| set >> j & 1 == 1)
            .all(|j| m[j].0 > 0.0 && m[j].1 > 0.0)
    };
    let (end, end_margins) = at(h);
    // An event or a wall met while sliding would need a motion along the
    // surfaces and into them at once, which is not integrated: the
    // iteration says so rather than step through it.
    let end_phase = phase_at(h);
    let values = (
        base.surface_values(sides, phase, y),
        base.surface_values(sides, &end_phase, &end),
    );
    let first = first_met(
        base,
        *region,
        &sub,
        location,
        phase,
        y,
        (h, &end),
        &values,
        stats,
    );
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
    let (j, bit) = running_out(surfaces, set, &m);
    *region = surface::leaving(*region, j, bit, m[j].0 <= m[j].1);
    Slid::Leaves(hi, exit)
}

/// The first switch outside the sliding set met by the sliding motion
/// from (phase, y) over the step to `end` after h, given the surfaces'
/// values at both ends: its index, offset and state (on its surface).
/// An event crossed on the way flags the iteration.
#[allow(clippy::too_many_arguments)]
fn first_met<const D: usize, F: Flow<D>, S: Flow<D>>(
    base: &F,
    region: u32,
    sub: &SubStep<S>,
    location: ImpactLocation,
    phase: &Phase,
    y: &[f64; D],
    (h, end): (f64, &[f64; D]),
    (before, after): &(SurfaceValues, SurfaceValues),
    stats: &mut IterationStats,
) -> Option<(usize, f64, [f64; D])> {
    let (sides, set) = (surface::sides(region), surface::sliding_set(region));
    let phase_at = |s: f64| rotate(phase, &cos_sin(sub.omega * s));
    let mut first: Option<(usize, f64, [f64; D])> = None;
    let others = base
        .surfaces()
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
        let rate = |s: f64, y: &[f64; D]| o * surface::rate_along(base, region, k, &phase_at(s), y);
        let (start, stop) = (
            (o * before.g[k], rate(0.0, y)),
            (o * after.g[k], rate(h, end)),
        );
        // The stop test without the reach bound: the sliding field's
        // turns are not bounded by the step's cubic as a free motion's.
        if !may_reach(start.0, start.1, stop.0, stop.1, h, false) {
            continue;
        }
        let hit = locate(
            sub, location, phase, y, h, end, start, stop, false, distance, rate,
        );
        if let Some((s, yc)) = hit {
            if first.is_none_or(|(_, earliest, _)| s < earliest) {
                first = Some((k, s, yc));
            }
        }
    }
    first
}

/// The sliding switch of `set` whose margin ran out (the most out, where
/// two did within the bisection) in the margins `m`: its index and bit.
fn running_out(surfaces: &[Surface], set: u32, m: &Margins) -> (usize, u32) {
    surfaces
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
        .expect("a sliding trajectory slides on a switch")
}
