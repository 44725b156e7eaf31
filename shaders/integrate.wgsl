// Kernel: advance trajectories through part of one map iteration.
//
// One invocation per trajectory (references only during the transient).
// Each dispatch takes at most `chunk_steps` RK4 steps, so no dispatch runs
// long enough to trip a driver watchdog and the host sees progress between
// dispatches. A failed (non-finite) trajectory stops; other lanes never read it.

#include "shared/bindings.wgsl"

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    var t: u32;
    var lane: u32;
    if (control.transient != 0u) {
        lane = gid.x;
        t = lane * TRAJ;
    } else {
        t = gid.x;
        lane = t / TRAJ;
    }
    if (lane >= control.lane_count) {
        return;
    }
    var c = counts[t];
    if ((c.z & FLAG_NONFINITE) != 0u) {
        return;
    }
    let p = load_params(lane);
    let base = t * TRAJ_STRIDE;
    var y = load_state(base);
#ifdef MAP
    if (c.x < 1u) {
        y = map_step(p, y);
        c.x = 1u;
    }
#else
    var comp = load_state(base + DIM);
    var phase = vec2<real>(traj[base + 2u * DIM], traj[base + 2u * DIM + 1u]);
    let lb = lane * LANE_STRIDE;
    let h = lanes[lb + LANE_H];
    let half = vec2<real>(lanes[lb + LANE_HALF], lanes[lb + LANE_HALF + 1u]);
    let omega = lanes[lb + LANE_OMEGA];
    let end = min(c.x + control.chunk_steps, control.steps_per_period);
#ifdef WALL
    var slowest = traj[base + TRAJ_SLOWEST];
#endif
    for (var k = c.x; k < end; k = k + 1u) {
#ifdef WALL
        if (at_rest_on(wall_position(p), y)) {
            // Stuck on the wall (see stuck_step): no plain RK4 step.
            let w = stuck_step(p, omega, phase, h);
            y = w.y;
            comp = State();
            c.z = c.z | rank_flags(w.rank_loss);
            phase = rotate(rotate(phase, half), half);
            continue;
        }
#endif
        let inc = rk4_increment(p, phase, half, y, h);
#ifdef COMPENSATED
        // Kahan summation: the increment of one step is far smaller than y,
        // and f32 would drop its low bits every step.
        let corrected = inc.y - comp;
        var y1 = select(y + corrected, y, control.opaque_zero != 0u);
        comp = (y1 - y) - corrected;
#else
        var y1 = y + inc.y;
#endif
#ifdef WALL
        if (y1.x > wall_position(p) || (y.y > real(0.0) && y1.y < real(0.0))) {
            let w = resolve_impacts(p, omega, phase, y, h, y1);
            // Whatever the wall did (an impact, a rest, a departure from
            // rest), the step ends where resolve_impacts says; the
            // compensation belongs to the plain step it replaced.
            if (any(w.y != y1)) {
                y1 = w.y;
                comp = State();
            }
            c.y = c.y + w.impacts;
            slowest = min(slowest, w.slowest);
            if (w.chattering) {
                c.z = c.z | FLAG_CHATTERING;
            }
            c.z = c.z | rank_flags(w.rank_loss);
        }
#endif
        y = y1;
        phase = inc.phase;
    }
    c.x = end;
    store_state(base + DIM, comp);
    traj[base + 2u * DIM] = phase.x;
    traj[base + 2u * DIM + 1u] = phase.y;
#ifdef WALL
    traj[base + TRAJ_SLOWEST] = slowest;
#endif
#endif
    if (!is_finite(y)) {
        c.z = c.z | FLAG_NONFINITE;
    }
    store_state(base, y);
    counts[t] = c;
}
