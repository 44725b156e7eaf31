//! The one intermediate representation every generated target is printed
//! from: the lowered instruction tape of a model's expressions and its
//! interpreter, the reference ([`tape`]); the step programs' language
//! ([`step`]) and the integrator's programs written in it ([`integrator`],
//! the kernels' stops and crossing location, [`events`], and their general
//! surfaces and sliding, [`surfaces`], and the step loop that resolves a
//! step's events, [`impacts`]).

pub mod events;
pub mod impacts;
pub mod integrator;
pub mod step;
pub mod surfaces;
pub mod tape;
