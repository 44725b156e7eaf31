//! What the integrator knows of a flow: the [`Flow`] trait (the right-hand
//! side, its walls and general surfaces, the resets, and the steps a flow
//! may take in code of its own), the types of its answers, and
//! [`InRegion`], a flow restricted to one region of its switches. Below
//! the code that steps and resolves crossings (`impact`, `surface`,
//! `section` and the step loop of `integrate`), above what a wall and a
//! surface are (`wall`, `region`) and the RK4 step (`rk4`).

use super::clock::Phase;
use super::region::{SlidingSet, Surface, SurfaceBatch, SurfaceValues};
use super::rk4;
use super::wall::Wall;

/// An event's reset at one state: the state after, DR, and ∂R/∂t.
pub type Reset<const D: usize> = ([f64; D], [[f64; D]; D], [f64; D]);

/// Event j's surface and its rates at a state, for holding the motion on
/// it (`model::compiled::EventHold`): g and ∇g, ġ and ∇ġ, g̈ along the free
/// field (> 0 presses into the surface), and the states the reset changes.
#[derive(Clone, Copy, Debug)]
pub struct EventHoldValues<const D: usize> {
    pub g: f64,
    pub gradient: [f64; D],
    pub rate: f64,
    pub rate_gradient: [f64; D],
    pub pressing: f64,
    pub pushed: [bool; D],
}

