//! The CPU's native code: what it looks like to its callers (signatures,
//! layouts, the libm callback: [`abi`]), the host's C compiler and its
//! cache of built objects ([`compiler`]), and the built library loaded and
//! called ([`library`]).

pub mod abi;
pub mod compiler;
pub mod library;
