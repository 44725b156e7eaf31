//! What a lane produces, and the statuses that say which of its numbers
//! to doubt.

use crate::integrate::MAX_EVENTS;

use super::plan::LanePlan;
use super::settings::MethodSettings;

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
    /// A sliding motion that is not integrated yet (against a wall or an
    /// event, on switches whose signs multiply in the field, or on two
    /// switches at once in the exact propagator), in this many
    /// iterations: the exponents are not to be trusted.
    Sliding {
        iterations: usize,
    },
    /// A direction contracts, in one iteration, to near the rounding noise of
    /// the finite difference, so the most negative exponents are not to be
    /// trusted: `bound` estimates their error per unit time from the relative
    /// noise ε = noise / min R_ii of each iteration, (⟨ε²⟩/2 + √(⟨ε²⟩/N)) / T.
    /// Shorten the map period.
    Unresolved {
        bound: f64,
    },
    /// Impacts with e = 0 (rank 1 lost) or sticking (2 lost: the resting
    /// mass's position and velocity, all of a 2-state system) collapse
    /// phase space: the last `exponents` exponents are -∞, exactly.
    Collapsed {
        exponents: usize,
    },
    /// Near-grazing iterations whose best finite difference still leaves
    /// an estimated exponent error `bound` per unit time above the limit
    /// (see [`estimate_resolving_grazing`]).
    Grazing {
        iterations: usize,
        bound: f64,
    },
    /// A GPU lane that its CPU recomputation contradicts (see
    /// `driver::validation_difference`) beyond the precision's tolerance.
    Mismatch {
        difference: f64,
    },
    /// A Poincaré map's trajectory did not come back to its section within
    /// the return bound at `iteration` (from the start of the transient):
    /// the lane stopped, with no exponents.
    NoReturn {
        iteration: usize,
    },
    /// A trajectory of the lane (its reference or a perturbed copy) met
    /// more located events in one iteration (or sub-map) than
    /// [`MAX_EVENTS_PER_ITERATION`](crate::integrate::MAX_EVENTS_PER_ITERATION)
    /// at `iteration` (from the start of the transient): the lane stopped
    /// there, with no exponents.
    TooManyEvents {
        iteration: usize,
    },
    /// The lane's fastest time scale needs more RK4 steps per period than
    /// [`MAX_STEPS_PER_PERIOD`](super::plan::MAX_STEPS_PER_PERIOD): it was not run.
    TooManySteps {
        needed: usize,
    },
    /// A start of a basin image's grid lies outside the admissible states
    /// at this value (behind a stop, beyond an event's surface): it was not
    /// run, and its start is labelled apart.
    Inadmissible,
    /// The exponents' sum misses the sum rule by `miss` per unit time, more
    /// than the precision's tolerance (`driver::sum_rule_tolerance`): an
    /// error no other check caught, which every exponent may carry.
    SumRule {
        miss: f64,
    },
    /// The averaging time is short against the flow's own time scales:
    /// `scales` of its slowest mode's 1/|μ| (`SystemInfo::slowest_rate`),
    /// fewer than `driver::SHORT_AVERAGE`. The exponents are an average
    /// over a stretch of the motion, not yet its asymptotic rates.
    ShortAverage {
        scales: f64,
    },
    /// The row's error estimate (`LaneResult::error`) is above its
    /// tolerance (`driver::error_tolerance`), or could not be made.
    Uncertain {
        error: f64,
    },
    /// A basin image's lane that stopped after transient iteration
    /// `iteration` (from 0), its reference having stayed within the
    /// attractor tolerance of a known attractor's point (see
    /// `early_stop`): its numbers are that attractor's lane's, its
    /// convergence time and kept points its own.
    EarlyStop {
        iteration: usize,
    },
}

impl LaneStatus {
    /// The status's name, as the CSV column starts.
    pub fn name(&self) -> &'static str {
        match self {
            LaneStatus::Ok => "ok",
            LaneStatus::NonFinite { .. } => "non-finite",
            LaneStatus::Chattering { .. } => "chattering",
            LaneStatus::Sliding { .. } => "sliding",
            LaneStatus::Unresolved { .. } => "unresolved",
            LaneStatus::Collapsed { .. } => "collapsed",
            LaneStatus::Grazing { .. } => "grazing",
            LaneStatus::Mismatch { .. } => "gpu-mismatch",
            LaneStatus::TooManySteps { .. } => "too-many-steps",
            LaneStatus::Inadmissible => "inadmissible-start",
            LaneStatus::TooManyEvents { .. } => "too-many-events",
            LaneStatus::NoReturn { .. } => "no-return",
            LaneStatus::SumRule { .. } => "sum-rule",
            LaneStatus::ShortAverage { .. } => "short-average",
            LaneStatus::Uncertain { .. } => "uncertain",
            LaneStatus::EarlyStop { .. } => "early-stop",
        }
    }

    /// Whether the lane gave no exponents at all (a run in which every lane
    /// failed exits with an error); other statuses flag numbers to doubt.
    pub fn is_failure(&self) -> bool {
        matches!(
            self,
            LaneStatus::NonFinite { .. }
                | LaneStatus::NoReturn { .. }
                | LaneStatus::TooManySteps { .. }
                | LaneStatus::TooManyEvents { .. }
                | LaneStatus::Inadmissible
        )
    }
}

