//! A system given as data: a compiled model (`crate::model::compiled`) run as
//! a flow ([`ModelFlow`]: its fields per region of the switches, its stops
//! as walls, its other events and switches as the integrator's surfaces)
//! and described to the rest of the tool like a built-in system
//! ([`info`]). A model that is piecewise linear also gets the exact
//! backend (`crate::model::compiled::piecewise_linear`).

use std::mem::MaybeUninit;

use nalgebra::{DMatrix, DVector, SMatrix};

use super::{
    ExactPropagator, FlowSettings, IterationStats, Parameter, Params, Part, System, SystemInfo,
};
use crate::error::number;
use crate::integrate::clock::Phase;
use crate::integrate::closed_form::{ExactStatus, ForcedImpactOscillator};
use crate::integrate::piecewise_linear::{PiecewiseLinear, PiecewiseStatus};
use crate::integrate::surface::{SlidingSet, MAX_SURFACES};
use crate::integrate::{
    part_map_many, rk4, time_map, time_map_many, Flow, Surface, SurfaceBatch, SurfaceValues,
    Switching, Wall,
};
use crate::model::compiled::{piecewise_linear, reads_state_or_time, walls_at, Code};
use crate::model::ir::tape::Registers;
use crate::model::language::expr::{Expr, Var};
use crate::model::native::abi::{Kind, Layout};
use crate::model::native::library::Native;

/// Model descriptions built in this process ([`info_as`]): each is kept
/// for the process, so this counts what the process holds for its models.
static DESCRIBED: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// How many model descriptions this process has built and keeps.
pub fn described() -> usize {
    DESCRIBED.load(std::sync::atomic::Ordering::Relaxed)
}

fn leak(s: &str) -> &'static str {
    Box::leak(s.to_owned().into_boxed_str())
}

/// The system description of a compiled model, for the scene, the
/// backends and the writers. Built once per scene and kept for the
/// process (the description is static for the built-ins).
pub fn info(code: Code) -> &'static SystemInfo {
    let sweep = code.model.names.parameters.first().cloned();
    info_as(
        code,
        "model.parameters",
        sweep.as_deref().unwrap_or_default(),
        ExactPropagator::PiecewiseLinear,
    )
}

/// [`info`] of a model whose `[model]` table reads as `text` (its
/// canonical form: the same table, the same text), compiled by `compile`
/// the first time this process meets it and kept: a model is compiled,
/// and its description held, once per process, however many scenes run
/// it (a Python loop over runs holds one, not one per run). The
/// environment that decides what the compiler builds (`CC`,
/// `LYAPSWEEP_STEP_LOOPS`, the cache directory) is part of the key. What is
/// held grows with the distinct models a process runs, not with its runs;
/// each is a few kilobytes besides its native code.
pub fn info_of(
    text: &str,
    compile: impl FnOnce() -> crate::error::Result<Code>,
) -> crate::error::Result<&'static SystemInfo> {
    type Kept = std::collections::BTreeMap<String, &'static SystemInfo>;
    static KEPT: std::sync::Mutex<Kept> = std::sync::Mutex::new(Kept::new());
    let environment: Vec<Option<String>> = ["CC", "LYAPSWEEP_STEP_LOOPS", "XDG_CACHE_HOME", "HOME"]
        .iter()
        .map(|name| std::env::var(name).ok())
        .collect();
    let key = format!("{text}\u{0}{environment:?}");
    let kept = |key: &str| {
        KEPT.lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(key)
            .copied()
    };
    if let Some(info) = kept(&key) {
        return Ok(info);
    }
    // Compiled outside the lock: other models compile at the same time.
    let code = compile()?;
    let mut all = KEPT.lock().unwrap_or_else(|e| e.into_inner());
    // Another thread may have kept the same model meanwhile: its is used,
    // and this one dropped.
    Ok(*all.entry(key).or_insert_with(|| info(code)))
}

/// [`info`] for a built-in kind given as a model (`system::MODEL_KINDS`):
/// its parameters are the scene's `[system]` keys, and `default_sweep` is
/// what a sweep naming no parameter sweeps, and `exact` how the exact
/// backend propagates it.
pub fn info_as(
    code: Code,
    table: &'static str,
    default_sweep: &str,
    exact: ExactPropagator,
) -> &'static SystemInfo {
    DESCRIBED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let code: &'static Code = Box::leak(Box::new(code));
    let model = &code.model;
    let parameters: Vec<Parameter> = model
        .names
        .parameters
        .iter()
        .zip(&model.defaults)
        .map(|(name, &default)| Parameter {
            name: leak(name),
            default,
            doc: "",
        })
        .collect();
    let on_section = code.section.as_ref().map(|s| s.state);
    let state_names: Vec<&'static str> = model
        .names
        .states
        .iter()
        .enumerate()
        .filter(|(i, _)| Some(*i) != on_section)
        .map(|(_, s)| leak(s))
        .collect();
    let mut events: Vec<&'static str> = code
        .walls
        .iter()
        .map(|w| leak(&w.name))
        .chain(code.surfaces.iter().map(|s| leak(&s.name)))
        .collect();
    // A built-in kind keeps the columns its scenes always had: its one
    // wall's crossings are `impacts_per_period`.
    if table == "system" && events.len() <= 1 {
        events.clear();
    }
    // A Poincaré map starts from a point of the flow (all states).
    let initial = if code.section.is_some() { 1.0 } else { 0.0 };
    Box::leak(Box::new(SystemInfo {
        kind: leak(&model.name),
        parameters: Box::leak(parameters.into_boxed_slice()),
        state_names: Box::leak(state_names.into_boxed_slice()),
        default_sweep: leak(default_sweep),
        default_initial_state: Box::leak(vec![initial; code.states()].into_boxed_slice()),
        is_flow: true,
        has_exact: code.is_piecewise_linear,
        exact,
        check,
        check_state,
        expected_sum,
        period: |p| code_of(p).period(&p.values),
        slowest_rate,
        forcing_frequency: |p| code_of(p).frequency(&p.values),
        gpu_refuses,
        wgsl: crate::model::codegen::wgsl::system_file(code),
        wall_reachable: if code.walls.is_empty() && code.surfaces.is_empty() {
            None
        } else {
            Some(may_reach_an_event)
        },
        model: Some(code),
        table,
        events: Box::leak(events.into_boxed_slice()),
    }))
}

