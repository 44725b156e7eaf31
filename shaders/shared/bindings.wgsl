// The buffers both kernels share. Host twins: src/backend/gpu/sweep.rs.
//
// A lane is one parameter value; it owns TRAJ trajectories (the reference,
// then the copies at x + δe_i, then for central differences those at
// x - δe_i, when exponents are wanted), stored
// lane-major so a lane's trajectories sit side by side and take the same
// branches (impacts) together.

struct Control {
    // Lanes in this batch.
    lane_count: u32,
    // RK4 steps per map period (1 for a map): parts × part_steps.
    steps_per_period: u32,
    // RK4 steps per integrate dispatch, bounding each dispatch's work.
    chunk_steps: u32,
    // 1 while discarding the transient: references only, nothing recorded.
    transient: u32,
    // Iteration slots in the output ring.
    ring: u32,
    // Always 0. Compensated (Kahan) sums must not be simplified algebraically,
    // and WGSL cannot mark them exact (SPIR-V NoContraction): a select on a
    // value the compiler cannot know hides the identity (y + c) - y = c.
    opaque_zero: u32,
    // While averaging, each iteration is cut into `parts` sub-maps of
    // `part_steps` steps (see system::Part): at the end of each, the finish
    // kernel takes the part's Jacobian and re-seeds the copies from the
    // reference, which runs on. One part is the whole iteration.
    part_steps: u32,
    parts: u32,
}

// Per lane: the system's parameters, then h, cos(ωh/2), sin(ωh/2), ω, δ.
const LANE_H: u32 = PARAM_COUNT;
const LANE_HALF: u32 = PARAM_COUNT + 1u;
const LANE_OMEGA: u32 = PARAM_COUNT + 3u;
const LANE_DELTA: u32 = PARAM_COUNT + 4u;
const LANE_STRIDE: u32 = PARAM_COUNT + 5u;

// Per trajectory: y (DIM), the compensation of y (DIM), the phase (2), the
// slowest impact speed of the iteration so far (NO_IMPACT if none); with
// general surfaces, then its region of the switches (between dispatches;
// recomputed from the state at the start of every part, as the CPU does)
// and the part's Σ ln |det S| of its crossings (the sum rule's term).
#ifdef SURFACES
const TRAJ_STRIDE: u32 = 2u * DIM + 5u;
const TRAJ_REGION: u32 = 2u * DIM + 3u;
const TRAJ_FLUX: u32 = 2u * DIM + 4u;
#else
const TRAJ_STRIDE: u32 = 2u * DIM + 3u;
#endif
const TRAJ_SLOWEST: u32 = 2u * DIM + 2u;
const NO_IMPACT: real = real(1e30);

// Invocations per workgroup, set by the host when it builds the pipeline
// (the benchmark measures several sizes).
override WORKGROUP_SIZE: u32 = 64u;

// counts[t]: (step within the period, impacts this iteration, flags, iteration).
const FLAG_CHATTERING: u32 = 1u;
const FLAG_NONFINITE: u32 = 2u;
// The iteration collapsed one dimension (an impact with e = 0), or two
// (sticking: the mass's position and velocity; all of them with two
// states): see IterationStats::rank_loss.
const FLAG_RANK_ONE: u32 = 4u;
const FLAG_RANK_TWO: u32 = 8u;
// The adapter cut this dispatch's loops short (see loop_budget_exhausted):
// the host redoes the batch with shorter dispatches.
const FLAG_TRUNCATED: u32 = 16u;
// Flags that outlive the iteration they were raised in. (A lane that slid
// once, even in the transient, went on from a state the kernels did not
// integrate: all it computes after is the CPU's to redo.)
const FLAG_STICKY: u32 = FLAG_NONFINITE | FLAG_TRUNCATED | FLAG_SLIDING;
// A copy seeded behind the wall (its reference within δ of it): its column
// is differenced on the other side (System::admits on the CPU).
const FLAG_BEHIND_WALL: u32 = 32u;
// A motion on a switch the kernels do not integrate (another surface met
// while sliding, a switch left against its new field, or no Filippov
// combination): IterationStats::sliding; the backend recomputes the lane
// on the CPU.
const FLAG_SLIDING: u32 = 64u;

fn rank_flags(rank_loss: u32) -> u32 {
    if (rank_loss >= 2u) {
        return FLAG_RANK_TWO;
    }
    return select(0u, FLAG_RANK_ONE, rank_loss > 0u);
}

@group(0) @binding(0) var<uniform> control: Control;
@group(0) @binding(1) var<storage, read> lanes: array<real>;
@group(0) @binding(2) var<storage, read_write> traj: array<real>;
@group(0) @binding(3) var<storage, read_write> counts: array<vec4<u32>>;
// Per ring slot and lane, a slot per part of an iteration: (impacts, flags,
// bits of the f32 max |y|, bits of the f32 nonlinearity), then with stops
// the impacts on each (SUMMARY_STRIDE vectors per slot).
@group(0) @binding(4) var<storage, read_write> summary: array<vec4<u32>>;
#ifdef WALL
const SUMMARY_STRIDE: u32 = 2u;
// Per trajectory: its impacts on each stop in the current part of an
// iteration (components past WALLS stay 0); counts[t].y is their sum.
@group(0) @binding(8) var<storage, read_write> crossings: array<vec4<u32>>;
#else
const SUMMARY_STRIDE: u32 = 1u;
#endif
#ifdef SURFACES
// Per ring slot and lane: the reference's Σ ln |det S| over the part's
// crossings of general surfaces (IterationStats::log_flux).
@group(0) @binding(9) var<storage, read_write> fluxes: array<real>;
#endif
#ifdef LYAPUNOV
// Per lane: the perturbation actually taken per copy, (x_i + δ) - x_i
// (then x_i - (x_i - δ) for central differences).
@group(0) @binding(5) var<storage, read_write> deltas: array<real>;
// Per ring slot (a part of an iteration) and lane: the estimated Jacobian,
// row-major.
@group(0) @binding(6) var<storage, read_write> jac: array<real>;
#endif
// Per ring slot (a part of an iteration) and lane: the reference's state at
// the part's end; the last part's is the Poincaré point (the host's orbit
// periods, bifurcation points and grazing re-estimates start from it).
@group(0) @binding(7) var<storage, read_write> points: array<real>;

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
