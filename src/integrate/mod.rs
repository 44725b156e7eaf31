//! Integrating one map iteration of a flow: classical RK4 with fixed steps,
//! wall impacts located inside the step that crosses the wall, returns to a
//! Poincaré section ([`section`]), and the closed-form propagator of the
//! impact oscillator that serves as ground truth, with its generalisation to
//! any piecewise-linear forced system ([`piecewise_linear`]).

mod avx2;
pub mod clock;
pub mod closed_form;
pub mod flow;
pub mod impact;
pub mod iteration;
pub(crate) mod locate;
pub mod piecewise_linear;
pub mod region;
pub mod rk4;
pub mod section;
pub mod surface;
pub mod wall;

// The names the rest of the tool reaches the integrator by; each lives in
// the child module of its layer (this file only drives the step loop).
pub use flow::{EventHoldValues, Flow, InRegion, Reset, Switching};
pub use iteration::{
    FlowSettings, ImpactLocation, IterationStats, Part, Stop, MAX_EVENTS, MAX_EVENTS_PER_ITERATION,
    STEPS_BETWEEN_STOP_LOOKS,
};
/// The cubic Hermite interpolant of a step, the oracle of the kernels'
/// generated `hermite_*` (tests/math64.rs holds them to the bit).
pub use locate::Hermite;
pub use region::{Surface, SurfaceBatch, SurfaceValues};
pub use wall::Wall;

use avx2::vectorised_or;
use clock::{half_turn, Phase, ZERO_PHASE};
use flow::column;
use wall::may_reach;

/// The time-T map of a flow: `steps` RK4 steps of h = T/steps from t = 0,
/// with every wall impact located and applied inside its step.
pub fn time_map<const D: usize, F: Flow<D>>(
    flow: &F,
    x: &[f64; D],
    period: f64,
    settings: &FlowSettings,
    stats: &mut IterationStats,
) -> [f64; D] {
    let mut ys = [*x];
    time_map_many(flow, &mut ys, period, settings, std::slice::from_mut(stats));
    ys[0]
}

/// [`time_map`] of several trajectories at once (a reference and its
/// perturbed copies), in lockstep: each step's forcing phases are computed
/// once, and the trajectories' independent RK4 chains interleave, which is
/// what keeps a core busy (one chain alone waits on its own latencies). Each
/// trajectory's arithmetic is exactly what it would be alone.
pub fn time_map_many<const D: usize, F: Flow<D>>(
    flow: &F,
    ys: &mut [[f64; D]],
    period: f64,
    settings: &FlowSettings,
    stats: &mut [IterationStats],
) {
    let mut phase = ZERO_PHASE;
    part_map_many(flow, ys, period, settings, Part::WHOLE, &mut phase, stats);
}

/// Part `part` of the time-T map (its share of the period's RK4 steps),
/// from the forcing phase `phase` at its start, which it advances to
/// the part's end. The parts of a period, run in order with the phase
/// passed on, do exactly the arithmetic of the whole [`time_map_many`].
///
/// The trajectories are stepped as structure-of-arrays batches of up to
/// eight (see `steps`), which the compiler vectorises: a hot
/// loop that only steps and detects, as the GPU's integrate kernel does.
/// A step that meets the wall (or starts at rest on it) is redone for that
/// trajectory alone by the impact code, outside the vector loop. Every
/// trajectory's arithmetic is exactly what it would be alone.
pub fn part_map_many<const D: usize, F: Flow<D>>(
    flow: &F,
    ys: &mut [[f64; D]],
    period: f64,
    settings: &FlowSettings,
    part: Part,
    phase: &mut Phase,
    stats: &mut [IterationStats],
) {
    vectorised_or(
        (ys, phase, stats),
        #[inline(always)]
        |(ys, phase, stats)| part_map_many_lanes(flow, ys, period, settings, part, phase, stats),
        |(ys, phase, stats)| {
            let start = *phase;
            phase_alone(flow, ys, period, settings, part, phase);
            for (y, st) in ys.chunks_mut(1).zip(stats.chunks_mut(1)) {
                let one = One(flow);
                *phase = steps::<D, 1, _>(&one, y, period, settings, part, [start], st)[0];
            }
        },
    );
}

