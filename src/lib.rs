//! lyapsweep: the whole Lyapunov spectrum and the bifurcation diagram of
//! non-smooth oscillators, swept over thousands of parameter values.
//!
//! The method is that of the seed paper: the flow is reduced to its Poincaré
//! (stroboscopic) map U, whose Jacobian is estimated from small orthogonal
//! perturbations integrated alongside the reference trajectory, so impacts
//! need no special linearisation; the Jacobians feed the classical QR
//! accumulation of exponents.
//!
//! Modules follow the mathematics: [`system`] (the models), [`integrate`]
//! (RK4, impact location, the closed-form propagator), [`method`] (the
//! perturbation Jacobian and the QR accumulation), [`backend`] (where lanes
//! run), [`driver`] (a scene run: batches, checks, reports, continuation),
//! [`scene`] (the input contract) and [`output`] (the CSV files and the
//! figures); [`command`] is what the command line and the Python package
//! do with them.

pub mod array;
pub mod attractor;
pub mod backend;
pub mod bench;
pub mod command;
pub mod driver;
pub mod environment;
pub mod error;
pub mod integrate;
pub mod limits;
pub mod method;
pub mod model;
pub mod orbit;
pub mod output;
pub mod perturbation;
pub mod plan;
pub mod scene;
pub mod system;

pub use attractor::Attractors;
pub use backend::{Progress, RunOptions};
pub use driver::{run, run_streaming, run_with, Report, Summary};
pub use error::{Error, Result};
pub use scene::Scene;
