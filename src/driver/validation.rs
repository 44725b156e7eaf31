//! The host's checks of a GPU run against the CPU path: the lanes the
//! kernels flag `sliding` recomputed, the failures of their transient
//! dated, the convergence times of a run with basin images taken from the
//! references recomputed, and a few sweep values recomputed to validate
//! the rest ([`Validation`], `gpu-mismatch` beyond
//! [`validation_tolerance`]).

use rayon::prelude::*;

use crate::attractor::group::{same_attractor, Rule};
use crate::backend::gpu::plan::follow_lane_plan;
use crate::method::{LaneResult, LaneStatus, MethodSettings};
use crate::plan::{cpu_twin, method_settings};
use crate::scene::{Backend, Precision, Scene};

/// The CPU recomputation of a few sweep values of a GPU run.
#[derive(Clone, Debug)]
pub struct Validation {
    /// Indices of the recomputed sweep values.
    pub lanes: Vec<usize>,
    /// The largest difference found (see [`validation_difference`]).
    pub max_difference: f64,
    /// Above this a row is marked `gpu-mismatch`.
    pub tolerance: f64,
}

/// The per-precision tolerance of the GPU's validation against the CPU.
pub fn validation_tolerance(precision: Precision) -> f64 {
    match precision {
        Precision::F64 => 1e-6,
        Precision::F32 => 1e-3,
    }
}

/// How far a GPU lane is from its CPU recomputation: the largest exponent
/// difference on a regular lane; on a chaotic one (λ1 > 0), where rounding
/// differences decorrelate the two trajectories within tens of iterations
/// and the exponents then differ by their statistical error, the difference
/// of the exponent sums less their orbit terms (which is local to each
/// iteration: a Poincaré map's flux term ln |F_k(x_0)/F_k(x_n)| / T depends
/// on where each trajectory ends, and differs by ~1e-5 at Lorenz's ρ = 28
/// over 500 returns).
pub fn validation_difference(gpu: &LaneResult, cpu: &LaneResult) -> f64 {
    if cpu.exponents.first().is_some_and(|&l1| l1 > 0.0) {
        ((gpu.exponent_sum() - gpu.orbit_term) - (cpu.exponent_sum() - cpu.orbit_term)).abs()
    } else {
        gpu.exponents
            .iter()
            .zip(&cpu.exponents)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }
}

/// Recomputes on the CPU path (f64, with the GPU's steps and parts) the
/// lanes the kernels flagged `sliding`: a motion on a switch they do not
/// integrate (another surface met while sliding, two switches slid on at
/// once), which they flag rather than step through; the CPU integrates
/// it. Returns their indices.
///
/// A lane the kernels end non-finite stays non-finite: a flagged part
/// gives the host no Jacobian, so a motion stopped at its flag no longer
/// fails the QR. The lanes once recomputed for that (a ball locking onto
/// a table, a belt's mass pressed into a stop) are flagged ones now
/// (docs/VALIDATION.md, `a_mass_carried_by_the_belt_into_a_stop_is_recomputed_on_the_cpu`).
pub(super) fn recompute_sliding(
    scene: &Scene,
    gpu: &MethodSettings,
    lanes: &mut [LaneResult],
) -> Vec<usize> {
    let flagged: Vec<usize> = (0..lanes.len())
        .filter(|&k| matches!(lanes[k].status, LaneStatus::Sliding { .. }))
        .collect();
    if flagged.is_empty() {
        return flagged;
    }
    let settings = cpu_twin(scene, gpu);
    for (&k, lane) in flagged.iter().zip(cpu_lanes(scene, &settings, &flagged)) {
        lanes[k] = lane;
    }
    flagged
}

/// Dates the failures the GPU found at the end of its transient, which
/// runs without readback: a lane that went non-finite (or lost its section)
/// in the transient is reported by the kernels at the first averaging
/// iteration. Its transient is run again on the CPU path, and where that
/// fails too, the row takes the CPU's iteration, as a CPU run would report
/// it (the lane gave no numbers either way).
pub(super) fn date_transient_failures(scene: &Scene, lanes: &mut [LaneResult]) {
    let mut settings = method_settings(scene, Backend::Cpu, Precision::F64);
    // The kernels' transient is the iterations before the aligning ones.
    let first_with_jacobians = settings.transient;
    let undated = |status: &LaneStatus| match status {
        LaneStatus::NonFinite { iteration }
        | LaneStatus::NoReturn { iteration }
        | LaneStatus::TooManyEvents { iteration } => *iteration == first_with_jacobians,
        _ => false,
    };
    let failed: Vec<usize> = (0..lanes.len())
        .filter(|&k| first_with_jacobians > 0 && undated(&lanes[k].status))
        .collect();
    if failed.is_empty() || follow_lane_plan(scene, &mut settings).is_err() {
        return;
    }
    // The transient alone: no averaging iteration is needed to date it.
    settings.iterations = settings.align + 1;
    for (&k, cpu) in failed.iter().zip(cpu_lanes(scene, &settings, &failed)) {
        if cpu.status.is_failure() {
            lanes[k].status = cpu.status;
        }
    }
}