/// Where there is no trajectory, only the forcing phase goes through the
/// part's steps, as it would with trajectories (see `reestimate_of`).
#[inline(always)]
fn phase_alone<const D: usize, F: Flow<D>>(
    flow: &F,
    ys: &[[f64; D]],
    period: f64,
    settings: &FlowSettings,
    part: Part,
    phase: &mut Phase,
) {
    if ys.is_empty() {
        let h = period / settings.steps_per_period as f64;
        let half = half_turn(flow.forcing_frequency(), h, settings.steps_per_period);
        for _ in part.steps(settings.steps_per_period) {
            *phase = rk4::stage_phases(phase, &half)[2];
        }
    }
}

/// Trajectories of one lane stepped together in one vector batch.
const BATCH: usize = 8;
/// Trajectories of neighbouring lanes stepped together. 16: with the C
/// compiler's step loop, 8 slots are one AVX-512 vector whose RK4 stages
/// are one chain of dependent operations, and two vectors in flight hide
/// its latency (the speed issue's sweep 9% faster, measured; 32 no faster
/// than 16, each slot's impacts ending the whole batch's loop more often).
pub const LANE_BATCH: usize = 16;

#[inline(always)]
fn part_map_many_lanes<const D: usize, F: Flow<D>>(
    flow: &F,
    ys: &mut [[f64; D]],
    period: f64,
    settings: &FlowSettings,
    part: Part,
    phase: &mut Phase,
    stats: &mut [IterationStats],
) {
    let start = *phase;
    phase_alone(flow, ys, period, settings, part, phase);
    for (chunk, st) in ys.chunks_mut(BATCH).zip(stats.chunks_mut(BATCH)) {
        let one = One(flow);
        // No batch of four: a lane's own trajectories are 1 + 2D with
        // central differences, five or more for any flow but a
        // one-dimensional one (compiling a third width for those was a
        // tenth of the crate's build).
        *phase = match chunk.len() {
            1 => steps::<D, 1, _>(&one, chunk, period, settings, part, [start; 1], st)[0],
            _ => steps::<D, BATCH, _>(&one, chunk, period, settings, part, [start; BATCH], st)[0],
        };
    }
}

/// The time-T map of several flows at once, one trajectory each
/// (trajectory k of `flows[k]`: the references of neighbouring lanes of a
/// sweep in their transient, or their references and copies while they
/// average), each over its own period with the same number of RK4 steps:
/// stepped as structure-of-arrays batches across lanes, so that a lane's
/// few trajectories do not run as latency-bound chains of their own. Each
/// trajectory's arithmetic is exactly [`time_map`]'s.
pub fn time_map_lanes<const D: usize, F: Flow<D>>(
    flows: &[&F],
    ys: &mut [[f64; D]],
    periods: &[f64],
    settings: &FlowSettings,
    stats: &mut [IterationStats],
) {
    vectorised_or(
        (ys, stats),
        #[inline(always)]
        |(ys, stats)| time_map_lanes_batched(flows, ys, periods, settings, stats),
        |(ys, stats)| {
            let chunks = ys.chunks_mut(1).zip(stats.chunks_mut(1));
            for ((y, st), (flows, periods)) in chunks.zip(flows.chunks(1).zip(periods.chunks(1))) {
                let each = Each { flows, periods };
                steps::<D, 1, _>(&each, y, 0.0, settings, Part::WHOLE, [ZERO_PHASE], st);
            }
        },
    );
}

#[inline(always)]
fn time_map_lanes_batched<const D: usize, F: Flow<D>>(
    flows: &[&F],
    ys: &mut [[f64; D]],
    periods: &[f64],
    settings: &FlowSettings,
    stats: &mut [IterationStats],
) {
    let chunks = ys
        .chunks_mut(LANE_BATCH)
        .zip(stats.chunks_mut(LANE_BATCH))
        .zip(flows.chunks(LANE_BATCH).zip(periods.chunks(LANE_BATCH)));
    for ((chunk, st), (flows, periods)) in chunks {
        let each = Each { flows, periods };
        let (whole, from) = (Part::WHOLE, ZERO_PHASE);
        match chunk.len() {
            1 => {
                steps::<D, 1, _>(&each, chunk, 0.0, settings, whole, [from; 1], st);
            }
            2..=4 => {
                steps::<D, 4, _>(&each, chunk, 0.0, settings, whole, [from; 4], st);
            }
            _ => {
                steps::<D, LANE_BATCH, _>(
                    &each,
                    chunk,
                    0.0,
                    settings,
                    whole,
                    [from; LANE_BATCH],
                    st,
                );
            }
        }
    }
}