/// A flow y' = F(t, y) in D dimensions, possibly forced, possibly with a wall.
///
/// Time enters only through the forcing phase (cos ωt, sin ωt), which every
/// map iteration restarts at ωt = 0 (see [`clock`](super::clock)): exact
/// for a forcing of period T, and no time variable can drift over long
/// runs.
pub trait Flow<const D: usize>: Sync {
    /// The right-hand side F(t, y), given phase = (cos ωt, sin ωt).
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D];

    /// ω of the forcing; 0 for an autonomous flow.
    fn forcing_frequency(&self) -> f64 {
        0.0
    }

    /// The rigid walls of the system (at most
    /// [`MAX_WALLS`](super::wall::MAX_WALLS)); every flow of one batch has
    /// the same number.
    fn walls(&self) -> &[Wall] {
        &[]
    }

    /// The flow's general surfaces ([`surface`](super::surface)): events
    /// with resets and switches of the field, at most
    /// [`MAX_SURFACES`](super::region::MAX_SURFACES); their crossings are
    /// counted after the walls'. Every flow of one batch has the same.
    fn surfaces(&self) -> &[Surface] {
        &[]
    }

    /// g of every surface at y, and its rate ∇g·F along the field of
    /// `region`, at forcing phase `phase`.
    fn surface_values(&self, _region: u32, _phase: &Phase, _y: &[f64; D]) -> SurfaceValues {
        unreachable!("a flow with surfaces evaluates them")
    }

    /// [`surface_values`](Self::surface_values) at W states of
    /// trajectories of this flow, all in `region` and at forcing phase
    /// `phase`, into `out` (one evaluation for the batch where the flow
    /// can; each in turn by default). Written where the step loop keeps
    /// them rather than returned: the copies of a returned batch, a
    /// `memcpy` each, and the loads right after them cost a model's step
    /// loop a sixth of its time (measured).
    #[inline(always)]
    fn surface_values_shared<const W: usize>(
        &self,
        region: u32,
        phase: &Phase,
        y: &[[f64; W]; D],
        out: &mut SurfaceBatch<W>,
    ) {
        for k in 0..W {
            out.set_column(k, &self.surface_values(region, phase, &column(y, k)));
        }
    }

    /// [`surface_values`](Self::surface_values) of one trajectory of each
    /// of W flows (neighbouring lanes of a sweep), each in its region and
    /// at its forcing phase, into `out`.
    #[inline(always)]
    fn surface_values_each<const W: usize>(
        flows: &[&Self; W],
        regions: &[u32; W],
        phases: &[Phase; W],
        y: &[[f64; W]; D],
        out: &mut SurfaceBatch<W>,
    ) where
        Self: Sized,
    {
        for k in 0..W {
            let v = flows[k].surface_values(regions[k], &phases[k], &column(y, k));
            out.set_column(k, &v);
        }
    }

    /// ∇g of surface j at y, at forcing phase `phase` (a surface may move
    /// with the forcing).
    fn surface_gradient(&self, _j: usize, _phase: &Phase, _y: &[f64; D]) -> [f64; D] {
        unreachable!("a flow with surfaces evaluates them")
    }

    /// The stick limit of switch j at y (see [`surface`](super::surface)'s
    /// sliding): the largest mean rate |m| the motion stays on the surface
    /// under; `None` for Filippov's own (the half jump of the rates).
    fn stick_limit(&self, _j: usize, _y: &[f64; D]) -> Option<f64> {
        None
    }

    /// Event j's reset of y (on its surface) at forcing phase `phase`: the
    /// state after, the reset's Jacobian DR, and its rate ∂R/∂t (0 for a
    /// reset that does not read the time).
    fn reset(&self, _j: usize, _phase: &Phase, _y: &[f64; D]) -> Reset<D> {
        unreachable!("a flow with events resets")
    }

    /// Event j's values for holding the motion on its surface, where the
    /// flow can hold it there (`None`: an accumulation of its crossings is
    /// flagged, not integrated).
    fn event_hold(&self, _j: usize, _phase: &Phase, _y: &[f64; D]) -> Option<EventHoldValues<D>> {
        None
    }

    /// Up to `steps` RK4 steps of W trajectories of this flow (a lane's
    /// reference and copies), all at forcing phase `phase` turned by `half`
    /// per half step and with step size h, in a step loop of the flow's
    /// own (native code) that stops before the first step in which a live
    /// slot (bit k of `live`) meets a wall, as the detection of
    /// [`part_map_many`](super::part_map_many)'s loop finds it. Returns the
    /// steps taken, with `y` and `phase` advanced by them to the bits that
    /// loop gives; `None` where the flow has no such loop (the step loop
    /// then takes every step). A flow with general surfaces is given them
    /// (`switching`): the loop then also stops before a step in which a
    /// live slot may cross one.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn walk_shared<const W: usize>(
        &self,
        _y: &mut [[f64; W]; D],
        _phase: &mut Phase,
        _half: &Phase,
        _h: f64,
        _live: u32,
        _steps: usize,
        _switching: Option<Switching<'_, W>>,
    ) -> Option<usize> {
        None
    }

    /// [`walk_shared`](Self::walk_shared) for one trajectory of each of W
    /// flows (neighbouring lanes of a sweep), each with its own step size
    /// and constants; `None` unless they share the forcing phase and turn.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn walk_each<const W: usize>(
        _flows: &[&Self; W],
        _y: &mut [[f64; W]; D],
        _phases: &mut [Phase; W],
        _half: &[Phase; W],
        _h: &[f64; W],
        _live: u32,
        _steps: usize,
        _switching: Option<Switching<'_, W>>,
    ) -> Option<usize>
    where
        Self: Sized,
    {
        None
    }

    /// The field in region `region` of the switches (bit b set: on the
    /// positive side of switch b); a flow without switches has one.
    #[inline(always)]
    fn rhs_in(&self, _region: u32, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        self.rhs(phase, y)
    }

    /// One RK4 step ([`rk4::step_at`]) of one trajectory: the impact
    /// code's re-steps of partial size. A flow whose evaluation has a cost
    /// per call takes it in one call (`step_one_in`) rather than four.
    #[inline(always)]
    fn step_one(&self, stages: &[Phase; 3], y: &[f64; D], h: f64) -> [f64; D] {
        rk4::step_at(self, stages, y, h)
    }

    /// [`step_one`](Self::step_one) in region `region` of the switches.
    #[inline(always)]
    fn step_one_in(&self, region: u32, stages: &[Phase; 3], y: &[f64; D], h: f64) -> [f64; D]
    where
        Self: Sized,
    {
        rk4::step_at(&InRegion { flow: self, region }, stages, y, h)
    }

    /// One RK4 step of one trajectory sliding on the switches of `set`
    /// (`rk4::step_at` of [`Sliding`](super::surface::Sliding)), where the flow has it
    /// compiled: the same bits, or `None`.
    fn slide_step(
        &self,
        _set: &SlidingSet,
        _stages: &[Phase; 3],
        _y: &[f64; D],
        _h: f64,
    ) -> Option<[f64; D]> {
        None
    }

    /// [`step_shared`](Self::step_shared) in region `region`.
    #[inline(always)]
    fn step_shared_in<const W: usize>(
        &self,
        _region: u32,
        stages: &[Phase; 3],
        y: &[[f64; W]; D],
        h: f64,
    ) -> [[f64; W]; D] {
        self.step_shared(stages, y, h)
    }

    /// [`step_each`](Self::step_each), each trajectory in its region.
    #[inline(always)]
    fn step_each_in<const W: usize>(
        flows: &[&Self; W],
        _regions: &[u32; W],
        stages: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D]
    where
        Self: Sized,
    {
        Self::step_each(flows, stages, y, h)
    }

    /// One RK4 step ([`rk4::step_at`]) of W trajectories of this flow (a
    /// lane's reference and copies), structure of arrays, all at the same
    /// stage phases. By default each trajectory's whole step in turn, its
    /// stages in registers (measured 25% faster on the seed's oscillator
    /// than stage by stage); a flow whose evaluation has a cost per call (a
    /// compiled model's tape) goes stage by stage to pay it once per stage
    /// for all W ([`rk4::step_batch`]).
    #[inline(always)]
    fn step_shared<const W: usize>(
        &self,
        stages: &[Phase; 3],
        y: &[[f64; W]; D],
        h: f64,
    ) -> [[f64; W]; D] {
        let mut out = [[0.0; W]; D];
        for k in 0..W {
            let o = rk4::step_at(self, stages, &crate::array::from_fn(|i| y[i][k]), h);
            for i in 0..D {
                out[i][k] = o[i];
            }
        }
        out
    }

    /// One RK4 step of one trajectory of each of W flows (neighbouring
    /// lanes of a sweep), each with its own stage phases and step size.
    #[inline(always)]
    fn step_each<const W: usize>(
        flows: &[&Self; W],
        stages: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D]
    where
        Self: Sized,
    {
        let mut out = [[0.0; W]; D];
        for k in 0..W {
            let o = rk4::step_at(
                flows[k],
                &stages[k],
                &crate::array::from_fn(|i| y[i][k]),
                h[k],
            );
            for i in 0..D {
                out[i][k] = o[i];
            }
        }
        out
    }
}

