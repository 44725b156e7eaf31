//! One lane: the whole method for one parameter value.
//!
//! Discard `transient` iterations of the reference, the last `align` of
//! them with their Jacobians, which turn the QR frame from I towards the
//! directions of growth without being counted; then run `iterations`
//! iterations, each giving the next reference point and the map's Jacobian
//! there (estimated from perturbed copies, or exact), and accumulate QR. A
//! lane that goes non-finite stops and says so; it never touches another
//! lane.
//!
//! [`MethodSettings`] is what the backends run: its `transient` is the
//! iterations without Jacobians, and its `iterations` begin with the
//! `align` ones, which [`LaneAccumulator`] takes for the frame alone. Every
//! backend gets the alignment that way, by running the settings it is
//! given.

use crate::integrate::MAX_EVENTS;
use nalgebra::{Const, DimMin, SMatrix};

use super::jacobian;
use super::qr::QrAccumulator;
use crate::integrate::clock::{Phase, ZERO_PHASE};
pub use crate::perturbation::perturbation_at;
use crate::system::{FlowSettings, IterationStats, Params, Part, System};

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
    /// Iterations of the reference alone, discarded.
    pub transient: usize,
    /// Iterations with Jacobians: the first `align` of them turn the QR
    /// frame only (the scene's transient's last ones), the others are
    /// averaged.
    pub iterations: usize,
    pub align: usize,
    pub initial_state: Vec<f64>,
    /// δ of the perturbed copies, relative to the state's size: the copies
    /// of x_n start at x_n ± δ·max(1, ‖x_n‖∞)·e_i (see [`perturbation_at`]).
    pub perturbation: f64,
    /// Forward (the paper's) or central differences.
    pub difference: jacobian::Difference,
    pub flow: FlowSettings,
    pub tangent: Tangent,
    /// Whether to compute exponents at all (`[output] lyapunov`).
    pub lyapunov: bool,
    /// How many of the last reference points to keep.
    pub bifurcation_points: usize,
    /// Parts per iteration when the scene fixes them (else [`plan_lane`]'s).
    pub submaps: Option<usize>,
    /// Whether rounding accumulates over the RK4 steps of an iteration (f64),
    /// or is compensated (the f32 kernels' Kahan update): with the number of
    /// steps, sets the smallest contraction the finite difference resolves.
    pub rounding_accumulates: bool,
    /// Keep every iteration's Jacobian in the result (for comparing backends).
    pub keep_jacobians: bool,
    /// The unit roundoff of the arithmetic the images are computed in
    /// (f64::EPSILON, or f32::EPSILON on the GPU's f32 path).
    pub rounding_unit: f64,
}

impl MethodSettings {
    /// The relative rounding noise of a finite-difference column after
    /// `steps` steps ([`difference_noise`] of an image of size 1): the
    /// steps count only where rounding accumulates.
    pub fn column_noise(&self, steps: usize) -> f64 {
        let steps = if self.rounding_accumulates { steps } else { 1 };
        difference_noise(self.rounding_unit, 1.0, steps, self.perturbation)
    }
}

/// The noise in a finite-difference column: the rounding of an image of
/// size `scale`, accumulated over the `steps` of one iteration, over δ.
/// An R_ii near it is mostly rounding.
pub fn difference_noise(unit: f64, scale: f64, steps: usize, delta: f64) -> f64 {
    unit * scale.max(1.0) * (steps as f64).sqrt() / delta
}

/// The estimated exponent error per unit time from finite-difference noise
/// (see [`LaneStatus::Unresolved`]) above which a lane is flagged.
pub const RESOLUTION_BOUND: f64 = 1e-3;

/// RK4 step times the system's stiffness above which a lane's steps are
/// raised: RK4 is stable up to 2.78, and at 0.1 the fastest mode's
/// per-step growth factor is right to a relative (0.1)⁴/120 ≈ 1e-6.
pub const MAX_STEP_RATE: f64 = 0.1;
/// RK4 steps per map period above which a lane is not run: one lane would
/// take hours (η = 1e-9 of the seed's oscillator, a period of 6e9 natural
/// time units, needs 6e10), and the clock and step counters lose their
/// resolution. Such a lane says `too-many-steps`.
pub const MAX_STEPS_PER_PERIOD: usize = 100_000_000;

/// An exponent a sliding phase may have collapsed is taken as collapsed
/// (-∞) where its mean ln R_ii per Jacobian is below ln of this many times
/// the finite difference's rounding noise ([`difference_noise`]): a
/// collapsed direction's R_ii is that rounding, and the sub-maps keep a
/// direction that only contracts 1/PART_NOISE above it.
const COLLAPSE_FLOOR: f64 = 10.0;

/// Relative rounding noise allowed in a part's most contracted column.
/// Its bias in an exponent is about PART_NOISE²/2 per part's time.
const PART_NOISE: f64 = 1e-2;