/// Steps one trajectory of a (forced) flow by `steps` RK4 steps of h from
/// the forcing phase `phase`, as [`part_map_many`] steps it between impacts
/// (the same stage phases and operations, so the same end), and integrates
/// `density` along it by the same RK4: a quadrature state q' = density
/// riding along, evaluated at the stage states. Returns the end and ∫
/// density dt. For a flow without walls; `half` is the grid's half-step
/// turn of the phase ([`half_turn`]). Like the step loop, it ends early
/// where `stop` is requested (looked at every [`STEPS_BETWEEN_STOP_LOOKS`]
/// steps): a stopped run's numbers are never read.
///
/// [`STEPS_BETWEEN_STOP_LOOKS`]: iteration::STEPS_BETWEEN_STOP_LOOKS
pub fn advance_integrating<const D: usize, F: Flow<D>>(
    flow: &F,
    y: &[f64; D],
    mut phase: Phase,
    (h, half): (f64, Phase),
    steps: usize,
    density: impl Fn(&Phase, &[f64; D]) -> f64,
    stop: &Stop,
) -> ([f64; D], f64) {
    debug_assert!(flow.walls().is_empty());
    let sixth = h / 6.0;
    let (mut y, mut integral) = (*y, 0.0);
    for step in 0..steps {
        if step % iteration::STEPS_BETWEEN_STOP_LOOKS == 0 && stop.requested() {
            break;
        }
        let phases = rk4::stage_phases(&phase, &half);
        let [start, mid, end] = &phases;
        let (next, [y1, y2, y3, y4]) = rk4::step_with_stages(flow, &phases, &y, h);
        integral += sixth
            * (density(start, &y1)
                + 2.0 * (density(mid, &y2) + density(mid, &y3))
                + density(end, &y4));
        y = next;
        phase = *end;
    }
    (y, integral)
}

/// The flows of the trajectories a batch steps, and their map periods.
trait Flows<const D: usize> {
    type F: Flow<D>;
    /// Whether every trajectory has the same flow and period, and so the
    /// same forcing phases at every step (computed once for all).
    const SHARED: bool;
    /// The flow of trajectory k.
    fn of(&self, k: usize) -> &Self::F;
    /// The map period of trajectory k (`period` when all share one).
    fn period(&self, k: usize, period: f64) -> f64;
    /// One RK4 step of every trajectory of the batch with its step size,
    /// from the stage phases `shared` when [`SHARED`](Self::SHARED), else
    /// each from its own in `each` (left unset when shared: building W
    /// copies of one phase every step cost the shared loop a tenth).
    fn step<const W: usize>(
        &self,
        shared: &[Phase; 3],
        each: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D];
    /// [`step`](Self::step), each trajectory in its region of the switches.
    fn step_in<const W: usize>(
        &self,
        regions: &[u32; W],
        shared: &[Phase; 3],
        each: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D];
    /// The surfaces' values and rates of every trajectory, each in its
    /// region (sides only), at the forcing phase `shared` when
    /// [`SHARED`](Self::SHARED), else each at its own in `each`; into
    /// `out`.
    fn surface_values<const W: usize>(
        &self,
        regions: &[u32; W],
        shared: &Phase,
        each: &[Phase; W],
        y: &[[f64; W]; D],
        out: &mut SurfaceBatch<W>,
    );
}

/// One flow for every trajectory: a lane's reference and its copies.
struct One<'a, F>(&'a F);

