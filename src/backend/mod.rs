//! Where the lanes run: the CPU reference path (the paper's method on RK4),
//! the exact closed-form tangent map, and (next) the GPU ensemble.

pub mod cpu;
pub mod gpu;

use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use crate::method::{LaneResult, MethodSettings, Tangent};
use crate::scene::{Backend, Precision, Scene};
use crate::system::FlowSettings;

/// The outcome of a sweep.
#[derive(Clone, Debug)]
pub struct Report {
    /// The backend that ran (never `Auto`).
    pub backend: Backend,
    /// Why `auto` chose it, if it did.
    pub choice: Option<String>,
    /// One result per sweep value, in sweep order.
    pub lanes: Vec<LaneResult>,
    /// The expected exponent sum of each lane (volume law).
    pub expected_sums: Vec<f64>,
    pub elapsed: Duration,
    pub threads: usize,
}

impl Report {
    /// The largest |λ_sum - expected_sum| over lanes that finished.
    pub fn max_sum_error(&self) -> Option<f64> {
        self.lanes
            .iter()
            .zip(&self.expected_sums)
            .filter(|(l, _)| !l.exponents.is_empty() && l.exponents.iter().all(|e| e.is_finite()))
            .map(|(l, expected)| (l.exponent_sum() - expected).abs())
            .filter(|e| !e.is_nan())
            .fold(None, |m, e| Some(m.map_or(e, |m: f64| m.max(e))))
    }

    /// Lanes whose status is not `ok`.
    pub fn flagged(&self) -> usize {
        self.lanes
            .iter()
            .filter(|l| l.status != crate::method::LaneStatus::Ok)
            .count()
    }
}

/// Picks the backend a scene asks for; an error when it cannot run it.
pub fn resolve(scene: &Scene) -> Result<(Backend, Option<String>)> {
    let (backend, choice) = match scene.backend {
        Backend::Auto => (
            Backend::Cpu,
            Some(
                "auto: the GPU backend is not built yet, so the CPU reference path runs".to_owned(),
            ),
        ),
        other => (other, None),
    };
    match backend {
        Backend::Gpu => {
            return Err(Error::Backend {
                backend: "gpu".into(),
                reason: "the GPU backend is not built yet; use \"cpu\" or \"auto\"".into(),
            })
        }
        Backend::Exact if !scene.system.has_exact => {
            return Err(Error::Backend {
                backend: "exact".into(),
                reason: format!(
                    "{} has no closed-form tangent map; use \"cpu\"",
                    scene.system.kind
                ),
            })
        }
        _ => {}
    }
    if scene.precision == Precision::F32 {
        return Err(Error::invalid(
            "run.precision",
            format!(
                "\"f32\" runs on the gpu backend only; the {} backend computes in f64",
                backend.name()
            ),
        ));
    }
    Ok((backend, choice))
}

/// The per-lane settings a scene implies for a backend.
pub fn method_settings(scene: &Scene, backend: Backend) -> MethodSettings {
    let i = &scene.integration;
    MethodSettings {
        transient: i.transient,
        iterations: i.iterations,
        initial_state: i.initial_state.clone(),
        perturbation: i.perturbation,
        flow: FlowSettings {
            steps_per_period: i.steps_per_period,
            impact_location: i.impact_location,
        },
        tangent: if backend == Backend::Exact {
            Tangent::Exact
        } else {
            Tangent::FiniteDifference
        },
        lyapunov: scene.lyapunov,
        bifurcation_points: scene.bifurcation_points,
        rounding_unit: f64::EPSILON,
        steps_per_iteration: if scene.system.is_flow {
            i.steps_per_period
        } else {
            1
        },
    }
}

/// Runs a whole sweep on the backend the scene asks for.
pub fn run(scene: &Scene) -> Result<Report> {
    let (backend, choice) = resolve(scene)?;
    let settings = method_settings(scene, backend);
    let start = Instant::now();
    let lanes = cpu::sweep(scene, &settings);
    let elapsed = start.elapsed();
    let expected_sums = lanes
        .iter()
        .enumerate()
        .map(|(k, lane)| {
            let rate = lane.impacts_per_period / lane.period;
            (scene.system.expected_sum)(&scene.lane_params(k), rate)
        })
        .collect();
    Ok(Report {
        backend,
        choice,
        lanes,
        expected_sums,
        elapsed,
        threads: rayon::current_num_threads(),
    })
}