/// How one lane's iterations are cut, from its system's time scales.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LanePlan {
    /// RK4 steps per period: the requested ones, or more where the
    /// requested step would leave the fastest time scale unresolved (stiff
    /// damping; a natural period far shorter than the forcing period).
    pub steps_per_period: usize,
    /// Parts per iteration (sub-maps, see [`Part`]): enough that the
    /// fastest contraction over one part stays above the finite
    /// difference's rounding noise by a factor 1/`PART_NOISE`.
    pub parts: usize,
}

impl LanePlan {
    /// Whether a lane may run on this plan (see [`MAX_STEPS_PER_PERIOD`]).
    pub fn affordable(&self) -> bool {
        self.steps_per_period <= MAX_STEPS_PER_PERIOD
    }
}

/// The result of a lane that was not run because its plan needs more than
/// [`MAX_STEPS_PER_PERIOD`] steps: no exponents (NaN), no points.
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
        orbit_term: f64::NAN,
        bifurcation: Vec::new(),
        jacobians: Vec::new(),
        grazing: 0,
        grazing_bound: f64::NAN,
        plan,
        status: LaneStatus::TooManySteps {
            needed: plan.steps_per_period,
        },
    }
}

/// The plan of a lane of system `S` (see [`LanePlan`]).
pub fn plan_lane<const D: usize, S: System<D>>(system: &S, settings: &MethodSettings) -> LanePlan {
    let period = system.period();
    let requested = settings.flow.steps_per_period;
    let (stiffness, contraction) = system.time_scales(&settings.initial_state, &settings.flow);
    let needed = (period * stiffness / MAX_STEP_RATE).ceil();
    // A plan over MAX_STEPS_PER_PERIOD is not run (`LanePlan::affordable`);
    // `as` saturates an infinite or overflowing need.
    let steps_per_period = if needed > requested as f64 {
        needed as usize
    } else {
        requested
    };
    let contraction = period * contraction;
    let parts = if let Some(fixed) = settings.submaps {
        fixed.clamp(1, steps_per_period)
    } else if settings.lyapunov && contraction > 0.0 {
        let noise = settings.column_noise(steps_per_period);
        // ln of the contraction one part may have; at least e, so that the
        // parts never outnumber |λ_min|·T.
        let allowed = (PART_NOISE / noise).ln().max(1.0);
        ((contraction / allowed).ceil() as usize).clamp(1, steps_per_period)
    } else {
        1
    };
    LanePlan {
        steps_per_period,
        parts,
    }
}

/// The Jacobian of one part of an iteration (the whole iteration, or a
/// sub-map) from the reference's state x at the part's start, by
/// [`estimate_resolving_grazing`], row-major, with what happened
/// (`dispatch::Runner::reestimate`).
pub fn reestimate_of<const D: usize, S: System<D>>(
    params: &Params,
    settings: &MethodSettings,
    part: Part,
    x: &[f64],
) -> (Vec<f64>, IterationStats)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let system = S::new(params);
    let x: [f64; D] = std::array::from_fn(|i| x[i]);
    let mut stats = IterationStats::default();
    // The forcing phase at the part's start, advanced through the earlier
    // parts exactly as the reference's was (no trajectory rides along).
    let mut phase = ZERO_PHASE;
    for earlier in Part::all(part.count).take(part.index) {
        system.part_many(&mut [], &settings.flow, earlier, &mut phase, &mut []);
    }
    let (_, j) = estimate_resolving_grazing(
        &system,
        &settings.flow,
        settings,
        part,
        &mut phase,
        &x,
        &mut stats,
    );
    (j.transpose().iter().copied().collect(), stats)
}

/// Whether an estimate with this nonlinearity and Jacobian is a grazing
/// iteration worth re-estimating: its truncation error in ln R_ii (the
/// nonlinearity, or its square for central differences, times the
/// Jacobian's Hadamard ratio) is above [`GRAZING_ERROR`] and above the
/// rounding error the same estimate carries anyway (the relative noise of a
/// column, u·√(steps accumulated)/δ, times the same ratio). Below the
/// rounding, a smaller δ can only trade truncation for more rounding: in
/// f64 that never decides (the noise is ~1e-8), but f32's δ = 2e-4 has
/// noise 6e-4: a threshold below that rounding had the host of an f32 GPU
/// run re-estimate thousands of the seed's iterations for nothing
/// (docs/BENCHMARKS.md, "f32's perturbation δ").
pub fn is_grazing<const D: usize>(
    settings: &MethodSettings,
    steps_per_part: usize,
    nonlinearity: f64,
    j: &SMatrix<f64, D, D>,
) -> bool
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (_, log_hadamard) = log_diagonal(j);
    let ratio = log_hadamard.exp();
    let suspect = nonlinearity.powi(settings.difference.order()) * ratio;
    let rounding = settings.column_noise(steps_per_part) * ratio;
    !suspect.is_nan() && suspect > GRAZING_ERROR.max(rounding)
}

