//! The one intermediate representation every generated target is printed
//! from: the lowered instruction tape of a model's expressions and its
//! interpreter, the reference ([`tape`]).

pub mod step;
pub mod tape;
