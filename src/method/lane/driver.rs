//! One lane driven alone: its transient, then its averaging iterations,
//! each cut into the parts its plan asks for.

use nalgebra::{Const, DimMin, SMatrix};

use super::accumulator::{all_finite, LaneAccumulator};
use super::early_stop::{stopped, KnownOrbit, Watch};
use super::grazing::estimate_resolving_grazing;
use super::plan::{plan_lane, LanePlan};
use super::result::{not_run, LaneResult};
use super::settings::{MethodSettings, Tangent};
use super::settling::{attractor_tolerance, Settling};
use crate::integrate::clock::ZERO_PHASE;
use crate::system::{FlowSettings, IterationStats, Params, Part, System};

/// One parameter value of a sweep, from one start.
#[derive(Clone, Debug)]
pub struct Lane<'a> {
    pub params: Params,
    pub settings: &'a MethodSettings,
    /// The state the lane starts from (the scene's `initial_state`, or
    /// one of its `[attractors]` starts).
    pub initial_state: Vec<f64>,
    /// The periodic orbits known at its value that it may stop early on
    /// (`settings.early_stop`; none: it runs whole).
    pub known: &'a [KnownOrbit],
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
        ..settings.flow.clone()
    };
    let mut x = system.start(&lane.initial_state, flow);
    if !all_finite(&x) {
        let mut acc = LaneAccumulator::<D>::new(settings, system.period(), plan);
        acc.fail_at(0, &x, &IterationStats::default());
        return acc.finish();
    }
    let mut settling = settings.keep_settling.then(Settling::default);
    if let Some(s) = settling.as_mut() {
        s.push(&x);
    }
    let tolerance = attractor_tolerance(settings.rounding_unit);
    // Early stops need the points from the start, for the convergence time.
    let mut watch = settling
        .as_ref()
        .and_then(|_| Watch::new(lane.known, settings.early_stop, tolerance));
    let mut discard = IterationStats::default();
    for n in 0..settings.transient {
        if settings.flow.stop.requested() {
            break;
        }
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
            acc.fail_at(n, &x, &discard);
            return acc.finish();
        }
        if let Some(s) = settling.as_mut() {
            s.push(&x);
            if let Some(orbit) = watch.as_mut().and_then(|w| w.sees(&x)) {
                return stopped(orbit, n, s, tolerance, settings.bifurcation_points);
            }
        }
    }
    let mut acc = LaneAccumulator::<D>::new(settings, system.period(), plan);
    if let Some(s) = settling {
        acc.settle_from(s);
    }
    average(&system, settings, plan, x, acc)
}

/// The averaging iterations of a lane from x, the end of its transient,
/// into `acc` (new, or holding the points before them).
pub(super) fn average<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    plan: LanePlan,
    mut x: [f64; D],
    mut acc: LaneAccumulator<D>,
) -> LaneResult
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let flow = &FlowSettings {
        steps_per_period: plan.steps_per_period,
        ..settings.flow.clone()
    };
    let mut jacobians = Vec::with_capacity(plan.parts);
    for _ in 0..settings.iterations {
        if settings.flow.stop.requested() {
            break;
        }
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
            estimated_iteration(system, flow, settings, plan.parts, x, stats, jacobians)
        }
        Tangent::FiniteDifference => system.iterate(x, flow, stats),
    }
}

/// One iteration's image, with the Jacobians of its parts pushed onto
/// `jacobians` in order: a section's tangent factors where the system
/// gives them, else each part's estimate from the perturbed copies, with
/// the grazing ladder. The lanes' exponents and the periodic orbits'
/// Newton steps both take their Jacobians from here.
pub fn estimated_iteration<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    settings: &MethodSettings,
    parts: usize,
    x: &[f64; D],
    stats: &mut IterationStats,
    jacobians: &mut Vec<SMatrix<f64, D, D>>,
) -> [f64; D]
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
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
    for part in Part::all(parts) {
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