/// A batch's general surfaces as a step loop of the flow's own takes them
/// (`Flow::walk_shared`): each slot's region of the switches, none
/// sliding or held, and the surfaces' values and rates at the slots'
/// states, which the loop writes back where it stops.
pub struct Switching<'a, const W: usize> {
    pub regions: [u32; W],
    pub values: &'a mut SurfaceBatch<W>,
}

/// Every flow is what an RK4 step reads (`rk4` knows no more of it).
impl<const D: usize, F: Flow<D> + ?Sized> rk4::Field<D> for F {
    #[inline(always)]
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        Flow::rhs(self, phase, y)
    }

    #[inline(always)]
    fn step_one(&self, stages: &[Phase; 3], y: &[f64; D], h: f64) -> [f64; D] {
        Flow::step_one(self, stages, y, h)
    }
}

/// A flow in one region of its switches: the one smooth field a step of
/// that region integrates.
pub struct InRegion<'a, F> {
    pub flow: &'a F,
    pub region: u32,
}

impl<const D: usize, F: Flow<D>> Flow<D> for InRegion<'_, F> {
    #[inline(always)]
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        self.flow.rhs_in(self.region, phase, y)
    }

    #[inline(always)]
    fn step_one(&self, stages: &[Phase; 3], y: &[f64; D], h: f64) -> [f64; D] {
        self.flow.step_one_in(self.region, stages, y, h)
    }

    fn forcing_frequency(&self) -> f64 {
        self.flow.forcing_frequency()
    }

    fn walls(&self) -> &[Wall] {
        self.flow.walls()
    }
}

/// Trajectory k of a structure-of-arrays batch.
#[inline(always)]
pub(super) fn column<const D: usize, const W: usize>(y: &[[f64; W]; D], k: usize) -> [f64; D] {
    crate::array::from_fn(|i| y[i][k])
}