/// [`plan_lane`] from parameter values (`dispatch::Runner::plan`).
pub fn plan_of<const D: usize, S: System<D>>(
    params: &Params,
    settings: &MethodSettings,
) -> LanePlan {
    plan_lane(&S::new(params), settings)
}

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
    /// `backend::validation_difference`) beyond the precision's tolerance.
    Mismatch {
        difference: f64,
    },
    /// A Poincaré map's trajectory did not come back to its section within
    /// the return bound at `iteration` (from the start of the transient):
    /// the lane stopped, with no exponents.
    NoReturn {
        iteration: usize,
    },
    /// The lane's fastest time scale needs more RK4 steps per period than
    /// [`MAX_STEPS_PER_PERIOD`]: it was not run.
    TooManySteps {
        needed: usize,
    },
    /// The exponents' sum misses the sum rule by `miss` per unit time, more
    /// than the precision's tolerance (`backend::sum_rule_tolerance`): an
    /// error no other check caught, which every exponent may carry.
    SumRule {
        miss: f64,
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
            LaneStatus::NoReturn { .. } => "no-return",
            LaneStatus::SumRule { .. } => "sum-rule",
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
            LaneStatus::SumRule { miss } => write!(f, "sum-rule(miss={miss:.1e})"),
            LaneStatus::NoReturn { iteration } => write!(f, "no-return(iteration={iteration})"),
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
    /// How the lane's iterations were cut.
    pub plan: LanePlan,
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
    let plan = plan_lane(&system, settings);
    if !plan.affordable() {
        return not_run(settings, D, system.period(), plan);
    }
    let flow = &FlowSettings {
        steps_per_period: plan.steps_per_period,
        ..settings.flow
    };
    let mut x = system.start(&settings.initial_state, flow);
    if !all_finite(&x) {
        let mut acc = LaneAccumulator::<D>::new(settings, system.period(), plan);
        acc.fail_at(0, &x);
        return acc.finish();
    }
    let mut discard = IterationStats::default();
    for n in 0..settings.transient {
        // The exact backend's transient is exact too: it is the ground truth.
        x = match settings.tangent {
            Tangent::FiniteDifference => system.iterate(&x, flow, &mut discard),
            Tangent::Exact => {
                system
                    .iterate_exact(&x, Part::WHOLE, &mut discard)
                    .expect("the exact backend is only offered for systems with a closed form")
                    .0
            }
        };
        system.wrap(&mut x);
        if !all_finite(&x) {
            let mut acc = LaneAccumulator::<D>::new(settings, system.period(), plan);
            acc.fail_at(n, &x);
            return acc.finish();
        }
    }
    average(&system, settings, plan, x)
}

/// [`run_lane`] for neighbouring lanes of a sweep: where they share their
/// plan's steps (and use finite differences), their transients run as one
/// batch, the references stepped together ([`System::iterate_lanes`]);
/// where the system allows it ([`System::averages_across_lanes`]) they
/// then average in lockstep (`average_lanes`), else each on its own.
/// Every lane's numbers are those of [`run_lane`], to the last bit.
pub fn run_lanes<const D: usize, S: System<D>>(lanes: &[Lane]) -> Vec<LaneResult>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let Some(first) = lanes.first() else {
        return Vec::new();
    };
    let settings = first.settings;
    let systems: Vec<S> = lanes.iter().map(|l| S::new(&l.params)).collect();
    let plans: Vec<LanePlan> = systems.iter().map(|s| plan_lane(s, settings)).collect();
    let together = lanes.len() > 1
        && settings.tangent == Tangent::FiniteDifference
        && lanes.iter().all(|l| std::ptr::eq(l.settings, settings))
        && plans
            .iter()
            .all(|p| p.affordable() && p.steps_per_period == plans[0].steps_per_period);
    if !together {
        return lanes.iter().map(run_lane::<D, S>).collect();
    }
    let flow = &FlowSettings {
        steps_per_period: plans[0].steps_per_period,
        ..settings.flow
    };
    let mut xs: Vec<[f64; D]> = systems
        .iter()
        .map(|s| s.start(&settings.initial_state, flow))
        .collect();
    let each: Vec<&S> = systems.iter().collect();
    let mut discard = vec![IterationStats::default(); lanes.len()];
    // A lane that fails goes on being stepped with the others (its
    // numbers touch no other lane's) but is reported at its first failure.
    let mut failed: Vec<Option<(usize, bool)>> = xs
        .iter()
        .map(|x| (!all_finite(x)).then(|| (0, crate::system::is_no_return(x))))
        .collect();
    for n in 0..settings.transient {
        discard.fill(IterationStats::default());
        S::iterate_lanes(&each, &mut xs, flow, &mut discard);
        for (system, x) in systems.iter().zip(xs.iter_mut()) {
            system.wrap(x);
        }
        for (k, x) in xs.iter().enumerate() {
            if failed[k].is_none() && !all_finite(x) {
                failed[k] = Some((n, crate::system::is_no_return(x)));
            }
        }
    }
    let lockstep = settings.lyapunov
        && plans.iter().all(|p| p.parts == 1)
        && systems.iter().all(|s| s.averages_across_lanes());
    let accumulators = systems
        .iter()
        .zip(&plans)
        .zip(&failed)
        .map(|((system, &plan), failed)| {
            let mut acc = LaneAccumulator::<D>::new(settings, system.period(), plan);
            if let Some((n, no_return)) = *failed {
                acc.fail(n);
                acc.no_return = no_return;
            }
            acc
        })
        .collect();
    if lockstep {
        return average_lanes(&systems, settings, flow, accumulators, xs);
    }
    systems
        .iter()
        .zip(plans)
        .zip(xs.into_iter().zip(accumulators))
        .map(|((system, plan), (x, acc))| match acc.failed_at {
            Some(_) => acc.finish(),
            None => average(system, settings, plan, x),
        })
        .collect()
}

