//! Which instance of the generic [`trace`] traces a system's branches,
//! as `method::dispatch` picks the lane code: a built-in by its kind, a
//! model by its dimension and map. A flow with walls gets the grazing
//! test (its walls' excess); a map or a section has none. (It lives here,
//! not in `method::dispatch`, because the method stands below the orbits.)

use nalgebra::{Const, DimMin};

use super::extremum::wall_excess;
use super::newton::Orbit;
use super::section::section_clearance;
use super::trace::{trace, Start, TraceSettings, Traced, Tracer};
use crate::integrate::Flow;
use crate::method::MethodSettings;
use crate::system::henon::Henon;
use crate::system::model::ModelFlow;
use crate::system::section::SectionFlow;
use crate::system::{Params, System, SystemInfo};

/// Every wall's excess over the orbit (see [`wall_excess`]).
fn excesses<const D: usize, S: System<D> + Flow<D>>(
    system: &S,
    settings: &MethodSettings,
    orbit: &Orbit<D>,
) -> Vec<f64> {
    (0..system.walls().len())
        .map(|w| wall_excess(system, settings, orbit, w))
        .collect()
}

fn trace_flow<const D: usize, S: System<D> + Flow<D>>(
    base: &Params,
    settings: &MethodSettings,
    settings_of_trace: &TraceSettings,
    start: &Start,
) -> Traced
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    trace::<D, S>(
        base,
        settings,
        settings_of_trace,
        start,
        Some(excesses::<D, S>),
        Some(section_clearance::<D, S>),
    )
}

fn trace_map<const D: usize, S: System<D>>(
    base: &Params,
    settings: &MethodSettings,
    settings_of_trace: &TraceSettings,
    start: &Start,
) -> Traced
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    trace::<D, S>(base, settings, settings_of_trace, start, None, None)
}

/// The tracer of `system`'s branches.
///
/// # Panics
/// As `method::dispatch::runner`: on a built-in kind without its line
/// here, or a model of more states than the lane code is instantiated for.
pub fn tracer(system: &SystemInfo) -> Tracer {
    if let Some(code) = system.model {
        macro_rules! by_dimension {
            ($with:ident, $flow:ident: $($d:literal $(/ $n:literal)?)*) => {
                match code.dimension() {
                    $($d => $with::<$d, $flow<$d $(, $n)?>>,)*
                    n => unreachable!("{n} map dimensions passed the model's check"),
                }
            };
        }
        return if code.section.is_some() {
            by_dimension!(trace_map, SectionFlow: 1/2 2/3 3/4 4/5 5/6)
        } else {
            by_dimension!(trace_flow, ModelFlow: 1 2 3 4 5 6)
        };
    }
    match system.kind {
        "henon" => trace_map::<2, Henon>,
        kind => unreachable!("the built-in system '{kind}' has no tracer"),
    }
}
