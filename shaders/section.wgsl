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

fn crossed(at: real, before: State, after: State) -> bool {
    let d0 = SECTION_DIRECTION * (before[SECTION_STATE] - at);
    let d1 = SECTION_DIRECTION * (after[SECTION_STATE] - at);
    return d0 < real(0.0) && d1 >= real(0.0);
}

#include "shared/loop_budget.wgsl"
#include "shared/dispatch.wgsl"

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let j = invocation_index(gid, groups);
    if (j >= control.job_count) {
        return;
    }
    var job = jobs[j];
    let mode = job.y & 0xffu;
    if (mode != ADVANCE && mode != SEEK) {
        return;
    }
    let p = load_params(job.x);
    let at = lanes[job.x * LANE_STRIDE + LANE_AT];
    let h = steps[j];
    let base = j * 2u * DIM;
    var y = load(base);
    // An autonomous flow: the clock stands still at phase 0.
    let still = vec2<real>(real(1.0), real(0.0));
    let end = min(job.w + control.chunk_steps, job.z);
    var k = job.w;
    var after = y;
#ifdef COMPENSATED
    // Kahan summation over the job's steps: an increment is far smaller
    // than y, and f32 would drop its low bits every step. Between
    // dispatches the compensation waits in the job's second state.
    var comp = load(base + DIM);
#endif
    for (; k < end; k = k + 1u) {
#ifdef COMPENSATED
        let corrected = rk4_increment(p, still, still, y, h).y - comp;
        after = select(y + corrected, y, control.opaque_zero != 0u);
        let next_comp = (after - y) - corrected;
#else
        after = y + rk4_increment(p, still, still, y, h).y;
#endif
        if (mode == SEEK && crossed(at, y, after)) {
            break;
        }
        y = after;
#ifdef COMPENSATED
        comp = next_comp;
#endif
        // NaN crosses nothing: a failed trajectory stops here (the CPU
        // steps it to the end of its budget for the same None).
        if (!all(abs(y) <= State(MAX_REAL))) {
            k = job.z;
            break;
        }
    }
    if (loop_budget_exhausted()) {
        jobs[j].y = job.y | TRUNCATED;
        return;
    }
    if (k < end) {
        // Only a crossing leaves the loop before its end.
        job.y = CROSSED;
        store(base + DIM, after);
    } else {
        if (k >= job.z) {
            job.y = select(DONE, MISSED, mode == SEEK);
        }
#ifdef COMPENSATED
        store(base + DIM, comp);
#endif
    }
    job.w = min(k, job.z);
    store(base, y);
    jobs[j] = job;
}
