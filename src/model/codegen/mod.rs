//! Source text printed from the IR: one printer parametrised by the
//! target's syntax ([`print`]), the C of the CPU's native code ([`c`]) and
//! the WGSL of the GPU's system file ([`wgsl`]).

pub mod c;
pub mod print;
pub mod step;
pub mod wgsl;
