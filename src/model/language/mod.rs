//! The model language: expressions ([`expr`]: parser, evaluation, symbolic
//! derivatives, text form), the `[model]` table checked into a [`Model`]
//! ([`table`]), and the arithmetic of the functions it calls, sin, cos and
//! tan with the GPU's bits ([`math64`]).

pub mod expr;
pub mod math64;
pub mod table;

pub use table::{Event, Map, Model};
