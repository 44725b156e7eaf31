//! A branch traced from a start: the periodic orbit solved there,
//! followed both ways over the sweep's range (`continuation`), every point
//! with its multipliers and a status, and the bifurcations on it located
//! by the test functions listed in [`located`]. This is what a run with
//! `[orbits]` does for each of its starts ([`trace_all`]); its results
//! hold states as vectors, so that the driver and the output need not know
//! the system's dimension.
//!
//! A branch switches at each of its period doublings to the doubled
//! branch, and at a grazing where it ended goes on past it where Newton
//! converges on the other side. Each is traced as a branch of its own
//! (one way, from its bifurcation; its first row names the branch it
//! came from), not as the same branch with its character changed: a
//! branch's rows keep one period and, between its located events
//! changes, one sequence of events, and the branch it came from may be
//! traced again from elsewhere without the two being told apart. A
//! branch that creeps towards a grazing ends there ([`creeping_end`]).

use nalgebra::{Complex, Const, DVector, DimMin};

use super::bifurcation::{bifurcations, Kind as MultiplierKind};
use super::continuation::{
    continue_branch_until, params_at, Branch, BranchEnd, BranchPoint, ContinuationSettings,
};
use super::doubling::doubled_orbit;
use super::events::{events, extrapolate_grazing, impact_speed_test, step_past, EventKind};
use super::locate::locate_zero;
use super::map::evaluate;
use super::newton::{least_period, relative_residual, NewtonSettings, Orbit};
use super::section::{crossing_ahead, step_across, Clearance};
use crate::method::MethodSettings;
use crate::system::{Params, System};

/// How every branch of a run is traced.
#[derive(Clone, Debug, PartialEq)]
pub struct TraceSettings {
    /// The continued parameter's index in [`Params::values`], and the range
    /// its branches are followed over (the sweep's).
    pub parameter: usize,
    pub bounds: (f64, f64),
    pub newton: NewtonSettings,
    /// The longest period (in map iterations) a branch is traced for.
    pub max_period: usize,
    /// Points a branch takes each way before it ends.
    pub max_points: usize,
    /// The first arclength step, and the range step control keeps it in.
    pub step: f64,
    pub min_step: f64,
    pub max_step: f64,
    /// A bifurcation is located to this in the parameter.
    pub locate_tolerance: f64,
}

/// The largest |Σ exponents - expected sum| per unit time, and the largest
/// change of ln|μ| over the δ ladder per unit time, with which a point is
/// `ok`: beyond them its exponents carry an error the tool cannot vouch
/// for to the digits it writes. Measured on the seed: 5e-12 for both.
pub const POINT_TOLERANCE: f64 = 1e-8;

/// The largest error estimate (in the parameter) of an impact's grazing
/// extrapolated from a branch's points that is reported: the accuracy
/// asked of every located bifurcation.
pub const GRAZING_EXTRAPOLATION: f64 = 1e-8;

/// Where a branch is traced from.
#[derive(Clone, Debug, PartialEq)]
pub struct Start {
    pub parameter: f64,
    /// The guess Newton starts from.
    pub state: Vec<f64>,
    pub period: usize,
    /// The orbit's points the start knows (a lane's last `period` points,
    /// D numbers each; empty for a listed orbit): a start with one of them
    /// on a traced branch is that branch's.
    pub points: Vec<f64>,
    pub origin: Origin,
    /// For a branch switched from another ([`Origin::Branch`]): where, and
    /// which way it leaves; it is traced that way only.
    pub onward: Option<Onward>,
}

/// What gave a start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    /// `[orbits] list`'s entry.
    Listed(usize),
    /// The sweep's lane (its index in the sweep, continuation passes after
    /// the scene's own lanes).
    Lane(usize),
    /// A bifurcation of the branch of this index (its `branch` in
    /// `orbits.csv`): the doubled branch of its period doubling, or the
    /// branch on the far side of its grazing.
    Branch(usize),
}

/// Where a switched branch starts, and which way it goes: from a period
/// doubling at λ* (its first point the period-p orbit there counted
/// twice, then the doubled orbit found near it, see [`doubled_orbit`]),
/// or from a grazing at λ_g (its first point the orbit found just past
/// it, see [`step_past`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Onward {
    pub kind: Kind,
    /// λ* or λ_g.
    pub parameter: f64,
    /// At a period doubling, the period-p orbit's state there; empty
    /// past a grazing.
    pub state: Vec<f64>,
    /// +1 when the branch leaves towards larger λ, -1 towards smaller.
    pub direction: f64,
}

/// The largest period doubling's or grazing's parameter distance, as a
/// fraction of the range, that a switched branch's first orbit may lie
/// from it: a doubled orbit found further off (λ - λ* grows with the
/// square of its amplitude) or an orbit past a grazing that far is not
/// the switched branch's.
const SWITCH_REACH: f64 = 0.05;

/// Why a point's numbers are in doubt; `Ok` when they are not.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PointStatus {
    Ok,
    /// The exponents miss the sum rule by `miss` per unit time.
    SumRule {
        miss: f64,
    },
    /// The multipliers moved by `error` (in ln|μ| per unit time) between
    /// the δ ladder's rungs.
    Uncertain {
        error: f64,
    },
}

