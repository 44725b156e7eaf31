//! Which instance of the method's generic lane code runs a system.
//!
//! The lane code is generic over the system's type and dimension
//! ([`run_lane`](super::run_lane)`::<D, S>`), while scenes, backends and
//! writers hold a system as its type-erased [`SystemInfo`]. This module
//! is the one place that maps the one to the other: a built-in by its
//! kind, a model by its dimension and map. (The systems used to carry
//! these function pointers themselves, which made `system` depend on
//! `method` and `method` on `system`.)

use nalgebra::{Const, DimMin};

use super::lane::{self, LanePlan};
use super::{Lane, LaneResult, MethodSettings};
use crate::integrate::{IterationStats, Part};
use crate::system::henon::Henon;
use crate::system::model::ModelFlow;
use crate::system::section::SectionFlow;
use crate::system::{Params, System, SystemInfo};

/// The method's code for one system, monomorphised.
#[derive(Clone, Copy)]
pub struct Runner {
    /// Runs one lane ([`lane::run_lane`]).
    pub run_lane: fn(&Lane) -> LaneResult,
    /// Neighbouring lanes, their transients stepped together
    /// ([`lane::run_lanes`]).
    pub run_lanes: fn(&[Lane]) -> Vec<LaneResult>,
    /// How a lane would be cut ([`lane::plan_lane`]), without running it.
    pub plan: fn(&Params, &MethodSettings) -> LanePlan,
    /// One part's Jacobian (the whole iteration's, or a sub-map's) from x,
    /// re-estimated on the CPU with the grazing ladder
    /// ([`lane::reestimate_of`]): what the GPU host does with the parts its
    /// kernels flag as grazing. Row-major.
    pub reestimate: Reestimate,
}

/// See [`Runner::reestimate`].
pub type Reestimate = fn(&Params, &MethodSettings, Part, &[f64]) -> (Vec<f64>, IterationStats);

impl Runner {
    fn of<const D: usize, S: System<D>>() -> Runner
    where
        Const<D>: DimMin<Const<D>, Output = Const<D>>,
    {
        Runner {
            run_lane: lane::run_lane::<D, S>,
            run_lanes: lane::run_lanes::<D, S>,
            plan: lane::plan_of::<D, S>,
            reestimate: lane::reestimate_of::<D, S>,
        }
    }
}

/// The method's code for `system`.
///
/// # Panics
/// On a built-in kind this module does not know (a system added to
/// [`crate::system::SYSTEMS`] without its line here), or a model of more
/// states than the lane code is instantiated for (the model's check
/// refuses those first).
pub fn runner(system: &SystemInfo) -> Runner {
    if let Some(code) = system.model {
        macro_rules! by_dimension {
            ($flow:ident: $($d:literal $(/ $n:literal)?)*) => {
                match code.dimension() {
                    $($d => Runner::of::<$d, $flow<$d $(, $n)?>>(),)*
                    n => unreachable!("{n} map dimensions passed the model's check"),
                }
            };
        }
        return if code.section.is_some() {
            by_dimension!(SectionFlow: 1/2 2/3 3/4 4/5 5/6)
        } else {
            by_dimension!(ModelFlow: 1 2 3 4 5 6)
        };
    }
    match system.kind {
        "henon" => Runner::of::<2, Henon>(),
        kind => unreachable!("the built-in system '{kind}' has no runner"),
    }
}