impl<const D: usize, F: Flow<D>> Flows<D> for One<'_, F> {
    type F = F;
    const SHARED: bool = true;
    #[inline(always)]
    fn of(&self, _k: usize) -> &F {
        self.0
    }
    #[inline(always)]
    fn period(&self, _k: usize, period: f64) -> f64 {
        period
    }
    #[inline(always)]
    fn step<const W: usize>(
        &self,
        shared: &[Phase; 3],
        _each: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        self.0.step_shared(shared, y, h[0])
    }
    #[inline(always)]
    fn step_in<const W: usize>(
        &self,
        regions: &[u32; W],
        shared: &[Phase; 3],
        _each: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        if regions.iter().all(|&r| r == regions[0]) {
            self.0.step_shared_in(regions[0], shared, y, h[0])
        } else {
            F::step_each_in(&[self.0; W], regions, &[*shared; W], y, h)
        }
    }
    /// Slots in different regions are evaluated once per region present,
    /// each over the whole batch, their own region's values kept.
    #[inline(always)]
    fn surface_values<const W: usize>(
        &self,
        regions: &[u32; W],
        shared: &Phase,
        _each: &[Phase; W],
        y: &[[f64; W]; D],
        out: &mut SurfaceBatch<W>,
    ) {
        let first = regions[0];
        self.0.surface_values_shared(first, shared, y, out);
        for (k, &r) in regions.iter().enumerate() {
            // The first slot of each other region evaluates it.
            if r != first && !regions[..k].contains(&r) {
                let mut other = SurfaceBatch::default();
                self.0.surface_values_shared(r, shared, y, &mut other);
                for m in (k..W).filter(|&m| regions[m] == r) {
                    out.take_column(m, &other);
                }
            }
        }
    }
}

/// A flow and a period per trajectory (unused slots repeat the first).
struct Each<'a, F> {
    flows: &'a [&'a F],
    periods: &'a [f64],
}

impl<const D: usize, F: Flow<D>> Flows<D> for Each<'_, F> {
    type F = F;
    const SHARED: bool = false;
    #[inline(always)]
    fn of(&self, k: usize) -> &F {
        self.flows[k.min(self.flows.len() - 1)]
    }
    #[inline(always)]
    fn period(&self, k: usize, _period: f64) -> f64 {
        self.periods[k.min(self.periods.len() - 1)]
    }
    #[inline(always)]
    fn step<const W: usize>(
        &self,
        _shared: &[Phase; 3],
        each: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        F::step_each(&crate::array::from_fn(|k| self.of(k)), each, y, h)
    }
    #[inline(always)]
    fn step_in<const W: usize>(
        &self,
        regions: &[u32; W],
        _shared: &[Phase; 3],
        each: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        F::step_each_in(&crate::array::from_fn(|k| self.of(k)), regions, each, y, h)
    }
    #[inline(always)]
    fn surface_values<const W: usize>(
        &self,
        regions: &[u32; W],
        _shared: &Phase,
        each: &[Phase; W],
        y: &[[f64; W]; D],
        out: &mut SurfaceBatch<W>,
    ) {
        F::surface_values_each(
            &crate::array::from_fn(|k| self.of(k)),
            regions,
            each,
            y,
            out,
        )
    }
}

/// The steps of `part` for up to W trajectories held as structure of
/// arrays (unused slots repeat the first trajectory and are never read),
/// each from its forcing phase in `phases`; returns the phases at the
/// part's end.
#[inline(always)]
fn steps<const D: usize, const W: usize, S: Flows<D>>(
    flows: &S,
    ys: &mut [[f64; D]],
    period: f64,
    settings: &FlowSettings,
    part: Part,
    phases: [Phase; W],
    stats: &mut [IterationStats],
) -> [Phase; W] {
    // Two loops from one body: a flow without general surfaces runs one
    // with no trace of them (their bookkeeping compiled in cost the
    // models' step loop a fifth of its speed, measured).
    if flows.of(0).surfaces().is_empty() {
        steps_of::<D, W, S, false>(flows, ys, period, settings, part, phases, stats)
    } else {
        steps_of::<D, W, S, true>(flows, ys, period, settings, part, phases, stats)
    }
}