impl std::fmt::Display for PointStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PointStatus::Ok => write!(f, "ok"),
            PointStatus::SumRule { miss } => write!(f, "sum-rule(miss={miss:.1e})"),
            PointStatus::Uncertain { error } => write!(f, "uncertain(error={error:.1e})"),
        }
    }
}

/// One orbit of a branch, with what its multipliers say.
#[derive(Clone, Debug, PartialEq)]
pub struct TracedPoint {
    pub parameter: f64,
    pub state: Vec<f64>,
    pub period: usize,
    /// Largest modulus first (see [`super::Floquet`]).
    pub multipliers: Vec<Complex<f64>>,
    pub exponents: Vec<f64>,
    pub expected_sum: f64,
    /// Crossings of each wall, then of each general surface, per map
    /// iteration (all `MAX_EVENTS`; the system's first ones are its events).
    pub crossings_per_period: Vec<f64>,
    pub impacts_per_period: f64,
    pub stable: bool,
    pub status: PointStatus,
}

/// What a test function found on a branch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Fold,
    PeriodDoubling,
    NeimarkSacker,
    /// The orbit touches a wall (or a surface) tangentially.
    Grazing,
    /// A motion starts to slide on a switch.
    Sliding,
    /// The orbit's sequence of events changes, not by a tangency.
    EventsChange,
}

impl Kind {
    pub const ALL: [Kind; 6] = [
        Kind::Fold,
        Kind::PeriodDoubling,
        Kind::NeimarkSacker,
        Kind::Grazing,
        Kind::Sliding,
        Kind::EventsChange,
    ];

    /// As `bifurcations.csv` names it.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Fold => "fold",
            Kind::PeriodDoubling => "period-doubling",
            Kind::NeimarkSacker => "neimark-sacker",
            Kind::Grazing => "grazing",
            Kind::Sliding => "sliding",
            Kind::EventsChange => "events-change",
        }
    }

    /// As the figure labels it.
    pub fn label(self) -> &'static str {
        match self {
            Kind::Fold => "LP",
            Kind::PeriodDoubling => "PD",
            Kind::NeimarkSacker => "NS",
            Kind::Grazing => "GR",
            Kind::Sliding => "SL",
            Kind::EventsChange => "EC",
        }
    }

    fn of(kind: MultiplierKind) -> Kind {
        match kind {
            MultiplierKind::Fold => Kind::Fold,
            MultiplierKind::PeriodDoubling => Kind::PeriodDoubling,
            MultiplierKind::NeimarkSacker => Kind::NeimarkSacker,
        }
    }
}

/// A located bifurcation of a traced branch.
#[derive(Clone, Debug, PartialEq)]
pub struct Located {
    pub kind: Kind,
    /// The orbit at the bifurcation (for a grazing, the nearest solved
    /// orbit on the side where the branch was).
    pub point: TracedPoint,
    /// Its place on the branch: between points `segment` and
    /// `segment + 1` (the branch's last point for one beyond its end).
    pub segment: usize,
}

/// A branch traced from its start: its points in order of the parameter's
/// path (from the low end up; a switched branch's from its bifurcation),
/// how each end ended, and its bifurcations
/// in the path's order. `failure` says why a start gave no branch.
#[derive(Clone, Debug, PartialEq)]
pub struct Traced {
    pub start: Start,
    pub points: Vec<TracedPoint>,
    /// How the path's first and last points ended it (the same for a
    /// closed branch).
    pub ends: [String; 2],
    pub bifurcations: Vec<Located>,
    pub failure: Option<String>,
    /// The starts of the branches switched from this one, at its period
    /// doublings and past its grazings (see [`trace_all`]).
    pub onward: Vec<Start>,
}

/// A branch end as `orbits.csv` writes it (no comma: one CSV field).
fn describe_end(end: &BranchEnd) -> String {
    match end {
        BranchEnd::Grazing { parameter, error } => {
            format!("grazing(at={parameter:e}; error={error:.1e})")
        }
        BranchEnd::Stalled { parameter, points } => {
            format!("stalled(at={parameter:e}; steps={points})")
        }
        BranchEnd::ShorterPeriod { parameter, period } => {
            format!("shorter-period(at={parameter:e}; period={period})")
        }
        BranchEnd::SectionCrossing { parameter } => format!("section(at={parameter:e})"),
        BranchEnd::Bound => "bound".into(),
        BranchEnd::Closed => "closed".into(),
        BranchEnd::MaxPoints => "max-points".into(),
        BranchEnd::Start(failure) => format!("no-orbit({failure})").replace(',', ";"),
        BranchEnd::StepTooSmall { parameter, failure } => {
            format!("step-too-small(at={parameter:e}; {failure})").replace(',', ";")
        }
    }
}

/// A switched branch's first end, as `orbits.csv` writes it: the kind of
/// bifurcation it was switched at, and the branch it came from.
pub fn switched_from(kind: Kind, branch: usize) -> String {
    format!("{}(from-branch={branch})", kind.name())
}

/// The wall excesses of an orbit, one per wall of the flow (see
/// [`super::wall_excess`]); none for a system without walls.
pub type WallExcess<const D: usize, S> = fn(&S, &MethodSettings, &Orbit<D>) -> Vec<f64>;