/// The averaging iterations of neighbouring lanes in lockstep, from their
/// transients' ends `xs` (for lanes of one whole part per iteration, with
/// exponents): each iteration integrates every lane's reference and copies
/// as batches across lanes, so a lane's three or five trajectories no
/// longer wait on their own chains' latencies, then takes each lane's
/// Jacobian and accumulates it as [`average`] does. A grazing iteration is
/// re-estimated by that lane alone ([`resolve_grazing`]), and a lane that
/// fails stops being stepped. Every lane's numbers are [`average`]'s.
fn average_lanes<const D: usize, S: System<D>>(
    systems: &[S],
    settings: &MethodSettings,
    flow: &FlowSettings,
    mut accumulators: Vec<LaneAccumulator<D>>,
    mut xs: Vec<[f64; D]>,
) -> Vec<LaneResult>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let mut live: Vec<usize> = (0..systems.len())
        .filter(|&k| accumulators[k].failed_at.is_none())
        .collect();
    let (mut owners, mut ys, mut st) = (Vec::new(), Vec::new(), Vec::new());
    let mut copies = Vec::with_capacity(live.len());
    for _ in 0..settings.iterations {
        if live.is_empty() {
            break;
        }
        copies.clear();
        owners.clear();
        ys.clear();
        for &k in &live {
            let delta = perturbation_at(settings.perturbation, &xs[k]);
            let c = jacobian::Copies::new(&systems[k], &xs[k], delta, settings.difference);
            ys.extend_from_slice(c.starts());
            owners.extend(std::iter::repeat_n(&systems[k], c.count()));
            copies.push(c);
        }
        st.clear();
        st.resize(ys.len(), IterationStats::default());
        S::iterate_lanes(&owners, &mut ys, flow, &mut st);
        let mut from = 0;
        let mut lane = copies.iter();
        live.retain(|&k| {
            let c = lane.next().expect("a lane's copies");
            let (system, x) = (&systems[k], xs[k]);
            let to = from + c.count();
            // As `step` takes a whole-part iteration: the part's statistics
            // from zero, merged into the iteration's.
            let mut part_stats = IterationStats::default();
            let mut first = part_stats;
            let estimate = c.difference(&ys[from..to], &st[from..to], &mut first);
            from = to;
            let (mut next, j) = resolve_grazing(
                system,
                flow,
                settings,
                Part::WHOLE,
                ZERO_PHASE,
                &x,
                &mut part_stats,
                first,
                estimate,
            );
            let mut stats = IterationStats::default();
            stats.merge(&part_stats);
            system.wrap(&mut next);
            xs[k] = next;
            accumulators[k].push(&next, &[j], &stats)
        });
    }
    accumulators
        .into_iter()
        .map(LaneAccumulator::finish)
        .collect()
}

/// The averaging iterations of a lane from x, the end of its transient.
fn average<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    plan: LanePlan,
    mut x: [f64; D],
) -> LaneResult
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let flow = &FlowSettings {
        steps_per_period: plan.steps_per_period,
        ..settings.flow
    };
    let mut acc = LaneAccumulator::<D>::new(settings, system.period(), plan);
    let mut jacobians = Vec::with_capacity(plan.parts);
    for _ in 0..settings.iterations {
        let mut stats = IterationStats::default();
        jacobians.clear();
        let mut next = step::<D, S>(system, flow, settings, plan, &x, &mut stats, &mut jacobians);
        // After the Jacobian: its columns are differences of unwrapped images.
        system.wrap(&mut next);
        if !acc.push(&next, &jacobians, &stats) {
            break;
        }
        x = next;
    }
    acc.finish()
}

/// Everything a lane accumulates over its averaging iterations, whichever
/// backend produced the iterations: the QR sums, the impact count, the
/// health counters and the kept bifurcation points.
#[derive(Clone, Debug)]
pub struct LaneAccumulator<const D: usize> {
    qr: QrAccumulator<D>,
    period: f64,
    plan: LanePlan,
    transient: usize,
    /// Iterations that turn the frame before the averaging, and how many
    /// of them have been taken.
    align: usize,
    aligned: usize,
    /// Iterations averaged (the settings' less the aligning ones).
    iterations: usize,
    lyapunov: bool,
    /// The first averaged iteration whose point is kept.
    first_kept: usize,
    /// Rounding unit and δ of the run, for the resolution bound.
    noise: Option<(f64, f64, usize)>,
    done: usize,
    impacts: u64,
    crossings: [u64; MAX_EVENTS],
    /// Σ of the iterations' own times and flux terms (Poincaré maps).
    time: f64,
    log_flux: f64,
    chattering: usize,
    sliding: usize,
    grazing: usize,
    grazing_error: f64,
    /// Jacobians taken (iterations × parts).
    parts_done: usize,
    /// The most dimensions any iteration collapsed for certain (sliding on
    /// that many switches at once, an impact with e = 0, sticking on a
    /// stop).
    rank_loss: usize,
    /// The most dimensions any iteration may have collapsed: its sliding
    /// phases, one per switch entered (see `finish`).
    rank_loss_bound: usize,
    noise_squares: f64,
    /// Σ ln of the finite difference's rounding noise over the Jacobians taken.
    log_noise: f64,
    bifurcation: Vec<f64>,
    jacobians: Option<Vec<f64>>,
    failed_at: Option<usize>,
    /// Whether the failure was a Poincaré map's trajectory not coming back
    /// (`NoReturn`), not a point that blew up.
    no_return: bool,
}

