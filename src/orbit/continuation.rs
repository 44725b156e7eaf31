//! Periodic orbits followed in one parameter λ by pseudo-arclength
//! continuation: the unknowns are (x, λ), the equations U^p(x; λ) - x = 0
//! and t·((x, λ) - predictor) = 0 with t the branch's unit tangent, so a
//! fold (where λ turns back and DU^p - I is singular) is an ordinary point
//! of the augmented system. ∂U^p/∂λ is a central difference in λ with the
//! same relative δ as the copies; DU^p comes from the copies themselves.

use nalgebra::{Const, DMatrix, DVector, DimMin};

use super::floquet::{refined_floquet_near, Floquet};
use super::map::evaluate;
use super::newton::{relative_residual, solve, Failure, NewtonSettings, Orbit};
use crate::method::MethodSettings;
use crate::perturbation::perturbation_at;
use crate::system::{Params, System};

/// How a branch is followed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContinuationSettings {
    /// The continued parameter: its index in [`Params::values`].
    pub parameter: usize,
    /// The range of λ the branch is followed over; it ends at either end.
    pub bounds: (f64, f64),
    /// +1 to start towards larger λ, -1 towards smaller.
    pub direction: f64,
    /// The first arclength step, and the range step control keeps it in.
    pub step: f64,
    pub min_step: f64,
    pub max_step: f64,
    /// Points after which the branch ends (a branch closing on itself, an
    /// isola, would otherwise go round for ever).
    pub max_points: usize,
    /// Corrector steps after which a step is retried shorter.
    pub max_corrector_steps: usize,
}

impl ContinuationSettings {
    /// Over `bounds` in parameter `parameter`, with steps of at most a
    /// fiftieth of the range.
    pub fn over(parameter: usize, bounds: (f64, f64)) -> Self {
        let range = (bounds.1 - bounds.0).abs();
        ContinuationSettings {
            parameter,
            bounds,
            direction: 1.0,
            step: range / 200.0,
            min_step: range * 1e-9,
            max_step: range / 50.0,
            max_points: 10_000,
            max_corrector_steps: 6,
        }
    }
}

/// One point of a branch.
#[derive(Clone, Debug)]
pub struct BranchPoint<const D: usize> {
    /// λ, the continued parameter's value.
    pub parameter: f64,
    pub orbit: Orbit<D>,
    pub floquet: Floquet,
}

/// Why a branch ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BranchEnd {
    /// It reached an end of the range.
    Bound,
    /// No orbit at the starting value.
    Start(Failure),
    /// The corrector failed at every step down to the smallest one, at
    /// λ = `parameter`; the last failure.
    StepTooSmall { parameter: f64, failure: Failure },
    /// [`ContinuationSettings::max_points`] reached.
    MaxPoints,
    /// It came back to its first point: a closed branch (an isola, such
    /// as the seed's impacting period-1 orbit between its two folds).
    Closed,
    /// Its impact's speed falls to 0 at λ = `parameter` ahead of its last
    /// point (extrapolated, with the error estimate `error`): the hook of
    /// [`continue_branch_until`] ended it there rather than let it creep
    /// on in ever smaller steps as the map's square root nears.
    Grazing { parameter: f64, error: f64 },
    /// Its last `points` steps were all tiny and together moved λ by
    /// next to nothing, up to λ = `parameter`: the hook of
    /// [`continue_branch_until`] ended it there, short of
    /// [`ContinuationSettings::max_points`] taken in the same place.
    Stalled { parameter: f64, points: usize },
    /// At λ = `parameter` the orbit closed after `period` iterations, a
    /// divisor of the branch's: the branch ran into the orbit of that
    /// period counted over (a period-2 orbit whose one impact grazed away
    /// becomes the free period-1 orbit twice). The hook of
    /// [`continue_branch_until`] ended it there, the point of the shorter
    /// orbit left out: that orbit is a branch of its own.
    ShorterPeriod { parameter: f64, period: usize },
    /// An impact of its orbit reaches the map's section at λ =
    /// `parameter` ahead (extrapolated), where the orbit's point jumps by
    /// the reset ([`super::section`]): the hook of
    /// [`continue_branch_until`] ended it short of there, for the tracer
    /// to step across; a branch that could not is ended so.
    SectionCrossing { parameter: f64 },
}

/// Asked after each new point of a branch (the points so far, the step
/// that reached the newest): `Some` ends the branch there with that end.
pub type EndHook<'a, const D: usize> = &'a dyn Fn(&[BranchPoint<D>], f64) -> Option<BranchEnd>;

/// A followed branch: its points in the order followed, and its end.
#[derive(Clone, Debug)]
pub struct Branch<const D: usize> {
    pub points: Vec<BranchPoint<D>>,
    pub end: BranchEnd,
}

/// The system at λ = `value` of parameter `index`, the others as `base`.
pub fn params_at(base: &Params, index: usize, value: f64) -> Params {
    let mut params = base.clone();
    params.set(index, value);
    params
}

