//! Periodic orbits of a system's map, stable or not: solved by Newton on
//! U^p(x) - x = 0 with the Jacobian DU^p from the method's perturbed
//! copies (`newton`, `map`), their Floquet multipliers and exponents with
//! the sum rule (`floquet`, from the Jacobian re-estimated over a δ ladder,
//! `ladder`), followed in one parameter by pseudo-arclength
//! continuation through folds (`continuation`), and the zeros of test
//! functions on a branch located to a tolerance in the parameter
//! (`locate`), grazing a wall among them (`extremum`), and the folds,
//! period doublings and Neimark–Sacker points on a branch from its
//! multipliers (`bifurcation`); the doubled branch followed from a period
//! doubling (`doubling`); where an orbit's events per period change (an
//! impact or a free flight grazing, sliding), and the branch restarted
//! past it (`events`); where an impact passes through the map's section
//! and the orbit's point jumps, the branch stepped across (`section`). A run's branches are traced from their starts with
//! their bifurcations (`trace`), by the instance `dispatch` picks for the
//! system.
//!
//! A sweep sees what attracts; these are the orbits between: the unstable
//! middle of a hysteresis loop, and where an orbit is born or lost.
//! Everything is generic over the system (`S: System<D>`); the grazing
//! test functions read the flow's walls (`S: Flow<D>`).

pub mod bifurcation;
pub mod continuation;
pub mod dispatch;
pub mod doubling;
pub mod events;
pub mod extremum;
pub mod floquet;
pub mod ladder;
pub mod locate;
pub mod map;
pub mod newton;
pub mod section;
pub mod trace;

pub use bifurcation::{bifurcations, locate_on_chord, Bifurcation, Kind};
pub use continuation::{
    continue_branch, continue_branch_until, params_at, Branch, BranchEnd, BranchPoint,
    ContinuationSettings, EndHook,
};
pub use doubling::{doubled_orbit, doubling_direction, doubling_separation, switch_at_doubling};
pub use events::{
    events, events_changes, extrapolate_grazing, extrapolate_to_zero, impact_speed_test,
    locate_events_change, step_past, EventKind, Events, EventsChange, Grazing,
};
pub use extremum::{free_approach, largest, wall_excess};
pub use floquet::{floquet, refined_floquet, Floquet};
pub use ladder::refined_jacobian;
pub use locate::{locate_zero, Located};
pub use map::{evaluate, Evaluation};
pub use newton::{least_period, relative_residual, solve, Failure, NewtonSettings, Orbit};
pub use section::{crossing_ahead, section_clearance, step_across, Clearance};
