// What the period map's kernels share. Their control struct, bindings,
// strides (LANE_STRIDE, TRAJ_STRIDE, SUMMARY_STRIDE) and flags are stated
// once in src/backend/gpu/bindings.rs (`SWEEP`), which writes them into the
// generated prelude.

// Per lane: the system's parameters, then h, cos(ωh/2), sin(ωh/2), ω, δ.
const LANE_H: u32 = PARAM_COUNT;
const LANE_HALF: u32 = PARAM_COUNT + 1u;
const LANE_OMEGA: u32 = PARAM_COUNT + 3u;
const LANE_DELTA: u32 = PARAM_COUNT + 4u;

// Per trajectory: y (DIM), the compensation of y (DIM), the phase (2), the
// slowest impact speed of the iteration so far (NO_IMPACT if none); with
// general surfaces, then its region of the switches (between dispatches;
// recomputed from the state at the start of every part, as the CPU does)
// and the part's Σ ln |det S| of its crossings (the sum rule's term).
#ifdef SURFACES
const TRAJ_REGION: u32 = 2u * DIM + 3u;
const TRAJ_FLUX: u32 = 2u * DIM + 4u;
#endif
const TRAJ_SLOWEST: u32 = 2u * DIM + 2u;
const NO_IMPACT: real = real(1e30);

// Flags that outlive the iteration they were raised in. (A lane that slid
// once, even in the transient, went on from a state the kernels did not
// integrate: all it computes after is the CPU's to redo. A failure keeps
// its cause.)
const FLAG_STICKY: u32 = FLAG_NONFINITE | FLAG_TRUNCATED | FLAG_SLIDING | FLAG_TOO_MANY_EVENTS;

fn rank_flags(rank_loss: u32) -> u32 {
    if (rank_loss >= 2u) {
        return FLAG_RANK_TWO;
    }
    return select(0u, FLAG_RANK_ONE, rank_loss > 0u);
}

fn load_state(base: u32) -> State {
    var y: State;
    for (var k = 0u; k < DIM; k = k + 1u) {
        y[k] = traj[base + k];
    }
    return y;
}

fn store_state(base: u32, y: State) {
    for (var k = 0u; k < DIM; k = k + 1u) {
        traj[base + k] = y[k];
    }
}

fn is_finite(y: State) -> bool {
    // NaN fails every comparison; infinity exceeds the largest real.
    return all(abs(y) <= State(MAX_REAL));
}

#include "shared/loop_budget.wgsl"
