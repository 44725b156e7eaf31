//! An orbit's Jacobian DU^p re-estimated over a ladder of δ, for its
//! multipliers. The method's δ (1e-6 in f64) balances truncation against
//! rounding for one iteration of an average over thousands, where the
//! rounding averages out; an orbit's multipliers come from one estimate,
//! whose rounding noise ε·√steps/δ (about 1e-8 relative at 1800 steps)
//! would stay in its exponents (measured: up to 2e-10 off -ζ on the seed's
//! non-impacting orbit). Central differences' truncation is O(δ²), zero
//! on a linear flow, so larger δ are tried too, neighbouring rungs are
//! combined to cancel that truncation, and the combination kept is the
//! one whose multipliers change least towards both neighbours, as the
//! grazing ladder keeps its rung (`method::lane::estimate_resolving_grazing`).

use nalgebra::{Const, DMatrix, DimMin, SMatrix};
use rayon::prelude::*;

use super::map::evaluate;
use super::newton::Orbit;
use crate::method::MethodSettings;
use crate::system::System;

/// Rungs δ·10^(k/2), k = 0..=RUNGS: from the method's δ up three
/// decades, combined in neighbouring pairs (see [`refined_jacobian`]). At 1e-3 the rounding noise is 1e-11 relative, and a nonlinear
/// flow's O(δ²) truncation shows as a change between rungs, which the
/// choice avoids.
const RUNGS: i32 = 6;

/// ln|μ_i| of a Jacobian, sorted.
fn log_moduli<const D: usize>(j: &SMatrix<f64, D, D>) -> Vec<f64> {
    let m = DMatrix::from_fn(D, D, |r, c| j[(r, c)]);
    let mut logs: Vec<f64> = m
        .complex_eigenvalues()
        .iter()
        .map(|e| e.norm().ln())
        .collect();
    logs.sort_by(|a, b| b.total_cmp(a));
    logs
}

/// DU^p at the orbit's point from the ladder, and the change in ln|μ|
/// between the neighbours of the estimate kept (its error estimate; per
/// unit time it is that over the orbit's time).
///
/// Each pair of neighbouring rungs is combined by Richardson's
/// extrapolation, (r²·J(δ) - J(r·δ))/(r² - 1) with r = √10: central
/// differences' error is c·δ² + O(δ⁴), so the combination removes it.
/// Where the map is nonlinear (an impact's saltation depends on the state)
/// c is of order 1 and the δ² term, not rounding, limits a single rung:
/// at the rung balancing c·δ² against rounding ε/δ (δ ≈ 2e-5) both are
/// near 5e-10 in ln|μ|, beyond the 1e-10 an orbit's exponents are held
/// to; extrapolated, the balance moves to δ⁴ against ε/δ, near 1e-11. On
/// a linear flow every rung is the same up to rounding, and so is the
/// combination. The combination kept is the one whose multipliers change
/// least towards both neighbouring combinations.
pub fn refined_jacobian<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    orbit: &Orbit<D>,
) -> (SMatrix<f64, D, D>, f64)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let refined = refine(system, settings, orbit, None);
    (refined.jacobian, refined.error)
}

/// A Jacobian re-estimated over the ladder.
#[derive(Clone, Copy, Debug)]
pub struct Refined<const D: usize> {
    pub jacobian: SMatrix<f64, D, D>,
    /// The change in ln|μ| towards the neighbouring combinations.
    pub error: f64,
    /// The combination kept: rungs `combination` and `combination + 1`
    /// (0 where none gave finite multipliers).
    pub combination: usize,
}

/// [`refined_jacobian`], tried first at a combination `near` = (c, most)
/// suggests (a neighbouring orbit's on the branch): only the four rungs
/// that combination and its two neighbours need, kept when its error is
/// at most `most`. The whole ladder otherwise. Neighbouring orbits of a
/// branch meet the same nonlinearity at the same δ, so the combination
/// kept moves rarely; where it does, or where the error grows, the whole
/// ladder decides as before.
pub fn refine<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    orbit: &Orbit<D>,
    near: Option<(usize, f64)>,
) -> Refined<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let last = RUNGS as usize;
    let mut plain = vec![None; last + 1];
    if let Some((c, most)) = near.filter(|(c, _)| (1..last - 1).contains(c)) {
        fill(system, settings, orbit, &mut plain, c - 1..=c + 2);
        let known: Vec<_> = plain[c - 1..=c + 2].iter().flatten().copied().collect();
        let combinations = combined(&known);
        let error = error_of(&combinations, 1);
        if error <= most {
            return Refined {
                jacobian: combinations[1].0,
                error,
                combination: c,
            };
        }
    }
    // The whole ladder, with the rungs already had.
    fill(system, settings, orbit, &mut plain, 0..=last);
    let plain: Vec<_> = plain.into_iter().flatten().collect();
    let combinations = combined(&plain);
    let (combination, error) = (1..combinations.len() - 1)
        .map(|k| (k, error_of(&combinations, k)))
        .filter(|(_, e)| !e.is_nan())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::INFINITY));
    Refined {
        jacobian: combinations[combination].0,
        error,
        combination,
    }
}

/// Rungs `ks` of the ladder not yet in `plain`: DU^p at δ·10^(k/2), rung
/// 0 the orbit's own estimate. The rungs are independent estimates: each
/// on a core of its own where one is free (a branch traced one way leaves
/// the other idle).
fn fill<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    orbit: &Orbit<D>,
    plain: &mut [Option<SMatrix<f64, D, D>>],
    ks: std::ops::RangeInclusive<usize>,
) where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let missing: Vec<usize> = ks.filter(|&k| plain[k].is_none()).collect();
    let found: Vec<SMatrix<f64, D, D>> = missing
        .par_iter()
        .map(|&k| {
            if k == 0 {
                return orbit.jacobian;
            }
            let rung = MethodSettings {
                perturbation: settings.perturbation * 10f64.powf(k as f64 / 2.0),
                ..settings.clone()
            };
            evaluate(system, &rung, &orbit.state, orbit.period, true).jacobian
        })
        .collect();
    for (k, j) in missing.into_iter().zip(found) {
        plain[k] = Some(j);
    }
}

/// Neighbouring rungs combined by Richardson's extrapolation, with their
/// ln|μ_i|.
fn combined<const D: usize>(plain: &[SMatrix<f64, D, D>]) -> Vec<(SMatrix<f64, D, D>, Vec<f64>)> {
    plain
        .windows(2)
        .map(|pair| {
            let j = (pair[0] * 10.0 - pair[1]) / 9.0;
            let logs = log_moduli(&j);
            (j, logs)
        })
        .collect()
}

/// The largest change of ln|μ| from combination `k` to either neighbour.
fn error_of<const D: usize>(combinations: &[(SMatrix<f64, D, D>, Vec<f64>)], k: usize) -> f64 {
    let change = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
    };
    let left = change(&combinations[k - 1].1, &combinations[k].1);
    let right = change(&combinations[k].1, &combinations[k + 1].1);
    left.max(right)
}
