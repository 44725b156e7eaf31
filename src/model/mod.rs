//! A system as data (the models issue): what a scene's `[model]` table
//! says, parsed once and read by every backend.
//!
//! So far: the expression tree ([`expr`]), with its parser, evaluation,
//! symbolic derivatives (for the sum rule) and text form, and the `[model]`
//! table checked and parsed into a [`Model`] ([`table`]). Scenes do not read
//! models yet; the compiled CPU evaluator and the generated WGSL build on
//! these.

pub mod expr;
pub mod table;
pub mod tape;

pub use table::{Event, Map, Model};