/// What every test function of a branch reads.
struct Context<'a, const D: usize, S: System<D>> {
    base: &'a Params,
    settings: &'a MethodSettings,
    trace: &'a TraceSettings,
    continuation: ContinuationSettings,
    walls: Option<WallExcess<D, S>>,
    clearance: Option<Clearance<D, S>>,
}

impl<const D: usize, S: System<D>> Context<'_, D, S>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    /// The solved `orbit` at λ = `lambda` as a branch point, with its
    /// multipliers.
    fn point(&self, lambda: f64, orbit: Orbit<D>) -> BranchPoint<D> {
        super::continuation::point::<D, S>(
            self.base,
            self.settings,
            self.trace.parameter,
            lambda,
            orbit,
        )
    }

    /// The system at λ = `lambda`, the other parameters the start's.
    fn system_at(&self, lambda: f64) -> S {
        S::new(&params_at(self.base, self.trace.parameter, lambda))
    }

    /// The branch of period-`period` orbits from `guess` at the start's
    /// λ, one way (`direction` in λ), ended where it runs into an orbit
    /// of a shorter period ([`shorter_period`]) or creeps ([`creeping_end`]).
    /// Where an impact of its orbit reaches the map's section, the branch
    /// steps across the point's jump ([`step_across`]) and goes on as the
    /// same branch, its points on both sides in one list (at most
    /// [`MAX_CROSSINGS`] times, a bound against a branch going round an
    /// isola for ever).
    fn follow(&self, guess: &[f64; D], period: usize, direction: f64) -> Branch<D> {
        let (mut branch, mut across) = self.follow_from(self.base, guess, period, direction);
        for _ in 0..MAX_CROSSINGS {
            let Some((lambda, orbit)) = across.or_else(|| self.across_failure(&branch)) else {
                break;
            };
            let [.., before, last] = &branch.points[..] else {
                break;
            };
            let onwards = (last.parameter - before.parameter).signum();
            let base = params_at(self.base, self.trace.parameter, lambda);
            let (next, next_across) = self.follow_from(&base, &orbit.state, period, onwards);
            if let BranchEnd::Start(_) = next.end {
                break;
            }
            branch.points.extend(next.points);
            branch.end = next.end;
            across = next_across;
        }
        branch
    }

    /// One stretch of [`follow`](Self::follow) from `base`'s λ, up to a
    /// crossing of the section or the branch's end; with the orbit on the
    /// crossing's far side where it ended there ([`BranchEnd::SectionCrossing`]).
    /// The stretch ends at a crossing ahead only where that orbit is
    /// found: elsewhere it goes on as it would without the test.
    fn follow_from(
        &self,
        base: &Params,
        guess: &[f64; D],
        period: usize,
        direction: f64,
    ) -> (Branch<D>, Option<(f64, Orbit<D>)>) {
        let continuation = ContinuationSettings {
            direction,
            ..self.continuation
        };
        let across = std::cell::Cell::new(None);
        let end = |points: &[BranchPoint<D>], step: f64| {
            shorter_period(self, points)
                .or_else(|| creeping_end(self, points, step))
                .or_else(|| {
                    let crossing = self.section_ahead(points, 2.0)?;
                    across.set(Some(self.step_across(points, crossing)?));
                    Some(BranchEnd::SectionCrossing {
                        parameter: crossing,
                    })
                })
        };
        let mut branch = continue_branch_until::<D, S>(
            base,
            self.settings,
            &self.trace.newton,
            &continuation,
            guess,
            period,
            &end,
        );
        if let BranchEnd::ShorterPeriod { .. } = branch.end {
            branch.points.pop();
        }
        (branch, across.take())
    }

    /// The section's crossing ahead of the branch's newest point within
    /// `reach` times its last step ([`crossing_ahead`]).
    fn section_ahead(&self, points: &[BranchPoint<D>], reach: f64) -> Option<f64> {
        let clearance = self.clearance?;
        crossing_ahead(self.base, self.trace.parameter, points, clearance, reach)
    }

    /// The orbit on the far side of a section's crossing ahead where the
    /// corrector failed, within [`SECTION_FAILURE_REACH`] of the branch's
    /// last steps (a step that landed beyond the crossing before the test
    /// saw it coming).
    fn across_failure(&self, branch: &Branch<D>) -> Option<(f64, Orbit<D>)> {
        let BranchEnd::StepTooSmall { .. } = branch.end else {
            return None;
        };
        let crossing = self.section_ahead(&branch.points, SECTION_FAILURE_REACH)?;
        self.step_across(&branch.points, crossing)
    }

    /// The orbit on the far side of the section's crossing at `crossing`
    /// ahead of `points` ([`step_across`]).
    fn step_across(&self, points: &[BranchPoint<D>], crossing: f64) -> Option<(f64, Orbit<D>)> {
        step_across(
            self.base,
            self.settings,
            &self.trace.newton,
            self.trace.parameter,
            self.trace.bounds,
            points,
            crossing,
            self.clearance?,
        )
    }
}

/// The most times one way of a branch steps across the map's section.
const MAX_CROSSINGS: usize = 16;

