//! A sweep batch's starting values, as the kernels read them: each lane's
//! constants, and each trajectory's first state, the copies perturbed in
//! the precision the kernels run.

use super::bindings::FLAG_BEHIND_WALL;
use crate::integrate::clock::half_turn;
use crate::method::MethodSettings;
use crate::scene::{Precision, Scene};

/// Per lane of `scene` (a batch): parameters, h, cos(ωh/2), sin(ωh/2), ω,
/// δ (`lane_stride` numbers), and the lanes' map periods.
pub fn lane_constants(
    scene: &Scene,
    settings: &MethodSettings,
    lane_stride: usize,
    steps: usize,
) -> (Vec<f64>, Vec<f64>) {
    let info = scene.system;
    let count = scene.lane_count();
    let mut lane_data = Vec::with_capacity(count * lane_stride);
    let mut periods = Vec::with_capacity(count);
    for k in 0..count {
        let params = scene.lane_params(k);
        let period = (info.period)(&params);
        let omega = (info.forcing_frequency)(&params);
        let h = period / steps as f64;
        let half = half_turn(omega, h, steps);
        lane_data.extend_from_slice(&params.values);
        lane_data.extend_from_slice(&[h, half[0], half[1], omega, settings.perturbation]);
        periods.push(period);
    }
    (lane_data, periods)
}

/// The trajectories' starting values, uploaded once.
pub struct Seeds {
    /// Per trajectory, its `traj_stride` numbers.
    pub traj: Vec<f64>,
    /// The copies' perturbations as the variant's precision takes them.
    pub deltas: Vec<f64>,
    /// Per trajectory: step 0, no impacts, its flags.
    pub counts: Vec<[u32; 4]>,
}

impl Seeds {
    /// The reference at the initial state, copies at x0 + δe_i, with the
    /// perturbation actually taken in the variant's precision.
    /// `traj` trajectories per lane of `traj_stride` numbers, with a
    /// region and a flux where the model has `surfaces`; every lane of
    /// `scene` (a batch).
    pub fn new<const D: usize>(
        scene: &Scene,
        settings: &MethodSettings,
        (traj, traj_stride): (usize, usize),
        surfaces: bool,
        precision: Precision,
    ) -> Seeds {
        let info = scene.system;
        let count = scene.lane_count();
        let mut traj_data = Vec::with_capacity(count * traj * traj_stride);
        let mut deltas = Vec::with_capacity(count * D);
        // Per trajectory: step 0, no impacts, FLAG_BEHIND_WALL for a copy
        // that starts behind the wall (as the finish kernel seeds them).
        let mut counts_data: Vec<[u32; 4]> = Vec::with_capacity(count * traj);
        for k in 0..count {
            let params = scene.lane_params(k);
            // Each lane from its start, with the perturbation actually
            // taken in the variant's precision.
            let x0 = scene.lane_initial_state(k);
            let delta = crate::method::lane::perturbation_at(settings.perturbation, x0);
            for t in 0..traj {
                let mut y = x0.to_vec();
                if t > 0 {
                    // Copies 1..=D at x + δe_i, then (central) D+1..=2D at x - δe_i.
                    let i = (t - 1) % D;
                    let sign = if t > D { -1.0 } else { 1.0 };
                    let (shifted, step) = match precision {
                        Precision::F64 => {
                            let s = x0[i] + sign * delta;
                            (s, sign * (s - x0[i]))
                        }
                        Precision::F32 => {
                            let (x, d) = (x0[i] as f32, delta as f32);
                            let s = if sign > 0.0 { x + d } else { x - d };
                            (
                                f64::from(s),
                                f64::from(if sign > 0.0 { s - x } else { x - s }),
                            )
                        }
                    };
                    y[i] = shifted;
                    deltas.push(step);
                }
                let behind = t > 0 && (info.check_state)(&params, &y).is_err();
                counts_data.push([0, 0, if behind { FLAG_BEHIND_WALL } else { 0 }, 0]);
                traj_data.extend_from_slice(&y);
                traj_data.extend(std::iter::repeat_n(0.0, D));
                // Phase (1, 0); the slowest impact speed: none yet (NO_IMPACT).
                traj_data.extend_from_slice(&[1.0, 0.0, 1e30]);
                if surfaces {
                    // The region (found from the state at the first step)
                    // and the flux.
                    traj_data.extend_from_slice(&[0.0, 0.0]);
                }
            }
        }

        Seeds {
            traj: traj_data,
            deltas,
            counts: counts_data,
        }
    }
}
