// Kernel: the end of a part of a map iteration (the whole iteration when it
// has one part), one invocation per lane.
//
// Averaging: write the estimated Jacobian of the part (column i =
// (U(x + δe_i) - U(x)) / δ_i, the paper's eq. 6, or the central
// (U(x + δe_i) - U(x - δe_i)) / 2δ), the reference's state and a summary into
// the part's ring slot. Always: re-seed the perturbed copies from the
// reference's new state, and at the end of an iteration restart the
// reference at phase 0, so the next part needs nothing from the host.

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
    let r = lane * TRAJ;
    var cr = counts[r];
    var flags = cr.z;
    // The end of a whole iteration (always, in the transient), or of a part
    // (a sub-map), after which the reference runs on at its phase. A failed
    // reference stopped where it failed: its iterations end at once, each
    // reporting the failure in its last part.
    let last = cr.x >= control.steps_per_period || (cr.z & FLAG_NONFINITE) != 0u;
#ifdef WRAP
    // A model's angles into [-π, π) at the end of an iteration (twin of
    // System::wrap on the CPU): the point, the restart and the copies'
    // seeds, not the Jacobian, whose columns are differences of the
    // copies' unwrapped images.
    let y = select(load_state(r * TRAJ_STRIDE), wrap_angles(load_state(r * TRAJ_STRIDE)), last);
#else
    let y = load_state(r * TRAJ_STRIDE);
#endif
    if (control.transient == 0u) {
        let part = select(cr.x / control.part_steps - 1u, control.parts - 1u, last);
        let slot = ((cr.w % control.ring) * control.parts + part) * control.lane_count + lane;
        // How far the copies left the linear regime at the wall (see
        // IterationStats::nonlinearity): the host re-estimates the
        // iterations where that matters (grazing).
        var nonlinearity = 0.0f;
#ifdef LYAPUNOV
        let columns = write_columns(lane, r, slot);
        flags = flags | columns.flags;
        nonlinearity = columns.nonlinearity;
#endif
        write_summary(r, slot, y, cr.y, flags, nonlinearity);
        if (last) {
            cr.w = cr.w + 1u;
        }
    }
    // The copies start where the reference is: the next iteration's step 0
    // and phase 0, or the next part's first step at the reference's phase
    // and with its compensation (so that a copy's exact start is the
    // reference's plus exactly its δ).
    var phase = vec2<real>(real(1.0), real(0.0));
    var comp = State();
    if (last) {
        cr.x = 0u;
        restart(r * TRAJ_STRIDE, y, phase, comp);
    } else {
        phase = vec2<real>(traj[r * TRAJ_STRIDE + 2u * DIM], traj[r * TRAJ_STRIDE + 2u * DIM + 1u]);
        comp = load_state(r * TRAJ_STRIDE + DIM);
        traj[r * TRAJ_STRIDE + TRAJ_SLOWEST] = NO_IMPACT;
#ifdef SURFACES
        traj[r * TRAJ_STRIDE + TRAJ_FLUX] = real(0.0);
#endif
    }
    cr.y = 0u;
    cr.z = flags & FLAG_STICKY;
    counts[r] = cr;
#ifdef WALL
    crossings[r] = vec4<u32>();
#endif
#ifdef LYAPUNOV
    reseed_copies(lane, r, y, phase, comp, cr);
#endif
}

#ifdef LYAPUNOV
// The flags the copies raise in the part, and how far they left the
// linear regime.
struct Columns {
    flags: u32,
    nonlinearity: f32,
}

