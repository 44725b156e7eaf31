//! Where a branch's orbits change their sequence of events, and how a
//! branch goes on past such a point.
//!
//! An orbit's events per period are its crossings of each wall (impacts
//! per stop) and switching surface, [`IterationStats::crossings`]. They
//! change at a grazing: an impact's speed falling to 0
//! ([`impact_speed_test`]), or a free flight's closest approach to a wall
//! reaching it with zero normal velocity
//! ([`super::extremum::free_approach`]), or at the onset of sliding. The
//! test functions are smooth on one side only (the events differ on the
//! other), so the change itself is located by bisection in the parameter
//! ([`locate_events_change`]), and a test function's zero by
//! [`super::locate_zero`] from its side.
//!
//! Past such a point Newton from the orbit on the near side meets the
//! square-root singularity of the impacting orbits (a saltation that grows
//! like 1/v), so a branch followed by pseudo-arclength stops there.
//! [`step_past`] restarts it on the other side by natural-parameter solves
//! at λ ± 10^-k from the grazing orbit, and the branch goes on from what
//! it finds (its multipliers jump there).

use nalgebra::{Const, DimMin};

use super::continuation::{params_at, point, BranchPoint};
use super::newton::{least_period, solve, Failure, NewtonSettings, Orbit};
use crate::integrate::{IterationStats, MAX_EVENTS};
use crate::method::MethodSettings;
use crate::system::{Params, System};

/// An orbit's events per period over its p iterations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Events {
    /// Its crossings of each wall (impacts per stop), then of each
    /// switching surface.
    pub crossings: [u32; MAX_EVENTS],
    /// The sliding phases it entered.
    pub sliding_phases: u32,
}

/// What a change of events is, by what changed: a crossing of a wall or
/// surface appearing or going (it does so tangentially: a grazing), else
/// a sliding phase beginning or ending (sliding).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EventKind {
    Grazing,
    Sliding,
    EventsChange,
}

impl EventKind {
    /// The name `bifurcations.csv` gives it.
    pub fn name(self) -> &'static str {
        match self {
            EventKind::Grazing => "grazing",
            EventKind::Sliding => "sliding",
            EventKind::EventsChange => "events-change",
        }
    }

    /// The kind of the change from `before` to `after`.
    pub fn of(before: &Events, after: &Events) -> EventKind {
        if before.sliding_phases != after.sliding_phases {
            EventKind::Sliding
        } else if before.crossings != after.crossings {
            EventKind::Grazing
        } else {
            EventKind::EventsChange
        }
    }
}

/// An orbit's events per period.
pub fn events<const D: usize>(orbit: &Orbit<D>) -> Events {
    Events {
        crossings: orbit.stats.crossings,
        sliding_phases: orbit.stats.sliding_phases,
    }
}

/// The impact-grazing test function of an impacting orbit: its slowest
/// impact's speed, zero where an impact grazes. Through a grazing the
/// impacting orbit's speed is linear in λ - λ_g (the map's square-root
/// singularity there shows in the multipliers, which grow like 1/v); measured on the seed's branch, v/(λ - λ_g) stays at 19 from
/// v = 8e-3 down to 2e-4. `None` for an orbit without impacts.
pub fn impact_speed_test<const D: usize>(orbit: &Orbit<D>) -> Option<f64> {
    let stats: &IterationStats = &orbit.stats;
    let v = stats.slowest_impact;
    (stats.impacts > 0 && v.is_finite()).then_some(v)
}

/// A located change of the events per period between two branch points.
#[derive(Clone, Debug)]
pub struct EventsChange<const D: usize> {
    /// The change's estimate: the middle of the bracket.
    pub parameter: f64,
    /// The bracket [near, far] in λ, at most the tolerance wide: solved
    /// orbits with `before`'s events at `near`, with other events (or
    /// none) at `far`.
    pub bracket: (f64, f64),
    /// The events on either side: the first point's, the second's.
    pub before: Events,
    pub after: Events,
    /// The solved orbit at the bracket's near end.
    pub orbit: Orbit<D>,
    /// Newton solves the search took.
    pub solves: usize,
}

