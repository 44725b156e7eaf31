//! Branch switching at a period doubling: the branch of period 2p born
//! where a period-p orbit's multiplier passes through -1.
//!
//! At the doubling point x* (period p, at λ*) DU^p has the eigenvector v
//! of μ = -1, and the doubled orbit near it is x* ± a·v + O(a²), with a²
//! of the order of |λ - λ*| on the side where it exists. So the orbit of
//! period 2p is solved with its amplitude along v fixed and λ free, and a
//! solution is kept only if it is a genuine period-2p orbit:
//! its image after p iterations is not itself (else it is the period-p
//! orbit counted twice, which is also a fixed point of U^{2p}).

use nalgebra::{Const, DMatrix, DVector, DimMin};

use super::continuation::{
    continue_branch, correct, params_at, point, Branch, BranchPoint, ContinuationSettings,
};
use super::map::evaluate;
use super::newton::{Failure, NewtonSettings};
use crate::method::MethodSettings;
use crate::system::{Params, System};

/// The real eigenvector of DU^p for its multiplier nearest -1, unit length
/// (`None` when that multiplier is complex or the matrix has no real
/// eigenvector there).
pub fn doubling_direction<const D: usize>(
    jacobian: &nalgebra::SMatrix<f64, D, D>,
) -> Option<[f64; D]> {
    let j = DMatrix::from_fn(D, D, |r, c| jacobian[(r, c)]);
    let mu = j
        .complex_eigenvalues()
        .iter()
        .copied()
        .min_by(|a, b| (a + 1.0).norm().total_cmp(&(b + 1.0).norm()))?;
    if mu.im.abs() > 1e-6 {
        return None;
    }
    // The null vector of J - μ·I: the right singular vector of its
    // smallest singular value.
    let shifted = &j - DMatrix::identity(D, D) * mu.re;
    let svd = shifted.svd(false, true);
    let v_t = svd.v_t?;
    let k = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?
        .0;
    let v: [f64; D] = crate::array::from_fn(|i| v_t[(k, i)]);
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    (norm.is_finite() && norm > 0.0).then(|| crate::array::from_fn(|i| v[i] / norm))
}

/// How far apart, relative to max(1, |x|∞), a period-2p orbit's point and
/// its image after p iterations are: 0 for the period-p orbit counted
/// twice.
pub fn doubling_separation<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    x: &[f64; D],
    p: usize,
) -> f64
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let half = evaluate(system, settings, x, p, false).image;
    super::newton::relative_residual(x, &half)
}

/// The first orbit of the doubled branch: a genuine period-2p orbit near
/// the period doubling `at` (a branch point of period p at its λ, as
/// [`super::bifurcations`] locates it). The doubled branch leaves the
/// doubling point along (v, 0) (v the eigenvector of μ = -1; λ changes
/// with the square of the amplitude), so the standard branch switching
/// applies: the continuation's corrector for period 2p from the predictor
/// (x* ± a·v, λ*) held orthogonal to (v, 0), which fixes the amplitude a
/// and leaves λ free. Amplitudes `amplitude`·max(1, |x*|∞) and a decade
/// either side are tried, both signs; the first solution whose p-iterate
/// differs from it by more than `separation` (relative) is kept, so it is
/// not the period-p orbit counted twice.
#[allow(clippy::too_many_arguments)]
pub fn doubled_orbit<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    continuation: &ContinuationSettings,
    at: &BranchPoint<D>,
    amplitude: f64,
    separation: f64,
) -> Result<BranchPoint<D>, Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let p = at.orbit.period;
    let index = continuation.parameter;
    let v = doubling_direction(&at.orbit.jacobian).ok_or(Failure::Singular { steps: 0 })?;
    let x = at.orbit.state;
    let scale = x.iter().fold(1.0_f64, |m, a| m.max(a.abs()));
    let t = DVector::from_fn(D + 1, |i, _| if i < D { v[i] } else { 0.0 });
    let mut last = Failure::NotConverged {
        steps: 0,
        residual: f64::NAN,
    };
    for a in [amplitude, 0.1 * amplitude, 10.0 * amplitude] {
        for sign in [1.0, -1.0] {
            let predictor = DVector::from_fn(D + 1, |i, _| {
                if i < D {
                    x[i] + sign * a * scale * v[i]
                } else {
                    at.parameter
                }
            });
            match correct::<D, S>(base, settings, newton, continuation, &predictor, &t, 2 * p) {
                Ok((orbit, lambda, _)) => {
                    let system = S::new(&params_at(base, index, lambda));
                    let apart = doubling_separation(&system, settings, &orbit.state, p);
                    if apart > separation {
                        return Ok(point::<D, S>(base, settings, index, lambda, orbit));
                    }
                }
                Err(failure) => last = failure,
            }
        }
    }
    Err(last)
}

/// The doubled branch (period 2p) followed from the period doubling `at`
/// with `continuation`, its direction set away from the doubling point:
/// [`doubled_orbit`] at the amplitude `amplitude`, then pseudo-arclength
/// continuation from there. `Err` when no genuine period-2p orbit is found near it.
#[allow(clippy::too_many_arguments)]
pub fn switch_at_doubling<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    continuation: &ContinuationSettings,
    at: &BranchPoint<D>,
    amplitude: f64,
    separation: f64,
) -> Result<Branch<D>, Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let index = continuation.parameter;
    let first = doubled_orbit::<D, S>(
        base,
        settings,
        newton,
        continuation,
        at,
        amplitude,
        separation,
    )?;
    let start = params_at(base, index, first.parameter);
    let away = ContinuationSettings {
        direction: (first.parameter - at.parameter).signum(),
        ..*continuation
    };
    Ok(continue_branch::<D, S>(
        &start,
        settings,
        newton,
        &away,
        &first.orbit.state,
        2 * at.orbit.period,
    ))
}
