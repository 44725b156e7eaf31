//! Bifurcations of a branch's orbits from their multipliers, each located
//! on the branch to a tolerance in the parameter: a fold (a multiplier
//! through +1, det(DU^p - I) = 0), a period doubling (through -1,
//! det(DU^p + I) = 0), a Neimark–Sacker point (a complex pair through
//! |μ| = 1, Π_{i<j}(μ_i·μ_j - 1) = 0 with the pair complex).
//!
//! A fold is where λ turns back, so no bracket in λ holds it: the search
//! runs along the chord between two branch points, each trial corrected
//! onto the branch orthogonally to the chord (the continuation's own
//! corrector), by regula falsi (Illinois) in the chord's fraction. λ is
//! quadratic in that fraction at a fold, so it is found to the square of
//! the fraction's error.

use nalgebra::{Const, DVector, DimMin};

use super::continuation::{correct, point, BranchPoint, ContinuationSettings};
use super::newton::{Failure, NewtonSettings};
use crate::method::MethodSettings;
use crate::system::{Params, System};

/// What kind of bifurcation a test function detects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Fold,
    PeriodDoubling,
    NeimarkSacker,
}

impl Kind {
    pub const ALL: [Kind; 3] = [Kind::Fold, Kind::PeriodDoubling, Kind::NeimarkSacker];

    pub fn name(self) -> &'static str {
        match self {
            Kind::Fold => "fold",
            Kind::PeriodDoubling => "period-doubling",
            Kind::NeimarkSacker => "neimark-sacker",
        }
    }

    /// The test function of a branch point: zero at the bifurcation,
    /// changing sign through it.
    pub fn test<const D: usize>(self, point: &BranchPoint<D>) -> f64 {
        // det(DU^p ∓ I) = Π(μ_i ∓ 1), from the multipliers already had.
        let m = &point.floquet.multipliers;
        let one = nalgebra::Complex::new(1.0, 0.0);
        let product = match self {
            Kind::Fold => m.iter().fold(one, |p, mu| p * (mu - 1.0)),
            Kind::PeriodDoubling => m.iter().fold(one, |p, mu| p * (mu + 1.0)),
            Kind::NeimarkSacker => {
                let mut product = one;
                for i in 0..m.len() {
                    for k in i + 1..m.len() {
                        product *= m[i] * m[k] - 1.0;
                    }
                }
                product
            }
        };
        product.re
    }

    /// Whether a zero of the test at `point` is this bifurcation: its
    /// critical multiplier on the unit circle (within [`ON_THE_CIRCLE`]),
    /// +1 for a fold, -1 for a period doubling, a complex pair of modulus
    /// 1 for Neimark–Sacker (a real pair with μ_i·μ_j = 1 is a neutral
    /// saddle, no bifurcation).
    fn on_the_unit_circle<const D: usize>(self, point: &BranchPoint<D>) -> bool {
        point.floquet.multipliers.iter().any(|m| match self {
            Kind::Fold => (m - 1.0).norm() <= ON_THE_CIRCLE,
            Kind::PeriodDoubling => (m + 1.0).norm() <= ON_THE_CIRCLE,
            Kind::NeimarkSacker => m.im != 0.0 && (m.norm() - 1.0).abs() <= ON_THE_CIRCLE,
        })
    }
}

/// How near the unit circle a located bifurcation's critical multiplier
/// must be. A test function det(DU^p ∓ I) also changes sign where a
/// multiplier jumps through infinity (a grazing impact's square root
/// makes DU^p blow up), and its "zero" there has no multiplier near ±1
/// (measured on the seed's period-2 branch: 4742 and 2.05); a true one
/// located to 1e-10 in the parameter has its multiplier within 1e-7.
pub const ON_THE_CIRCLE: f64 = 1e-3;