impl<const D: usize> LaneAccumulator<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    pub fn new(settings: &MethodSettings, period: f64, plan: LanePlan) -> Self {
        let iterations = settings.iterations - settings.align;
        let kept = settings.bifurcation_points.min(iterations);
        let steps_per_part = if settings.rounding_accumulates {
            plan.steps_per_period / plan.parts
        } else {
            1
        };
        LaneAccumulator {
            qr: QrAccumulator::new(),
            period,
            plan,
            transient: settings.transient,
            align: settings.align,
            aligned: 0,
            iterations,
            lyapunov: settings.lyapunov,
            first_kept: iterations - kept,
            noise: (settings.tangent == Tangent::FiniteDifference).then_some((
                settings.rounding_unit,
                settings.perturbation,
                steps_per_part,
            )),
            done: 0,
            impacts: 0,
            crossings: [0; MAX_EVENTS],
            time: 0.0,
            log_flux: 0.0,
            chattering: 0,
            sliding: 0,
            grazing: 0,
            grazing_error: 0.0,
            parts_done: 0,
            rank_loss: 0,
            rank_loss_bound: 0,
            noise_squares: 0.0,
            log_noise: 0.0,
            bifurcation: Vec::with_capacity(kept * D),
            jacobians: settings.keep_jacobians.then(Vec::new),
            failed_at: None,
            no_return: false,
        }
    }

    /// Takes one iteration with Jacobians (aligning, then averaging): the reference's new point, the
    /// Jacobians of the map's parts in order (none when exponents are not
    /// wanted) and what happened on the way. Returns false once the lane
    /// has failed.
    pub fn push(
        &mut self,
        next: &[f64; D],
        jacobians: &[SMatrix<f64, D, D>],
        stats: &IterationStats,
    ) -> bool {
        if !all_finite(next) {
            self.fail_at(self.taken(), next);
            return false;
        }
        let scale = next.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        self.record(scale, Some(next), jacobians, stats)
    }

    /// [`push`](Self::push) for a backend that has checked the point itself
    /// and reports only its size `scale` = max |x_i| (the noise estimate's
    /// scale), and the point only when bifurcation points are wanted.
    pub fn record(
        &mut self,
        scale: f64,
        point: Option<&[f64; D]>,
        jacobians: &[SMatrix<f64, D, D>],
        stats: &IterationStats,
    ) -> bool {
        if self.failed_at.is_some() {
            return false;
        }
        let n = self.done;
        if jacobians.iter().any(|j| !j.iter().all(|v| v.is_finite())) {
            self.fail(self.taken());
            return false;
        }
        let aligning = self.aligned < self.align;
        if let Some(kept) = self.jacobians.as_mut().filter(|_| !aligning) {
            for j in jacobians {
                kept.extend(j.transpose().iter());
            }
        }
        // An iteration that collapsed phase space (an impact with e = 0,
        // sticking) has a Jacobian of rank D - loss: its last `loss` R_ii are
        // zero in exact arithmetic and rounding here, and the exponents they
        // feed are -∞ (set in `finish`). When nothing is left (loss = D),
        // the frame Q is kept as it is. Sliding phases on several switches
        // one after the other may collapse up to one direction each
        // (`bound`): those R_ii may be rounding too.
        let loss = (stats.rank_loss as usize).min(D);
        let bound = (stats.sliding_phases as usize).max(loss).min(D);
        let kept = D - bound;
        let noise = self.noise.map(|(unit, delta, steps)| {
            difference_noise(unit, scale, steps, delta * scale.max(1.0))
        });
        for j in jacobians.iter().filter(|_| loss < D) {
            let diag = match noise {
                Some(noise) if bound > 0 => {
                    self.qr.push_collapsing(j, COLLAPSE_FLOOR * noise, bound)
                }
                _ => self.qr.push(j),
            };
            if !diag[..kept].iter().all(|r| r.ln().is_finite()) {
                // A singular Jacobian: a direction contracted below what δ and
                // rounding can resolve in one iteration.
                self.fail(self.taken());
                return false;
            }
            if aligning {
                continue;
            }
            if let Some(noise) = noise {
                self.log_noise += noise.ln();
                if bound == 0 {
                    let smallest = diag.iter().fold(f64::INFINITY, |m, &r| m.min(r));
                    self.noise_squares += (noise / smallest).powi(2);
                }
            }
        }
        if aligning {
            self.aligned += 1;
            if self.aligned == self.align {
                self.qr.restart_sums();
            }
            return true;
        }
        self.rank_loss = self.rank_loss.max(loss);
        self.rank_loss_bound = self.rank_loss_bound.max(bound);
        self.parts_done += jacobians.len();
        self.impacts += u64::from(stats.impacts);
        for (c, &s) in self.crossings.iter_mut().zip(&stats.crossings) {
            *c += u64::from(s);
        }
        self.time += stats.time;
        self.log_flux += stats.log_flux;
        self.chattering += usize::from(stats.chattering);
        self.sliding += usize::from(stats.sliding);
        self.grazing += usize::from(stats.grazing);
        self.grazing_error += stats.grazing_error;
        if let (true, Some(point)) = (n >= self.first_kept, point) {
            self.bifurcation.extend_from_slice(point);
        }
        self.done += 1;
        true
    }

    /// The iterations taken so far, counted from the start of the transient:
    /// the index of the next one.
    fn taken(&self) -> usize {
        self.transient + self.aligned + self.done
    }

    /// Marks the lane failed at `iteration` (counted from the start of the transient).
    pub fn fail(&mut self, iteration: usize) {
        self.failed_at.get_or_insert(iteration);
    }

    /// Marks the lane failed at `iteration` on the non-finite point `x`:
    /// [`LaneStatus::NoReturn`] where `x` is a Poincaré map's image of no
    /// return, else [`LaneStatus::NonFinite`].
    pub fn fail_at(&mut self, iteration: usize, x: &[f64]) {
        if self.failed_at.is_none() {
            self.no_return = crate::system::is_no_return(x);
        }
        self.fail(iteration);
    }

    /// The lane's result after all its iterations.
    pub fn finish(mut self) -> LaneResult {
        // A Poincaré map's iterations take their own times: the period is
        // their mean, so that exponents are per unit of the total time.
        let orbit_term = if self.time > 0.0 {
            self.period = self.time / self.done.max(1) as f64;
            self.log_flux / self.time
        } else if self.log_flux != 0.0 {
            self.log_flux / (self.done.max(1) as f64 * self.period)
        } else {
            0.0
        };
        if let Some(iteration) = self.failed_at {
            return LaneResult {
                exponents: if self.lyapunov {
                    vec![f64::NAN; D]
                } else {
                    Vec::new()
                },
                impacts_per_period: f64::NAN,
                crossings_per_period: [f64::NAN; MAX_EVENTS],
                period: self.period,
                orbit_term: f64::NAN,
                bifurcation: self.bifurcation,
                jacobians: self.jacobians.unwrap_or_default(),
                grazing: self.grazing,
                grazing_bound: f64::NAN,
                plan: self.plan,
                status: if self.no_return {
                    LaneStatus::NoReturn { iteration }
                } else {
                    LaneStatus::NonFinite { iteration }
                },
            };
        }
        // With relative noise ε_n in the smallest R_ii, ln R_ii is biased by
        // about -ε_n²/2 and scattered by ε_n; over N Jacobians (iterations ×
        // parts) of time τ each that bounds the exponent error by
        // (⟨ε²⟩/2 + √(⟨ε²⟩/N)) / τ.
        let taken = self.parts_done.max(1) as f64;
        let part_time = if self.time > 0.0 {
            self.time / taken
        } else {
            self.period / self.plan.parts as f64
        };
        let mean_square = self.noise_squares / taken;
        let resolution_bound = (0.5 * mean_square + (mean_square / taken).sqrt()) / part_time;
        let exponents = if self.lyapunov {
            let mut e = if self.time > 0.0 {
                self.qr.exponents_over(self.time)
            } else {
                self.qr.exponents(part_time)
            }
            .to_vec();
            e.sort_by(|a, b| b.total_cmp(a));
            // Directions beyond the certain ones that sliding phases may
            // have collapsed: collapsed where the finite differences saw
            // nothing in them above their own rounding, on average over
            // the Jacobians (a direction that contracts for real is kept
            // well above it by the sub-maps' plan, PART_NOISE).
            if self.noise.is_some() && self.parts_done > 0 {
                let floor = self.log_noise / taken + COLLAPSE_FLOOR.ln();
                while self.rank_loss < self.rank_loss_bound
                    && e[D - 1 - self.rank_loss] * part_time < floor
                {
                    self.rank_loss += 1;
                }
            }
            for x in &mut e[D - self.rank_loss..] {
                *x = f64::NEG_INFINITY;
            }
            e
        } else {
            Vec::new()
        };
        let grazing_bound = self.grazing_error / (self.done.max(1) as f64 * self.period);
        let status = if self.chattering > 0 {
            LaneStatus::Chattering {
                iterations: self.chattering,
            }
        } else if self.sliding > 0 {
            LaneStatus::Sliding {
                iterations: self.sliding,
            }
        } else if resolution_bound > RESOLUTION_BOUND {
            LaneStatus::Unresolved {
                bound: resolution_bound,
            }
        } else if self.rank_loss > 0 && self.lyapunov {
            LaneStatus::Collapsed {
                exponents: self.rank_loss,
            }
        } else if grazing_bound > RESOLUTION_BOUND {
            LaneStatus::Grazing {
                iterations: self.grazing,
                bound: grazing_bound,
            }
        } else {
            LaneStatus::Ok
        };
        LaneResult {
            exponents,
            impacts_per_period: self.impacts as f64 / self.iterations as f64,
            crossings_per_period: self.crossings.map(|c| c as f64 / self.iterations as f64),
            period: self.period,
            orbit_term,
            bifurcation: self.bifurcation,
            jacobians: self.jacobians.unwrap_or_default(),
            grazing: self.grazing,
            grazing_bound,
            plan: self.plan,
            status,
        }
    }
}