/// How many of its last steps ahead a branch whose corrector failed may
/// have its section's crossing for the tracer to step across it.
const SECTION_FAILURE_REACH: f64 = 50.0;

/// The branch of `start`, traced over `trace.bounds` both ways (a
/// switched start, one way from its bifurcation), with the starts of the
/// branches switched from it.
pub fn trace<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    trace: &TraceSettings,
    start: &Start,
    walls: Option<WallExcess<D, S>>,
    clearance: Option<Clearance<D, S>>,
) -> Traced
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let failed = |reason: String| Traced {
        start: start.clone(),
        points: Vec::new(),
        ends: [reason.clone(), reason.clone()],
        bifurcations: Vec::new(),
        failure: Some(reason),
        onward: Vec::new(),
    };
    if start.period > trace.max_period {
        return failed(format!(
            "period-above-max(period={}; max_period={})",
            start.period, trace.max_period
        ));
    }
    if start.state.len() != D {
        return failed(format!("state-length({} not {D})", start.state.len()));
    }
    let base = params_at(base, trace.parameter, start.parameter);
    let context = Context {
        base: &base,
        settings,
        trace,
        continuation: ContinuationSettings {
            parameter: trace.parameter,
            bounds: trace.bounds,
            direction: 1.0,
            step: trace.step,
            min_step: trace.min_step,
            max_step: trace.max_step,
            max_points: trace.max_points,
            max_corrector_steps: 6,
        },
        walls,
        clearance,
    };
    let guess: [f64; D] = crate::array::from_fn(|i| start.state[i]);
    let followed = match &start.onward {
        None => both_ways(&context, &guess, start.period),
        Some(onward) => one_way(&context, onward, &guess, start.period),
    };
    let (path, ends) = match followed {
        Ok(followed) => followed,
        Err(end) => return failed(describe_end(&end)),
    };
    let mut found = located(&context, &path, &ends);
    if start.onward.as_ref().map(|o| o.kind) == Some(Kind::PeriodDoubling) {
        // The doubled branch's first point is the period doubling itself,
        // the period-p orbit counted twice, with its multiplier +1: the
        // fold test's sign change next to it is that pitchfork, no fold.
        found
            .located
            .retain(|b| b.kind != Kind::Fold || b.segment != 0);
    }
    found.located.sort_by_key(|b| b.segment);
    let switched = |end: &Option<BranchEnd>| match (end, &start.onward, start.origin) {
        (Some(end), _, _) => describe_end(end),
        (None, Some(onward), Origin::Branch(from)) => switched_from(onward.kind, from),
        (None, ..) => String::new(),
    };
    Traced {
        start: start.clone(),
        points: path.iter().map(traced_point).collect(),
        ends: [switched(&ends[0]), switched(&ends[1])],
        bifurcations: found.located,
        failure: None,
        onward: onward_starts(&context, &found.doublings, &found.grazings),
    }
}

/// A branch's points in the order of its path, and how it ended at its
/// first and last point (`None`: it starts at the bifurcation it was
/// switched from); `Err` with the end when no orbit was found at its
/// start.
type Followed<const D: usize> = Result<(Vec<BranchPoint<D>>, [Option<BranchEnd>; 2]), BranchEnd>;

/// A start's branch followed from `guess` both ways at once, on two of
/// the host's cores: the way down is wasted only on a branch that closes
/// on itself going up.
fn both_ways<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    guess: &[f64; D],
    period: usize,
) -> Followed<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (up, down) = rayon::join(
        || context.follow(guess, period, 1.0),
        || context.follow(guess, period, -1.0),
    );
    if let BranchEnd::Start(_) = up.end {
        return Err(up.end);
    }
    Ok(if up.end == BranchEnd::Closed {
        (up.points, [Some(up.end), Some(up.end)])
    } else {
        let mut path: Vec<BranchPoint<D>> = down.points.into_iter().skip(1).rev().collect();
        path.extend(up.points);
        (path, [Some(down.end), Some(up.end)])
    })
}

/// A switched branch followed from `guess` away from its bifurcation, in
/// the order followed (from the bifurcation, whichever way in λ); a doubled branch begins with the doubling's orbit
/// counted twice (period 2p at λ*), so that it starts at the bifurcation.
fn one_way<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    onward: &Onward,
    guess: &[f64; D],
    period: usize,
) -> Followed<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let branch = context.follow(guess, period, onward.direction);
    if let BranchEnd::Start(_) = branch.end {
        return Err(branch.end);
    }
    let mut path = Vec::with_capacity(branch.points.len() + 1);
    if onward.kind == Kind::PeriodDoubling && onward.state.len() == D {
        let x: [f64; D] = crate::array::from_fn(|i| onward.state[i]);
        let at = context.system_at(onward.parameter);
        let twice = evaluate(&at, context.settings, &x, period, true);
        let orbit = Orbit {
            state: x,
            period,
            jacobian: twice.jacobian,
            residual: relative_residual(&x, &twice.image),
            steps: 0,
            stats: twice.stats,
            time: twice.time,
        };
        path.push(context.point(onward.parameter, orbit));
    }
    path.extend(branch.points);
    Ok((path, [None, Some(branch.end)]))
}

