//! An impact at the map's section. A stroboscopic map samples the flow at
//! t ≡ 0 (mod T); where an impacting orbit's impact passes through that
//! time as the parameter moves, the orbit itself changes smoothly, but its
//! section point jumps by the reset (v → -e·v): just before, the point is
//! about to hit the wall; just after, it has just left it. The map U is
//! discontinuous there, so pseudo-arclength continuation, whose predictor
//! and corrector assume a smooth branch of (x, λ), cannot step across;
//! the tracer steps across instead (`trace`), and this is its test: how
//! soon the section point reaches its wall.
//!
//! The orbit's multipliers do not jump (the maps sampled at two phases are
//! conjugate), nor do its events per period: only the point does.

use nalgebra::{Const, DimMin};

use super::continuation::{params_at, BranchPoint};
use super::events::events;
use super::map::evaluate;
use super::newton::{solve, NewtonSettings, Orbit};
use crate::integrate::Flow;
use crate::method::MethodSettings;
use crate::system::{Params, System};

/// The signed time, in map periods, from the orbit's section point to the
/// nearest wall it impacts, along the point's own velocity: -gap/speed of
/// each wall the orbit hits (> 0 while the point moves towards the wall,
/// < 0 when it has just left it). Through an impact at the section's time
/// it passes through 0 with the impact time's own slope, smooth on both
/// sides, so its zero in the parameter is where the point jumps. NaN when
/// the orbit impacts no wall. A point moving faster than twice the orbit's
/// slowest impact (before or after it) is taken to be at none of its
/// impacts: its time to the wall is that of a flight that turns back
/// short of it (a period-2 orbit whose one impact grazes away, measured on
/// the seed) or of another impact than the slowest, which this leaves out.
pub fn section_clearance<const D: usize, S: System<D> + Flow<D>>(
    system: &S,
    orbit: &Orbit<D>,
) -> f64 {
    let x = &orbit.state;
    let slowest = orbit.stats.slowest_impact;
    system
        .walls()
        .iter()
        .zip(&orbit.stats.crossings)
        .filter(|(wall, &c)| c > 0 && wall.speed(x).abs() <= 2.0 * slowest)
        .map(|(wall, _)| -wall.gap(x) / wall.speed(x) / system.period())
        .filter(|s| !s.is_nan())
        .min_by(|a, b| a.abs().total_cmp(&b.abs()))
        .unwrap_or(f64::NAN)
}

/// [`section_clearance`] as the tracer takes it, for a flow with walls.
pub type Clearance<const D: usize, S> = fn(&S, &Orbit<D>) -> f64;

/// How near the section, in map periods, a branch's newest point must be
/// for its crossing to be looked for: far enough out that continuation's
/// steps (the seed's: a few hundredths of a period in the impact's time)
/// reach it before they would step across it, near enough that the
/// linear estimate -gap/speed is the impact's time.
const SECTION_REACH: f64 = 0.25;

/// The parameter where an impact of the branch's orbit reaches the
/// section, when it lies ahead of the branch's newest point within
/// `reach` times its last step: the zero of [`section_clearance`] by the
/// secant through the last two points, both with the same events, their
/// clearances of one sign and falling towards it. `None` otherwise.
pub fn crossing_ahead<const D: usize, S: System<D>>(
    base: &Params,
    index: usize,
    points: &[BranchPoint<D>],
    clearance: Clearance<D, S>,
    reach: f64,
) -> Option<f64> {
    let [.., before, last] = points else {
        return None;
    };
    if last.orbit.stats.impacts == 0 || events(&last.orbit) != events(&before.orbit) {
        return None;
    }
    let at =
        |p: &BranchPoint<D>| clearance(&S::new(&params_at(base, index, p.parameter)), &p.orbit);
    let (a, b) = (at(before), at(last));
    let falling = a.signum() == b.signum() && b.abs() < a.abs();
    if !falling || b.abs() > SECTION_REACH {
        return None;
    }
    let moved = last.parameter - before.parameter;
    let crossing = last.parameter - b * moved / (b - a);
    let ahead = crossing - last.parameter;
    (ahead * moved >= 0.0 && ahead.abs() <= reach * moved.abs()).then_some(crossing)
}

/// The branch's orbit past the crossing at λ_c = `crossing` ahead of its
/// newest point (at λ_n): solved at λ_c + (λ_c - λ_n), at least half the
/// last step beyond λ_c, by Newton from the newest point's image U^p(x)
/// there (the motion itself carries the point through its impact), and
/// kept when it is the same orbit on the section's other side: the same
/// events per period, its clearance of the other sign. `None` where there
/// is no such orbit, or λ_c's mirror lies outside `bounds`.
#[allow(clippy::too_many_arguments)]
pub fn step_across<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    index: usize,
    bounds: (f64, f64),
    points: &[BranchPoint<D>],
    crossing: f64,
    clearance: Clearance<D, S>,
) -> Option<(f64, Orbit<D>)>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let [.., before, last] = points else {
        return None;
    };
    let ahead = crossing - last.parameter;
    let beyond = ahead
        .abs()
        .max(0.5 * (last.parameter - before.parameter).abs());
    let lambda = crossing + ahead.signum() * beyond;
    if lambda < bounds.0.min(bounds.1) || lambda > bounds.0.max(bounds.1) {
        return None;
    }
    let system = S::new(&params_at(base, index, lambda));
    let p = last.orbit.period;
    let guess = evaluate(&system, settings, &last.orbit.state, p, false).image;
    let orbit = solve(&system, settings, newton, &guess, p).ok()?;
    let here = clearance(
        &S::new(&params_at(base, index, last.parameter)),
        &last.orbit,
    );
    let there = clearance(&system, &orbit);
    let across = there.signum() != here.signum() && there.abs() <= SECTION_REACH;
    (across && events(&orbit) == events(&last.orbit)).then_some((lambda, orbit))
}
