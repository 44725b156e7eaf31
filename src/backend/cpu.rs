//! The CPU reference path: every lane on its own thread of a rayon pool.
//! A lane's state lives on the stack (fixed-size arrays and matrices), so the
//! inner loop allocates nothing.

use rayon::prelude::*;

use crate::method::{Lane, LaneResult, MethodSettings};
use crate::scene::Scene;

/// Runs every sweep value of `scene`, in parallel, results in sweep order.
pub fn sweep(scene: &Scene, settings: &MethodSettings) -> Vec<LaneResult> {
    (0..scene.sweep.values.len())
        .into_par_iter()
        .map(|k| {
            let lane = Lane {
                params: scene.lane_params(k),
                settings,
            };
            (scene.system.run_lane)(&lane)
        })
        .collect()
}
