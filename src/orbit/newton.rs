//! Periodic orbits by Newton's method on F(x) = U^p(x) - x, the Jacobian
//! DU^p - I from the perturbed copies ([`super::map`]). A finite-difference
//! Jacobian carries a relative error near 1e-8, so the iteration converges
//! linearly at that rate: one or two steps from a continuation's predictor.

use nalgebra::{Const, DimMin, SMatrix, SVector};

use super::map::{evaluate, Evaluation};
use crate::method::MethodSettings;
use crate::system::{IterationStats, System};

/// When Newton stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonSettings {
    /// Converged when |U^p(x) - x|∞ ≤ tolerance·max(1, |x|∞).
    pub tolerance: f64,
    /// Newton steps before the solve gives up.
    pub max_steps: usize,
    /// Halvings of a step that did not lower the residual (or left the
    /// admissible states, or gave a non-finite image) before giving up.
    pub max_halvings: usize,
}

impl Default for NewtonSettings {
    fn default() -> Self {
        NewtonSettings {
            // Rounding in one RK4 period map of states of size 1 is near
            // 1e-14 (ε·√steps); 1e-10 leaves four decades for it.
            tolerance: 1e-10,
            max_steps: 30,
            max_halvings: 8,
        }
    }
}

/// Why a solve found no orbit: the solve's status, never a panic.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Failure {
    /// Not converged after `steps` Newton steps; the residual left.
    NotConverged { steps: usize, residual: f64 },
    /// Every step tried led out of the admissible states (behind a wall).
    Inadmissible { steps: usize },
    /// The image (or the start) is not finite: the trajectory blew up, or
    /// a section's map has no return.
    NonFinite { steps: usize },
    /// DU^p - I is singular: a multiplier at +1 (a fold), where Newton in
    /// the state alone has no unique step.
    Singular { steps: usize },
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Failure::NotConverged { steps, residual } => {
                write!(
                    f,
                    "not converged after {steps} Newton steps (residual {residual:e})"
                )
            }
            Failure::Inadmissible { steps } => {
                write!(f, "left the admissible states after {steps} Newton steps")
            }
            Failure::NonFinite { steps } => {
                write!(f, "non-finite state after {steps} Newton steps")
            }
            Failure::Singular { steps } => {
                write!(
                    f,
                    "DU^p - I singular after {steps} Newton steps (a multiplier at +1)"
                )
            }
        }
    }
}

/// A periodic orbit of period p: its point x = U^p(x), and DU^p there.
#[derive(Clone, Copy, Debug)]
pub struct Orbit<const D: usize> {
    pub state: [f64; D],
    /// The period in map iterations.
    pub period: usize,
    /// DU^p(x), estimated as the lanes estimate their Jacobians.
    pub jacobian: SMatrix<f64, D, D>,
    /// |U^p(x) - x|∞ / max(1, |x|∞).
    pub residual: f64,
    /// The Newton steps the solve took (0: the guess was the orbit).
    pub steps: usize,
    /// The p iterations' statistics (crossings per wall and surface, flux).
    pub stats: IterationStats,
    /// The p iterations' time (p·T for a period map).
    pub time: f64,
}

/// |F|∞ relative to max(1, |x|∞), the convergence measure.
pub fn relative_residual<const D: usize>(x: &[f64; D], image: &[f64; D]) -> f64 {
    let scale = x.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
    let r = x
        .iter()
        .zip(image)
        .fold(0.0_f64, |m, (a, b)| m.max((b - a).abs()));
    r / scale
}

/// Whether x may be iterated: finite and admitted by the system.
fn usable<const D: usize, S: System<D>>(system: &S, x: &[f64; D]) -> Result<(), bool> {
    if !x.iter().all(|v| v.is_finite()) {
        Err(false)
    } else if !system.admits(x) {
        Err(true)
    } else {
        Ok(())
    }
}