fn code_of(p: &Params) -> &'static Code {
    p.info.model.expect("a model's parameters")
}

fn check(p: &Params) -> std::result::Result<(), (&'static str, String)> {
    let code = code_of(p);
    super::check_finite(p)?;
    for ((param, &value), &(min, max)) in p
        .info
        .parameters
        .iter()
        .zip(&p.values)
        .zip(&code.model.ranges)
    {
        if !(min..=max).contains(&value) {
            let reason = match (min.is_finite(), max.is_finite()) {
                (true, true) => format!(
                    "must lie in [{}, {}], got {}",
                    number(min),
                    number(max),
                    number(value)
                ),
                (true, false) => format!("must be >= {}, got {}", number(min), number(value)),
                _ => format!("must be <= {}, got {}", number(max), number(value)),
            };
            return Err((param.name, reason));
        }
    }
    let t = code.period(&p.values);
    if !(t.is_finite() && t > 0.0) {
        let crate::model::Map::Period(period) = &code.model.map else {
            unreachable!("a Poincaré map has no period expression")
        };
        // A period that is one parameter (the `lorenz` kind's
        // `system.period`) is that parameter's fault.
        let bare = match period {
            Expr::Var(Var::Param(i)) => Some(p.info.parameters[*i].name),
            _ => None,
        };
        return Err(match bare.or_else(|| blamed(p, period)) {
            Some(name) => (
                name,
                format!(
                    "the map's period must be a finite number > 0, got {}",
                    number(t)
                ),
            ),
            None => (
                "model.map.period",
                format!("must be a finite number > 0, got {}", number(t)),
            ),
        });
    }
    if let Some(section) = &code.section {
        let at = section.at.eval(&[], &p.values, 0.0);
        if !at.is_finite() {
            return Err((
                "model.map.section.at",
                format!("must be finite, got {}", number(at)),
            ));
        }
    }
    for limit in code
        .model
        .switches
        .iter()
        .filter_map(|s| s.stick_limit.as_ref())
    {
        if let Some(value) = crate::model::language::table::bad_stick_limit(limit, &p.values) {
            return Err((
                blamed(p, limit).unwrap_or("model.switches.stick_limit"),
                format!(
                    "the stick limit {}, got {}",
                    crate::model::language::table::STICK_LIMIT_RULE,
                    number(value)
                ),
            ));
        }
    }
    for w in &code.walls {
        let e = w.restitution.eval(&[], &p.values, 0.0);
        if !(0.0..=1.0).contains(&e) {
            return Err((
                blamed(p, &w.restitution).unwrap_or(w.reset_key.as_str()),
                format!("the restitution e must lie in [0, 1], got {e}"),
            ));
        }
    }
    Ok(())
}

/// The parameter a bad value of an expression that the scene's author did
/// not write is blamed on: a built-in kind given as a model
/// (`system::MODEL_KINDS`) has no `model.map.period` in its `[system]`
/// table to name, so an expression of one parameter names that parameter.
fn blamed(p: &Params, expr: &Expr) -> Option<&'static str> {
    if p.info.table != "system" {
        return None;
    }
    let mut read = (0..p.values.len()).filter(|&i| expr.uses(Var::Param(i)));
    match (read.next(), read.next()) {
        (Some(i), None) => Some(p.info.parameters[i].name),
        _ => None,
    }
}

/// Whether the motion from `x` can reach one of the model's events at
/// these parameters (`SystemInfo::wall_reachable`): proved unreachable only
/// for a linear field between events
/// ([`PiecewiseLinear::may_reach_an_event`]).
fn may_reach_an_event(p: &Params, x: &[f64]) -> bool {
    piecewise_linear(code_of(p), &p.values)
        .is_none_or(|system| system.may_reach_an_event(&DVector::from_column_slice(x)))
}

fn check_state(p: &Params, x: &[f64]) -> std::result::Result<(), String> {
    let code = code_of(p);
    for s in code.surfaces.iter().filter(|s| s.kind == Surface::Event) {
        let g = s.g.eval(x, &p.values, 0.0);
        if g > 0.0 {
            return Err(format!(
                "it lies beyond the event '{}' (its surface is {} > 0 there)",
                s.name,
                number(g)
            ));
        }
    }
    for w in walls_at(code, &p.values) {
        if w.side * (x[w.coordinate] - w.position) > 0.0 {
            return Err(format!(
                "{} = {} lies behind the stop at {}",
                code.model.names.states[w.coordinate],
                number(x[w.coordinate]),
                number(w.position)
            ));
        }
    }
    Ok(())
}

/// The exponents per unit time sum to div F (constant here) plus, per
/// unit time, 2·ln e of every crossing of a stop (each multiplies volume
/// by e²). Where div F depends on the state, a Poincaré map integrates it
/// along its returns (its average is in the lane's orbit term, 0 here);
/// a period map does not yet (NaN).
fn expected_sum(p: &Params, crossings_per_time: &[f64]) -> f64 {
    let code = code_of(p);
    let mut sum = match (&code.divergence, &code.divergence_along) {
        (Some(divergence), _) => divergence.eval(&[], &p.values, 0.0),
        // Integrated along the orbit: in the lane's orbit term.
        (None, Some(_)) => 0.0,
        (None, None) => return f64::NAN,
    };
    for (w, &rate) in code.walls.iter().zip(crossings_per_time) {
        if rate != 0.0 {
            sum += 2.0 * w.restitution.eval(&[], &p.values, 0.0).ln() * rate;
        }
    }
    sum
}

