//! Where a test function on a branch's orbits vanishes: a grazing (a
//! wall's excess, [`super::extremum::wall_excess`]), or any function of the
//! orbit and its multipliers. The orbit is re-solved by Newton at each
//! trial value of the parameter, from the nearest solved orbit on the
//! test's side.
//!
//! A test function is smooth only while the orbit keeps its sequence of
//! events: a trial orbit whose crossings differ from the starting point's,
//! or that has no orbit at all, lies across (a wall's excess is
//! identically zero on the impacting side). The zero is then located from
//! the one side by secants, with bisection of the bracket whenever a
//! secant lands across: superlinear where the test function is linear
//! near its zero, and never worse than bisection.

use nalgebra::{Const, DimMin};

use super::continuation::params_at;
use super::newton::{solve, Failure, NewtonSettings, Orbit};
use crate::method::MethodSettings;
use crate::system::{Params, System};

/// A located zero of a test function.
#[derive(Clone, Copy, Debug)]
pub struct Located<const D: usize> {
    /// The zero's estimate: the last secant's root, or the bracket's middle.
    pub parameter: f64,
    /// The bracket [from, to] the zero lies in when the search ended.
    pub bracket: (f64, f64),
    /// The solved orbit nearest the zero on the starting point's side.
    pub orbit: Orbit<D>,
    /// Newton solves the search took.
    pub solves: usize,
}

/// One solved trial: λ, the test's value, the orbit.
type Side<const D: usize> = (f64, f64, Orbit<D>);

/// The zero of `test` between the orbit `a` at its λ (where the test has a
/// value) and λ_b (where the orbit `b`, if any, has the other sign, or
/// none), to `tolerance` in the parameter `index`. `Err` when `a` has no
/// value or `b` is on its side.
#[allow(clippy::too_many_arguments)]
pub fn locate_zero<const D: usize, S: System<D>, T: Fn(&S, &Orbit<D>) -> Option<f64>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    index: usize,
    a: (f64, &Orbit<D>),
    b: (f64, Option<&Orbit<D>>),
    test: T,
    tolerance: f64,
) -> Result<Located<D>, Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let value = |lambda: f64, orbit: &Orbit<D>, events: &[u32]| {
        (orbit.stats.crossings[..] == *events)
            .then(|| test(&S::new(&params_at(base, index, lambda)), orbit))
            .flatten()
    };
    let events = a.1.stats.crossings;
    let not_bracketed = Failure::NotConverged {
        steps: 0,
        residual: f64::NAN,
    };
    let ga = value(a.0, a.1, &events).ok_or(not_bracketed)?;
    let gb = b.1.and_then(|orbit| value(b.0, orbit, &events));
    if gb.is_some_and(|g| g.signum() == ga.signum()) {
        return Err(not_bracketed);
    }
    let mut near: Side<D> = (a.0, ga, *a.1);
    let mut before: Option<Side<D>> = None;
    let mut far = (b.0, gb);
    // Illinois: the far end's value halved each time the near end moves
    // twice in a row, so that regula falsi does not stall on one side.
    let mut near_moved = false;
    // A trial on the test's side starts within the bracket from a solved
    // orbit moved along its secant and converges in two or three steps;
    // one across (an impacting orbit near grazing, with its large DU^p)
    // need not be solved, only recognised, and a full solve of it costs
    // tens of steps with the grazing ladder at each.
    let trial_newton = NewtonSettings {
        max_steps: newton.max_steps.min(8),
        max_halvings: newton.max_halvings.min(3),
        ..*newton
    };
    let mut solves = 0;
    // With no value across, the secant needs a second point on the
    // test's side: a probe a tenth of the bracket back from `a`.
    if far.1.is_none() {
        let probe = near.0 - 0.1 * (far.0 - near.0);
        let system = S::new(&params_at(base, index, probe));
        solves += 1;
        if let Ok(orbit) = solve(&system, settings, &trial_newton, &near.2.state, a.1.period) {
            if let Some(g) = value(probe, &orbit, &events).filter(|g| g.signum() == ga.signum()) {
                before = Some((probe, g, orbit));
            }
        }
    }
    let mut estimate = near.0;
    while (far.0 - near.0).abs() > tolerance && solves < 200 {
        let secant = match (far.1, &before) {
            (Some(gf), _) => near.0 - near.1 * (far.0 - near.0) / (gf - near.1),
            (None, Some(prev)) => near.0 - near.1 * (near.0 - prev.0) / (near.1 - prev.1),
            (None, None) => f64::NAN,
        };
        let inside = |l: f64| (l - near.0) * (l - far.0) < 0.0;
        let trial = if inside(secant) {
            secant
        } else {
            0.5 * (near.0 + far.0)
        };
        let last_estimate = estimate;
        estimate = if inside(secant) { secant } else { estimate };
        if inside(secant) && (estimate - last_estimate).abs() < 0.1 * tolerance {
            break;
        }
        // From the side's orbit, moved along its own secant in the state.
        let guess: [f64; D] = match &before {
            Some(prev) if prev.0 != near.0 => {
                let r = (trial - near.0) / (near.0 - prev.0);
                crate::array::from_fn(|i| near.2.state[i] + r * (near.2.state[i] - prev.2.state[i]))
            }
            _ => near.2.state,
        };
        let system = S::new(&params_at(base, index, trial));
        solves += 1;
        let found = solve(&system, settings, &trial_newton, &guess, a.1.period).ok();
        let g = found.as_ref().and_then(|o| value(trial, o, &events));
        match (g, found) {
            (Some(g), Some(orbit)) if g.signum() == near.1.signum() => {
                before = Some(std::mem::replace(&mut near, (trial, g, orbit)));
                if near_moved {
                    far.1 = far.1.map(|f| 0.5 * f);
                }
                near_moved = true;
            }
            (g, _) => {
                far = (trial, g);
                near_moved = false;
            }
        }
    }
    let parameter = if (far.0 - near.0).abs() <= tolerance {
        0.5 * (near.0 + far.0)
    } else {
        estimate
    };
    Ok(Located {
        parameter,
        bracket: (near.0, far.0),
        orbit: near.2,
        solves,
    })
}