/// One averaging iteration: the reference image, with the Jacobians of
/// the iteration's parts pushed onto `jacobians` when exponents are wanted.
#[allow(clippy::too_many_arguments)]
fn step<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    settings: &MethodSettings,
    plan: LanePlan,
    x: &[f64; D],
    stats: &mut IterationStats,
    jacobians: &mut Vec<SMatrix<f64, D, D>>,
) -> [f64; D]
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    match settings.tangent {
        Tangent::Exact => {
            let mut y = *x;
            for part in Part::all(plan.parts) {
                let (next, j) = system
                    .iterate_exact(&y, part, stats)
                    .expect("the exact backend is only offered for systems with a closed form");
                if settings.lyapunov {
                    jacobians.push(j);
                }
                y = next;
            }
            y
        }
        Tangent::FiniteDifference if settings.lyapunov => {
            if let Some(next) = system.tangent_factors(
                x,
                flow,
                settings.perturbation,
                settings.difference,
                stats,
                jacobians,
            ) {
                return next;
            }
            let (mut y, mut phase) = (*x, ZERO_PHASE);
            for part in Part::all(plan.parts) {
                let mut part_stats = IterationStats::default();
                let (next, j) = estimate_resolving_grazing(
                    system,
                    flow,
                    settings,
                    part,
                    &mut phase,
                    &y,
                    &mut part_stats,
                );
                stats.merge(&part_stats);
                jacobians.push(j);
                y = next;
            }
            y
        }
        Tangent::FiniteDifference => system.iterate(x, flow, stats),
    }
}

