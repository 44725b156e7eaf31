// Kernel: advance trajectories through a stretch of one map iteration.
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
    // While averaging, a dispatch stops at the end of the current part,
    // where the finish kernel re-seeds the copies.
    var part_end = control.steps_per_period;
    if (control.transient == 0u) {
        part_end = (c.x / control.part_steps + 1u) * control.part_steps;
    }
    let end = min(c.x + control.chunk_steps, part_end);
#ifdef WALL
    var slowest = traj[base + TRAJ_SLOWEST];
#endif
    for (var k = c.x; k < end; k = k + 1u) {
        let next_phase = rotate(rotate(phase, half), half);
#ifdef WALL
        // At rest on the wall, from the step's start or from an impact
        // inside it: stuck_step takes (the rest of) the step, called here
        // only (see resolve_impacts).
        var sticks = at_rest_on(wall_position(p), y);
        var rest_at = real(0.0);
        var rest_phase = phase;
        if (!sticks) {
#endif
            let inc = rk4_increment(p, phase, half, y, h);
#ifdef COMPENSATED
            // Kahan summation: the increment of one step is far smaller
            // than y, and f32 would drop its low bits every step.
            let corrected = inc.y - comp;
            var y1 = select(y + corrected, y, control.opaque_zero != 0u);
            comp = (y1 - y) - corrected;
#else
            var y1 = y + inc.y;
#endif
#ifdef WALL
            if (y1.x > wall_position(p) || (y.y > real(0.0) && y1.y < real(0.0))) {
                let w = resolve_impacts(p, omega, phase, y, h, y1);
                // Whatever the wall did (an impact, a rest, a departure
                // from rest), the step ends where resolve_impacts says; the
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
                sticks = w.sticks;
                rest_at = w.rest_at;
                rest_phase = w.rest_phase;
            }
#endif
            y = y1;
#ifdef WALL
        }
        if (sticks) {
            let w = stuck_step(p, omega, rest_phase, h - rest_at);
            y = w.y;
            comp = State();
            c.z = c.z | rank_flags(w.rank_loss);
        }
#endif
        phase = next_phase;
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
    if (loop_budget_exhausted()) {
        c.z = c.z | FLAG_TRUNCATED;
    }
    store_state(base, y);
    counts[t] = c;
}
