//! Where the lanes run: the CPU reference path (the paper's method on RK4,
//! or the exact closed-form tangent map where the system has one, as the
//! method's dispatch picks it), and the GPU ensemble. A run of a scene on
//! them, its batches, checks and reports, is the driver's
//! (`crate::driver`).

pub mod cpu;
pub mod gpu;
pub mod options;
pub mod progress;

pub use options::RunOptions;
pub use progress::Progress;
