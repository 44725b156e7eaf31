// Kernel: advance trajectories through a stretch of one map iteration.
//
// One invocation per trajectory (references only during the transient).
// Each dispatch takes at most `chunk_steps` RK4 steps, so no dispatch runs
// long enough to trip a driver watchdog and the host sees progress between
// dispatches. A failed (non-finite) trajectory stops; other lanes never read it.

#include "shared/bindings.wgsl"
#include "shared/dispatch.wgsl"

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    var t: u32;
    var lane: u32;
    if (control.transient != 0u) {
        lane = invocation_index(gid, groups);
        t = lane * TRAJ;
    } else {
        t = invocation_index(gid, groups);
        lane = t / TRAJ;
    }
    if (lane >= control.lane_count) {
        return;
    }
    var c = counts[t];
    if ((c.z & FLAG_NONFINITE) != 0u) {
        return;
    }
    let base = t * TRAJ_STRIDE;
    var y = load_state(base);
#ifdef MAP
    if (c.x < 1u) {
        y = map_step(load_params(lane), y);
        c.x = 1u;
    }
#else
    let tr = advance(lane, t, load_trajectory(base, y, c));
    store_trajectory(base, tr);
    y = tr.y;
    c = tr.c;
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

#ifndef MAP
// A flow's trajectory as a dispatch advances it: its state, the
// compensation of the state, the forcing phase and counts[t]; with stops,
// the slowest impact speed of the iteration so far; with surfaces, its
// region of the switches and the part's Σ ln |det S| (the buffers' layout
// is in bindings.wgsl and src/backend/gpu/bindings.rs).
struct Trajectory {
    y: State,
    comp: State,
    phase: vec2<real>,
    c: vec4<u32>,
#ifdef WALL
    slowest: real,
#endif
#ifdef SURFACES
    region: u32,
    flux: real,
#endif
}

// Trajectory record at `base` in traj, with its state y and counts c.
fn load_trajectory(base: u32, y: State, c: vec4<u32>) -> Trajectory {
    var tr: Trajectory;
    tr.y = y;
    tr.comp = load_state(base + DIM);
    tr.phase = vec2<real>(traj[base + 2u * DIM], traj[base + 2u * DIM + 1u]);
    tr.c = c;
#ifdef WALL
    tr.slowest = traj[base + TRAJ_SLOWEST];
#endif
#ifdef SURFACES
    tr.region = u32(traj[base + TRAJ_REGION]);
    tr.flux = traj[base + TRAJ_FLUX];
#endif
    return tr;
}

// The trajectory's record past its state (which main stores with counts[t]).
fn store_trajectory(base: u32, tr: Trajectory) {
    store_state(base + DIM, tr.comp);
    traj[base + 2u * DIM] = tr.phase.x;
    traj[base + 2u * DIM + 1u] = tr.phase.y;
#ifdef WALL
    traj[base + TRAJ_SLOWEST] = tr.slowest;
#endif
#ifdef SURFACES
    traj[base + TRAJ_REGION] = real(tr.region);
    traj[base + TRAJ_FLUX] = tr.flux;
#endif
}

// A lane's step: h, the rotation (cos, sin)(ωh/2) of the forcing phase
// through half a step, and ω.
struct Stepping {
    h: real,
    half: vec2<real>,
    omega: real,
}

// Trajectory t of `lane` advanced by this dispatch's steps, up to the end
// of the current part (the CPU's part_map_many and its step loop,
// integrate::steps_of).
fn advance(lane: u32, t: u32, tr_in: Trajectory) -> Trajectory {
    let p = load_params(lane);
    let lb = lane * LANE_STRIDE;
    let step = Stepping(lanes[lb + LANE_H], vec2<real>(lanes[lb + LANE_HALF], lanes[lb + LANE_HALF + 1u]), lanes[lb + LANE_OMEGA]);
    // While averaging, a dispatch stops at the end of the current part,
    // where the finish kernel re-seeds the copies.
    var part_end = control.steps_per_period;
    if (control.transient == 0u) {
        part_end = (tr_in.c.x / control.part_steps + 1u) * control.part_steps;
    }
    let end = min(tr_in.c.x + control.chunk_steps, part_end);
#ifdef WALL
    var tr = wall_steps(p, t, step, end, tr_in);
#else
    var tr = plain_steps(p, step, end, tr_in);
#endif
    tr.c.x = end;
    return tr;
}

