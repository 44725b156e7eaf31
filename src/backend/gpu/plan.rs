//! What the kernels run a scene with: the variant they compile (only the
//! parts the scene uses) and the one lane plan every lane of the sweep
//! follows.

use super::shader::Variant;
use crate::error::{Error, Result};
use crate::method::lane::LanePlan;
use crate::method::MethodSettings;
use crate::scene::{Precision, Scene};

/// The kernel variant a scene needs: only the parts it uses.
pub fn variant(scene: &Scene, precision: Precision) -> Variant {
    // Over the whole sweep, so that every shard compiles the same kernels.
    let wall = scene.system.wall_reachable.is_some_and(|reachable| {
        (0..scene.sweep.lanes()).any(|k| {
            let state = scene
                .sweep
                .initial_state_at(k, &scene.integration.initial_state);
            reachable(&scene.params_at(k), state)
        })
    });
    Variant {
        system: scene.system,
        precision,
        lyapunov: scene.lyapunov,
        difference: scene.difference(),
        wall,
        impact_location: scene.integration.impact_location,
    }
}

/// The GPU integrates every lane of a sweep with the same plan: the most
/// steps and the most parts (sub-maps) any lane of the whole sweep (not
/// only of the shard) needs (see
/// `method::lane::plan_lane`), the steps raised to a whole number per part.
/// A lane cut into more parts than it needs gives the same exponents from
/// more, shorter differences.
pub fn lane_plan(scene: &Scene, settings: &MethodSettings) -> Result<LanePlan> {
    let mut plan = LanePlan {
        steps_per_period: settings.flow.steps_per_period,
        parts: 1,
    };
    // Whether the kernels would compile impact code (precision is irrelevant).
    let wall = variant(scene, Precision::F64).wall;
    // Over the whole sweep, so that a shard runs every lane as the whole
    // sweep would. The starts of one point share its parameters, so its
    // refusal and plan: one lane of each run of lanes at one point is
    // planned (a million starts per value once took minutes here).
    let mut last_point = None;
    for k in 0..scene.sweep.lanes() {
        let point = scene.sweep.point_of(k);
        if last_point.replace(point) == Some(point) {
            continue;
        }
        let params = scene.params_at_point(point);
        if let Some(reason) = (scene.system.gpu_refuses)(&params).filter(|_| wall) {
            return Err(Error::invalid(
                "run.backend",
                format!(
                    "{}: {reason}: use backend = \"cpu\" (\"auto\" does)",
                    scene.describe(k)
                ),
            ));
        }
        let lane = (crate::method::runner(scene.system).plan)(&params, settings);
        if !lane.affordable() {
            // Not run: its row says too-many-steps (see `crate::driver::Runner`).
            continue;
        }
        plan.steps_per_period = plan.steps_per_period.max(lane.steps_per_period);
        plan.parts = plan.parts.max(lane.parts);
    }
    plan.steps_per_period = plan.steps_per_period.next_multiple_of(plan.parts);
    // The kernels count steps in u32.
    if plan.steps_per_period > u32::MAX as usize {
        return Err(Error::invalid(
            "integration.steps_per_period",
            format!(
                "the sweep needs {} RK4 steps per period, more than the GPU kernels count (2^32 - 1)",
                plan.steps_per_period
            ),
        ));
    }
    Ok(plan)
}

/// `settings` for every lane of a GPU sweep, and for the CPU lanes that
/// validate or re-estimate it: the sweep's [`lane_plan`].
pub fn follow_lane_plan(scene: &Scene, settings: &mut MethodSettings) -> Result<()> {
    let plan = lane_plan(scene, settings)?;
    settings.flow.steps_per_period = plan.steps_per_period;
    settings.submaps = Some(plan.parts);
    Ok(())
}