/// The step loop of [`steps`], with or without general surfaces: the
/// flow's own loop ([`walk`]) takes the steps that meet nothing, this one
/// the step that meets a wall or surface, resolving it, and bounds each
/// trajectory's located events ([`EventBound`]; where every trajectory
/// has ended, the rest of the call, millions of steps where flights grew
/// that short, is not taken) and the steps between two looks at the stop
/// request.
///
/// Measured choices it keeps:
/// - The forcing phase, when the slots share it, sits in a register: an
///   array of W copies, written a scalar at a time and read back as
///   pairs, stalled every step on failed store forwards. `phases` is then
///   unused until the end.
/// - The surfaces' values are kept outside the loop and touched only
///   where there are surfaces (zeroing and copying them every step cost
///   the flows without any a tenth of their time), in two buffers that
///   swap roles each step (`at_start` indexes the start's): copying the
///   end's values to the start each step was a `memcpy` whose stores the
///   next step's loads waited for.
/// - Which slots meet a wall or surface in a step is a mask, bit k for
///   slot k: the loop over an array of bools that found whether any was
///   set read back, one at a time, the bytes the vector compares had just
///   stored, and cost a tenth of the loop.
#[inline(always)]
fn steps_of<const D: usize, const W: usize, S: Flows<D>, const SURFACES: bool>(
    flows: &S,
    ys: &mut [[f64; D]],
    period: f64,
    settings: &FlowSettings,
    part: Part,
    mut phases: [Phase; W],
    stats: &mut [IterationStats],
) -> [Phase; W] {
    // The slots' masks (`live`, `meets`) are a bit each in a u32.
    const { assert!(W < 32) };
    let n = ys.len();
    let steps = settings.steps_per_period;
    let h: [f64; W] = crate::array::from_fn(|k| flows.period(k, period) / steps as f64);
    let omega: [f64; W] = crate::array::from_fn(|k| flows.of(k).forcing_frequency());
    let half: [Phase; W] = crate::array::from_fn(|k| half_turn(omega[k], h[k], steps));
    let walls = WallColumns::of(flows);
    let mut y: [[f64; W]; D] =
        crate::array::from_fn(|i| crate::array::from_fn(|w| ys[w.min(n - 1)][i]));
    // General surfaces (none without SURFACES: `steps` takes that loop for
    // those flows), each trajectory's region of the switches.
    let surfaces: &[Surface] = flows.of(0).surfaces();
    let mut phase = phases[0];
    let unset = [[ZERO_PHASE; 3]; W];
    let mut regions = [0u32; W];
    // The surfaces' values and rates at the step's start and end.
    let mut values = [SurfaceBatch::<W>::default(); 2];
    let mut at_start = 0;
    if SURFACES {
        let start_of = |k: usize| phase_of(S::SHARED, &phases, &phase, k);
        start_regions(flows, &y, start_of, n, &mut regions, &mut values[at_start]);
    }
    // A flow with a step loop of its own takes the steps that meet no wall
    // there, and this loop the one that does (or every step, without).
    let live = (1u32 << n) - 1;
    let mut bound = EventBound::<W>::new(stats);
    let mut left = part.steps(steps).len();
    // Steps until the next look at the stop request (at once: parts call again).
    let mut unseen = 0;
    while left > 0 {
        if unseen == 0 {
            if settings.stop.requested() {
                // Cut short: a stopped run's lanes are never read.
                break;
            }
            unseen = STEPS_BETWEEN_STOP_LOOKS;
        }
        // A sliding or held trajectory takes the slow path at every step.
        if !(SURFACES && regions[..n].iter().any(|&r| surface::is_constrained(r))) {
            let switching = SURFACES.then(|| Switching {
                regions: crate::array::from_fn(|k| regions[k.min(n - 1)]),
                values: &mut values[at_start],
            });
            let phases = (&mut phase, &mut phases);
            // At most the steps until the next look (a loop that takes
            // them all met nothing: the next begins where it ended).
            let most = left.min(unseen);
            let walked = walk(flows, &mut y, phases, (&half, &h), (live, most), switching);
            (left, unseen) = (left - walked, unseen - walked);
            if left == 0 || walked == most {
                continue;
            }
        }
        left -= 1;
        unseen -= 1;
        // The batch's step, then detection. Every slot's sides (unused
        // slots repeat the last trajectory's).
        let sides: [u32; W] = crate::array::from_fn(|k| surface::sides(regions[k.min(n - 1)]));
        let (mut y1, next_phase, next) = batch_step::<D, W, S, SURFACES>(
            flows,
            &y,
            (&phase, &phases),
            (&half, &h),
            &sides,
            &unset,
        );
        // Bit k: slot k meets a wall or surface in this step.
        let mut meets = walls.meets(&y, &y1, &h);
        if SURFACES {
            let end = (&sides, &next_phase, &next);
            meets |= surfaces_met(
                flows,
                (surfaces, &regions),
                (&mut values, at_start),
                end,
                &y1,
                &h,
            );
        }
        // Unused slots repeat a trajectory and are never resolved.
        meets &= (1u32 << n) - 1;
        if meets != 0 {
            let slots = Slots {
                flows,
                location: settings.impact_location,
                omega: &omega,
                h: &h,
                start_of: |k: usize| phase_of(S::SHARED, &phases, &phase, k),
                end_of: |k: usize| phase_of(S::SHARED, &next, &next_phase, k),
            };
            let end_values = SURFACES.then(|| &mut values[1 - at_start]);
            slots.resolve(meets, (&y, &mut y1), &mut regions, end_values, stats);
            bound.end_past_it(meets, &mut y1, stats);
            if bound.ended == live {
                y = y1;
                break;
            }
        }
        y = y1;
        phases = next;
        phase = next_phase;
        if SURFACES {
            at_start = 1 - at_start;
        }
    }
    for (k, out) in ys.iter_mut().enumerate() {
        *out = crate::array::from_fn(|i| y[i][k]);
    }
    crate::array::from_fn(|k| phase_of(S::SHARED, &phases, &phase, k))
}

