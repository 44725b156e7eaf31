//! A branch traced from a start: the periodic orbit solved there,
//! followed both ways over the sweep's range (`continuation`), every point
//! with its multipliers and a status, and the bifurcations on it located
//! by the test functions listed in [`located`]. This is what a run with
//! `[orbits]` does for each of its starts ([`trace_all`]); its results
//! hold states as vectors, so that the driver and the output need not know
//! the system's dimension.

use nalgebra::{Complex, Const, DVector, DimMin};

use super::bifurcation::{bifurcations, Kind as MultiplierKind};
use super::continuation::{
    continue_branch, params_at, BranchEnd, BranchPoint, ContinuationSettings,
};
use super::events::{extrapolate_grazing, impact_speed_test, EventKind};
use super::locate::locate_zero;
use super::newton::{NewtonSettings, Orbit};
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
}

/// What gave a start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    /// `[orbits] list`'s entry.
    Listed(usize),
    /// The sweep's lane (its index in the sweep, continuation passes after
    /// the scene's own lanes).
    Lane(usize),
}

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
/// path (from the low end up), how each end ended, and its bifurcations
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
}

/// A branch end as `orbits.csv` writes it (no comma: one CSV field).
fn describe_end(end: &BranchEnd) -> String {
    match end {
        BranchEnd::Bound => "bound".into(),
        BranchEnd::Closed => "closed".into(),
        BranchEnd::MaxPoints => "max-points".into(),
        BranchEnd::Start(failure) => format!("no-orbit({failure})").replace(',', ";"),
        BranchEnd::StepTooSmall { parameter, failure } => {
            format!("step-too-small(at={parameter:e}; {failure})").replace(',', ";")
        }
    }
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
}

/// The branch of `start`, traced over `trace.bounds` both ways.
pub fn trace<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    trace: &TraceSettings,
    start: &Start,
    walls: Option<WallExcess<D, S>>,
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
    let continuation = ContinuationSettings {
        parameter: trace.parameter,
        bounds: trace.bounds,
        direction: 1.0,
        step: trace.step,
        min_step: trace.min_step,
        max_step: trace.max_step,
        max_points: trace.max_points,
        max_corrector_steps: 6,
    };
    let context = Context {
        base: &base,
        settings,
        trace,
        continuation,
        walls,
    };
    let guess: [f64; D] = crate::array::from_fn(|i| start.state[i]);
    let follow = |direction: f64| {
        let continuation = ContinuationSettings {
            direction,
            ..continuation
        };
        continue_branch::<D, S>(
            &base,
            settings,
            &trace.newton,
            &continuation,
            &guess,
            start.period,
        )
    };
    // Both ways at once, on two of the host's cores: the way down is
    // wasted only on a branch that closes on itself going up.
    let (up, down) = rayon::join(|| follow(1.0), || follow(-1.0));
    if let BranchEnd::Start(_) = up.end {
        return failed(describe_end(&up.end));
    }
    let (path, ends) = if up.end == BranchEnd::Closed {
        let end = describe_end(&up.end);
        (up.points, [end.clone(), end])
    } else {
        let ends = [describe_end(&down.end), describe_end(&up.end)];
        let mut path: Vec<BranchPoint<D>> = down.points.into_iter().skip(1).rev().collect();
        path.extend(up.points);
        (path, ends)
    };
    let mut found = located(&context, &path, [&ends[0], &ends[1]]);
    found.sort_by_key(|b| b.segment);
    Traced {
        start: start.clone(),
        points: path.iter().map(traced_point).collect(),
        ends,
        bifurcations: found,
        failure: None,
    }
}

/// Every bifurcation on `path` (a branch's points in order, its ends
/// described as `ends`), from each test function in turn. A new test
/// function is one more line here.
fn located<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    path: &[BranchPoint<D>],
    ends: [&str; 2],
) -> Vec<Located>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let mut found = Vec::new();
    found.extend(multiplier_bifurcations(context, path));
    found.extend(grazing_at_ends(context, path, ends));
    found.extend(events_changes(context, path));
    found
}

/// Folds, period doublings and Neimark–Sacker points: a multiplier
/// through +1, -1, or a complex pair through the unit circle.
fn multiplier_bifurcations<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    path: &[BranchPoint<D>],
) -> Vec<Located>
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
    found
        .into_iter()
        .filter(|b| on_the_unit_circle(Kind::of(b.kind), &b.point.floquet.multipliers))
        .map(|b| Located {
            kind: Kind::of(b.kind),
            segment: segment_of(path, b.point.parameter, &b.point.orbit.state),
            point: traced_point(&b.point),
        })
        .collect()
}

