//! A compiled model at one lane's parameters run as a flow
//! ([`ModelFlow`]): its fields per region of the switches, its stops as
//! walls, its other events and switches as the integrator's surfaces, and
//! its native step loops and batches.

use std::mem::MaybeUninit;

use nalgebra::DMatrix;

use crate::integrate::clock::Phase;
use crate::integrate::closed_form::ForcedImpactOscillator;
use crate::integrate::piecewise_linear::PiecewiseLinear;
use crate::integrate::surface::{SlidingSet, MAX_SURFACES};
use crate::integrate::{rk4, Flow, Surface, SurfaceBatch, SurfaceValues, Switching, Wall};
use crate::model::compiled::{piecewise_linear, Code};
use crate::model::ir::tape::Registers;
use crate::model::language::expr::Expr;
use crate::model::native::abi::{Kind, Layout};
use crate::model::native::library::Native;
use crate::system::{ExactPropagator, Params, SystemInfo};

use super::description::eigen_scales;

/// A model at one lane's parameter values.
#[derive(Clone, Debug)]
pub struct ModelFlow<const D: usize> {
    pub(super) code: &'static Code,
    pub(super) params: Vec<f64>,
    /// Each region's tape's lane constants at these parameters.
    pub(super) constants: Vec<Vec<f64>>,
    /// Each region's surface tape's lane constants.
    pub(super) surface_constants: Vec<Vec<f64>>,
    pub(super) frequency: f64,
    pub(super) period: f64,
    pub(super) walls: Vec<Wall>,
    /// Each surface's gradient and each switch's stick limit where they
    /// read neither state nor time, at these parameters: the sliding of a friction model asks for both at
    /// every stage of every step, and walking their trees (a `Vec` per
    /// call of a function) took a twentieth of the friction belt's time.
    pub(super) constant_gradients: Vec<Option<Vec<f64>>>,
    pub(super) constant_stick_limits: Vec<Option<f64>>,
    /// The exact backend's propagator of the lane, where the model has
    /// one, built when that backend first asks.
    pub(super) exact: std::sync::OnceLock<Option<Exact>>,
    /// Which one (`SystemInfo::exact`), and the parameters by name for
    /// the seed's closed form.
    pub(super) info: &'static SystemInfo,
}

/// A lane's exact propagator ([`ExactPropagator`]).
#[derive(Clone, Debug)]
pub(super) enum Exact {
    PiecewiseLinear(PiecewiseLinear),
    SeedClosedForm(ForcedImpactOscillator),
}

impl<const D: usize> ModelFlow<D> {
    /// The lane's exact propagator, if its model has one.
    pub(super) fn exact_propagator(&self) -> Option<Exact> {
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
/// lanes) cost the models 2 to 6 percent of their run, when measured.
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
    pub(super) fn jacobian_at(&self, y: &[f64; D], t: f64, region: u32) -> DMatrix<f64> {
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
    pub(super) fn scales_at_origin(&self) -> (f64, f64) {
        (0..self.code.regions.len() as u32)
            .map(|r| eigen_scales(&self.jacobian_at(&[0.0; D], 0.0, r)))
            .fold((0.0, 0.0), |a, b| (a.0.max(b.0), a.1.max(b.1)))
    }
}