/// What the test functions found on a branch: the located bifurcations,
/// and the orbits its branches are switched from: the period doublings'
/// (period p), and the grazings' on the branch's side with λ_g.
struct Found<const D: usize> {
    located: Vec<Located>,
    doublings: Vec<BranchPoint<D>>,
    grazings: Vec<(f64, Orbit<D>)>,
}

/// Every bifurcation on `path` (a branch's points in order, ended by
/// `ends` at its first and last point), from each test function in turn.
/// A new test function is one more line here.
fn located<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    path: &[BranchPoint<D>],
    ends: &[Option<BranchEnd>; 2],
) -> Found<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (mut located, doublings) = multiplier_bifurcations(context, path);
    let (grazing, grazings): (Vec<Located>, Vec<(f64, Orbit<D>)>) =
        grazing_at_ends(context, path, ends).into_iter().unzip();
    located.extend(grazing);
    located.extend(events_changes(context, path));
    Found {
        located,
        doublings,
        grazings,
    }
}

/// The starts of the branches switched from a traced one: at each period
/// doubling the doubled branch (period 2p, up to `max_period`), from its
/// first orbit near the doubling ([`doubled_orbit`]); past each grazing at
/// a branch's end, the branch on the far side where Newton converges
/// there ([`step_past`], from 10^-8 of the range out to 10^-3). Each
/// within [`SWITCH_REACH`] of its bifurcation. Their origin is set by
/// [`trace_all`], which knows the branch's index.
fn onward_starts<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    doublings: &[BranchPoint<D>],
    grazings: &[(f64, Orbit<D>)],
) -> Vec<Start>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (low, high) = context.trace.bounds;
    let reach = SWITCH_REACH * (high - low).abs();
    let start = |kind: Kind, from: f64, state: Vec<f64>, first: &BranchPoint<D>| Start {
        parameter: first.parameter,
        state: first.orbit.state.to_vec(),
        period: first.orbit.period,
        points: Vec::new(),
        origin: Origin::Branch(usize::MAX),
        onward: Some(Onward {
            kind,
            parameter: from,
            state,
            direction: if first.parameter >= from { 1.0 } else { -1.0 },
        }),
    };
    let mut starts = Vec::new();
    for at in doublings {
        if 2 * at.orbit.period > context.trace.max_period {
            continue;
        }
        let first = doubled_orbit::<D, S>(
            context.base,
            context.settings,
            &context.trace.newton,
            &context.continuation,
            at,
            1e-2,
            1e-6,
        );
        if let Ok(first) = first {
            if (first.parameter - at.parameter).abs() <= reach && in_range(context, first.parameter)
            {
                let state = at.orbit.state.to_vec();
                starts.push(start(Kind::PeriodDoubling, at.parameter, state, &first));
            }
        }
    }
    // 10^-k of the range's scale, λ_g's own: the decades of `step_past`.
    let decades = 3..=8;
    for (grazing, orbit) in grazings {
        let past = step_past::<D, S>(
            context.base,
            context.settings,
            &context.trace.newton,
            context.trace.parameter,
            *grazing,
            orbit,
            decades.clone(),
        );
        if let Ok(first) = past {
            if (first.parameter - grazing).abs() <= reach && in_range(context, first.parameter) {
                starts.push(start(Kind::Grazing, *grazing, Vec::new(), &first));
            }
        }
    }
    starts
}

fn in_range<const D: usize, S: System<D>>(context: &Context<D, S>, lambda: f64) -> bool {
    let (low, high) = context.trace.bounds;
    lambda >= low.min(high) && lambda <= high.max(low)
}

/// Ends a branch creeping towards an impact's grazing: once its step has
/// shrunk to [`CREEP`] times the largest and its newest point impacts,
/// where the slowest impact's speed extrapolated to 0 from the branch's
/// own points ([`extrapolate_grazing`]) lies ahead of the branch (the way
/// λ moves), further than its points left would reach at the pace of its
/// last step. Newton loses the impacting
/// orbit within about v² of the grazing (v the speed), so the branch
/// would otherwise take its remaining points in steps that shrink with
/// v², each with multipliers near 1/v that miss the sum rule (measured
/// on the seed: its period-2 branch took 330 steps of 3e-10 in η near
/// 0.8283, its period-8 branch 350 of 3e-7 near 0.7246).
///
/// Where no impact's speed extrapolates to 0 ahead (the branch creeps
/// towards a free flight's grazing, or another corner), the branch ends
/// stalled once its last [`STALL`] steps were all below [`CREEP`] times
/// the largest and together moved λ by less than [`CREEP`] of the range.
fn creeping_end<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    points: &[BranchPoint<D>],
    step: f64,
) -> Option<BranchEnd> {
    let [.., before, last] = points else {
        return None;
    };
    if step > CREEP * context.trace.max_step {
        return None;
    }
    grazing_ahead(context, points, before, last).or_else(|| stalled(context, points))
}