/// The surfaces' values at the step's end (`end`: the slots' sides and
/// phases, `y1`), into the buffer of `values` that is not `at_start`, and
/// the slots that meet a surface in the step ([`surface_meets`]).
#[inline(always)]
fn surfaces_met<const D: usize, const W: usize, S: Flows<D>>(
    flows: &S,
    (surfaces, regions): (&[Surface], &[u32; W]),
    (values, at_start): (&mut [SurfaceBatch<W>; 2], usize),
    (sides, phase, phases): (&[u32; W], &Phase, &[Phase; W]),
    y1: &[[f64; W]; D],
    h: &[f64; W],
) -> u32 {
    let [first, second] = values;
    let (before, after) = if at_start == 0 {
        (&*first, second)
    } else {
        (&*second, first)
    };
    flows.surface_values(sides, phase, phases, y1, after);
    surface_meets(surfaces, regions, (before, after), h)
}

/// The located events in `stats`: wall impacts and crossings of events
/// and switches.
#[inline(always)]
fn events(stats: &IterationStats) -> u32 {
    stats
        .crossings
        .iter()
        .fold(0u32, |sum, &c| sum.wrapping_add(c))
}

/// The bound on each trajectory's located events in one call of the step
/// loop, [`MAX_EVENTS_PER_ITERATION`].
struct EventBound<const W: usize> {
    /// Each slot's located events before this call (its statistics may
    /// carry a whole transient's).
    counted: [u32; W],
    /// The slots ended past the bound (bit k).
    ended: u32,
}

impl<const W: usize> EventBound<W> {
    #[inline(always)]
    fn new(stats: &[IterationStats]) -> Self {
        EventBound {
            counted: crate::array::from_fn(|k| stats.get(k).map_or(0, events)),
            ended: 0,
        }
    }

    /// Ends, non-finite, each slot of `resolved` whose events in this call
    /// passed the bound, flagging it: its lane stops with that status.
    /// Their later steps in the call are plain steps of NaN (no wall or
    /// surface is met by NaN), until every slot has ended.
    #[inline(always)]
    fn end_past_it<const D: usize>(
        &mut self,
        resolved: u32,
        y1: &mut [[f64; W]; D],
        stats: &mut [IterationStats],
    ) {
        for k in (0..W).filter(|&k| resolved & (1 << k) != 0) {
            let st = &mut stats[k];
            if events(st).wrapping_sub(self.counted[k]) > MAX_EVENTS_PER_ITERATION {
                st.too_many_events = true;
                self.ended |= 1 << k;
                for row in y1.iter_mut() {
                    row[k] = f64::NAN;
                }
            }
        }
    }
}

/// The steps a flow's own step loop takes from y before one meets a wall
/// or surface (none without a loop of its own), of the `left` the part
/// has: `Flow::walk_shared` where the slots share their phase, else
/// `Flow::walk_each`.
#[inline(always)]
fn walk<const D: usize, const W: usize, S: Flows<D>>(
    flows: &S,
    y: &mut [[f64; W]; D],
    (phase, phases): (&mut Phase, &mut [Phase; W]),
    (half, h): (&[Phase; W], &[f64; W]),
    (live, left): (u32, usize),
    switching: Option<Switching<'_, W>>,
) -> usize {
    let walked = if S::SHARED {
        flows
            .of(0)
            .walk_shared(y, phase, &half[0], h[0], live, left, switching)
    } else {
        let each = crate::array::from_fn(|k| flows.of(k));
        S::F::walk_each(&each, y, phases, half, h, live, left, switching)
    };
    walked.unwrap_or(0)
}