// The part's estimated Jacobian of lane (reference r) into ring slot
// `slot`, a column per coordinate from its copies (the CPU's
// jacobian::Copies::difference).
fn write_columns(lane: u32, r: u32, slot: u32) -> Columns {
    var out = Columns(0u, 0.0f);
    for (var i = 0u; i < DIM; i = i + 1u) {
        // Column i from the copy at x + δe_i and, for central
        // differences, the one at x - δe_i (else the reference itself).
        var plus = r + 1u + i;
#ifdef CENTRAL
        var minus = r + 1u + DIM + i;
        let step_plus = deltas[lane * 2u * DIM + i];
        let step_minus = deltas[lane * 2u * DIM + DIM + i];
        out.flags = out.flags | ((counts[plus].z | counts[minus].z) & (FLAG_CHATTERING | FLAG_TRUNCATED | FLAG_SLIDING | FLAG_TOO_MANY_EVENTS));
        // A copy that met a stop a different number of times than the
        // reference crossed a grazing boundary: its difference is O(1)
        // wrong. Difference on the other side, where the map is smooth.
        let same_plus = same_impacts(r, plus) && (counts[plus].z & FLAG_BEHIND_WALL) == 0u;
        let same_minus = same_impacts(r, minus) && (counts[minus].z & FLAG_BEHIND_WALL) == 0u;
        var step = step_plus + step_minus;
        if (!same_plus && same_minus) {
            plus = r;
            step = step_minus;
        } else if (same_plus && !same_minus) {
            minus = r;
            step = step_plus;
        }
#else
        let minus = r;
        let step = deltas[lane * DIM + i];
        out.flags = out.flags | (counts[plus].z & (FLAG_CHATTERING | FLAG_TRUNCATED | FLAG_SLIDING | FLAG_TOO_MANY_EVENTS));
#endif
        // The two images are close, so their difference is exact; their
        // low bits are what the column is made of.
        var difference = load_state(plus * TRAJ_STRIDE) - load_state(minus * TRAJ_STRIDE);
#ifdef COMPENSATED
        // Each compensation holds the rounding its state still owes (the
        // exact sum is y - comp): without it, f32 would round every column
        // by up to ulp(y)/δ.
        difference = difference - (load_state(plus * TRAJ_STRIDE + DIM) - load_state(minus * TRAJ_STRIDE + DIM));
#endif
        for (var k = 0u; k < DIM; k = k + 1u) {
            jac[slot * DIM * DIM + k * DIM + i] = difference[k] / step;
        }
#ifdef WALL
        out.nonlinearity = max(out.nonlinearity, max(departure(r, plus), departure(r, minus)));
#endif
#ifdef CENTRAL
        if (plus != r && minus != r) {
            out.nonlinearity = max(out.nonlinearity, asymmetry(r, plus, minus));
        }
#endif
    }
    return out;
}

// The copies of lane (reference r) seeded from the reference's state y, at
// its phase and with its compensation: δ relative to the state's size, as
// on the CPU, δ·max(1, ‖y‖∞).
fn reseed_copies(lane: u32, r: u32, y: State, phase: vec2<real>, comp: State, cr: vec4<u32>) {
    var size = real(1.0);
    for (var k = 0u; k < DIM; k = k + 1u) {
        size = max(size, abs(y[k]));
    }
    let delta = lanes[lane * LANE_STRIDE + LANE_DELTA] * size;
    let p = load_params(lane);
    for (var i = 0u; i < DIM; i = i + 1u) {
        var yi = y;
        yi[i] = y[i] + delta;
#ifdef CENTRAL
        deltas[lane * 2u * DIM + i] = yi[i] - y[i];
#else
        deltas[lane * DIM + i] = yi[i] - y[i];
#endif
        restart((r + 1u + i) * TRAJ_STRIDE, yi, phase, comp);
        counts[r + 1u + i] = vec4<u32>(cr.x, 0u, cr.z | behind_wall(p, yi), 0u);
#ifdef WALL
        crossings[r + 1u + i] = vec4<u32>();
#endif
#ifdef CENTRAL
        var ym = y;
        ym[i] = y[i] - delta;
        deltas[lane * 2u * DIM + DIM + i] = y[i] - ym[i];
        restart((r + 1u + DIM + i) * TRAJ_STRIDE, ym, phase, comp);
        counts[r + 1u + DIM + i] = vec4<u32>(cr.x, 0u, cr.z | behind_wall(p, ym), 0u);
#ifdef WALL
        crossings[r + 1u + DIM + i] = vec4<u32>();
#endif
#endif
    }
}
#endif

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