/// A located bifurcation.
#[derive(Clone, Debug)]
pub struct Bifurcation<const D: usize> {
    pub kind: Kind,
    /// The branch point at the bifurcation (its λ, orbit, multipliers).
    pub point: BranchPoint<D>,
    /// The change in λ of the search's last step (its error estimate).
    pub error: f64,
    /// Corrector solves the search took.
    pub solves: usize,
}

/// Every fold, period doubling and Neimark–Sacker point between
/// consecutive points of `points` (a branch followed by
/// [`super::continue_branch`] with `continuation`), located to
/// `tolerance` in λ. A search that fails (the corrector does not converge
/// on the chord) leaves that bifurcation out, so does a zero whose
/// critical multiplier is not on the unit circle (a test function's sign
/// change through infinity, see [`ON_THE_CIRCLE`]), and so does a pair with a
/// point whose multipliers fail the sum rule ([`super::Floquet::trustworthy`]):
/// within ~v² of a grazing (v the impact's speed) the perturbed copies
/// meet the wall differently from the orbit, and the test functions'
/// signs there are noise.
pub fn bifurcations<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    continuation: &ContinuationSettings,
    points: &[BranchPoint<D>],
    tolerance: f64,
) -> Vec<Bifurcation<D>>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let mut found = Vec::new();
    for pair in points.windows(2) {
        if !pair.iter().all(|p| p.floquet.trustworthy()) {
            continue;
        }
        for kind in Kind::ALL {
            let (ga, gb) = (kind.test(&pair[0]), kind.test(&pair[1]));
            if ga.signum() == gb.signum() || ga.is_nan() || gb.is_nan() {
                continue;
            }
            let search = locate_on_chord::<D, S>(
                base,
                settings,
                newton,
                continuation,
                (&pair[0], &pair[1]),
                kind,
                tolerance,
            );
            if let Ok(b) = search {
                if kind.on_the_unit_circle(&b.point) {
                    found.push(b);
                }
            }
        }
    }
    found
}

/// The zero of `kind`'s test function between branch points `a` and `b`
/// (of opposite signs), along their chord.
pub fn locate_on_chord<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    newton: &NewtonSettings,
    continuation: &ContinuationSettings,
    (a, b): (&BranchPoint<D>, &BranchPoint<D>),
    kind: Kind,
    tolerance: f64,
) -> Result<Bifurcation<D>, Failure>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let y = |p: &BranchPoint<D>| {
        DVector::from_fn(
            D + 1,
            |i, _| if i < D { p.orbit.state[i] } else { p.parameter },
        )
    };
    let (ya, yb) = (y(a), y(b));
    let chord = &yb - &ya;
    let t = chord.normalize();
    let (mut low, mut high) = ((0.0, kind.test(a)), (1.0, kind.test(b)));
    let (mut best, mut last_lambda, mut error) = (a.clone(), a.parameter, f64::INFINITY);
    let mut side = 0;
    let mut solves = 0;
    while error > tolerance && solves < 100 {
        let sigma = low.0 - low.1 * (high.0 - low.0) / (high.1 - low.1);
        let predictor = &ya + &chord * sigma;
        solves += 1;
        let (orbit, lambda, _) = correct::<D, S>(
            base,
            settings,
            newton,
            continuation,
            &predictor,
            &t,
            a.orbit.period,
        )?;
        let here = point::<D, S>(base, settings, continuation.parameter, lambda, orbit);
        let g = kind.test(&here);
        error = (lambda - last_lambda).abs();
        last_lambda = lambda;
        best = here;
        // Illinois: halve the value of an end kept twice in a row.
        if g.signum() == low.1.signum() {
            low = (sigma, g);
            if side == -1 {
                high.1 *= 0.5;
            }
            side = -1;
        } else {
            high = (sigma, g);
            if side == 1 {
                low.1 *= 0.5;
            }
            side = 1;
        }
        if g == 0.0 {
            break;
        }
    }
    Ok(Bifurcation {
        kind,
        point: best,
        error,
        solves,
    })
}