/// Every change of the events per period between consecutive points of
/// `points` (a branch in parameter `index`), each located by bisection in
/// λ to `tolerance`. A pair whose search fails is left out.
pub fn events_changes<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    index: usize,
    points: &[BranchPoint<D>],
    tolerance: f64,
) -> Vec<EventsChange<D>>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    points
        .windows(2)
        .filter(|pair| events(&pair[0].orbit) != events(&pair[1].orbit))
        .filter_map(|pair| {
            locate_events_change::<D, S>(
                base,
                settings,
                newton,
                index,
                (pair[0].parameter, &pair[0].orbit),
                (pair[1].parameter, &pair[1].orbit),
                tolerance,
            )
            .ok()
        })
        .collect()
}

/// The change of events between the orbit `a` at λ_a and the orbit `b` at
/// λ_b (whose events differ), located by bisection in λ to `tolerance`:
/// each trial solved by Newton from the side whose end is nearer (its
/// state moved linearly towards the other's), and classed by its events.
/// A trial with no orbit, or one with a third sequence of events, counts
/// as the far side.
pub fn locate_events_change<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    index: usize,
    a: (f64, &Orbit<D>),
    b: (f64, &Orbit<D>),
    tolerance: f64,
) -> Result<EventsChange<D>, Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (before, after) = (events(a.1), events(b.1));
    if before == after {
        return Err(Failure::NotConverged {
            steps: 0,
            residual: f64::NAN,
        });
    }
    let (mut near, mut far) = ((a.0, *a.1), (b.0, *b.1));
    let mut solves = 0;
    while (far.0 - near.0).abs() > tolerance && solves < 200 {
        let lambda = 0.5 * (near.0 + far.0);
        let guess: [f64; D] = crate::array::from_fn(|i| 0.5 * (near.1.state[i] + far.1.state[i]));
        let system = S::new(&params_at(base, index, lambda));
        solves += 1;
        // From the middle of the two orbits first, then from each end:
        // the one whose events it keeps decides the side.
        let found = [guess, near.1.state, far.1.state]
            .iter()
            .find_map(|g| solve(&system, settings, newton, g, a.1.period).ok());
        match found {
            Some(orbit) if events(&orbit) == before => near = (lambda, orbit),
            Some(orbit) if events(&orbit) == after => far = (lambda, orbit),
            _ => far.0 = lambda,
        }
    }
    Ok(EventsChange {
        parameter: 0.5 * (near.0 + far.0),
        bracket: (near.0, far.0),
        before,
        after,
        orbit: near.1,
        solves,
    })
}

impl<const D: usize> EventsChange<D> {
    /// Grazing, sliding or another change of events.
    pub fn kind(&self) -> EventKind {
        EventKind::of(&self.before, &self.after)
    }
}

/// The first orbit past a grazing (or any change of events) at λ_g,
/// `at` the orbit there on the branch's side: natural-parameter solves at
/// λ_g + s·10^-k·max(1, |λ_g|), the largest k of `decades` first (the
/// nearest), s = +1 then -1, Newton from `at`; the first that converges to
/// an orbit whose events differ from `at`'s (the branch's other side, not
/// the orbit it came from), at its least period ([`least_period`]). Its
/// multipliers, against the branch's last point's, are the jump at the
/// grazing.
#[allow(clippy::too_many_arguments)]
pub fn step_past<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    index: usize,
    grazing: f64,
    at: &Orbit<D>,
    decades: std::ops::RangeInclusive<i32>,
) -> Result<BranchPoint<D>, Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let mut last = Failure::NotConverged {
        steps: 0,
        residual: f64::NAN,
    };
    let scale = grazing.abs().max(1.0);
    for k in decades.rev() {
        for sign in [1.0, -1.0] {
            let lambda = grazing + sign * scale * 10f64.powi(-k);
            let system = S::new(&params_at(base, index, lambda));
            match solve(&system, settings, newton, &at.state, at.period) {
                Ok(orbit) if events(&orbit) != events(at) => {
                    let least = least_period(&system, settings, &orbit);
                    let orbit = if least < orbit.period {
                        solve(&system, settings, newton, &orbit.state, least)?
                    } else {
                        orbit
                    };
                    return Ok(point::<D, S>(base, settings, index, lambda, orbit));
                }
                Ok(_) => {}
                Err(failure) => last = failure,
            }
        }
    }
    Err(last)
}

