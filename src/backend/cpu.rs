//! The CPU reference path: every lane on its own thread of a rayon pool.
//! A lane's state lives on the stack (fixed-size arrays and matrices), so the
//! inner loop allocates nothing.

use rayon::prelude::*;

use super::Progress;
use crate::method::{Lane, LaneResult, MethodSettings};
use crate::scene::Scene;

/// Runs every lane of `scene` (of its shard, when sharded), in parallel,
/// results in sweep order.
pub fn sweep(scene: &Scene, settings: &MethodSettings, progress: &Progress) -> Vec<LaneResult> {
    (0..scene.lane_count())
        .into_par_iter()
        .map(|k| {
            let lane = Lane {
                params: scene.lane_params(k),
                settings,
            };
            let result = (scene.system.run_lane)(&lane);
            progress.advance((settings.transient + settings.iterations) as u64);
            result
        })
        .collect()
}