/// Gives the lanes of a GPU run that keeps convergence times (basin
/// images) their times: the kernels' transient leaves its points on the
/// device, so each lane's reference is recomputed on the CPU path (f64,
/// with the GPU's steps and parts, without exponents: one trajectory an
/// iteration where a CPU run's averaging takes D + 1 or 2D + 1) and its
/// time taken where the recomputed lane ends
/// on the GPU lane's attractor (the attractor test at the GPU's precision);
/// elsewhere, and for failed lanes, it stays empty.
pub(super) fn settle_on_the_host(scene: &Scene, gpu: &MethodSettings, lanes: &mut [LaneResult]) {
    if !gpu.keep_settling {
        return;
    }
    let unsettled: Vec<usize> = (0..lanes.len())
        .filter(|&k| lanes[k].settled.is_none() && !lanes[k].status.is_failure())
        .collect();
    if unsettled.is_empty() {
        return;
    }
    let mut settings = cpu_twin(scene, gpu);
    settings.lyapunov = false;
    settings.bifurcation_points = 0;
    let rule = Rule::new(scene.system.dimension(), gpu.rounding_unit);
    for (&k, cpu) in unsettled
        .iter()
        .zip(cpu_lanes(scene, &settings, &unsettled))
    {
        if same_attractor(&lanes[k], &cpu, rule) {
            lanes[k].settled = cpu.settled;
        }
    }
}

/// Lanes `picked` of the sweep run on the CPU path with `settings`, in
/// parallel: what a GPU run hands back to the CPU.
fn cpu_lanes(scene: &Scene, settings: &MethodSettings, picked: &[usize]) -> Vec<LaneResult> {
    picked
        .par_iter()
        .map(|&k| {
            let lane = crate::method::Lane {
                params: scene.lane_params(k),
                settings,
                initial_state: scene.lane_initial_state(k).to_vec(),
                known: &[],
            };
            (crate::method::runner(scene.system).run_lane)(&lane)
        })
        .collect()
}

/// Recomputes `scene.validate` sweep values, spread over the run, on the
/// CPU path (f64) and marks GPU rows that differ beyond the tolerance: of
/// a batch, those that fall in it.
pub(super) fn validate(
    scene: &Scene,
    precision: Precision,
    gpu: &MethodSettings,
    lanes: &mut [LaneResult],
) -> Option<Validation> {
    if scene.validate == 0 || !scene.lyapunov || lanes.is_empty() {
        return None;
    }
    // Spread over the run, whichever of its batches `scene` is: the picks
    // that fall in this batch, as its own lanes.
    let n = scene.run_lane_count();
    let batch = scene.batch.clone().unwrap_or(0..n);
    let m = scene.validate.min(n);
    let mut picks: Vec<usize> = (0..m)
        .map(|k| {
            if m == 1 {
                0
            } else {
                (k * (n - 1) + (m - 1) / 2) / (m - 1)
            }
        })
        .filter(|k| batch.contains(k))
        .map(|k| k - batch.start)
        .collect();
    picks.dedup();
    // The same δ and difference scheme as the GPU run (both follow the
    // scene's precision), so the difference measures arithmetic only.
    // The GPU ran every lane with the sweep's steps and parts.
    let settings = cpu_twin(scene, gpu);
    let tolerance = validation_tolerance(precision);
    let mut max_difference: f64 = 0.0;
    for &k in &picks {
        if scene.lane_start_inadmissible(k) {
            continue;
        }
        let lane = crate::method::Lane {
            params: scene.lane_params(k),
            settings: &settings,
            initial_state: scene.lane_initial_state(k).to_vec(),
            known: &[],
        };
        let cpu = (crate::method::runner(scene.system).run_lane)(&lane);
        let finished = |l: &LaneResult| l.exponents.iter().all(|e| e.is_finite());
        if !finished(&cpu) || !finished(&lanes[k]) {
            continue;
        }
        let difference = validation_difference(&lanes[k], &cpu);
        max_difference = max_difference.max(difference);
        if difference > tolerance && lanes[k].status == LaneStatus::Ok {
            lanes[k].status = LaneStatus::Mismatch { difference };
        }
    }
    Some(Validation {
        lanes: picks,
        max_difference,
        tolerance,
    })
}