/// The rate of the slowest of the flow's own modes: the smallest |μ| over
/// the eigenvalues μ of every region's Jacobian at the origin, where the
/// plan reads the fastest too (`ModelFlow::scales_at_origin`). Neutral
/// modes (|μ| below 1e-9 of the largest: a free coordinate, an angle's
/// drift) have no time scale and are left out; 0 when every mode is.
fn slowest_rate(p: &Params) -> f64 {
    let code = code_of(p);
    let n = code.states();
    let origin = vec![0.0; n];
    let slowest = code
        .regions
        .iter()
        .map(|field| {
            let values: Vec<f64> = field
                .jacobian
                .iter()
                .map(|e| e.eval(&origin, &p.values, 0.0))
                .collect();
            let moduli: Vec<f64> = DMatrix::from_row_slice(n, n, &values)
                .complex_eigenvalues()
                .iter()
                .map(|l| l.norm())
                .collect();
            let largest = moduli.iter().copied().fold(0.0, f64::max);
            moduli
                .into_iter()
                .filter(|&m| m > 1e-9 * largest && m.is_finite())
                .fold(f64::INFINITY, f64::min)
        })
        .fold(f64::INFINITY, f64::min);
    if slowest.is_finite() {
        slowest
    } else {
        0.0
    }
}

/// θ in [-π, π): θ - 2π·floor((θ + π)/2π). Twin of the generated
/// `wrap_angles` of `model::codegen::wgsl`, operation for operation.
pub fn wrap_angle(theta: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    theta - TAU * ((theta + PI) / TAU).floor()
}

/// Periods of the pilot that finds a nonlinear model's time scales.
const PILOT_PERIODS: usize = 2;
/// Samples of the Jacobian per pilot period.
const PILOT_SAMPLES: usize = 32;

/// (max |λ|, max -Re λ, at least 0) of a Jacobian's eigenvalues.
fn eigen_scales(j: &DMatrix<f64>) -> (f64, f64) {
    let eigen = j.complex_eigenvalues();
    (
        eigen.iter().map(|l| l.norm()).fold(0.0, f64::max),
        eigen.iter().map(|l| -l.re).fold(0.0, f64::max),
    )
}

/// A model at one lane's parameter values.
#[derive(Clone, Debug)]
pub struct ModelFlow<const D: usize> {
    code: &'static Code,
    params: Vec<f64>,
    /// Each region's tape's lane constants at these parameters.
    constants: Vec<Vec<f64>>,
    /// Each region's surface tape's lane constants.
    surface_constants: Vec<Vec<f64>>,
    frequency: f64,
    period: f64,
    walls: Vec<Wall>,
    /// Each surface's gradient and each switch's stick limit where they
    /// read neither state nor time, at these parameters: the sliding of a friction model asks for both at
    /// every stage of every step, and walking their trees (a `Vec` per
    /// call of a function) took a twentieth of the friction belt's time.
    constant_gradients: Vec<Option<Vec<f64>>>,
    constant_stick_limits: Vec<Option<f64>>,
    /// The exact backend's propagator of the lane, where the model has
    /// one, built when that backend first asks.
    exact: std::sync::OnceLock<Option<Exact>>,
    /// Which one (`SystemInfo::exact`), and the parameters by name for
    /// the seed's closed form.
    info: &'static SystemInfo,
}

/// A lane's exact propagator ([`ExactPropagator`]).
#[derive(Clone, Debug)]
enum Exact {
    PiecewiseLinear(PiecewiseLinear),
    SeedClosedForm(ForcedImpactOscillator),
}

impl<const D: usize> ModelFlow<D> {
    /// The lane's exact propagator, if its model has one.
    fn exact_propagator(&self) -> Option<Exact> {
        match self.info.exact {
            ExactPropagator::PiecewiseLinear => {
                piecewise_linear(self.code, &self.params).map(Exact::PiecewiseLinear)
            }
            ExactPropagator::SeedClosedForm => {
                let p = Params {
                    info: self.info,
                    values: self.params.clone(),
                };
                ForcedImpactOscillator::new(
                    p.get("zeta"),
                    p.get("f"),
                    p.get("eta"),
                    p.get("wall"),
                    p.get("restitution"),
                )
                .ok()
                .map(Exact::SeedClosedForm)
            }
        }
    }
}

