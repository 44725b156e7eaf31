// Kernel: the end of a map iteration, one invocation per lane.
//
// Averaging: write the estimated Jacobian (column i = (U(x + δe_i) - U(x)) /
// δ_i, the paper's eq. 6), the Poincaré point and a summary into this
// iteration's ring slot. Always: restart the reference at phase 0 and
// re-seed the perturbed copies from its new point, so the next iteration
// needs nothing from the host.

#include "shared/bindings.wgsl"

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let lane = gid.x;
    if (lane >= control.lane_count) {
        return;
    }
    let r = lane * TRAJ;
    var cr = counts[r];
    let y = load_state(r * TRAJ_STRIDE);
    var flags = cr.z;
    if (control.transient == 0u) {
        let slot = (cr.w % control.ring) * control.lane_count + lane;
#ifdef LYAPUNOV
        for (var i = 0u; i < DIM; i = i + 1u) {
            let ci = counts[r + 1u + i];
            flags = flags | (ci.z & FLAG_CHATTERING);
            let base_i = (r + 1u + i) * TRAJ_STRIDE;
            // y_i - y is exact (the two are close); the copies differ from
            // the reference by δ, so their low bits matter.
            var difference = load_state(base_i) - y;
#ifdef COMPENSATED
            // Each compensation holds the rounding its state still owes
            // (the exact sum is y - comp): without it, f32 would round every
            // column by up to ulp(y)/δ.
            difference = difference - (load_state(base_i + DIM) - load_state(r * TRAJ_STRIDE + DIM));
#endif
            let d = deltas[lane * DIM + i];
            for (var k = 0u; k < DIM; k = k + 1u) {
                jac[slot * DIM * DIM + k * DIM + i] = difference[k] / d;
            }
        }
#endif
#ifdef POINTS
        for (var k = 0u; k < DIM; k = k + 1u) {
            points[slot * DIM + k] = y[k];
        }
#endif
        var scale = real(0.0);
        for (var k = 0u; k < DIM; k = k + 1u) {
            scale = max(scale, abs(y[k]));
        }
        summary[slot] = vec4<u32>(cr.y, flags, bitcast<u32>(f32(scale)), 0u);
        cr.w = cr.w + 1u;
    }
    cr.x = 0u;
    cr.y = 0u;
    cr.z = flags & FLAG_NONFINITE;
    counts[r] = cr;
    restart(r * TRAJ_STRIDE, y);
#ifdef LYAPUNOV
    let delta = lanes[lane * LANE_STRIDE + LANE_DELTA];
    for (var i = 0u; i < DIM; i = i + 1u) {
        var yi = y;
        yi[i] = y[i] + delta;
        deltas[lane * DIM + i] = yi[i] - y[i];
        restart((r + 1u + i) * TRAJ_STRIDE, yi);
        counts[r + 1u + i] = vec4<u32>(0u, 0u, cr.z, 0u);
    }
#endif
}

// A trajectory starting a map iteration at y: phase 0, no compensation.
fn restart(base: u32, y: State) {
    store_state(base, y);
    store_state(base + DIM, State());
    traj[base + 2u * DIM] = real(1.0);
    traj[base + 2u * DIM + 1u] = real(0.0);
}
