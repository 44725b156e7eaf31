//! The period map U^p of an orbit of period p (in map iterations), its
//! image and its Jacobian DU^p, estimated exactly as a lane estimates its
//! iterations' Jacobians: the lane's plan (RK4 steps, sub-maps), perturbed
//! copies differenced by `method::jacobian` with the grazing δ ladder, or
//! a section's own tangent factors. A periodic orbit's multipliers then
//! come from the same numbers as the exponents of the lane that sits on it.

use nalgebra::{Const, DimMin, SMatrix};

use crate::method::lane::{estimated_iteration, plan_lane};
use crate::method::MethodSettings;
use crate::system::{FlowSettings, IterationStats, System};

/// U^p(x), with DU^p(x) where asked for, and what happened on the way.
#[derive(Clone, Copy, Debug)]
pub struct Evaluation<const D: usize> {
    pub image: [f64; D],
    /// DU^p(x); the identity where no Jacobian was asked for.
    pub jacobian: SMatrix<f64, D, D>,
    /// The p iterations' statistics merged (crossings, impacts, flux).
    pub stats: IterationStats,
    /// The time the p iterations took: p·T for a period map, the return
    /// times' sum for a section.
    pub time: f64,
}

/// The flow settings a lane of `system` integrates with: the scene's,
/// with the steps its plan asks for.
pub fn flow_of<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
) -> FlowSettings {
    FlowSettings {
        steps_per_period: plan_lane(system, settings).steps_per_period,
        ..settings.flow.clone()
    }
}

/// U^p(x) and, when `jacobian`, DU^p(x): p iterations of the reference,
/// each wrapped as a lane wraps it, the Jacobian the product of the
/// iterations' (and their sub-maps') estimates.
pub fn evaluate<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    x: &[f64; D],
    p: usize,
    jacobian: bool,
) -> Evaluation<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let plan = plan_lane(system, settings);
    let flow = FlowSettings {
        steps_per_period: plan.steps_per_period,
        ..settings.flow.clone()
    };
    let mut out = Evaluation {
        image: *x,
        jacobian: SMatrix::identity(),
        stats: IterationStats::default(),
        time: 0.0,
    };
    for _ in 0..p {
        let mut stats = IterationStats::default();
        let mut next = if jacobian {
            let (next, j) = iteration_with_jacobian(
                system, settings, &flow, plan.parts, &out.image, &mut stats,
            );
            out.jacobian = j * out.jacobian;
            next
        } else {
            system.iterate(&out.image, &flow, &mut stats)
        };
        // After the Jacobian, as the lane does: its columns are
        // differences of unwrapped images.
        system.wrap(&mut next);
        out.time += if stats.time > 0.0 {
            stats.time
        } else {
            system.period()
        };
        out.stats.merge(&stats);
        out.image = next;
        if !next.iter().all(|v| v.is_finite()) {
            break;
        }
    }
    out
}

/// One iteration's image and Jacobian, as `method::lane`'s driver takes
/// them: a section's tangent factors where the system gives them, else
/// the product of its parts' estimates, each with the grazing ladder.
fn iteration_with_jacobian<const D: usize, S: System<D>>(
    system: &S,
    settings: &MethodSettings,
    flow: &FlowSettings,
    parts: usize,
    x: &[f64; D],
    stats: &mut IterationStats,
) -> ([f64; D], SMatrix<f64, D, D>)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let mut factors = Vec::new();
    let next = estimated_iteration(system, flow, settings, parts, x, stats, &mut factors);
    let j = factors.iter().fold(SMatrix::identity(), |j, f| f * j);
    (next, j)
}