/// A grazing iteration: its estimated error in ln R_ii is above this. The
/// estimate is the copies' nonlinearity (forward differences) or its square
/// (central), times the Jacobian's Hadamard ratio Π‖column‖ / |det|: near
/// grazing the Jacobian is nearly of rank one with large entries, and the
/// contracting part, which sets the smallest exponents and the sum, is a
/// small difference of large numbers.
///
/// Measured: at 1e-6 forward differences at δ = 1e-8 flagged nearly every
/// impacting iteration of a periodic orbit (nonlinearity ~1e-7 times a ratio
/// of ~10), and the ladder made the paper-recipe comparison 5 times slower
/// for an error of 1e-8 instead of 5e-8. Real grazing iterations score far
/// above 1 (2e5 at the seed sweep's worst value), so 1e-4 separates them.
pub const GRAZING_ERROR: f64 = 1e-4;
/// The δ ladder of a grazing iteration: rungs δ·10^(-k/2), k = 1..=RUNGS,
/// down to the rounding floor. Twenty rungs reach ten decades below δ: from
/// f32's 2e-4 (the GPU host re-estimates in f64 at the scene's δ) they reach
/// the f64 floor, where eight rungs stopped at 2e-8 and missed the seed's
/// worst value by 1.2e-3.
const GRAZING_RUNGS: i32 = 20;

/// ln R_ii of J's QR factorisation, and ln of J's Hadamard ratio.
fn log_diagonal<const D: usize>(j: &SMatrix<f64, D, D>) -> ([f64; D], f64)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (_, r) = super::qr::qr_positive(*j);
    let log_r: [f64; D] = std::array::from_fn(|i| r[(i, i)].ln());
    let log_columns: f64 = (0..D).map(|i| j.column(i).norm().ln()).sum();
    (log_r, log_columns - log_r.iter().sum::<f64>())
}

/// The Jacobian estimate of one iteration; near grazing, the best of a
/// ladder of smaller δ.
///
/// A slow impact at speed v bends the map on the scale δ·a/v² (a the
/// acceleration at the wall), and a copy may meet the wall once more or
/// less than the reference; the copies then leave the linear regime
/// (`IterationStats::nonlinearity`). Such an iteration is re-estimated at
/// δ·10^(-k/2) down to the rounding floor; the estimate kept is the one
/// that changes least towards the next smaller δ (where truncation has
/// stopped mattering and rounding has not started to), and that change is
/// its error estimate. The reference image is the same whatever δ.
pub fn estimate_resolving_grazing<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    settings: &MethodSettings,
    part: Part,
    phase: &mut Phase,
    x: &[f64; D],
    stats: &mut IterationStats,
) -> ([f64; D], SMatrix<f64, D, D>)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let delta = perturbation_at(settings.perturbation, x);
    let start = *phase;
    let mut first = *stats;
    let estimate = jacobian::estimate(
        system,
        flow,
        part,
        phase,
        x,
        delta,
        settings.difference,
        &mut first,
    );
    resolve_grazing(
        system, flow, settings, part, start, x, stats, first, estimate,
    )
}

