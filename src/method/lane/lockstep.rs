//! Neighbouring lanes of a sweep stepped together: their transients as one
//! batch, and where the system allows, their averaging iterations in
//! lockstep, every lane's numbers those of a lane run alone.

use nalgebra::{Const, DimMin};

use super::accumulator::{all_finite, Failure, LaneAccumulator};
use super::driver::{average, run_lane, Lane};
use super::early_stop::{self, Watch};
use super::grazing::resolve_grazing;
use super::plan::{plan_lane, LanePlan};
use super::result::LaneResult;
use super::settings::{MethodSettings, Tangent};
use super::settling::{attractor_tolerance, Settling};
use crate::integrate::clock::ZERO_PHASE;
use crate::method::jacobian;
use crate::perturbation::perturbation_at;
use crate::system::{FlowSettings, IterationStats, Part, System};

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
        ..settings.flow.clone()
    };
    let Transients {
        xs,
        failed,
        mut settling,
        stopped,
    } = transients(&systems, lanes, settings, flow);
    let lockstep = settings.lyapunov
        && plans.iter().all(|p| p.parts == 1)
        && systems.iter().all(|s| s.averages_across_lanes());
    let accumulators = systems
        .iter()
        .zip(&plans)
        .zip(&failed)
        .zip(&mut settling)
        .map(|(((system, &plan), failed), settling)| {
            let mut acc = LaneAccumulator::<D>::new(settings, system.period(), plan);
            if let Some((n, cause)) = *failed {
                acc.fail_because(n, cause);
            }
            if let Some(s) = settling.take() {
                acc.settle_from(s);
            }
            acc
        })
        .collect();
    let averaged = if lockstep {
        average_lanes(&systems, settings, flow, accumulators, xs, &stopped)
    } else {
        systems
            .iter()
            .zip(plans)
            .zip(xs.into_iter().zip(accumulators))
            .zip(&stopped)
            .map(
                |(((system, plan), (x, acc)), stopped)| match (acc.failed_at, stopped) {
                    (_, Some(_)) | (Some(_), None) => acc.finish(),
                    (None, None) => average(system, settings, plan, x, acc),
                },
            )
            .collect()
    };
    // A lane that stopped early has its result already (the accumulator
    // made for it took no iteration).
    averaged
        .into_iter()
        .zip(stopped)
        .map(|(averaged, stopped)| stopped.unwrap_or(averaged))
        .collect()
}

/// The references of lanes stepped together through their transients.
struct Transients<const D: usize> {
    /// Where each ended (or stopped).
    xs: Vec<[f64; D]>,
    /// The first failure of each, with its iteration.
    failed: Vec<Option<(usize, Failure)>>,
    /// The points of each from its start (with `keep_settling`).
    settling: Vec<Option<Settling<D>>>,
    /// The result of each that stopped early.
    stopped: Vec<Option<LaneResult>>,
}

/// The transients of `lanes` (of `systems`) as one batch of references,
/// a lane that stops early left out of the batch from then on.
fn transients<const D: usize, S: System<D>>(
    systems: &[S],
    lanes: &[Lane],
    settings: &MethodSettings,
    flow: &FlowSettings,
) -> Transients<D> {
    let mut xs: Vec<[f64; D]> = systems
        .iter()
        .zip(lanes)
        .map(|(s, lane)| s.start(&lane.initial_state, flow))
        .collect();
    let mut discard = vec![IterationStats::default(); lanes.len()];
    // A lane that fails goes on being stepped with the others (its
    // numbers touch no other lane's) but is reported at its first failure.
    let start = IterationStats::default();
    let mut failed: Vec<Option<(usize, Failure)>> = xs
        .iter()
        .map(|x| (!all_finite(x)).then(|| (0, Failure::of(x, &start))))
        .collect();
    let mut settling: Vec<Option<Settling<D>>> = xs
        .iter()
        .map(|x| {
            settings.keep_settling.then(|| {
                let mut s = Settling::default();
                s.push(x);
                s
            })
        })
        .collect();
    let tolerance = attractor_tolerance(settings.rounding_unit);
    let mut watches: Vec<Option<Watch>> = lanes
        .iter()
        .zip(&settling)
        .map(|(lane, s)| {
            s.as_ref()
                .and_then(|_| Watch::new(lane.known, settings.early_stop, tolerance))
        })
        .collect();
    let mut stopped: Vec<Option<LaneResult>> = vec![None; lanes.len()];
    // The lanes still stepped, and their references gathered once some
    // have stopped early (a lane's numbers do not depend on its batch).
    let (mut live, mut each): (Vec<usize>, Vec<&S>) = systems.iter().enumerate().unzip();
    let mut ys: Vec<[f64; D]> = Vec::new();
    for n in 0..settings.transient {
        if settings.flow.stop.requested() || live.is_empty() {
            break;
        }
        discard.truncate(live.len());
        discard.fill(IterationStats::default());
        if live.len() == xs.len() {
            S::iterate_lanes(&each, &mut xs, flow, &mut discard);
        } else {
            ys.clear();
            ys.extend(live.iter().map(|&k| xs[k]));
            S::iterate_lanes(&each, &mut ys, flow, &mut discard);
            for (&k, y) in live.iter().zip(&ys) {
                xs[k] = *y;
            }
        }
        let mut any_stopped = false;
        for (j, &k) in live.iter().enumerate() {
            let x = &mut xs[k];
            systems[k].wrap(x);
            if failed[k].is_none() && !all_finite(x) {
                failed[k] = Some((n, Failure::of(x, &discard[j])));
            }
            if let Some(s) = settling[k].as_mut() {
                s.push(x);
                if let Some(orbit) = watches[k].as_mut().and_then(|w| w.sees(x)) {
                    let points = settings.bifurcation_points;
                    stopped[k] = Some(early_stop::stopped(orbit, n, s, tolerance, points));
                    any_stopped = true;
                }
            }
        }
        if any_stopped {
            live.retain(|&k| stopped[k].is_none());
            each = live.iter().map(|&k| &systems[k]).collect();
        }
    }
    Transients {
        xs,
        failed,
        settling,
        stopped,
    }
}

/// The averaging iterations of neighbouring lanes in lockstep, from their
/// transients' ends `xs` (for lanes of one whole part per iteration, with
/// exponents): each iteration integrates every lane's reference and copies
/// as batches across lanes, so a lane's three or five trajectories no
/// longer wait on their own chains' latencies, then takes each lane's
/// Jacobian and accumulates it as [`average`] does. A grazing iteration is
/// re-estimated by that lane alone ([`resolve_grazing`]), and a lane that
/// fails stops being stepped; one that `stopped` early is not stepped.
/// Every lane's numbers are [`average`]'s.
fn average_lanes<const D: usize, S: System<D>>(
    systems: &[S],
    settings: &MethodSettings,
    flow: &FlowSettings,
    mut accumulators: Vec<LaneAccumulator<D>>,
    mut xs: Vec<[f64; D]>,
    stopped: &[Option<LaneResult>],
) -> Vec<LaneResult>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let mut live: Vec<usize> = (0..systems.len())
        .filter(|&k| accumulators[k].failed_at.is_none() && stopped[k].is_none())
        .collect();
    let (mut owners, mut ys, mut st) = (Vec::new(), Vec::new(), Vec::new());
    let mut copies = Vec::with_capacity(live.len());
    for _ in 0..settings.iterations {
        if live.is_empty() || settings.flow.stop.requested() {
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
