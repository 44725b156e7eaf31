// Kernel: the end of a part of a map iteration (the whole iteration when it
// has one part), one invocation per lane.
//
// Averaging: write the estimated Jacobian of the part (column i =
// (U(x + δe_i) - U(x)) / δ_i, the paper's eq. 6, or the central
// (U(x + δe_i) - U(x - δe_i)) / 2δ), the reference's state and a summary into
// the part's ring slot. Always: re-seed the perturbed copies from the
// reference's new state, and at the end of an iteration restart the
// reference at phase 0, so the next part needs nothing from the host.
// That arithmetic, `finish_lane` and the functions it calls, is generated
// from its step program (src/model/ir/finish.rs); what is written here is
// the dispatch and the part's record in the buffers the host reads.

#include "shared/bindings.wgsl"
#include "shared/dispatch.wgsl"

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let lane = invocation_index(gid, groups);
    if (lane >= control.lane_count) {
        return;
    }
    finish_lane(lane);
}

// The part's record of the reference r in ring slot `slot`: its point,
// summary (impacts, flags, size, nonlinearity), impacts per stop and
// Σ ln |det S| (what the CPU's IterationStats and points hold; read back
// by src/backend/gpu/sweep.rs).
fn write_summary(r: u32, slot: u32, y: State, impacts: u32, flags: u32, nonlinearity: f32) {
    for (var k = 0u; k < DIM; k = k + 1u) {
        points[slot * DIM + k] = y[k];
    }
    var scale = real(0.0);
    for (var k = 0u; k < DIM; k = k + 1u) {
        scale = max(scale, abs(y[k]));
    }
    summary[SUMMARY_STRIDE * slot] = vec4<u32>(impacts, flags, bitcast<u32>(f32(scale)), bitcast<u32>(nonlinearity));
#ifdef WALL
    summary[SUMMARY_STRIDE * slot + 1u] = crossings[r];
#endif
#ifdef SURFACES
    fluxes[slot] = traj[r * TRAJ_STRIDE + TRAJ_FLUX];
#endif
}
