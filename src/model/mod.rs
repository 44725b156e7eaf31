//! A system as data (the models issue): what a scene's `[model]` table
//! says, parsed once and read by every backend.
//!
//! So far: the expression tree ([`expr`]), with its parser, evaluation,
//! symbolic derivatives (for the sum rule) and text form. The model table,
//! the compiled CPU evaluator and the generated WGSL build on it.

pub mod expr;