#ifdef WALL
// The steps up to `end` of a system with stops (and surfaces). The hot
// loop only steps and detects: a step whose plain image reaches a stop or
// turns back inside it (or may cross a surface), or a mass at rest on a
// stop, ends it, and resolve_step takes that one step and goes back. With
// the resolution inlined into every step, lavapipe ran the kernel 21 times
// slower than the kernel without a wall, even when no impact happened
// (lavapipe runs masked code in full: docs/BENCHMARKS-GPU.md, "What lavapipe
// runs").
fn wall_steps(p_lane: Params, t: u32, step: Stepping, end: u32, tr_in: Trajectory) -> Trajectory {
#ifdef SURFACES
    // The lane's parameters and the trajectory's region (set below).
    var p = p_lane;
#else
    let p = p_lane;
#endif
    var tr = tr_in;
    let walls = stops_of(p);
    var k = tr.c.x;
#ifdef SURFACES
    // The region: from the state at the start of a part (of the whole
    // iteration in the transient), as the CPU path finds it at the start
    // of each call; else carried over from the last dispatch.
    let part_start = select(k % control.part_steps == 0u, k == 0u, control.transient != 0u);
    if (part_start) {
        tr.region = region_of(p, tr.phase, tr.y);
    }
    p.region = tr.region;
    // The surfaces' values at the step's start (carried from step to
    // step, as the CPU's at_start).
    var before = surface_values(p, tr.phase, tr.y);
    if ((tr.c.z & FLAG_SLIDING) != 0u) {
        // A lane flagged sliding is the CPU's to recompute: its
        // trajectories only count their steps from here on (stepping on
        // from a state the kernels did not integrate costs, and can run
        // past lavapipe's loop cap).
        k = end;
    }
#endif
    loop {
        var y1 = tr.y;
        var comp1 = tr.comp;
        var pending = false;
        for (; k < end; k = k + 1u) {
            let y = tr.y;
            if (resting_on(walls, y) < WALLS) {
                pending = true;
                break;
            }
            let inc = rk4_increment(p, tr.phase, step.half, y, step.h);
#ifdef COMPENSATED
            // Kahan summation: the increment of one step is far smaller
            // than y, and f32 would drop its low bits every step.
            let corrected = inc.y - tr.comp;
            y1 = select(y + corrected, y, control.opaque_zero != 0u);
            comp1 = (y1 - y) - corrected;
#else
            y1 = y + inc.y;
#endif
            if (reaches_a_stop(walls, y, step.h, y1)) {
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
            if (crosses_a_surface(p.region, before, after, step.h)) {
                pending = true;
                break;
            }
            before = after;
#endif
            tr.y = y1;
            tr.comp = comp1;
            tr.phase = rotate(rotate(tr.phase, step.half), step.half);
        }
        if (!pending) {
            break;
        }
        // The step resolved and recorded (generated: resolve_step and
        // record, src/model/ir/trajectory.rs); its crossings go straight
        // to the buffer.
        let resolved = resolve_step(p, walls, step, y1, comp1, tr);
        tr = resolved.tr;
        k = k + 1u;
        // Past the bound on located events in the part, the step's
        // resolution done (the CPU's end_past_the_bound): the trajectory
        // ends non-finite (NaN made at run time: a constant 0/0 is a
        // shader-creation error), flagged, and stops here (stepping its
        // NaN on would only count against lavapipe's loop cap).
        let counted = crossings[t] + resolved.crossings;
        crossings[t] = counted;
        if (counted.x + counted.y + counted.z + counted.w > MAX_EVENTS_PER_ITERATION) {
            let zero = real(control.opaque_zero);
            tr.y = State(zero / zero);
            tr.comp = State();
            tr.c.z = tr.c.z | FLAG_TOO_MANY_EVENTS;
            k = end;
        }
#ifdef SURFACES
        p.region = tr.region;
        before = surface_values(p, tr.phase, tr.y);
        // Flagged sliding, the lane is the CPU's from here on, at once as
        // at a dispatch's start: stepping on to the dispatch's end through
        // a motion the kernels cannot follow left the lane wherever the
        // dispatch ended, so adapters with other dispatch lengths (an
        // H100's whole periods, lavapipe's 256 steps) ended it apart.
        if ((tr.c.z & FLAG_SLIDING) != 0u) {
            k = end;
        }
#endif
    }
    return tr;
}

#else
// The steps up to `end` of a system without stops: plain RK4 (rk4::step).
fn plain_steps(p: Params, step: Stepping, end: u32, tr_in: Trajectory) -> Trajectory {
    var tr = tr_in;
    for (var k = tr.c.x; k < end; k = k + 1u) {
        let next_phase = rotate(rotate(tr.phase, step.half), step.half);
        let y = tr.y;
        let inc = rk4_increment(p, tr.phase, step.half, y, step.h);
#ifdef COMPENSATED
        // Kahan summation: the increment of one step is far smaller than
        // y, and f32 would drop its low bits every step.
        let corrected = inc.y - tr.comp;
        let y1 = select(y + corrected, y, control.opaque_zero != 0u);
        tr.comp = (y1 - y) - corrected;
#else
        let y1 = y + inc.y;
#endif
        tr.y = y1;
        tr.phase = next_phase;
    }
    return tr;
}
#endif
#endif