/// One RK4 step of every slot of the batch from y (see
/// `Flow::step_shared`), each in its region's field (`sides`) where there
/// are surfaces: the states at its end, and the forcing phases there
/// (shared, and each slot's: `phases` again where shared, left alone).
/// `unset` stands for the slots' own stage phases where they share them.
#[inline(always)]
fn batch_step<const D: usize, const W: usize, S: Flows<D>, const SURFACES: bool>(
    flows: &S,
    y: &[[f64; W]; D],
    (phase, phases): (&Phase, &[Phase; W]),
    (half, h): (&[Phase; W], &[f64; W]),
    sides: &[u32; W],
    unset: &[[Phase; 3]; W],
) -> ([[f64; W]; D], Phase, [Phase; W]) {
    let shared = rk4::stage_phases(phase, &half[0]);
    let each: [[Phase; 3]; W] = if S::SHARED {
        *unset
    } else {
        crate::array::from_fn(|k| rk4::stage_phases(&phases[k], &half[k]))
    };
    let y1 = if !SURFACES {
        flows.step(&shared, &each, y, h)
    } else {
        flows.step_in(sides, &shared, &each, y, h)
    };
    let next: [Phase; W] = if S::SHARED {
        *phases
    } else {
        crate::array::from_fn(|k| each[k][2])
    };
    (y1, shared[2], next)
}

/// Trajectory k's forcing phase: `phase` where the slots share it, else
/// its own in `phases`.
#[inline(always)]
fn phase_of<const W: usize>(shared: bool, phases: &[Phase; W], phase: &Phase, k: usize) -> Phase {
    if shared {
        *phase
    } else {
        phases[k]
    }
}

/// Each trajectory's region of the switches at the start, and its
/// surfaces' values and rates there (into `values`).
#[inline(always)]
fn start_regions<const D: usize, const W: usize, S: Flows<D>>(
    flows: &S,
    y: &[[f64; W]; D],
    start_of: impl Fn(usize) -> Phase,
    n: usize,
    regions: &mut [u32; W],
    values: &mut SurfaceBatch<W>,
) {
    for (k, region) in regions.iter_mut().enumerate().take(n) {
        let (flow, yk) = (flows.of(k), column(y, k));
        let phase = start_of(k);
        *region = surface::region_of(flow, &phase, &yk);
        values.set_column(
            k,
            &flow.surface_values(surface::sides(*region), &phase, &yk),
        );
    }
}

/// The walls of a batch's system as columns over its slots: wall j's
/// position and side in each slot (its coordinates are the same in every
/// slot: one system).
struct WallColumns<'a, const W: usize> {
    walls: &'a [Wall],
    position: [[f64; W]; wall::MAX_WALLS],
    side: [[f64; W]; wall::MAX_WALLS],
}

impl<'a, const W: usize> WallColumns<'a, W> {
    #[inline(always)]
    fn of<const D: usize, S: Flows<D>>(flows: &'a S) -> Self {
        let walls: [&[Wall]; W] = crate::array::from_fn(|k| flows.of(k).walls());
        debug_assert!(walls.iter().all(|w| w.len() == walls[0].len()));
        WallColumns {
            walls: walls[0],
            position: crate::array::from_fn(|j| {
                crate::array::from_fn(|k| walls[k].get(j).map_or(0.0, |w| w.position))
            }),
            side: crate::array::from_fn(|j| {
                crate::array::from_fn(|k| walls[k].get(j).map_or(0.0, |w| w.side))
            }),
        }
    }

