//! A system given as data: a compiled model (`crate::model::compiled`) run as
//! a flow and described to the rest of the tool like a built-in system.
//! [`description`] (its [`info`]: names, checks, the sum rule, time
//! scales), [`flow`] (the lane's [`ModelFlow`]: fields per region, stops
//! as walls, surfaces, the native step loops), [`map`] (the flow as the
//! method's `System`). A model that is piecewise linear also gets the
//! exact backend (`crate::model::compiled::piecewise_linear`).

pub mod description;
pub mod flow;
pub mod map;

pub use description::{described, info, info_as, info_of, wrap_angle};
pub use flow::ModelFlow;
