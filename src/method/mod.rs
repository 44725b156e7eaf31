//! The seed paper's method: Lyapunov exponents of a map x_{n+1} = U(x_n)
//! from Jacobians estimated by small orthogonal perturbations (eq. 6),
//! accumulated by QR (the classical Benettin / Parker–Chua scheme).

pub mod dispatch;
pub mod jacobian;
pub mod lane;
pub mod qr;

pub use dispatch::{runner, Runner};
pub use lane::{
    run_lane, Lane, LaneAccumulator, LaneResult, LaneStatus, MethodSettings, Stop, Tangent,
};
