//! A system as data (the models issue): what a scene's `[model]` table
//! says, parsed once and read by every backend.
//!
//! So far: the expression tree ([`expr`]), with its parser, evaluation,
//! symbolic derivatives (for the sum rule) and text form, and the `[model]`
//! table checked and parsed into a [`Model`] ([`table`]); the CPU's
//! compiled evaluator ([`tape`]) and the GPU's generated system file
//! ([`wgsl`]) are both built from those trees.

pub mod expr;
pub mod table;
pub mod tape;
pub mod wgsl;

pub use table::{Event, Map, Model};