/// The end where the branch's newest orbit closes after fewer iterations
/// than its period: where its events changed from the point before (an
/// impact grazed away), the only place a branch of genuine period-p
/// orbits turns into a shorter orbit counted over without a period
/// doubling (where the events do not change, and the doubled branch's
/// first points are near the shorter orbit by right).
fn shorter_period<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    points: &[BranchPoint<D>],
) -> Option<BranchEnd>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let [.., before, last] = points else {
        return None;
    };
    if last.orbit.period == 1 || events(&last.orbit) == events(&before.orbit) {
        return None;
    }
    let system = context.system_at(last.parameter);
    let least = least_period(&system, context.settings, &last.orbit);
    (least < last.orbit.period).then_some(BranchEnd::ShorterPeriod {
        parameter: last.parameter,
        period: least,
    })
}

/// The end at an impact's grazing ahead, see [`creeping_end`].
fn grazing_ahead<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    points: &[BranchPoint<D>],
    before: &BranchPoint<D>,
    last: &BranchPoint<D>,
) -> Option<BranchEnd> {
    if last.orbit.stats.impacts == 0 {
        return None;
    }
    let test = |_: &S, o: &Orbit<D>| impact_speed_test(o);
    let grazing =
        extrapolate_grazing::<D, S, _>(context.base, context.trace.parameter, points, test).ok()?;
    let ahead = grazing.parameter - last.parameter;
    let moving = last.parameter - before.parameter;
    let left = context.trace.max_points.saturating_sub(points.len()) as f64;
    let beyond_reach = ahead.abs() > left * moving.abs();
    (beyond_reach && ahead * moving >= 0.0).then_some(BranchEnd::Grazing {
        parameter: grazing.parameter,
        error: grazing.error,
    })
}

/// The stalled end, see [`creeping_end`].
fn stalled<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    points: &[BranchPoint<D>],
) -> Option<BranchEnd> {
    let recent = points.get(points.len().checked_sub(STALL + 1)?..)?;
    let tiny = CREEP * context.trace.max_step;
    let creeping = recent.windows(2).all(|pair| {
        let (a, b) = (&pair[0], &pair[1]);
        let states: f64 = (0..D)
            .map(|i| (a.orbit.state[i] - b.orbit.state[i]).powi(2))
            .sum();
        (states + (a.parameter - b.parameter).powi(2)).sqrt() <= tiny
    });
    let (low, high) = context.trace.bounds;
    let span = (recent[STALL].parameter - recent[0].parameter).abs();
    let last = recent[STALL].parameter;
    (creeping && span < CREEP * (high - low).abs()).then_some(BranchEnd::Stalled {
        parameter: last,
        points: STALL,
    })
}

/// The steps after which a creeping branch that went nowhere ends.
const STALL: usize = 50;

/// The fraction of the largest step below which a branch creeps: a
/// smooth branch's steps stay above it (the seed's, away from grazings
/// and folds: a tenth of the largest or more).
const CREEP: f64 = 1e-3;

/// Folds, period doublings and Neimark–Sacker points: a multiplier
/// through +1, -1, or a complex pair through the unit circle.
/// With the period doublings' branch points, from which the doubled
/// branches are switched.
fn multiplier_bifurcations<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    path: &[BranchPoint<D>],
) -> (Vec<Located>, Vec<BranchPoint<D>>)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let found = bifurcations::<D, S>(
        context.base,
        context.settings,
        &context.trace.newton,
        &context.continuation,
        path,
        context.trace.locate_tolerance,
    );
    let located = found
        .iter()
        .map(|b| Located {
            kind: Kind::of(b.kind),
            segment: segment_of(path, b.point.parameter, &b.point.orbit.state),
            point: traced_point(&b.point),
        })
        .collect();
    let doublings = found
        .into_iter()
        .filter(|b| b.kind == MultiplierKind::PeriodDoubling)
        .map(|b| b.point)
        .collect();
    (located, doublings)
}

