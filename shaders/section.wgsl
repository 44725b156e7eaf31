// Kernel: the RK4 steps of a Poincaré map's trajectories.
//
// The host (src/backend/gpu/section.rs) runs the map's algorithm, the
// CPU's own (src/system/section.rs): returns of the reference to the
// section, then the tangent map in parts, each a fixed number of steps of
// the reference and its copies. It hands the GPU the steps, as one job per
// trajectory, and locates each crossing, builds each factor and takes the
// QR itself. A job either
// - ADVANCEs its trajectory by `limit` steps of its h, or
// - SEEKs the section: steps of h until one crosses it (from behind it to
//   on or past it, the CPU's `Section::crossed`), leaving the step's start
//   in the state and its end after it, with `taken` the step's index; past
//   `limit` steps it gives up (MISSED: no return, a failed lane).
// Each dispatch takes at most `chunk_steps` steps of every job, so no
// dispatch trips a driver watchdog or lavapipe's loop cap.

// Its control struct, bindings, LANE_STRIDE and job modes are stated
// once in src/backend/gpu/bindings.rs (`SECTION`), which writes them into
// the generated prelude. Per lane: the system's parameters, then the
// section's `at`.
const LANE_AT: u32 = PARAM_COUNT;

fn load(base: u32) -> State {
    var y: State;
    for (var k = 0u; k < DIM; k = k + 1u) {
        y[k] = states[base + k];
    }
    return y;
}

fn store(base: u32, y: State) {
    for (var k = 0u; k < DIM; k = k + 1u) {
        states[base + k] = y[k];
    }
}

fn is_finite(y: State) -> bool {
    // NaN fails every comparison; infinity exceeds the largest real.
    return all(abs(y) <= State(MAX_REAL));
}

#include "shared/loop_budget.wgsl"
#include "shared/dispatch.wgsl"

// A job's steps, the crossing test and the f32 compensation are generated
// from the section's step program (src/model/ir/section.rs): `section_job`.
@compute @workgroup_size(WORKGROUP_SIZE)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let j = invocation_index(gid, groups);
    if (j >= control.job_count) {
        return;
    }
    section_job(j);
}