/// The rest of [`estimate_resolving_grazing`] once the first estimate
/// (U(x), DU(x) at the scene's δ, with its statistics `first`) is taken:
/// kept unless the iteration grazes, else the δ ladder from `start`, the
/// forcing phase at the part's start. `stats` are those before the
/// estimate, and after it on return.
#[allow(clippy::too_many_arguments)]
fn resolve_grazing<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    settings: &MethodSettings,
    part: Part,
    start: Phase,
    x: &[f64; D],
    stats: &mut IterationStats,
    first: IterationStats,
    (image, j0): ([f64; D], SMatrix<f64, D, D>),
) -> ([f64; D], SMatrix<f64, D, D>)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let delta = perturbation_at(settings.perturbation, x);
    // A collapsed iteration's Jacobian is singular by nature, not by error.
    let steps_per_part = flow.steps_per_period / part.count;
    if first.rank_loss > 0 || !is_grazing(settings, steps_per_part, first.nonlinearity, &j0) {
        *stats = first;
        return (image, j0);
    }
    let (log0, _) = log_diagonal(&j0);
    // Rungs sit half a decade apart, so a plateau two rungs wide is a
    // decade of δ. The rounding floor: relative noise u·√steps/δ of 1e-2 in an image-sized
    // column; the ladder itself finds where rounding starts to matter.
    let floor = perturbation_at(
        settings.rounding_unit * (flow.steps_per_period as f64 / part.count as f64).sqrt() * 1e2,
        x,
    );
    let mut rungs = vec![(j0, log0, first)];
    for k in 1..=GRAZING_RUNGS {
        let d = delta * 10f64.powf(-f64::from(k) / 2.0);
        if d < floor {
            break;
        }
        let mut st = *stats;
        let mut again = start;
        let (_, j) = jacobian::estimate(
            system,
            flow,
            part,
            &mut again,
            x,
            d,
            settings.difference,
            &mut st,
        );
        let (log_r, _) = log_diagonal(&j);
        rungs.push((j, log_r, st));
    }
    let change = |a: &[f64; D], b: &[f64; D]| {
        let sum = (a.iter().sum::<f64>() - b.iter().sum::<f64>()).abs();
        a.iter().zip(b).fold(sum, |m, (x, y)| m.max((x - y).abs()))
    };
    // A rung's error: its larger change towards either neighbour, so that
    // two rungs agreeing by chance in the rounding noise do not pass for a
    // plateau.
    let (best, error) = (1..rungs.len().saturating_sub(1))
        .map(|k| {
            let left = change(&rungs[k - 1].1, &rungs[k].1);
            let right = change(&rungs[k].1, &rungs[k + 1].1);
            (k, left.max(right))
        })
        .filter(|(_, e)| !e.is_nan())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::INFINITY));
    let (j, _, st) = rungs.swap_remove(best);
    *stats = IterationStats {
        grazing: true,
        grazing_error: error,
        ..st
    };
    (image, j)
}

fn all_finite(x: &[f64]) -> bool {
    x.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{self, Backend, Precision};

    fn settings(precision: &str) -> MethodSettings {
        let text = format!(
            "[system]\nkind = \"impact-oscillator\"\n[sweep]\nvalues = [0.7]\n[run]\nprecision = \"{precision}\"\n"
        );
        let scene = scene::parse(&text, "test", "test", &[]).expect("scene");
        let precision = if precision == "f32" {
            Precision::F32
        } else {
            Precision::F64
        };
        crate::plan::method_settings(&scene, Backend::Gpu, precision)
    }

    #[test]
    fn grazing_is_truncation_above_the_estimate_s_own_rounding() {
        let (f64s, f32s) = (settings("f64"), settings("f32"));
        assert_eq!(f32s.perturbation, 2e-4);
        // Columns (1, 0) and (1, 0.1): Hadamard ratio |c2|/R22 = 10.05.
        let j = SMatrix::<f64, 2, 2>::new(1.0, 1.0, 0.0, 0.1);
        // Central differences: truncation nonlinearity²·ratio. At 1e-2 it
        // is 1e-3: above GRAZING_ERROR and f64's rounding (u·√1800/1e-6
        // ·ratio ≈ 9e-8), below f32's (u/2e-4·ratio ≈ 6e-3).
        assert!(is_grazing(&f64s, 1800, 1e-2, &j));
        assert!(!is_grazing(&f32s, 1800, 1e-2, &j));
        // At 0.1 (1e-1 of truncation) both re-estimate; at 1e-3 neither.
        assert!(is_grazing(&f64s, 1800, 0.1, &j));
        assert!(is_grazing(&f32s, 1800, 0.1, &j));
        assert!(!is_grazing(&f64s, 1800, 1e-3, &j));
        assert!(!is_grazing(&f32s, 1800, 1e-3, &j));
    }
}