/// The segment of `path` nearest (λ, x): the one whose chord passes
/// closest, for ordering what was found along the branch.
fn segment_of<const D: usize>(path: &[BranchPoint<D>], lambda: f64, x: &[f64; D]) -> usize {
    let y = DVector::from_fn(D + 1, |i, _| if i < D { x[i] } else { lambda });
    let of = |p: &BranchPoint<D>| {
        DVector::from_fn(
            D + 1,
            |i, _| if i < D { p.orbit.state[i] } else { p.parameter },
        )
    };
    (0..path.len().saturating_sub(1))
        .map(|k| {
            let (a, b) = (of(&path[k]), of(&path[k + 1]));
            let chord = &b - &a;
            let s = ((&y - &a).dot(&chord) / chord.norm_squared().max(f64::MIN_POSITIVE))
                .clamp(0.0, 1.0);
            (k, (&a + chord * s - &y).norm())
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(k, _)| k)
}

/// A wall grazed where a branch ended for want of an orbit: at an end
/// where the corrector failed (not at a bound, not closed), for each wall
/// the end's orbit stays clear of, the wall's excess located from the
/// free side out beyond the end. Kept when the orbit found there touches
/// the wall (its excess within the Newton tolerance of 0, relative to the
/// wall's position): a branch that ended for another reason is not said
/// to graze. An impacting end's grazing is its impact's
/// ([`impact_grazing`]), also where the branch was ended creeping
/// towards it ([`BranchEnd::Grazing`]). Each with λ_g and the orbit on the
/// branch's side, from which the branch past it is switched.
fn grazing_at_ends<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    path: &[BranchPoint<D>],
    ends: &[Option<BranchEnd>; 2],
) -> Vec<(Located, (f64, Orbit<D>))>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let Some(walls) = context.walls else {
        return Vec::new();
    };
    let mut found = Vec::new();
    let last = path.len().saturating_sub(1);
    for (end, (index, inner)) in ends
        .iter()
        .zip([(0, 1.min(last)), (last, last.saturating_sub(1))])
    {
        let grazes = matches!(
            end,
            Some(
                BranchEnd::StepTooSmall { .. }
                    | BranchEnd::Grazing { .. }
                    | BranchEnd::ShorterPeriod { .. }
            )
        );
        if !grazes || path.is_empty() {
            continue;
        }
        let here = &path[index];
        if here.orbit.stats.impacts > 0 {
            found.extend(impact_grazing(context, path, index));
        }
        // Onwards along the branch's own direction in λ at its end.
        let away = here.parameter - path[inner].parameter;
        let direction = if away != 0.0 {
            away.signum()
        } else if index == 0 {
            -1.0
        } else {
            1.0
        };
        let beyond = here.parameter + direction * context.trace.max_step;
        let system = context.system_at(here.parameter);
        let excess = walls(&system, context.settings, &here.orbit);
        for (w, &g) in excess.iter().enumerate() {
            if g.is_nan() || g >= 0.0 || here.orbit.stats.crossings[w] != 0 {
                continue;
            }
            let settings = context.settings;
            let test = |s: &S, o: &Orbit<D>| walls(s, settings, o).get(w).copied();
            let Ok(zero) = locate_zero::<D, S, _>(
                context.base,
                context.settings,
                &context.trace.newton,
                context.trace.parameter,
                (here.parameter, &here.orbit),
                (beyond, None),
                test,
                context.trace.locate_tolerance,
            ) else {
                continue;
            };
            let solved_at = zero.bracket.0;
            let at = context.system_at(solved_at);
            let touching = walls(&at, context.settings, &zero.orbit)
                .get(w)
                .is_some_and(|g| g.abs() <= 1e-6 * excess_scale(&zero.orbit.state));
            if !touching {
                continue;
            }
            // The orbit solved nearest the zero, at the zero's estimate.
            let point = context.point(solved_at, zero.orbit);
            let located = Located {
                kind: Kind::Grazing,
                point: TracedPoint {
                    parameter: zero.parameter,
                    ..traced_point(&point)
                },
                segment: index,
            };
            found.push((located, (zero.parameter, zero.orbit)));
        }
    }
    found
}

/// An impact grazed where an impacting branch ended for want of an orbit
/// (Newton loses it within about v² of the grazing): its slowest impact's
/// speed extrapolated to 0 from the branch's own points towards that end
/// ([`extrapolate_grazing`]). Kept when the extrapolation's error
/// estimate is within [`GRAZING_EXTRAPOLATION`].
fn impact_grazing<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    path: &[BranchPoint<D>],
    end: usize,
) -> Option<(Located, (f64, Orbit<D>))> {
    let towards: Vec<BranchPoint<D>> = if end == 0 {
        path.iter().rev().cloned().collect()
    } else {
        path.to_vec()
    };
    let test = |_: &S, o: &Orbit<D>| impact_speed_test(o);
    let grazing =
        extrapolate_grazing::<D, S, _>(context.base, context.trace.parameter, &towards, test)
            .ok()?;
    let located = Located {
        kind: Kind::Grazing,
        point: TracedPoint {
            parameter: grazing.parameter,
            ..traced_point(&path[end])
        },
        segment: end,
    };
    (grazing.error <= GRAZING_EXTRAPOLATION)
        .then_some((located, (grazing.parameter, grazing.orbit)))
}

fn excess_scale<const D: usize>(x: &[f64; D]) -> f64 {
    x.iter().fold(1.0_f64, |m, v| m.max(v.abs()))
}

/// Where two neighbouring points of the branch have different sequences
/// of events (crossings per period of each wall and surface, sliding
/// phases): each change located by bisection in the parameter
/// ([`super::events::events_changes`]) and named by what changed.
fn events_changes<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    path: &[BranchPoint<D>],
) -> Vec<Located>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    super::events::events_changes::<D, S>(
        context.base,
        context.settings,
        &context.trace.newton,
        context.trace.parameter,
        path,
        context.trace.locate_tolerance,
    )
    .into_iter()
    .map(|change| {
        let point = context.point(change.bracket.0, change.orbit);
        Located {
            kind: match change.kind() {
                EventKind::Grazing => Kind::Grazing,
                EventKind::Sliding => Kind::Sliding,
                EventKind::EventsChange => Kind::EventsChange,
            },
            segment: segment_of(path, change.parameter, &change.orbit.state),
            point: TracedPoint {
                parameter: change.parameter,
                ..traced_point(&point)
            },
        }
    })
    .collect()
}