    /// The slots (bit k) whose step from y to y1 meets a wall: at rest on
    /// it before the step, or the stop test ([`wall::may_reach`]) after it;
    /// in two passes, as the step loops (`c::WalkText::detect` says why): the
    /// turns that the plain test finds again, only those within reach of
    /// the wall.
    #[inline(always)]
    fn meets<const D: usize>(&self, y: &[[f64; W]; D], y1: &[[f64; W]; D], h: &[f64; W]) -> u32 {
        if self.walls.is_empty() {
            return 0;
        }
        let detect = |within_reach: bool| {
            let mut hits = [false; W];
            for (j, wall) in self.walls.iter().enumerate() {
                let (c, v) = (wall.coordinate, wall.velocity);
                let (position, side) = (&self.position[j], &self.side[j]);
                for k in 0..W {
                    let (g0, s0) = (side[k] * (y[c][k] - position[k]), side[k] * y[v][k]);
                    let (g1, s1) = (side[k] * (y1[c][k] - position[k]), side[k] * y1[v][k]);
                    hits[k] |= ((y[c][k] == position[k]) & (y[v][k] == 0.0))
                        | may_reach(g0, s0, g1, s1, h[k], within_reach);
                }
            }
            hits.iter()
                .enumerate()
                .fold(0u32, |m, (k, &hit)| m | (hit as u32) << k)
        };
        let meets = detect(false);
        if meets != 0 {
            detect(true)
        } else {
            meets
        }
    }
}

/// The slots (bit k) that may cross a general surface in a step from the
/// surfaces' values `before` to `after` (the stop test of each,
/// `surface::may_cross`), or that slide or are held: over all W slots, a
/// vector per surface (the unused ones are masked off by the caller).
#[inline(always)]
fn surface_meets<const W: usize>(
    surfaces: &[Surface],
    regions: &[u32; W],
    (before, after): (&SurfaceBatch<W>, &SurfaceBatch<W>),
    h: &[f64; W],
) -> u32 {
    let mut hits = [false; W];
    for k in 0..W {
        // A sliding or held trajectory takes the slow path at every step.
        hits[k] = surface::is_constrained(regions[k]);
    }
    for (j, &kind) in surfaces.iter().enumerate() {
        let (g0, rate0) = (before.g(j), before.rate(j));
        let (g1, rate1) = (after.g(j), after.rate(j));
        for k in 0..W {
            hits[k] |=
                surface::may_cross(kind, regions[k], (g0[k], rate0[k]), (g1[k], rate1[k]), h[k]);
        }
    }
    let mut meets = 0u32;
    for (k, &hit) in hits.iter().enumerate() {
        meets |= (hit as u32) << k;
    }
    meets
}

/// What the slow path needs of a batch's step: the slots' flows, how
/// impacts are located, their forcing frequencies and step sizes, and
/// each slot's forcing phase at the step's start and end.
struct Slots<'a, S, const W: usize, P, Q> {
    flows: &'a S,
    location: ImpactLocation,
    omega: &'a [f64; W],
    h: &'a [f64; W],
    start_of: P,
    end_of: Q,
}

impl<S, const W: usize, P: Fn(usize) -> Phase, Q: Fn(usize) -> Phase> Slots<'_, S, W, P, Q> {
    /// The step of each slot in `meets` redone alone by the impact code
    /// from its start (column k of y) into y1 (at rest on a wall: stuck
    /// there while pressed), its region updated, and where there are
    /// surfaces its surfaces' values at the step's end into `end_values`.
    #[inline(always)]
    fn resolve<const D: usize>(
        &self,
        meets: u32,
        (y, y1): (&[[f64; W]; D], &mut [[f64; W]; D]),
        regions: &mut [u32; W],
        mut end_values: Option<&mut SurfaceBatch<W>>,
        stats: &mut [IterationStats],
    ) where
        S: Flows<D>,
    {
        let (omega, h) = (self.omega, self.h);
        for k in (0..W).filter(|&k| meets & (1 << k) != 0) {
            let flow = self.flows.of(k);
            let before = column(y, k);
            let start = (self.start_of)(k);
            let after = if let Some(j) = impact::resting_on(flow.walls(), &before) {
                impact::stuck_step(
                    flow,
                    &mut regions[k],
                    j,
                    self.location,
                    omega[k],
                    &start,
                    &before,
                    h[k],
                    &mut stats[k],
                )
            } else {
                impact::resolve(
                    flow,
                    &mut regions[k],
                    self.location,
                    omega[k],
                    &start,
                    &before,
                    h[k],
                    column(y1, k),
                    &mut stats[k],
                )
            };
            for i in 0..D {
                y1[i][k] = after[i];
            }
            if let Some(values) = end_values.as_deref_mut() {
                let at_end =
                    flow.surface_values(surface::sides(regions[k]), &(self.end_of)(k), &after);
                values.set_column(k, &at_end);
            }
        }
    }
}