/// How near the unit circle a located bifurcation's critical multiplier
/// must be. A test function det(DU^p ∓ I) also changes sign where a
/// multiplier jumps through infinity (a grazing impact's square root
/// makes DU^p blow up), and its "zero" there has no multiplier near ±1
/// (measured on the seed's period-2 branch: 4742 and 2.05); a true one
/// located to 1e-10 in the parameter has its multiplier within 1e-7.
const ON_THE_CIRCLE: f64 = 1e-3;

/// Whether `kind`'s multiplier is on the unit circle: +1 for a fold, -1
/// for a period doubling, a complex pair of modulus 1 for Neimark–Sacker.
fn on_the_unit_circle(kind: Kind, multipliers: &[Complex<f64>]) -> bool {
    multipliers.iter().any(|m| match kind {
        Kind::Fold => (m - 1.0).norm() <= ON_THE_CIRCLE,
        Kind::PeriodDoubling => (m + 1.0).norm() <= ON_THE_CIRCLE,
        Kind::NeimarkSacker => m.im != 0.0 && (m.norm() - 1.0).abs() <= ON_THE_CIRCLE,
        _ => false,
    })
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
/// to graze.
fn grazing_at_ends<const D: usize, S: System<D>>(
    context: &Context<D, S>,
    path: &[BranchPoint<D>],
    ends: [&str; 2],
) -> Vec<Located>
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
        if !end.starts_with("step-too-small") || path.is_empty() {
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
        let system = S::new(&params_at(
            context.base,
            context.trace.parameter,
            here.parameter,
        ));
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
            let at = S::new(&params_at(context.base, context.trace.parameter, solved_at));
            let touching = walls(&at, context.settings, &zero.orbit)
                .get(w)
                .is_some_and(|g| g.abs() <= 1e-6 * excess_scale(&zero.orbit.state));
            if !touching {
                continue;
            }
            // The orbit solved nearest the zero, at the zero's estimate.
            let point = super::continuation::point::<D, S>(
                context.base,
                context.settings,
                context.trace.parameter,
                solved_at,
                zero.orbit,
            );
            found.push(Located {
                kind: Kind::Grazing,
                point: TracedPoint {
                    parameter: zero.parameter,
                    ..traced_point(&point)
                },
                segment: index,
            });
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
) -> Option<Located> {
    let towards: Vec<BranchPoint<D>> = if end == 0 {
        path.iter().rev().cloned().collect()
    } else {
        path.to_vec()
    };
    let test = |_: &S, o: &Orbit<D>| impact_speed_test(o);
    let grazing =
        extrapolate_grazing::<D, S, _>(context.base, context.trace.parameter, &towards, test)
            .ok()?;
    (grazing.error <= GRAZING_EXTRAPOLATION).then(|| Located {
        kind: Kind::Grazing,
        point: TracedPoint {
            parameter: grazing.parameter,
            ..traced_point(&path[end])
        },
        segment: end,
    })
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
        let point = super::continuation::point::<D, S>(
            context.base,
            context.settings,
            context.trace.parameter,
            change.bracket.0,
            change.orbit,
        );
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
/// one period that close at one value would be one branch's fold.
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
    let points = &traced.points;
    let segments = points.windows(2).filter_map(|pair| {
        let (a, b) = (&pair[0], &pair[1]);
        let (low, high) = if a.parameter <= b.parameter {
            (a.parameter, b.parameter)
        } else {
            (b.parameter, a.parameter)
        };
        if lambda < low || lambda > high {
            return None;
        }
        let s = if high > low {
            (lambda - a.parameter) / (b.parameter - a.parameter)
        } else {
            0.0
        };
        Some(
            a.state
                .iter()
                .zip(&b.state)
                .map(|(p, q)| p + s * (q - p))
                .collect::<Vec<f64>>(),
        )
    });
    let single =
        (points.len() == 1 && points[0].parameter == lambda).then(|| points[0].state.clone());
    segments
        .chain(single)
        .any(|x| candidates.iter().any(|c| near(c, &x)))
}

/// Traces a branch of `start` (a monomorphised [`trace`]).
pub type Tracer = fn(&Params, &MethodSettings, &TraceSettings, &Start) -> Traced;

/// Every start's branch, each branch once: a start on a branch already
/// traced is skipped, and a start that gave no branch is reported only if
/// no branch traced from another start covers it. Listed starts come
/// first, then the lanes' in the order given. `stop` is asked between
/// branches.
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
    for start in starts {
        if stop() {
            break;
        }
        if branches.iter().any(|b| covers(b, start)) {
            continue;
        }
        let traced = tracer(base, settings, trace, start);
        if traced.failure.is_some() {
            failed.push(traced);
        } else {
            branches.push(traced);
        }
    }
    failed.retain(|f| !branches.iter().any(|b| covers(b, &f.start)));
    branches.extend(failed);
    branches
}