/// ∂U^p/∂λ at (x, λ), a central difference over ±δ·max(1, |λ|).
fn parameter_derivative<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    index: usize,
    x: &[f64; D],
    lambda: f64,
    p: usize,
) -> [f64; D]
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let h = perturbation_at(settings.perturbation, &[lambda]);
    let (up, down) = (lambda + h, lambda - h);
    let image = |l: f64| evaluate(&S::new(&params_at(base, index, l)), settings, x, p, false).image;
    let (a, b) = (image(up), image(down));
    crate::array::from_fn(|i| (a[i] - b[i]) / (up - down))
}

/// The augmented Jacobian [[DU^p - I, ∂U^p/∂λ], [row]] of (x, λ).
fn augmented<const D: usize>(
    orbit_jacobian: &nalgebra::SMatrix<f64, D, D>,
    dl: &[f64; D],
    row: &DVector<f64>,
) -> DMatrix<f64> {
    DMatrix::from_fn(D + 1, D + 1, |r, c| match (r < D, c < D) {
        (true, true) => orbit_jacobian[(r, c)] - if r == c { 1.0 } else { 0.0 },
        (true, false) => dl[r],
        (false, _) => row[c],
    })
}

/// The branch's unit tangent at a solution, oriented along `previous`.
fn tangent<const D: usize>(
    orbit_jacobian: &nalgebra::SMatrix<f64, D, D>,
    dl: &[f64; D],
    previous: &DVector<f64>,
) -> Option<DVector<f64>> {
    let mut rhs = DVector::zeros(D + 1);
    rhs[D] = 1.0;
    let t = augmented(orbit_jacobian, dl, previous).lu().solve(&rhs)?;
    let norm = t.norm();
    (norm.is_finite() && norm > 0.0).then(|| t / norm)
}

/// Newton on the augmented system from the predictor `y`, orthogonal to
/// `t`: the orbit, λ and ∂U^p/∂λ there, and the steps taken.
pub(super) fn correct<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    continuation: &ContinuationSettings,
    predictor: &DVector<f64>,
    t: &DVector<f64>,
    p: usize,
) -> Result<(Orbit<D>, f64, [f64; D]), Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let index = continuation.parameter;
    let mut y = predictor.clone();
    for steps in 0..=continuation.max_corrector_steps {
        let x: [f64; D] = crate::array::from_fn(|i| y[i]);
        let lambda = y[D];
        let system = S::new(&params_at(base, index, lambda));
        if !y.iter().all(|v| v.is_finite()) {
            return Err(Failure::NonFinite { steps });
        }
        if !system.admits(&x) {
            return Err(Failure::Inadmissible { steps });
        }
        let at = evaluate(&system, settings, &x, p, true);
        let residual = relative_residual(&x, &at.image);
        if !residual.is_finite() {
            return Err(Failure::NonFinite { steps });
        }
        let dl = parameter_derivative::<D, S>(base, settings, index, &x, lambda, p);
        if residual <= newton.tolerance {
            let orbit = Orbit {
                state: x,
                period: p,
                jacobian: at.jacobian,
                residual,
                steps,
                stats: at.stats,
                time: at.time,
            };
            return Ok((orbit, lambda, dl));
        }
        if steps == continuation.max_corrector_steps {
            return Err(Failure::NotConverged { steps, residual });
        }
        let mut g = DVector::zeros(D + 1);
        for i in 0..D {
            g[i] = at.image[i] - x[i];
        }
        g[D] = t.dot(&(&y - predictor));
        let Some(dy) = augmented(&at.jacobian, &dl, t).lu().solve(&(-g)) else {
            return Err(Failure::Singular { steps });
        };
        y += dy;
    }
    unreachable!("the loop returns at its last step")
}

/// The branch of period-`p` orbits through the orbit near `guess` at the
/// parameter's value in `base`, followed over `continuation.bounds`.
///
/// Step control: a step whose corrector needed at most two steps grows by
/// half, one that needed more than three shrinks, one that failed (or
/// turned the tangent by more than ~37°, a sign of jumping between
/// branches or a corner) is retried at half the length, down to
/// `min_step`. The last point is solved at the bound itself.
pub fn continue_branch<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    continuation: &ContinuationSettings,
    guess: &[f64; D],
    p: usize,
) -> Branch<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let never = |_: &[BranchPoint<D>], _: f64| None;
    continue_branch_until::<D, S>(base, settings, newton, continuation, guess, p, &never)
}

/// The branch's first point, solved from `guess`, and its tangent there
/// pointing along `continuation.direction` in λ.
fn first_point<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    continuation: &ContinuationSettings,
    guess: &[f64; D],
    p: usize,
) -> Result<(BranchPoint<D>, DVector<f64>), Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let index = continuation.parameter;
    let start = base.values[index];
    let first = solve(&S::new(base), settings, newton, guess, p)?;
    let dl = parameter_derivative::<D, S>(base, settings, index, &first.state, start, p);
    let mut along = DVector::zeros(D + 1);
    along[D] = continuation.direction.signum();
    let t = tangent(&first.jacobian, &dl, &along).ok_or(Failure::Singular { steps: 0 })?;
    Ok((point::<D, S>(base, settings, index, start, first), t))
}