// Whether trajectory t met each stop as often as the reference r (twin of
// `same` in method::jacobian).
fn same_impacts(r: u32, t: u32) -> bool {
#ifdef WALL
    return all(crossings[t] == crossings[r]);
#else
    return counts[t].y == counts[r].y;
#endif
}

#ifdef WALL
// A copy's departure from the reference r at the stops: the relative
// difference of their slowest impact speeds, or a large value when they met
// a stop a different number of times (0 for the reference itself, or
// without impacts).
fn departure(r: u32, t: u32) -> f32 {
    if (t == r) {
        return 0.0f;
    }
    if ((counts[t].z & FLAG_BEHIND_WALL) != 0u) {
        return 1e30f;
    }
#ifdef SURFACES
    // No crossing of any kind (surfaces' count beside the impacts).
    if (traj[r * TRAJ_STRIDE + TRAJ_SLOWEST] == NO_IMPACT) {
        return 0.0f;
    }
#else
    if (counts[r].y == 0u) {
        return 0.0f;
    }
#endif
    if (!same_impacts(r, t)) {
        return 1e30f;
    }
    let vr = traj[r * TRAJ_STRIDE + TRAJ_SLOWEST];
    let vt = traj[t * TRAJ_STRIDE + TRAJ_SLOWEST];
    return f32(abs(vt - vr) / vr);
}
#endif

// FLAG_BEHIND_WALL for a copy seeded at y behind a stop, else 0 (twin of
// System::admits).
fn behind_wall(p: Params, y: State) -> u32 {
#ifdef WALL
    let walls = stops_of(p);
    for (var j = 0u; j < WALLS; j = j + 1u) {
        if (gap(stop(walls, j), y) > real(0.0)) {
            return FLAG_BEHIND_WALL;
        }
    }
#endif
#ifdef SURFACES
    // Beyond an event's surface (at t = 0, as the CPU's check_state).
    let g = surface_g(p, vec2<real>(real(1.0), real(0.0)), y);
    for (var j = 0u; j < SURFACES; j = j + 1u) {
        if (SURFACE_BIT[j] == EVENT && g[j] > real(0.0)) {
            return FLAG_BEHIND_WALL;
        }
    }
#endif
    return 0u;
}

// A trajectory starting a map iteration or a part at y, with its phase and
// compensation, and no impact yet.
fn restart(base: u32, y: State, phase: vec2<real>, comp: State) {
    store_state(base, y);
    store_state(base + DIM, comp);
    traj[base + 2u * DIM] = phase.x;
    traj[base + 2u * DIM + 1u] = phase.y;
    traj[base + TRAJ_SLOWEST] = NO_IMPACT;
#ifdef SURFACES
    traj[base + TRAJ_FLUX] = real(0.0);
#endif
}

#ifdef CENTRAL
// How far a central column's copies left the linear regime between the
// stops, |U₊ + U₋ - 2U₀| / |U₊ - U₋| in max norms (twin of the CPU's
// `asymmetry` in jacobian::Copies::difference).
fn asymmetry(r: u32, plus: u32, minus: u32) -> f32 {
    var up = load_state(plus * TRAJ_STRIDE) - load_state(r * TRAJ_STRIDE);
    var down = load_state(minus * TRAJ_STRIDE) - load_state(r * TRAJ_STRIDE);
#ifdef COMPENSATED
    up = up - (load_state(plus * TRAJ_STRIDE + DIM) - load_state(r * TRAJ_STRIDE + DIM));
    down = down - (load_state(minus * TRAJ_STRIDE + DIM) - load_state(r * TRAJ_STRIDE + DIM));
#endif
    var even = real(0.0);
    var odd = real(0.0);
    for (var k = 0u; k < DIM; k = k + 1u) {
        even = max(even, abs(up[k] + down[k]));
        odd = max(odd, abs(up[k] - down[k]));
    }
    if (even == real(0.0)) {
        return 0.0f;
    }
    return f32(even / odd);
}
#endif
