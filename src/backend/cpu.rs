//! The CPU reference path: every lane on its own thread of a rayon pool.
//! A lane's state lives on the stack (fixed-size arrays and matrices), so the
//! inner loop allocates nothing.

use rayon::prelude::*;

use super::Progress;
use crate::method::{Lane, LaneResult, MethodSettings};
use crate::scene::Scene;

/// Lanes whose transients are stepped together (`method::lane::run_lanes`):
/// one batch of references.
const NEIGHBOURS: usize = crate::integrate::LANE_BATCH;

/// Runs every lane of `scene` (of its shard, when sharded), in parallel,
/// results in sweep order.
pub fn sweep(scene: &Scene, settings: &MethodSettings, progress: &Progress) -> Vec<LaneResult> {
    let lanes: Vec<usize> = (0..scene.lane_count()).collect();
    lanes
        .par_chunks(NEIGHBOURS)
        .flat_map_iter(|chunk| {
            let lanes: Vec<Lane> = chunk
                .iter()
                .map(|&k| Lane {
                    params: scene.lane_params(k),
                    settings,
                    initial_state: scene.lane_initial_state(k).to_vec(),
                })
                .collect();
            let results = (crate::method::runner(scene.system).run_lanes)(&lanes);
            progress.advance((lanes.len() * (settings.transient + settings.iterations)) as u64);
            results
        })
        .collect()
}
