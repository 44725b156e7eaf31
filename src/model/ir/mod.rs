//! The one intermediate representation every generated target is printed
//! from: the lowered instruction tape of a model's expressions and its
//! interpreter, the reference ([`tape`]); the step programs' language
//! ([`step`]) and the integrator's programs written in it ([`integrator`],
//! the kernels' stops and crossing location, [`events`], and their general
//! surfaces and sliding, [`surfaces`], the step loop that resolves a
//! step's events, [`impacts`], and that step recorded in a trajectory,
//! [`trajectory`]), and the finish kernel's end of a part, its Jacobian
//! columns and re-seeded copies ([`finish`]), and the section kernel's
//! steps to a Poincaré section ([`section`]).

pub mod events;
pub mod finish;
pub mod impacts;
pub mod integrator;
pub mod section;
pub mod step;
pub mod surfaces;
pub mod tape;
pub mod trajectory;