/// A branch point as the output writes it, with its status.
fn traced_point<const D: usize>(point: &BranchPoint<D>) -> TracedPoint {
    let f = &point.floquet;
    let time = point.orbit.time;
    let period = point.orbit.period as f64;
    let miss = f.sum_error();
    let ladder = f.ladder_error / time;
    let status = if miss.is_nan() || miss.abs() > POINT_TOLERANCE {
        PointStatus::SumRule { miss }
    } else if ladder.is_nan() || ladder > POINT_TOLERANCE {
        PointStatus::Uncertain { error: ladder }
    } else {
        PointStatus::Ok
    };
    TracedPoint {
        parameter: point.parameter,
        state: point.orbit.state.to_vec(),
        period: point.orbit.period,
        multipliers: f.multipliers.clone(),
        exponents: f.exponents.clone(),
        expected_sum: f.expected_sum,
        crossings_per_period: point
            .orbit
            .stats
            .crossings
            .iter()
            .map(|&c| f64::from(c) / period)
            .collect(),
        impacts_per_period: f64::from(point.orbit.stats.impacts) / period,
        stable: f.stable(),
        status,
    }
}

/// Whether `start` lies on the traced branch `traced`: of its period, and
/// one of its points (its state, when it knows none) within 1e-2 (relative
/// to max(1, |x|∞)) of the branch's polygon at its parameter value. The
/// polygon's own error is the branch's curvature times its step squared,
/// far below that on the steps continuation takes; two distinct orbits of
/// one period that close at one value would be one branch's fold. Where
/// the branch's point jumps between two rows (an impact at the map's
/// section, see [`super::section`]) the chord between them is no orbit's:
/// there the segments on either side, extended to the start's value, are
/// the branch's.
pub fn covers(traced: &Traced, start: &Start) -> bool {
    let d = start.state.len();
    if traced.points.is_empty() || traced.points[0].period != start.period || d == 0 {
        return false;
    }
    let candidates: Vec<&[f64]> = if start.points.is_empty() {
        vec![&start.state[..]]
    } else {
        start.points.chunks_exact(d).collect()
    };
    let lambda = start.parameter;
    let near = |x: &[f64], y: &[f64]| {
        let scale = x.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
        x.iter().zip(y).all(|(a, b)| (a - b).abs() <= 1e-2 * scale)
    };
    // The line through points k and k + 1 at λ.
    let line = |points: &[TracedPoint], k: usize| -> Vec<f64> {
        let (a, b) = (&points[k], &points[k + 1]);
        let s = if b.parameter != a.parameter {
            (lambda - a.parameter) / (b.parameter - a.parameter)
        } else {
            0.0
        };
        a.state
            .iter()
            .zip(&b.state)
            .map(|(p, q)| p + s * (q - p))
            .collect()
    };
    let points = &traced.points;
    let segments = (0..points.len().saturating_sub(1)).filter(|&k| {
        let (a, b) = (points[k].parameter, points[k + 1].parameter);
        lambda >= a.min(b) && lambda <= a.max(b)
    });
    let lines = segments.flat_map(|k| {
        let sides = [k.checked_sub(1), Some(k), Some(k + 1)];
        sides
            .into_iter()
            .flatten()
            .filter(|&j| j + 1 < points.len())
            .map(|j| line(points, j))
            .collect::<Vec<_>>()
    });
    let single =
        (points.len() == 1 && points[0].parameter == lambda).then(|| points[0].state.clone());
    lines
        .chain(single)
        .any(|x| candidates.iter().any(|c| near(c, &x)))
}

/// Traces a branch of `start` (a monomorphised [`trace`]).
pub type Tracer = fn(&Params, &MethodSettings, &TraceSettings, &Start) -> Traced;

/// Every start's branch, each branch once: a start on a branch already
/// traced is skipped, and a start that gave no branch is reported only if
/// no branch traced from another start covers it. Listed starts come
/// first, then the lanes' in the order given; the branches switched from
/// a traced branch ([`Traced::onward`]) are taken right after it, so that
/// a doubled branch is traced from its period doubling before a lane on
/// it starts it anew. `stop` is asked between branches.
pub fn trace_all(
    tracer: Tracer,
    base: &Params,
    settings: &MethodSettings,
    trace: &TraceSettings,
    starts: &[Start],
    stop: &dyn Fn() -> bool,
) -> Vec<Traced> {
    let mut branches: Vec<Traced> = Vec::new();
    let mut failed: Vec<Traced> = Vec::new();
    let mut pending: std::collections::VecDeque<Start> = starts.iter().cloned().collect();
    let mut switched = 0;
    while let Some(start) = pending.pop_front() {
        if stop() {
            break;
        }
        if branches.iter().any(|b| covers(b, &start)) {
            continue;
        }
        if start.onward.is_some() {
            if switched == MAX_SWITCHED {
                continue;
            }
            switched += 1;
        }
        let traced = tracer(base, settings, trace, &start);
        if traced.failure.is_some() {
            failed.push(traced);
            continue;
        }
        let from = Origin::Branch(branches.len());
        for onward in traced.onward.iter().rev() {
            pending.push_front(Start {
                origin: from,
                ..onward.clone()
            });
        }
        branches.push(traced);
    }
    failed.retain(|f| !branches.iter().any(|b| covers(b, &f.start)));
    branches.extend(failed);
    branches
}

/// The most branches a run switches to (at period doublings and past
/// grazings): a cascade of period doublings ends at `max_period`, and
/// each branch is traced once, but a chaotic band's many grazings could
/// chain on; a bound on the stage's work.
const MAX_SWITCHED: usize = 64;