impl<const D: usize> Flow<D> for ModelFlow<D> {
    /// The field of the region y lies in (integration goes through
    /// [`rhs_in`](Flow::rhs_in), each step in its trajectory's region).
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        use crate::integrate::surface::{region_of, sides};
        self.rhs_in(sides(region_of(self, phase, y)), phase, y)
    }

    fn rhs_in(&self, region: u32, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        let field = &self.code.regions[region as usize];
        let constants = &self.constants[region as usize];
        let y: [[f64; 1]; D] = crate::array::from_fn(|i| [y[i]]);
        let out: [[f64; 1]; D] = match &field.native {
            Some(native) => native.call(Kind::Rhs, Layout::Shared, &y, phase, constants, &[]),
            None => field.equations.eval(|j| [constants[j]], &[*phase], &y),
        };
        crate::array::from_fn(|i| out[i][0])
    }

    #[inline(always)]
    fn step_one_in(&self, region: u32, stages: &[Phase; 3], y: &[f64; D], h: f64) -> [f64; D] {
        // One native call for the step (the stages' four calls of
        // `rhs_in` each paid the call's marshalling: a tenth of the seed's
        // 200-step sweep, in the impacts' re-steps).
        let y: [[f64; 1]; D] = crate::array::from_fn(|i| [y[i]]);
        let out = self.step_shared_in::<1>(region, stages, &y, h);
        crate::array::from_fn(|i| out[i][0])
    }

    fn slide_step(
        &self,
        set: &SlidingSet,
        stages: &[Phase; 3],
        y: &[f64; D],
        h: f64,
    ) -> Option<[f64; D]> {
        // The C compiler's step of a slide on one switch or two with
        // constant gradients: the stages' field calls and the equivalent
        // control's arithmetic in one call (a friction model's sliding).
        let loops = self.code.switch_loops.as_ref()?.as_ref().ok()?;
        let base = set.base();
        let below = self.constants[base as usize].as_slice();
        let above = |bit: u32| self.constants[(base | 1 << bit) as usize].as_slice();
        let gradient = |j: usize| self.constant_gradients[j].as_deref();
        match *set.members() {
            [(j, bit)] => {
                let fields = [below, above(bit)];
                loops.slide_step(base, &[bit], stages, y, h, &fields, &[gradient(j)?])
            }
            [(j, b0), (k, b1)] => {
                let fields = [below, above(b0), above(b1)];
                let gradients = [gradient(j)?, gradient(k)?];
                loops.slide_step(base, &[b0, b1], stages, y, h, &fields, &gradients)
            }
            _ => None,
        }
    }

    fn surfaces(&self) -> &[Surface] {
        &self.code.kinds
    }

    fn surface_values(&self, region: u32, phase: &Phase, y: &[f64; D]) -> SurfaceValues {
        // By value (`Native::call`), not in place: a lone trajectory's
        // values are scalars, which only the call's reading takes from the
        // store buffer.
        let field = &self.code.regions[region as usize];
        let constants = &self.surface_constants[region as usize];
        let y: [[f64; 1]; D] = crate::array::from_fn(|i| [y[i]]);
        let out: [[f64; 1]; 2 * MAX_SURFACES] = match &field.surfaces_native {
            Some(native) => native.call(Kind::Rhs, Layout::Shared, &y, phase, constants, &[]),
            None => field.surfaces.eval(|j| [constants[j]], &[*phase], &y),
        };
        SurfaceValues {
            g: crate::array::from_fn(|j| out[2 * j][0]),
            rate: crate::array::from_fn(|j| out[2 * j + 1][0]),
        }
    }

    /// The surfaces' native code where there is one for W (the same
    /// operations as the tape's interpreter, so the same bits).
    #[inline(always)]
    fn surface_values_shared<const W: usize>(
        &self,
        region: u32,
        phase: &Phase,
        y: &[[f64; W]; D],
        out: &mut SurfaceBatch<W>,
    ) {
        let field = &self.code.regions[region as usize];
        let constants = &self.surface_constants[region as usize];
        match &field.surfaces_native {
            Some(native) if Native::has::<W>() => {
                let rows = &mut out.rows;
                native.call_into(Kind::Rhs, Layout::Shared, y, phase, constants, &[], rows)
            }
            _ => out.rows = field.surfaces.eval(|j| [constants[j]; W], &[*phase; W], y),
        }
    }

    /// Slots in different regions are evaluated once per region present,
    /// each region's code over the whole batch, its slots kept.
    #[inline(always)]
    fn surface_values_each<const W: usize>(
        flows: &[&Self; W],
        regions: &[u32; W],
        phases: &[Phase; W],
        y: &[[f64; W]; D],
        out: &mut SurfaceBatch<W>,
    ) {
        let first = regions[0];
        Self::surface_values_each_region(first, flows, phases, y, out);
        for (k, &r) in regions.iter().enumerate() {
            // The first slot of each other region evaluates it.
            if r != first && !regions[..k].contains(&r) {
                let mut other = SurfaceBatch::default();
                Self::surface_values_each_region(r, flows, phases, y, &mut other);
                for m in (k..W).filter(|&m| regions[m] == r) {
                    out.take_column(m, &other);
                }
            }
        }
    }

    // Inlined into its callers (the sliding field's, per stage): returned
    // through memory, its scalar stores were read back as one 128-bit
    // load, which waited for them (a store-forward stall).
    #[inline(always)]
    fn surface_gradient(&self, j: usize, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        if let Some(gradient) = &self.constant_gradients[j] {
            return crate::array::from_fn(|i| gradient[i]);
        }
        let s = &self.code.surfaces[j];
        // (A gradient that does not read t is the same at any t.)
        let t = if s.gradient_reads_time {
            self.time_at(phase)
        } else {
            0.0
        };
        crate::array::from_fn(|i| s.gradient[i].eval(y, &self.params, t))
    }

    fn stick_limit(&self, j: usize, y: &[f64; D]) -> Option<f64> {
        if let Some(limit) = self.constant_stick_limits[j] {
            return Some(limit);
        }
        self.code.surfaces[j]
            .stick_limit
            .as_ref()
            .map(|l| l.eval(y, &self.params, 0.0))
    }

    fn event_hold(
        &self,
        j: usize,
        phase: &Phase,
        y: &[f64; D],
    ) -> Option<crate::integrate::EventHoldValues<D>> {
        let s = &self.code.surfaces[j];
        let hold = s.hold.as_ref()?;
        let t = self.time_at(phase);
        let at = |e: &Expr| e.eval(y, &self.params, t);
        Some(crate::integrate::EventHoldValues {
            g: at(&s.g),
            gradient: crate::array::from_fn(|i| at(&s.gradient[i])),
            rate: at(&hold.rate),
            rate_gradient: crate::array::from_fn(|i| at(&hold.rate_gradient[i])),
            pressing: at(&hold.pressing),
            pushed: crate::array::from_fn(|i| hold.pushed[i]),
        })
    }

    fn reset(&self, j: usize, phase: &Phase, y: &[f64; D]) -> crate::integrate::Reset<D> {
        let s = &self.code.surfaces[j];
        let t = self.time_at(phase);
        (
            crate::array::from_fn(|i| s.reset[i].eval(y, &self.params, t)),
            crate::array::from_fn(|i| {
                crate::array::from_fn(|k| s.reset_jacobian[i * D + k].eval(y, &self.params, t))
            }),
            crate::array::from_fn(|i| s.reset_rate[i].eval(y, &self.params, t)),
        )
    }

    fn forcing_frequency(&self) -> f64 {
        self.frequency
    }

    fn walls(&self) -> &[Wall] {
        &self.walls
    }

    /// The equations' native step loop ([`Native::walk`]), compiled for a
    /// period map without general surfaces, with its stops; with them, the
    /// regions' loop of the C compiler ([`SwitchLoops::walk`]).
    #[inline(always)]
    fn walk_shared<const W: usize>(
        &self,
        y: &mut [[f64; W]; D],
        phase: &mut Phase,
        half: &Phase,
        h: f64,
        live: u32,
        steps: usize,
        switching: Option<Switching<'_, W>>,
    ) -> Option<usize> {
        let mut walls = [0.0; crate::integrate::impact::MAX_WALLS];
        for (j, wall) in self.walls.iter().enumerate() {
            walls[j] = wall.position;
        }
        let mut clock = [phase[0], phase[1], half[0], half[1]];
        let taken = match switching {
            None => self.code.regions[0].native.as_ref()?.walk(
                Layout::Shared,
                y,
                &mut clock,
                &self.constants[0],
                &[h],
                &walls,
                live,
                steps,
            ),
            Some(Switching { regions, values }) => {
                let loops = self.code.switch_loops.as_ref()?.as_ref().ok()?;
                let mut lanes = [[std::ptr::null(); 2]; 1 << MAX_SURFACES];
                let count = self.constants.len();
                for (r, lane) in lanes[..count].iter_mut().enumerate() {
                    *lane = [
                        self.constants[r].as_ptr(),
                        self.surface_constants[r].as_ptr(),
                    ];
                }
                loops.walk(
                    Layout::Shared,
                    y,
                    &mut clock,
                    &lanes[..count],
                    &[h],
                    &walls,
                    live,
                    steps,
                    &regions,
                    &mut values.rows,
                )
            }
        };
        *phase = [clock[0], clock[1]];
        taken
    }

    #[inline(always)]
    fn walk_each<const W: usize>(
        flows: &[&Self; W],
        y: &mut [[f64; W]; D],
        phases: &mut [Phase; W],
        half: &[Phase; W],
        h: &[f64; W],
        live: u32,
        steps: usize,
        switching: Option<Switching<'_, W>>,
    ) -> Option<usize> {
        // The loop turns one phase for every slot: lanes on the same grid
        // share it to the bit (`clock::half_turn`); others step one step
        // at a time.
        let bits = |p: &Phase| p.map(f64::to_bits);
        let one_phase = (1..W)
            .all(|k| bits(&phases[k]) == bits(&phases[0]) && bits(&half[k]) == bits(&half[0]));
        if !one_phase {
            return None;
        }
        let mut clock = [phases[0][0], phases[0][1], half[0][0], half[0][1]];
        // Rows of W: each wall's position (its side is compiled in).
        let mut walls = [[0.0; W]; crate::integrate::impact::MAX_WALLS];
        for (k, flow) in flows.iter().enumerate() {
            for (j, wall) in flow.walls.iter().enumerate() {
                walls[j][k] = wall.position;
            }
        }
        let taken = match switching {
            None => {
                let native = flows[0].code.regions[0].native.as_ref()?;
                let slots: [&[f64]; W] =
                    crate::array::from_fn(|k| flows[k].constants[0].as_slice());
                if slots[0].len() > EACH_CONSTANTS {
                    return None;
                }
                let mut scratch = [MaybeUninit::uninit(); EACH_CONSTANTS];
                let lane = side_by_side(&slots, &mut scratch);
                native.walk(
                    Layout::Each,
                    y,
                    &mut clock,
                    lane.as_flattened(),
                    h,
                    walls.as_flattened(),
                    live,
                    steps,
                )
            }
            Some(Switching { regions, values }) => {
                let loops = flows[0].code.switch_loops.as_ref()?.as_ref().ok()?;
                // The constants of the regions present, side by side (the
                // loop reads no other region's); past a few regions at
                // once, the step loop of `integrate` takes the steps.
                let mut scratch = [[MaybeUninit::uninit(); EACH_CONSTANTS]; 2 * PRESENT_REGIONS];
                let mut free = scratch.iter_mut();
                let mut lanes = [[std::ptr::null(); 2]; 1 << MAX_SURFACES];
                let count = flows[0].constants.len();
                for (r, lane) in lanes[..count].iter_mut().enumerate() {
                    if !regions.contains(&(r as u32)) {
                        continue;
                    }
                    let field: [&[f64]; W] =
                        crate::array::from_fn(|k| flows[k].constants[r].as_slice());
                    let surfaces: [&[f64]; W] =
                        crate::array::from_fn(|k| flows[k].surface_constants[r].as_slice());
                    if field[0].len().max(surfaces[0].len()) > EACH_CONSTANTS {
                        return None;
                    }
                    let (a, b) = (free.next()?, free.next()?);
                    *lane = [
                        side_by_side(&field, a).as_ptr().cast(),
                        side_by_side(&surfaces, b).as_ptr().cast(),
                    ];
                }
                loops.walk(
                    Layout::Each,
                    y,
                    &mut clock,
                    &lanes[..count],
                    h,
                    walls.as_flattened(),
                    live,
                    steps,
                    &regions,
                    &mut values.rows,
                )
            }
        };
        *phases = [[clock[0], clock[1]]; W];
        taken
    }

    #[inline(always)]
    fn step_shared<const W: usize>(
        &self,
        stages: &[Phase; 3],
        y: &[[f64; W]; D],
        h: f64,
    ) -> [[f64; W]; D] {
        self.step_shared_in(0, stages, y, h)
    }

    #[inline(always)]
    fn step_shared_in<const W: usize>(
        &self,
        region: u32,
        stages: &[Phase; 3],
        y: &[[f64; W]; D],
        h: f64,
    ) -> [[f64; W]; D] {
        let constants = &self.constants[region as usize];
        if let Some(native) = self.native::<W>(region) {
            let clock = stages.as_flattened();
            return native.call(Kind::Step, Layout::Shared, y, clock, constants, &[h]);
        }
        let tape = &self.code.regions[region as usize].equations;
        let mut registers = Registers::new();
        tape.prepare(&mut registers, |j| [constants[j]; W]);
        rk4::step_batch(
            #[inline(always)]
            |s, y| tape.run(&mut registers, &[stages[s]; W], y),
            y,
            &[h; W],
        )
    }

    #[inline(always)]
    fn step_each<const W: usize>(
        flows: &[&Self; W],
        stages: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        Self::step_each_region(0, flows, stages, y, h)
    }

    /// Slots in different regions are stepped once per region present,
    /// each region's code over the whole batch, its slots kept.
    #[inline(always)]
    fn step_each_in<const W: usize>(
        flows: &[&Self; W],
        regions: &[u32; W],
        stages: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        let first = regions[0];
        let mut out = Self::step_each_region(first, flows, stages, y, h);
        let mut done = 1u32 << first;
        for &r in regions {
            if done & (1 << r) == 0 {
                done |= 1 << r;
                let other = Self::step_each_region(r, flows, stages, y, h);
                for k in (0..W).filter(|&k| regions[k] == r) {
                    for i in 0..D {
                        out[i][k] = other[i][k];
                    }
                }
            }
        }
        out
    }
}

