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
#ifdef SURFACES
    // The lane's parameters and the trajectory's region (set below).
    var p = load_params(lane);
#else
    let p = load_params(lane);
#endif
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
    let walls = stops_of(p);
    var k = c.x;
#ifdef SURFACES
    // The region: from the state at the start of a part (of the whole
    // iteration in the transient), as the CPU path finds it at the start
    // of each call; else carried over from the last dispatch.
    let part_start = select(k % control.part_steps == 0u, k == 0u, control.transient != 0u);
    if (part_start) {
        p.region = region_of(p, phase, y);
    } else {
        p.region = u32(traj[base + TRAJ_REGION]);
    }
    var flux = traj[base + TRAJ_FLUX];
    // The surfaces' values at the step's start (carried from step to
    // step, as the CPU's at_start).
    var before = surface_values(p, phase, y);
    if ((c.z & FLAG_SLIDING) != 0u) {
        // A lane flagged sliding is the CPU's to recompute: its
        // trajectories only count their steps from here on (stepping on
        // from a state the kernels did not integrate costs, and can run
        // past lavapipe's loop cap).
        k = end;
    }
#endif
    // The hot loop only steps and detects: a step whose plain image reaches
    // a stop or turns back inside it, or a mass at rest on a stop, ends
    // it, and the resolution path below takes that one step and goes back.
    // With the resolution inlined into every step, lavapipe ran the kernel
    // 21 times slower than the kernel without a wall, even when no impact
    // happened (lavapipe runs masked code in full: docs/BENCHMARKS.md,
    // "What lavapipe runs").
    loop {
        var y1 = y;
        var comp1 = comp;
        var pending = false;
        for (; k < end; k = k + 1u) {
            if (resting_on(walls, y) < WALLS) {
                pending = true;
                break;
            }
            let inc = rk4_increment(p, phase, half, y, h);
#ifdef COMPENSATED
            // Kahan summation: the increment of one step is far smaller
            // than y, and f32 would drop its low bits every step.
            let corrected = inc.y - comp;
            y1 = select(y + corrected, y, control.opaque_zero != 0u);
            comp1 = (y1 - y) - corrected;
#else
            y1 = y + inc.y;
#endif
            if (reaches_a_stop(walls, y, h, y1)) {
                pending = true;
                break;
            }
#ifdef SURFACES
            // A sliding motion takes the resolution path at every step (its
            // field is the sliding one, which the plain step did not take).
            if (is_sliding(p.region)) {
                pending = true;
                break;
            }
            let after = surface_values(p, inc.phase, y1);
            if (crosses_a_surface(p.region, before, after, h)) {
                pending = true;
                break;
            }
            before = after;
#endif
            y = y1;
            comp = comp1;
            phase = rotate(rotate(phase, half), half);
        }
        if (!pending) {
            break;
        }
        // Step k meets a stop (or starts at rest on one).
        let next_phase = rotate(rotate(phase, half), half);
        // At rest on a stop, from the step's start or from an impact inside
        // it: stuck_step takes (the rest of) the step, called here only
        // (see resolve_impacts).
        var stuck = resting_on(walls, y);
        var rest_at = real(0.0);
        var rest_phase = phase;
        if (stuck == WALLS) {
#ifdef SURFACES
            crossed = Crossed(p.region, real(0.0), false, 0u);
#endif
            let w = resolve_impacts(p, walls, omega, phase, y, h, y1);
#ifdef SURFACES
            p.region = crossed.region;
            flux = flux + crossed.log_flux;
            if (crossed.sliding) {
                c.z = c.z | FLAG_SLIDING;
            }
            // The sliding phases entered, counted in the flags' high half.
            c.z = c.z + (min(crossed.sliding_phases, 0xffffu - (c.z >> 16u)) << 16u);
#endif
            // Whatever the stops did (an impact, a rest, a departure from
            // rest), the step ends where resolve_impacts says; the
            // compensation belongs to the plain step it replaced.
            if (any(w.y != y1)) {
                y = w.y;
                comp = State();
            } else {
                y = y1;
                comp = comp1;
            }
            c.y = c.y + w.impacts;
            // Straight to the buffer: a vector kept live across the step
            // loop would cost every step (registers), for a rare event.
            crossings[t] = crossings[t] + w.crossings;
            slowest = min(slowest, w.slowest);
            if (w.chattering) {
                c.z = c.z | FLAG_CHATTERING;
#ifdef SURFACES
                // Crossings of a general event that accumulate (a ball
                // locking onto a vibrating table) are held on the surface
                // by the CPU path (impact::hold_step), not here: the lane
                // is the CPU's.
                c.z = c.z | FLAG_SLIDING;
#endif
            }
            c.z = c.z | rank_flags(w.rank_loss);
            stuck = w.stuck;
            rest_at = w.rest_at;
            rest_phase = w.rest_phase;
        }
        if (stuck < WALLS) {
#ifdef SURFACES
            // Released from a stop, the CPU resolves the rest of the step
            // with its surfaces, where stuck_step takes one plain step:
            // the lane is the CPU's, as a motion the kernels cannot slide.
            c.z = c.z | FLAG_SLIDING;
#endif
            let w = stuck_step(p, walls, stuck, omega, rest_phase, y, h - rest_at);
            y = w.y;
            comp = State();
            c.z = c.z | rank_flags(w.rank_loss);
        }
        phase = next_phase;
        k = k + 1u;
#ifdef SURFACES
        before = surface_values(p, phase, y);
        // Flagged sliding, the lane is the CPU's from here on, at once as
        // at a dispatch's start: stepping on to the dispatch's end through
        // a motion the kernels cannot follow left the lane wherever the
        // dispatch ended, so adapters with other dispatch lengths (an
        // H100's whole periods, lavapipe's 256 steps) ended it apart.
        if ((c.z & FLAG_SLIDING) != 0u) {
            k = end;
        }
#endif
    }
#else
    for (var k = c.x; k < end; k = k + 1u) {
        let next_phase = rotate(rotate(phase, half), half);
        let inc = rk4_increment(p, phase, half, y, h);
#ifdef COMPENSATED
        // Kahan summation: the increment of one step is far smaller than
        // y, and f32 would drop its low bits every step.
        let corrected = inc.y - comp;
        let y1 = select(y + corrected, y, control.opaque_zero != 0u);
        comp = (y1 - y) - corrected;
#else
        let y1 = y + inc.y;
#endif
        y = y1;
        phase = next_phase;
    }
#endif
    c.x = end;
    store_state(base + DIM, comp);
    traj[base + 2u * DIM] = phase.x;
    traj[base + 2u * DIM + 1u] = phase.y;
#ifdef WALL
    traj[base + TRAJ_SLOWEST] = slowest;
#endif
#ifdef SURFACES
    traj[base + TRAJ_REGION] = real(p.region);
    traj[base + TRAJ_FLUX] = flux;
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
