//! One lane: the whole method for one parameter value.
//!
//! Discard `transient` iterations of the reference; then, with Q = I, run
//! `iterations` iterations, each giving the next reference point and the
//! map's Jacobian there (estimated from perturbed copies, or exact), and
//! accumulate QR. A lane that goes non-finite stops and says so; it never
//! touches another lane.

use nalgebra::{Const, DimMin, SMatrix};

use super::jacobian::forward_difference;
use super::qr::QrAccumulator;
use crate::system::{FlowSettings, IterationStats, Params, System};

/// Where each iteration's Jacobian comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tangent {
    /// The paper's method: forward differences of perturbed copies.
    FiniteDifference,
    /// The closed-form tangent map (the `exact` backend).
    Exact,
}

/// The settings shared by every lane of a sweep.
#[derive(Clone, Debug)]
pub struct MethodSettings {
    pub transient: usize,
    pub iterations: usize,
    pub initial_state: Vec<f64>,
    /// δ of the perturbed copies.
    pub perturbation: f64,
    pub flow: FlowSettings,
    pub tangent: Tangent,
    /// Whether to compute exponents at all (`[output] lyapunov`).
    pub lyapunov: bool,
    /// How many of the last reference points to keep.
    pub bifurcation_points: usize,
    /// Rounding operations that accumulate in one iteration's image (the RK4
    /// steps of a flow, 1 for a map): sets the smallest contraction the
    /// finite difference resolves.
    pub steps_per_iteration: usize,
}

impl MethodSettings {
    /// The noise in a finite-difference column: the rounding of an image of
    /// size `scale`, accumulated over the steps of one iteration, over δ.
    /// An R_ii near it is mostly rounding.
    pub fn difference_noise(&self, scale: f64) -> f64 {
        f64::EPSILON * scale.max(1.0) * (self.steps_per_iteration as f64).sqrt() / self.perturbation
    }
}

/// The estimated exponent error per unit time from finite-difference noise
/// (see [`LaneStatus::Unresolved`]) above which a lane is flagged.
pub const RESOLUTION_BOUND: f64 = 1e-3;

/// One parameter value of a sweep.
#[derive(Clone, Debug)]
pub struct Lane<'a> {
    pub params: Params,
    pub settings: &'a MethodSettings,
}

/// Why a lane's numbers should not be trusted, if they should not.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LaneStatus {
    Ok,
    /// The state or a Jacobian became NaN or infinite; the lane stopped.
    /// `iteration` counts from the start of the transient.
    NonFinite {
        iteration: usize,
    },
    /// Impacts accumulated faster than a step can resolve (or the mass was
    /// pressed into the wall) in this many iterations.
    Chattering {
        iterations: usize,
    },
    /// A direction contracts, in one iteration, to near the rounding noise of
    /// the finite difference, so the most negative exponents are not to be
    /// trusted: `bound` estimates their error per unit time (mean over
    /// iterations of noise / min R_ii, over T). Shorten the map period.
    Unresolved {
        bound: f64,
    },
}

impl std::fmt::Display for LaneStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LaneStatus::Ok => write!(f, "ok"),
            LaneStatus::NonFinite { iteration } => write!(f, "non-finite(iteration={iteration})"),
            LaneStatus::Chattering { iterations } => {
                write!(f, "chattering(iterations={iterations})")
            }
            LaneStatus::Unresolved { bound } => write!(f, "unresolved(bound={bound:.1e})"),
        }
    }
}

/// What one lane produced.
#[derive(Clone, Debug, PartialEq)]
pub struct LaneResult {
    /// Exponents per unit time, non-increasing; empty without `lyapunov`,
    /// NaN after a non-finite failure.
    pub exponents: Vec<f64>,
    /// Reference impacts per map iteration, over the averaging iterations.
    pub impacts_per_period: f64,
    /// The map period T.
    pub period: f64,
    /// The last `bifurcation_points` reference points, D numbers each.
    pub bifurcation: Vec<f64>,
    pub status: LaneStatus,
}