/// The most regions whose constants [`ModelFlow::walk_each`] gathers for
/// the regions' step loop at once (on the stack, per call); a batch with
/// more present steps in the step loop of `integrate`.
const PRESENT_REGIONS: usize = 4;

/// The most lane constants [`ModelFlow::step_each`] gathers for the native
/// code (on the stack, per step); a model with more runs the interpreter.
const EACH_CONSTANTS: usize = 32;

/// The W slots' constants side by side, constant j of every slot in row j,
/// in `scratch`'s first rows (as many as a slot has constants). Only those
/// rows are written: zeroing the whole scratch (2 KiB at W = 8, a
/// `memset` before every step and every surfaces' evaluation of a batch of
/// lanes) cost the models 2 to 6 percent of their run (docs/BENCHMARKS.md).
#[inline(always)]
fn side_by_side<'s, const W: usize>(
    slots: &[&[f64]; W],
    scratch: &'s mut [MaybeUninit<[f64; W]>; EACH_CONSTANTS],
) -> &'s [[f64; W]] {
    let l = slots[0].len();
    for (j, row) in scratch[..l].iter_mut().enumerate() {
        row.write(crate::array::from_fn(|k| slots[k][j]));
    }
    // SAFETY: rows 0..l were written just above; MaybeUninit<T> has T's
    // layout.
    unsafe { std::slice::from_raw_parts(scratch.as_ptr().cast::<[f64; W]>(), l) }
}