/// [`continue_branch`], asking `end` after each new point whether the
/// branch ends there.
pub fn continue_branch_until<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    continuation: &ContinuationSettings,
    guess: &[f64; D],
    p: usize,
    end: EndHook<D>,
) -> Branch<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let index = continuation.parameter;
    let (low, high) = continuation.bounds;
    let start = base.values[index];
    let (first, mut t) = match first_point::<D, S>(base, settings, newton, continuation, guess, p) {
        Ok(first) => first,
        Err(failure) => {
            return Branch {
                points: Vec::new(),
                end: BranchEnd::Start(failure),
            }
        }
    };
    let mut points = vec![first];
    let mut step = continuation.step;
    let mut last_failure;
    // Whether the branch has gone further from its first point than a
    // few of its steps: only then can it close on it.
    let mut left = false;
    while points.len() < continuation.max_points {
        let here = points.last().expect("a branch has its first point");
        let y = DVector::from_fn(D + 1, |i, _| {
            if i < D {
                here.orbit.state[i]
            } else {
                here.parameter
            }
        });
        let predictor = &y + &t * step;
        let lambda = predictor[D];
        if lambda > high || lambda < low {
            let bound = if lambda > high { high } else { low };
            let reach = (bound - y[D]) / t[D];
            let guess: [f64; D] = crate::array::from_fn(|i| y[i] + reach * t[i]);
            let at_bound = params_at(base, index, bound);
            match solve(&S::new(&at_bound), settings, newton, &guess, p) {
                Ok(orbit) => {
                    let near = points.last();
                    let new = point_near::<D, S>(base, settings, index, bound, orbit, near);
                    points.push(new);
                    return Branch {
                        points,
                        end: BranchEnd::Bound,
                    };
                }
                Err(failure) => last_failure = failure,
            }
        } else {
            match correct::<D, S>(base, settings, newton, continuation, &predictor, &t, p) {
                Ok((orbit, lambda, derivative)) => {
                    let turned = tangent(&orbit.jacobian, &derivative, &t);
                    let smooth = turned.as_ref().is_some_and(|n| n.dot(&t) > 0.8);
                    if smooth || step <= continuation.min_step {
                        if let Some(n) = turned {
                            t = n;
                        }
                        let steps = orbit.steps;
                        let near = points.last();
                        let new = point_near::<D, S>(base, settings, index, lambda, orbit, near);
                        points.push(new);
                        if closes(&points, &t, &mut left, step) {
                            return Branch {
                                points,
                                end: BranchEnd::Closed,
                            };
                        }
                        if let Some(end) = end(&points, step) {
                            return Branch { points, end };
                        }
                        step = if steps <= 2 {
                            step * 1.5
                        } else if steps > 3 {
                            step * 0.7
                        } else {
                            step
                        };
                        step = step.clamp(continuation.min_step, continuation.max_step);
                        continue;
                    }
                    last_failure = Failure::NotConverged {
                        steps: orbit.steps,
                        residual: orbit.residual,
                    };
                }
                Err(failure) => last_failure = failure,
            }
        }
        if step <= continuation.min_step {
            let parameter = points.last().map_or(start, |p| p.parameter);
            return Branch {
                points,
                end: BranchEnd::StepTooSmall {
                    parameter,
                    failure: last_failure,
                },
            };
        }
        step = (step * 0.5).max(continuation.min_step);
    }
    Branch {
        points,
        end: BranchEnd::MaxPoints,
    }
}

/// Whether the branch's newest point is back at its first: within the
/// step just taken of it, heading the way the branch left it, after having
/// been further than three steps away.
fn closes<const D: usize>(
    points: &[BranchPoint<D>],
    t: &DVector<f64>,
    left: &mut bool,
    step: f64,
) -> bool {
    let y = |p: &BranchPoint<D>| {
        DVector::from_fn(
            D + 1,
            |i, _| if i < D { p.orbit.state[i] } else { p.parameter },
        )
    };
    let (first, last) = (y(&points[0]), y(points.last().expect("a point")));
    let distance = (&last - &first).norm();
    if distance > 3.0 * step {
        *left = true;
        return false;
    }
    // Back near the start, moving on past it (not towards it, which is
    // the branch turning back on itself within a step).
    *left && t.dot(&(&last - &first)) >= 0.0
}

/// A solved orbit at λ as a branch point, its multipliers from the δ
/// ladder.
pub(super) fn point<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    index: usize,
    lambda: f64,
    orbit: Orbit<D>,
) -> BranchPoint<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    point_near::<D, S>(base, settings, index, lambda, orbit, None)
}

/// [`point`], its ladder tried first where `near`'s (the branch's
/// previous point) was kept ([`refined_floquet_near`]).
fn point_near<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    index: usize,
    lambda: f64,
    mut orbit: Orbit<D>,
    near: Option<&BranchPoint<D>>,
) -> BranchPoint<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let params = params_at(base, index, lambda);
    let near = near.map(|p| &p.floquet);
    let floquet = refined_floquet_near(&S::new(&params), settings, &params, &mut orbit, near);
    BranchPoint {
        parameter: lambda,
        orbit,
        floquet,
    }
}
