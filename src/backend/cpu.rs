//! The CPU reference path: every lane on its own thread of a rayon pool.
//! A lane's state lives on the stack (fixed-size arrays and matrices), so the
//! inner loop allocates nothing.

use rayon::prelude::*;

use super::Progress;
use crate::method::lane::KnownOrbits;
use crate::method::{Lane, LaneResult, LaneStatus, MethodSettings};
use crate::scene::Scene;

/// Lanes whose transients are stepped together (`method::lane::run_lanes`):
/// one batch of references.
const NEIGHBOURS: usize = crate::integrate::LANE_BATCH;

/// Runs every lane of `scene` (of its shard, when sharded), in parallel,
/// results in sweep order; none when the run is stopped. With `known`,
/// the scene's own starts (not a continuation's seeds) may stop early on
/// the orbits known at their values (`settings.early_stop`).
pub fn sweep(
    scene: &Scene,
    settings: &MethodSettings,
    known: Option<&KnownOrbits>,
    progress: &Progress,
) -> Vec<LaneResult> {
    let known = known.filter(|_| scene.sweep.seeds.is_none());
    // Each chunk's results go straight into their slots: collecting a
    // parallel iterator of unknown length would hold them twice at its end.
    let mut slots: Vec<Option<LaneResult>> = (0..scene.lane_count()).map(|_| None).collect();
    slots
        .par_chunks_mut(NEIGHBOURS)
        .enumerate()
        .for_each(|(c, slots)| {
            // A stopped run sets up no more lanes (a million of them take
            // seconds even when each ends at its first iteration).
            if settings.flow.stop.requested() {
                return;
            }
            let first = c * NEIGHBOURS;
            let (run, unrun): (Vec<usize>, Vec<usize>) =
                (first..first + slots.len()).partition(|&k| !scene.lane_start_inadmissible(k));
            let lanes: Vec<Lane> = run
                .iter()
                .map(|&k| Lane {
                    params: scene.lane_params(k),
                    settings,
                    initial_state: scene.lane_initial_state(k).to_vec(),
                    known: known.map_or(&[], |known| {
                        &known.per_point[scene.sweep.point_of(scene.sweep_lane(k))]
                    }),
                })
                .collect();
            let results = (crate::method::runner(scene.system).run_lanes)(&lanes);
            progress.advance((slots.len() * (settings.transient + settings.iterations)) as u64);
            for (k, result) in run.into_iter().zip(results) {
                slots[k - first] = Some(result);
            }
            for k in unrun {
                slots[k - first] = Some(inadmissible(scene, settings, k));
            }
        });
    if settings.flow.stop.requested() {
        // Not results: the runner returns `Error::Stopped`.
        return Vec::new();
    }
    slots
        .into_iter()
        .map(|r| r.expect("every chunk fills its slots"))
        .collect()
}

/// The result of lane `k`, whose start is outside the admissible states:
/// not run ([`Scene::lane_start_inadmissible`]).
pub fn inadmissible(scene: &Scene, settings: &MethodSettings, k: usize) -> LaneResult {
    let params = scene.lane_params(k);
    let plan = (crate::method::runner(scene.system).plan)(&params, settings);
    let period = (scene.system.period)(&params);
    let mut lane = crate::method::lane::not_run(settings, scene.system.dimension(), period, plan);
    lane.status = LaneStatus::Inadmissible;
    lane
}