impl<const D: usize> ModelFlow<D> {
    /// The local time of forcing phase (cos ωt, sin ωt) within the period:
    /// where an expression evaluated as a tree (a reset, a gradient) reads
    /// `t`, it reads the same cos ωt and sin ωt as the tapes' clock.
    fn time_at(&self, phase: &Phase) -> f64 {
        if self.frequency == 0.0 {
            return 0.0;
        }
        phase[1].atan2(phase[0]).rem_euclid(std::f64::consts::TAU) / self.frequency
    }

    /// The native code of a region's equations, if there is one for
    /// batches of W.
    #[inline(always)]
    fn native<const W: usize>(&self, region: u32) -> Option<&'static Native> {
        self.code.regions[region as usize]
            .native
            .as_ref()
            .filter(|_| Native::has::<W>())
    }

    /// One RK4 step of one trajectory of each of W flows, all in region
    /// `region` (see `Flow::step_each`).
    #[inline(always)]
    fn step_each_region<const W: usize>(
        region: u32,
        flows: &[&Self; W],
        stages: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        let r = region as usize;
        // Each slot's constants of this region, looked up once per step.
        let slots: [&[f64]; W] = crate::array::from_fn(|k| flows[k].constants[r].as_slice());
        let l = slots[0].len();
        if let Some(native) = flows[0].native::<W>(region).filter(|_| l <= EACH_CONSTANTS) {
            // The slots' constants and stage phases side by side.
            let mut scratch = [MaybeUninit::uninit(); EACH_CONSTANTS];
            let lane = side_by_side(&slots, &mut scratch);
            let mut clock = [[0.0; W]; 6];
            for s in 0..3 {
                for k in 0..W {
                    clock[2 * s][k] = stages[k][s][0];
                    clock[2 * s + 1][k] = stages[k][s][1];
                }
            }
            let (lane, clock) = (lane.as_flattened(), clock.as_flattened());
            return native.call(Kind::Step, Layout::Each, y, clock, lane, h);
        }
        let tape = &flows[0].code.regions[r].equations;
        let mut registers = Registers::new();
        tape.prepare(&mut registers, |j| crate::array::from_fn(|k| slots[k][j]));
        rk4::step_batch(
            #[inline(always)]
            |s, y| tape.run(&mut registers, &crate::array::from_fn(|k| stages[k][s]), y),
            y,
            h,
        )
    }

    /// The surfaces' values and rates of one trajectory of each of W
    /// flows, all in region `region` (see `Flow::surface_values_each`).
    #[inline(always)]
    fn surface_values_each_region<const W: usize>(
        region: u32,
        flows: &[&Self; W],
        phases: &[Phase; W],
        y: &[[f64; W]; D],
        out: &mut SurfaceBatch<W>,
    ) {
        let r = region as usize;
        let slots: [&[f64]; W] =
            crate::array::from_fn(|k| flows[k].surface_constants[r].as_slice());
        let l = slots[0].len();
        let field = &flows[0].code.regions[r];
        match &field.surfaces_native {
            Some(native) if Native::has::<W>() && l <= EACH_CONSTANTS => {
                // The slots' constants and phases side by side.
                let mut scratch = [MaybeUninit::uninit(); EACH_CONSTANTS];
                let lane = side_by_side(&slots, &mut scratch);
                let mut clock = [[0.0; W]; 2];
                for k in 0..W {
                    clock[0][k] = phases[k][0];
                    clock[1][k] = phases[k][1];
                }
                let (lane, clock) = (lane.as_flattened(), clock.as_flattened());
                native.call_into(Kind::Rhs, Layout::Each, y, clock, lane, &[], &mut out.rows)
            }
            _ => {
                out.rows =
                    field
                        .surfaces
                        .eval(|j| crate::array::from_fn(|k| slots[k][j]), phases, y)
            }
        }
    }

    /// The flow's Jacobian at y and time t, as a matrix.
    fn jacobian_at(&self, y: &[f64; D], t: f64, region: u32) -> DMatrix<f64> {
        let values: Vec<f64> = self.code.regions[region as usize]
            .jacobian
            .iter()
            .map(|e| e.eval(y, &self.params, t))
            .collect();
        DMatrix::from_row_slice(D, D, &values)
    }
}

