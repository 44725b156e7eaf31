//! An orbit's Floquet multipliers (the eigenvalues μ_i of DU^p) and its
//! asymptotic exponents ln|μ_i| / (p·T), stable and unstable orbits alike,
//! with the sum rule checked as for every lane's row.

use nalgebra::{Complex, Const, DMatrix, DimMin};

use super::ladder::refine;
use super::newton::Orbit;
use crate::method::MethodSettings;
use crate::system::{Params, System};

/// What the multipliers say of an orbit.
#[derive(Clone, Debug, PartialEq)]
pub struct Floquet {
    /// The eigenvalues of DU^p, largest modulus first (a complex pair
    /// adjacent, positive imaginary part first).
    pub multipliers: Vec<Complex<f64>>,
    /// ln|μ_i| / time, in the multipliers' order (largest first).
    pub exponents: Vec<f64>,
    /// The exponent sum the system's volume law predicts for the orbit's
    /// crossings per unit time, plus its flux term (a state-dependent
    /// divergence, a section's return): what a lane's row is checked
    /// against.
    pub expected_sum: f64,
    /// The change in ln|μ_i| between the δ ladder's rungs around the one
    /// kept ([`super::ladder`]); 0 where the orbit's own estimate was used.
    pub ladder_error: f64,
    /// The ladder's combination kept ([`super::ladder::Refined`]), which
    /// the branch's next orbit tries first.
    pub ladder_combination: usize,
}

impl Floquet {
    /// Σ exponents - expected sum.
    pub fn sum_error(&self) -> f64 {
        self.exponents.iter().sum::<f64>() - self.expected_sum
    }

    /// Whether the multipliers pass the sum rule to 1e-6 per unit time:
    /// their product is the volume law's. An estimate that fails it (the
    /// perturbed copies of an orbit within ~v² of grazing meet the wall
    /// differently from it) says nothing of the multipliers' crossings.
    pub fn trustworthy(&self) -> bool {
        self.sum_error().abs() <= 1e-6
    }

    /// Whether every multiplier lies inside the unit circle.
    pub fn stable(&self) -> bool {
        self.multipliers.iter().all(|m| m.norm() < 1.0)
    }
}

/// The multipliers and exponents of `orbit` of the system at `params`.
pub fn floquet<const D: usize>(orbit: &Orbit<D>, params: &Params) -> Floquet {
    let j = DMatrix::from_fn(D, D, |r, c| orbit.jacobian[(r, c)]);
    let mut multipliers: Vec<Complex<f64>> = j.complex_eigenvalues().iter().copied().collect();
    multipliers.sort_by(|a, b| b.norm().total_cmp(&a.norm()).then(b.im.total_cmp(&a.im)));
    let exponents = multipliers
        .iter()
        .map(|m| m.norm().ln() / orbit.time)
        .collect();
    let rates: Vec<f64> = orbit
        .stats
        .crossings
        .iter()
        .map(|&c| f64::from(c) / orbit.time)
        .collect();
    let expected_sum =
        (params.info.expected_sum)(params, &rates) + orbit.stats.log_flux / orbit.time;
    Floquet {
        multipliers,
        exponents,
        expected_sum,
        ladder_error: 0.0,
        ladder_combination: 0,
    }
}

/// [`floquet`] of the orbit's Jacobian re-estimated over the δ ladder
/// ([`super::ladder::refined_jacobian`]), which replaces the orbit's own.
pub fn refined_floquet<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    params: &Params,
    orbit: &mut Orbit<D>,
) -> Floquet
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    refined_floquet_near(system, settings, params, orbit, None)
}

/// [`refined_floquet`], the ladder tried first where the multipliers of
/// `near` (a neighbouring orbit of the branch) were found: its
/// combination, kept if its error is at most [`LADDER_DRIFT`] times that
/// orbit's, or [`LADDER_FLOOR`] per unit time (see [`refine`]).
pub fn refined_floquet_near<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    params: &Params,
    orbit: &mut Orbit<D>,
    near: Option<&Floquet>,
) -> Floquet
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let hint = near.map(|f| {
        let most = (LADDER_DRIFT * f.ladder_error).max(LADDER_FLOOR * orbit.time);
        (f.ladder_combination, most)
    });
    let refined = refine(system, settings, orbit, hint);
    orbit.jacobian = refined.jacobian;
    Floquet {
        ladder_error: refined.error,
        ladder_combination: refined.combination,
        ..floquet(orbit, params)
    }
}

/// How much larger than its neighbour's a ladder combination's error may
/// be for it to be kept without the whole ladder.
pub const LADDER_DRIFT: f64 = 4.0;

/// A ladder error per unit time that is always small enough to keep
/// (see [`LADDER_DRIFT`]): a tenth of the 1e-10 an orbit's exponents
/// are held to.
pub const LADDER_FLOOR: f64 = 1e-11;