impl std::fmt::Display for LaneStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LaneStatus::Ok => write!(f, "ok"),
            LaneStatus::NonFinite { iteration } => write!(f, "non-finite(iteration={iteration})"),
            LaneStatus::Chattering { iterations } => {
                write!(f, "chattering(iterations={iterations})")
            }
            LaneStatus::Sliding { iterations } => write!(f, "sliding(iterations={iterations})"),
            LaneStatus::Unresolved { bound } => write!(f, "unresolved(bound={bound:.1e})"),
            LaneStatus::Collapsed { exponents } => write!(f, "collapsed(exponents={exponents})"),
            // The count is in the `grazing` column; no comma in a CSV field.
            LaneStatus::Grazing { bound, .. } => write!(f, "grazing(bound={bound:.1e})"),
            LaneStatus::Mismatch { difference } => {
                write!(f, "gpu-mismatch(difference={difference:.1e})")
            }
            LaneStatus::TooManySteps { needed } => {
                write!(f, "too-many-steps(needed={:.1e})", *needed as f64)
            }
            LaneStatus::Inadmissible => write!(f, "inadmissible-start"),
            LaneStatus::SumRule { miss } => write!(f, "sum-rule(miss={miss:.1e})"),
            LaneStatus::ShortAverage { scales } => write!(f, "short-average(scales={scales:.1e})"),
            LaneStatus::Uncertain { error } => write!(f, "uncertain(error={error:.1e})"),
            LaneStatus::NoReturn { iteration } => write!(f, "no-return(iteration={iteration})"),
            LaneStatus::TooManyEvents { iteration } => {
                write!(f, "too-many-events(iteration={iteration})")
            }
            LaneStatus::EarlyStop { iteration } => write!(f, "early-stop(iteration={iteration})"),
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
    /// Of these, the impacts on each wall of the system, in its order
    /// (`MAX_EVENTS` numbers; NaN like `impacts_per_period` when it is).
    pub crossings_per_period: [f64; MAX_EVENTS],
    /// The map period T (of a Poincaré map, the mean return time).
    pub period: f64,
    /// The period of the orbit in map iterations, from its last points
    /// (see [`RecentPoints`](super::orbit::RecentPoints)): `None` when
    /// aperiodic, or when its period exceeds the settings' `max_period`.
    pub orbit_period: Option<usize>,
    /// The orbit's last points, oldest first, D numbers each: its
    /// `orbit_period` points, or when it has none the last 2·max_period
    /// (fewer if fewer were taken). The last point is the lane's final
    /// state: what a neighbouring value is continued from. Empty unless the
    /// settings keep it (`keep_orbit`: runs with `[attractors]` or `[orbits]`).
    pub orbit: Vec<f64>,
    /// The iterations from the start until the reference came within the
    /// attractor tolerance of its orbit for good (see `settling`): with
    /// `keep_settling` only, `None` otherwise and for a failed lane.
    pub settled: Option<usize>,
    /// A term of the sum rule that depends on the orbit, per unit time: a
    /// Poincaré map's ln |F_k(x_0)/F_k(x_n)| over the averaging time (0
    /// for a period map).
    pub orbit_term: f64,
    /// The last `bifurcation_points` reference points, D numbers each.
    pub bifurcation: Vec<f64>,
    /// Every iteration's Jacobian, row-major, when `keep_jacobians` is set.
    pub jacobians: Vec<f64>,
    /// Averaging iterations re-estimated as grazing (see
    /// [`estimate_resolving_grazing`]).
    pub grazing: usize,
    /// Their estimated error per unit time in the exponents:
    /// Σ (error in ln R_ii) / (N·T); 0 without grazing iterations.
    pub grazing_bound: f64,
    /// The exponents' estimated error per unit time (see
    /// `uncertainty`): what the frame's start still puts into λ1 plus the
    /// largest standard error of the block means. NaN without exponents,
    /// or where fewer than two blocks were averaged.
    pub error: f64,
    /// How the lane's iterations were cut.
    pub plan: LanePlan,
    pub status: LaneStatus,
}

impl LaneResult {
    pub fn exponent_sum(&self) -> f64 {
        self.exponents.iter().sum()
    }
}

/// The result of a lane that was not run because its plan needs more than
/// [`MAX_STEPS_PER_PERIOD`](super::plan::MAX_STEPS_PER_PERIOD) steps: no exponents (NaN), no points.
pub fn not_run(
    settings: &MethodSettings,
    dimension: usize,
    period: f64,
    plan: LanePlan,
) -> LaneResult {
    LaneResult {
        exponents: if settings.lyapunov {
            vec![f64::NAN; dimension]
        } else {
            Vec::new()
        },
        impacts_per_period: f64::NAN,
        crossings_per_period: [f64::NAN; MAX_EVENTS],
        period,
        orbit_period: None,
        orbit: Vec::new(),
        settled: None,
        orbit_term: f64::NAN,
        bifurcation: Vec::new(),
        jacobians: Vec::new(),
        grazing: 0,
        grazing_bound: f64::NAN,
        error: f64::NAN,
        plan,
        status: LaneStatus::TooManySteps {
            needed: plan.steps_per_period,
        },
    }
}