impl<const D: usize> ModelFlow<D> {
    /// (max |λ|, max -Re λ) of every region's Jacobian at the origin: a
    /// piecewise-linear model's time scales, all of its regions'.
    fn scales_at_origin(&self) -> (f64, f64) {
        (0..self.code.regions.len() as u32)
            .map(|r| eigen_scales(&self.jacobian_at(&[0.0; D], 0.0, r)))
            .fold((0.0, 0.0), |a, b| (a.0.max(b.0), a.1.max(b.1)))
    }
}

impl<const D: usize> System<D> for ModelFlow<D> {
    fn new(p: &Params) -> Self {
        let code = code_of(p);
        ModelFlow {
            code,
            params: p.values.clone(),
            constants: code
                .regions
                .iter()
                .map(|f| f.equations.lane_values(&p.values).constants)
                .collect(),
            surface_constants: code
                .regions
                .iter()
                .map(|f| f.surfaces.lane_values(&p.values).constants)
                .collect(),
            frequency: code.frequency(&p.values),
            period: code.period(&p.values),
            walls: walls_at(code, &p.values),
            constant_gradients: code
                .surfaces
                .iter()
                .map(|s| {
                    s.gradient.iter().all(|e| !reads_state_or_time(e)).then(|| {
                        s.gradient
                            .iter()
                            .map(|e| e.eval(&[], &p.values, 0.0))
                            .collect()
                    })
                })
                .collect(),
            constant_stick_limits: code
                .surfaces
                .iter()
                .map(|s| match &s.stick_limit {
                    Some(l) if !reads_state_or_time(l) => Some(l.eval(&[], &p.values, 0.0)),
                    _ => None,
                })
                .collect(),
            exact: std::sync::OnceLock::new(),
            info: p.info,
        }
    }

    fn period(&self) -> f64 {
        self.period
    }

    fn iterate(&self, x: &[f64; D], flow: &FlowSettings, stats: &mut IterationStats) -> [f64; D] {
        time_map(self, x, self.period, flow, stats)
    }

    /// The piecewise-linear propagator's span: exact flow matrices between
    /// crossings located by a certified search, saltation matrices at them
    /// (or the seed's closed form, for its kind).
    fn iterate_exact(
        &self,
        x: &[f64; D],
        part: Part,
        stats: &mut IterationStats,
    ) -> Option<([f64; D], SMatrix<f64, D, D>)> {
        let exact = self
            .exact
            .get_or_init(|| self.exact_propagator())
            .as_ref()?;
        let (t0, t1) = part.span(self.period);
        let exact = match exact {
            Exact::PiecewiseLinear(exact) => exact,
            Exact::SeedClosedForm(closed) => {
                let it = closed.iterate_span([x[0], x[1]], t0, t1);
                stats.impacts += it.impacts;
                stats.crossings[0] += it.impacts;
                stats.rank_loss = stats.rank_loss.max(it.rank_loss);
                stats.chattering |= it.status != ExactStatus::Ok;
                let state: [f64; D] = crate::array::from_fn(|i| it.state[i]);
                return Some((state, SMatrix::from_column_slice(it.jacobian.as_slice())));
            }
        };
        let y = DVector::from_column_slice(x);
        let it = exact.iterate_span(&y, exact.region(&y), t0, t1);
        let walls = self.walls.len();
        let mut wall_log_det = 0.0;
        for (j, &c) in it.crossings.iter().enumerate() {
            stats.crossings[j] += c;
            if j < walls {
                stats.impacts += c;
                if c > 0 {
                    wall_log_det += 2.0 * f64::from(c) * self.walls[j].restitution.ln();
                }
            }
        }
        // The walls' e² per impact is in the expected sum already; the
        // general surfaces' det S goes with the orbit.
        let general = it.log_det_saltation - wall_log_det;
        if general.is_finite() {
            stats.log_flux += general;
        } else {
            stats.rank_loss = stats.rank_loss.max(1);
        }
        // Sliding forgets one direction, a mass held on a stop two.
        stats.rank_loss = stats.rank_loss.max(it.rank_loss);
        stats.slowest_impact = stats.slowest_impact.min(it.min_crossing_rate);
        match it.status {
            PiecewiseStatus::Ok => {}
            PiecewiseStatus::Sliding => stats.sliding = true,
            PiecewiseStatus::Grazing => {
                stats.grazing = true;
                stats.grazing_error = f64::INFINITY;
            }
            PiecewiseStatus::Chattering | PiecewiseStatus::Sticking => stats.chattering = true,
            PiecewiseStatus::Diverged => {}
        }
        let state: [f64; D] = crate::array::from_fn(|i| it.state[i]);
        Some((state, SMatrix::from_column_slice(it.jacobian.as_slice())))
    }

