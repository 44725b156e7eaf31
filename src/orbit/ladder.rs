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
    let mut rung = settings.clone();
    let plain: Vec<SMatrix<f64, D, D>> = (0..=RUNGS)
        .map(|k| {
            rung.perturbation = settings.perturbation * 10f64.powf(f64::from(k) / 2.0);
            if k == 0 {
                orbit.jacobian
            } else {
                evaluate(system, &rung, &orbit.state, orbit.period, true).jacobian
            }
        })
        .collect();
    let rungs: Vec<(SMatrix<f64, D, D>, Vec<f64>)> = plain
        .windows(2)
        .map(|pair| {
            let j = (pair[0] * 10.0 - pair[1]) / 9.0;
            let logs = log_moduli(&j);
            (j, logs)
        })
        .collect();
    let change = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
    };
    let (best, error) = (1..rungs.len() - 1)
        .map(|k| {
            let left = change(&rungs[k - 1].1, &rungs[k].1);
            let right = change(&rungs[k].1, &rungs[k + 1].1);
            (k, left.max(right))
        })
        .filter(|(_, e)| !e.is_nan())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::INFINITY));
    (rungs[best].0, error)
}