/// A grazing located by extrapolation from its side.
#[derive(Clone, Copy, Debug)]
pub struct Grazing<const D: usize> {
    /// λ where the test function reaches 0.
    pub parameter: f64,
    /// The change between the quadratic and the linear extrapolation: the
    /// estimate's error is far below it.
    pub error: f64,
    /// The branch's last orbit, the solved one nearest the grazing.
    pub orbit: Orbit<D>,
}

/// λ at g = 0 of the polynomial through the points (g_i, λ_i): λ as a
/// function of the test, by Neville's scheme (the samples' g distinct).
pub fn extrapolate_to_zero(samples: &[(f64, f64)]) -> f64 {
    let mut p: Vec<f64> = samples.iter().map(|s| s.1).collect();
    let g: Vec<f64> = samples.iter().map(|s| s.0).collect();
    for level in 1..p.len() {
        for i in 0..p.len() - level {
            let (a, b) = (g[i], g[i + level]);
            p[i] = (b * p[i] - a * p[i + 1]) / (b - a);
        }
    }
    p[0]
}

/// The grazing of an impacting branch that ended short of it (Newton
/// loses the orbit within ~v² of grazing, v its slowest impact's speed):
/// `test` (an impact's speed, [`impact_speed_test`]) is a smooth function
/// of λ through the grazing on its side, linear in λ - λ_g, so λ is a
/// smooth function of it, and λ_g is λ at test = 0, extrapolated from the
/// branch's own orbits: its last point, and before it the points whose
/// test is at least twice the previous one's (spread geometrically
/// towards the branch's inside, all with the last point's events), four
/// at most. The estimate is the cubic through four (the quadratic through
/// three where there are only three), its error the change from one
/// degree lower. `Err` with fewer than three such points.
pub fn extrapolate_grazing<const D: usize, S: System<D>, T: Fn(&S, &Orbit<D>) -> Option<f64>>(
    base: &Params,
    index: usize,
    points: &[BranchPoint<D>],
    test: T,
) -> Result<Grazing<D>, Failure> {
    let none = Failure::NotConverged {
        steps: 0,
        residual: f64::NAN,
    };
    let last = points.last().ok_or(none)?;
    let same = events(&last.orbit);
    let value = |p: &BranchPoint<D>| {
        (events(&p.orbit) == same)
            .then(|| test(&S::new(&params_at(base, index, p.parameter)), &p.orbit))
            .flatten()
    };
    let mut samples = vec![(value(last).ok_or(none)?, last.parameter)];
    for p in points.iter().rev().skip(1) {
        if samples.len() == 4 {
            break;
        }
        let Some(g) = value(p) else { break };
        let previous = samples.last().expect("a sample").0;
        if g.abs() >= 2.0 * previous.abs() {
            samples.push((g, p.parameter));
        }
    }
    if samples.len() < 3 {
        return Err(none);
    }
    let estimate = extrapolate_to_zero(&samples);
    let lower = extrapolate_to_zero(&samples[..samples.len() - 1]);
    Ok(Grazing {
        parameter: estimate,
        error: (estimate - lower).abs(),
        orbit: last.orbit,
    })
}