    fn iterate_lanes(
        systems: &[&Self],
        xs: &mut [[f64; D]],
        flow: &FlowSettings,
        stats: &mut [IterationStats],
    ) {
        super::time_map_lanes(systems, xs, flow, stats)
    }

    /// Not where [`part_many`](System::part_many) integrates a
    /// state-dependent divergence along the reference.
    fn averages_across_lanes(&self) -> bool {
        self.code.equations_divergence().is_none()
    }

    fn iterate_many(&self, ys: &mut [[f64; D]], flow: &FlowSettings, stats: &mut [IterationStats]) {
        time_map_many(self, ys, self.period, flow, stats)
    }

    fn part_many(
        &self,
        ys: &mut [[f64; D]],
        flow: &FlowSettings,
        part: Part,
        phase: &mut Phase,
        stats: &mut [IterationStats],
    ) {
        let (start, start_phase) = (ys.first().copied(), *phase);
        part_map_many(self, ys, self.period, flow, part, phase, stats);
        // A divergence that depends on the state: integrated along the
        // reference (the same steps again, alone), for the sum rule.
        if let (Some(tape), Some(start)) = (&self.code.equations_divergence(), start) {
            let h = self.period / flow.steps_per_period as f64;
            let half = crate::integrate::clock::half_turn(self.frequency, h, flow.steps_per_period);
            let steps = part.steps(flow.steps_per_period).len();
            let constants = tape.lane_values(&self.params).constants;
            let density = |phase: &Phase, y: &[f64; D]| -> f64 {
                let y: [[f64; 1]; D] = crate::array::from_fn(|i| [y[i]]);
                let out: [[f64; 1]; 1] = tape.eval(|j| [constants[j]], &[*phase], &y);
                out[0][0]
            };
            let (end, integral) = crate::integrate::advance_integrating(
                self,
                &start,
                start_phase,
                (h, half),
                steps,
                density,
            );
            debug_assert_eq!(end, ys[0]);
            stats[0].log_flux += integral;
        }
    }

    /// The largest |eigenvalue| of the Jacobian at the origin: exact for a
    /// flow linear between impacts (the seed's oscillator gives 1, as its
    /// hand-written twin does), an estimate for a nonlinear one (see
    /// `time_scales`).
    fn stiffness(&self) -> f64 {
        self.scales_at_origin().0
    }

    /// The fastest decay rate at the origin, -min Re λ (0 if none decays).
    fn contraction(&self) -> f64 {
        self.scales_at_origin().1
    }

    /// A flow whose Jacobian depends on the state (or time) has its time
    /// scales where its orbit goes, not at the origin (van der Pol's
    /// origin is unstable; it contracts on its relaxation cycle): the
    /// largest over the origin and a pilot of `PILOT_PERIODS` periods
    /// from the initial state, sampled `PILOT_SAMPLES` times a period. A
    /// constant Jacobian (a flow linear between impacts) is read at the
    /// origin alone, as [`stiffness`](System::stiffness) does.
    fn time_scales(&self, initial: &[f64], flow: &FlowSettings) -> (f64, f64) {
        let at_origin = (self.stiffness(), self.contraction());
        let constant = self
            .code
            .regions
            .iter()
            .all(|f| f.jacobian.iter().all(|e| !reads_state_or_time(e)));
        if constant || initial.len() != D {
            return at_origin;
        }
        let mut y: [f64; D] = crate::array::from_fn(|i| initial[i]);
        let mut scales = at_origin;
        let mut stats = [IterationStats::default()];
        for _ in 0..PILOT_PERIODS {
            let mut phase = crate::integrate::clock::ZERO_PHASE;
            for part in Part::all(PILOT_SAMPLES) {
                let t = self.period * part.index as f64 / PILOT_SAMPLES as f64;
                let region = crate::integrate::surface::sides(
                    crate::integrate::surface::region_of(self, &phase, &y),
                );
                let (stiffness, contraction) = eigen_scales(&self.jacobian_at(&y, t, region));
                scales = (scales.0.max(stiffness), scales.1.max(contraction));
                let mut ys = [y];
                part_map_many(
                    self,
                    &mut ys,
                    self.period,
                    flow,
                    part,
                    &mut phase,
                    &mut stats,
                );
                y = ys[0];
                if !y.iter().all(|v| v.is_finite()) {
                    return scales;
                }
            }
        }
        scales
    }

    fn admits(&self, y: &[f64; D]) -> bool {
        self.walls.iter().all(|w| w.gap(y) <= 0.0)
            && self
                .code
                .surfaces
                .iter()
                .all(|s| s.kind != Surface::Event || s.g.eval(y, &self.params, 0.0) <= 0.0)
    }

    fn wrap(&self, x: &mut [f64; D]) {
        for &i in &self.code.model.angles {
            x[i] = wrap_angle(x[i]);
        }
    }
}

/// Why the GPU kernels cannot run this model, the same for every lane
/// (`model::codegen::wgsl::check`); `None` when its generated WGSL runs.
fn gpu_refuses(p: &Params) -> Option<String> {
    crate::model::codegen::wgsl::check(code_of(p))
        .err()
        .map(|why| why.to_string())
}