impl LaneResult {
    pub fn exponent_sum(&self) -> f64 {
        self.exponents.iter().sum()
    }
}

/// Runs the method for one lane on system `S` of dimension `D`.
pub fn run_lane<const D: usize, S: System<D>>(lane: &Lane) -> LaneResult
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let settings = lane.settings;
    let system = S::new(&lane.params);
    let period = system.period();
    let flow = &settings.flow;
    let failed = |iteration: usize, bifurcation: Vec<f64>| LaneResult {
        exponents: if settings.lyapunov {
            vec![f64::NAN; D]
        } else {
            Vec::new()
        },
        impacts_per_period: f64::NAN,
        period,
        bifurcation,
        status: LaneStatus::NonFinite { iteration },
    };

    let mut x: [f64; D] = std::array::from_fn(|i| settings.initial_state[i]);
    let mut discard = IterationStats::default();
    for n in 0..settings.transient {
        x = system.iterate(&x, flow, &mut discard);
        if !all_finite(&x) {
            return failed(n, Vec::new());
        }
    }

    let mut qr = QrAccumulator::<D>::new();
    let mut bifurcation = Vec::with_capacity(settings.bifurcation_points * D);
    let first_kept = settings.iterations - settings.bifurcation_points.min(settings.iterations);
    let (mut impacts, mut chattering, mut noise_over_r) = (0u64, 0usize, 0.0);
    for n in 0..settings.iterations {
        let mut stats = IterationStats::default();
        let (next, jacobian) = step::<D, S>(&system, flow, settings, &x, &mut stats);
        let healthy = all_finite(&next)
            && jacobian
                .as_ref()
                .is_none_or(|j| j.iter().all(|v| v.is_finite()));
        if !healthy {
            return failed(settings.transient + n, bifurcation);
        }
        if let Some(j) = jacobian {
            let diag = qr.push(&j);
            if !diag.iter().all(|r| r.ln().is_finite()) {
                // A singular Jacobian: a direction contracted below what δ and
                // rounding can resolve in one iteration.
                return failed(settings.transient + n, bifurcation);
            }
            if settings.tangent == Tangent::FiniteDifference {
                let scale = next.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                let smallest = diag.iter().fold(f64::INFINITY, |m, &r| m.min(r));
                noise_over_r += settings.difference_noise(scale) / smallest;
            }
        }
        impacts += u64::from(stats.impacts);
        chattering += usize::from(stats.chattering);
        if n >= first_kept {
            bifurcation.extend_from_slice(&next);
        }
        x = next;
    }

    let resolution_bound = noise_over_r / (settings.iterations as f64 * period);
    let exponents = if settings.lyapunov {
        let mut e = qr.exponents(period).to_vec();
        e.sort_by(|a, b| b.total_cmp(a));
        e
    } else {
        Vec::new()
    };
    LaneResult {
        exponents,
        impacts_per_period: impacts as f64 / settings.iterations as f64,
        period,
        bifurcation,
        status: if chattering > 0 {
            LaneStatus::Chattering {
                iterations: chattering,
            }
        } else if resolution_bound > RESOLUTION_BOUND {
            LaneStatus::Unresolved {
                bound: resolution_bound,
            }
        } else {
            LaneStatus::Ok
        },
    }
}

/// One averaging iteration: the reference image and, when exponents are
/// wanted, the Jacobian there.
fn step<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    settings: &MethodSettings,
    x: &[f64; D],
    stats: &mut IterationStats,
) -> ([f64; D], Option<SMatrix<f64, D, D>>) {
    match settings.tangent {
        Tangent::Exact => {
            let (next, j) = system
                .iterate_exact(x, stats)
                .expect("the exact backend is only offered for systems with a closed form");
            (next, settings.lyapunov.then_some(j))
        }
        Tangent::FiniteDifference => {
            let next = system.iterate(x, flow, stats);
            let j = settings
                .lyapunov
                .then(|| forward_difference(system, flow, x, &next, settings.perturbation, stats));
            (next, j)
        }
    }
}

fn all_finite(x: &[f64]) -> bool {
    x.iter().all(|v| v.is_finite())
}