/// The periodic orbit of period `p` near `guess`, by damped Newton: each
/// step solves (DU^p - I)·dx = -(U^p(x) - x), and is halved while it does
/// not lower the residual, leaves the admissible states or blows up.
pub fn solve<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    guess: &[f64; D],
    p: usize,
) -> Result<Orbit<D>, Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    match usable(system, guess) {
        Err(true) => return Err(Failure::Inadmissible { steps: 0 }),
        Err(false) => return Err(Failure::NonFinite { steps: 0 }),
        Ok(()) => {}
    }
    let mut x = *guess;
    let mut at = evaluate(system, settings, &x, p, true);
    let mut residual = relative_residual(&x, &at.image);
    for steps in 0..=newton.max_steps {
        if !residual.is_finite() {
            return Err(Failure::NonFinite { steps });
        }
        if residual <= newton.tolerance {
            return Ok(orbit(x, p, residual, steps, &at));
        }
        if steps == newton.max_steps {
            break;
        }
        let f = SVector::<f64, D>::from_fn(|i, _| at.image[i] - x[i]);
        let a = at.jacobian - SMatrix::<f64, D, D>::identity();
        let Some(dx) = a.lu().solve(&(-f)) else {
            return Err(Failure::Singular { steps });
        };
        let (next, next_at, next_residual) =
            damped_step(system, settings, newton, &x, &dx, p, residual, steps)?;
        (x, at, residual) = (next, next_at, next_residual);
    }
    Err(Failure::NotConverged {
        steps: newton.max_steps,
        residual,
    })
}

/// The smallest divisor d of `orbit`'s period with U^d(x) = x to
/// [`LEAST_PERIOD_TOLERANCE`] (relative, as the residual): a period-p
/// solve may converge on an orbit of period d counted p/d times (Newton
/// past a period-2 orbit's grazing finds the free period-1 orbit twice
/// over), which is that orbit, not a branch of period p.
pub fn least_period<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    orbit: &Orbit<D>,
) -> usize
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let p = orbit.period;
    (1..p)
        .filter(|d| p % d == 0)
        .find(|&d| {
            let image = evaluate(system, settings, &orbit.state, d, false).image;
            relative_residual(&orbit.state, &image) <= LEAST_PERIOD_TOLERANCE
        })
        .unwrap_or(p)
}

/// How near U^d(x) must come back to x for [`least_period`] to call x an
/// orbit of period d: far above a solve's 1e-10 (a period-d orbit solved
/// as period p misses U^d(x) = x by its residual over |1 - μ|), far below
/// the distance between the points of a period-p orbit away from its
/// period doubling (the seed's doubled orbits: 0.1 to 1.4).
pub const LEAST_PERIOD_TOLERANCE: f64 = 1e-6;

/// x + s·dx for s = 1, 1/2, …: the first that is usable and lowers the
/// residual, with its evaluation.
#[allow(clippy::too_many_arguments)]
fn damped_step<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    x: &[f64; D],
    dx: &SVector<f64, D>,
    p: usize,
    residual: f64,
    steps: usize,
) -> Result<([f64; D], Evaluation<D>, f64), Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (mut scale, mut inadmissible, mut best) = (1.0, false, None);
    for _ in 0..=newton.max_halvings {
        let trial: [f64; D] = crate::array::from_fn(|i| x[i] + scale * dx[i]);
        scale *= 0.5;
        if let Err(behind) = usable(system, &trial) {
            inadmissible |= behind;
            continue;
        }
        let at = evaluate(system, settings, &trial, p, true);
        let r = relative_residual(&trial, &at.image);
        if r < residual {
            return Ok((trial, at, r));
        }
        // A step that does not lower the residual is still a step when no
        // halving does better (a Newton iterate may rise once before it
        // falls): keep the best finite one.
        if r.is_finite() && best.as_ref().is_none_or(|(_, _, b)| r < *b) {
            best = Some((trial, at, r));
        }
    }
    match best {
        Some(found) => Ok(found),
        None if inadmissible => Err(Failure::Inadmissible { steps: steps + 1 }),
        None => Err(Failure::NonFinite { steps: steps + 1 }),
    }
}

fn orbit<const D: usize>(
    x: [f64; D],
    p: usize,
    residual: f64,
    steps: usize,
    at: &Evaluation<D>,
) -> Orbit<D> {
    Orbit {
        state: x,
        period: p,
        jacobian: at.jacobian,
        residual,
        steps,
        stats: at.stats,
        time: at.time,
    }
}
