#ifdef SURFACES
// ---- General surfaces: twins of src/integrate/surface.rs and of the
// surface branch of resolve and cross in src/integrate/impact/. The
// system file gives SURFACES, each one's SURFACE_BIT (EVENT for an event),
// surface_g, surface_values (g and the rate ∇g·F + ∂g/∂t along the field
// of p.region), surface_gradient and reset. A trajectory's field is that
// of its region, p.region: rhs reads a switch's side from it, never from
// the state.

// What resolve_impacts did to the surfaces in its step, beside its
// WallStep: the region it ends in, Σ ln |det S| of its crossings, and
// whether one could not be resolved (sliding). Set by the integrate kernel
// before the call, read after it.
struct Crossed {
    region: u32,
    log_flux: real,
    sliding: bool,
    // Sliding phases entered (IterationStats::sliding_phases).
    sliding_phases: u32,
}
var<private> crossed: Crossed;

// Region bits from SLIDING_SHIFT up mark a motion sliding on surface j
// (bit SLIDING_SHIFT + j), the bits below are the sides (surface::SLIDING).
const SLIDING_SHIFT: u32 = 16u;
const SIDES: u32 = 0xffffu;

fn is_sliding(region: u32) -> bool {
    return (region >> SLIDING_SHIFT) != 0u;
}

// The equivalent control of a motion sliding on one switch (Filippov's
// convex combination, surface::equivalent_on with one switch): the sides'
// fields lo and hi, their rates a and b along ∇g, α = a/(a - b), the field
// lo + α(hi - lo) (filippov_alpha and filippov_field, generated from the
// step program), and the stick margins (L - m, L + m), m = (a + b)/2, L
// the stick limit or the half jump (a - b)/2.
struct Equivalent {
    field: State,
    alpha: real,
    margins: vec2<real>,
}

fn equivalent(p: Params, phase: vec2<real>, y: State) -> Equivalent {
    let s = switch_sides(p, firstTrailingBit(p.region >> SLIDING_SHIFT), phase, y);
    let alpha = filippov_alpha(s.a, s.b);
    return Equivalent(filippov_field(s.lo, s.hi, alpha), alpha, s.margins);
}

// Switch j's two sides at y, for a trajectory on either side of it or
// sliding on it: the fields lo (g < 0) and hi, their rates a and b along
// ∇g, and the stick margins (L - m, L + m), m = (a + b)/2, L the stick
// limit or the half jump (a - b)/2; both > 0, the switch holds the motion
// (surface::joining_margins, and the sides of surface::equivalent_on, for
// one switch). What a crossing decides sliding from and what the sliding
// motion leaves by, written once.
struct SwitchSides {
    lo: State,
    hi: State,
    a: real,
    b: real,
    margins: vec2<real>,
}

fn switch_sides(p: Params, j: u32, phase: vec2<real>, y: State) -> SwitchSides {
    let bit = SURFACE_BIT[j];
    var lo_p = p;
    lo_p.region = (p.region & SIDES) & ~(1u << bit);
    var hi_p = lo_p;
    hi_p.region = lo_p.region | (1u << bit);
    let lo = field(lo_p, phase, y);
    let hi = field(hi_p, phase, y);
    let n = surface_gradient(p, phase, y, j);
    let a = dot_in_order(n, lo);
    let b = dot_in_order(n, hi);
    let mean = real(0.5) * (a + b);
    let limit = stick_limit(p, y, j, real(0.5) * (a - b));
    return SwitchSides(lo, hi, a, b, vec2<real>(limit - mean, limit + mean));
}

// The sliding field (NaN where the combination does not exist, as the
// CPU's Sliding flow).
fn sliding_field(p: Params, phase: vec2<real>, y: State) -> State {
    let e = equivalent(p, phase, y);
    if (!(abs(e.alpha) <= MAX_REAL)) {
        var zero = real(0.0);
        return State(zero / zero);
    }
    return e.field;
}

// The switch still holds the motion: both margins > 0 (as the CPU's
// slide and cross test them).
fn holds(m: vec2<real>) -> bool {
    return m.x > real(0.0) && m.y > real(0.0);
}

// How a sliding sub-step ended (Slid in impact.rs).
struct Slid {
    // Left the switch (to region `region`) after s, at y; else still
    // sliding at the end, at y.
    leaves: bool,
    s: real,
    y: State,
    region: u32,
    // Something the kernels do not integrate met while sliding (another
    // switch, an event): the lane is the CPU's.
    flagged: bool,
}

// Slides on the switch of p's sliding set for up to h from (phase, y):
// twin of `slide` in impact.rs for one switch. Another surface crossed on
// the way, or a stop reached, is flagged rather than located; an exit (a stick margin reaching
// 0) is bisected on RK4 re-stepped along the sliding field, and the region
// leaves to the side whose margin ran out.
fn slide(p: Params, omega: real, phase: vec2<real>, y: State, h: real) -> Slid {
    let j = firstTrailingBit(p.region >> SLIDING_SHIFT);
    // One re-step for the whole slide (one call site, as locate_newton):
    // its first pass to the step's end, then the bisection's midpoints.
    var lo = real(0.0);
    var hi = h;
    var exit: State;
    var m: vec2<real>;
    var flagged = false;
    var to = h;
    var passes = 0u;
    loop {
        let y_to = sub_step(p, omega, phase, y, to).y;
        let phase_to = rotate(phase, cos_sin(omega * to));
        let m_to = equivalent(p, phase_to, y_to).margins;
        if (passes == 0u) {
            var sides = p;
            sides.region = p.region & SIDES;
            let before = surface_values(sides, phase, y);
            let after = surface_values(sides, phase_to, y_to);
            for (var k = 0u; k < SURFACES; k = k + 1u) {
                if (k == j) {
                    continue;
                }
                let o = orientation(sides.region, SURFACE_BIT[k]);
                if (o * after.g[k] > real(0.0) && !(SURFACE_BIT[k] == EVENT && o * before.g[k] > real(0.0))) {
                    flagged = true;
                }
            }
            // A stop reached while sliding would need a motion along the
            // switch and into the stop at once: flagged, as on the CPU.
            if (behind_a_stop(stops_of(p), y_to)) {
                flagged = true;
            }
            if (holds(m_to)) {
                return Slid(false, h, y_to, p.region, flagged);
            }
            exit = y_to;
            m = m_to;
        } else if (holds(m_to)) {
            lo = to;
        } else {
            hi = to;
            exit = y_to;
            m = m_to;
        }
        // A bisection to EPSILON·h takes 53 midpoints; 128 bounds the loop
        // for lavapipe's iteration cap whatever the margins do.
        if (passes == 128u || !(hi - lo > EPSILON * h)) {
            break;
        }
        passes = passes + 1u;
        to = real(0.5) * (lo + hi);
    }
    // Leaves to the side whose margin ran out (surface::leaving).
    let bit = SURFACE_BIT[j];
    var region = p.region & ~(1u << (SLIDING_SHIFT + j));
    if (m.x <= m.y) {
        region = region | (1u << bit);
    } else {
        region = region & ~(1u << bit);
    }
    return Slid(true, hi, exit, region, flagged);
}

// The region of y: bit b set where switch b's g > 0 (surface::region_of).
fn region_of(p: Params, phase: vec2<real>, y: State) -> u32 {
    let g = surface_g(p, phase, y);
    var region = 0u;
    for (var j = 0u; j < SURFACES; j = j + 1u) {
        if (SURFACE_BIT[j] != EVENT && g[j] > real(0.0)) {
            region = region | (1u << SURFACE_BIT[j]);
        }
    }
    return region;
}

// The region after a reset jumps the state from y to `after` (an event's
// reset, a stop's rebound): a switch that the jump moves strictly off its
// side (g from ≤ 0 to > 0, or from ≥ 0 to < 0) takes the side of `after`,
// the others keep their bit (surface::jumped). A sliding region is kept (a
// reset met while sliding is flagged first).
fn jumped(p: Params, phase: vec2<real>, y: State, after: State) -> u32 {
    if (is_sliding(p.region)) {
        return p.region;
    }
    let g0 = surface_g(p, phase, y);
    let g1 = surface_g(p, phase, after);
    var region = p.region;
    for (var j = 0u; j < SURFACES; j = j + 1u) {
        let bit = SURFACE_BIT[j];
        if (bit != EVENT && g1[j] > real(0.0) && g0[j] <= real(0.0)) {
            region = region | (1u << bit);
        } else if (bit != EVENT && g1[j] < real(0.0) && g0[j] >= real(0.0)) {
            region = region & ~(1u << bit);
        }
    }
    return region;
}

// Whether a step of size h from values `before` to `after` may cross
// surface j: its end lies across, or its rate turns from approaching to
// leaving inside it within reach of the surface (surface::may_cross; the
// step program's oriented_may_meet, as the native step loops test it).
fn may_cross(region: u32, j: u32, before: SurfaceValues, after: SurfaceValues, h: real) -> bool {
    return oriented_may_meet(orientation(region, SURFACE_BIT[j]), surface_pair(j, before), surface_pair(j, after), h);
}

// Surface j's (g, rate) in values v.
fn surface_pair(j: u32, v: SurfaceValues) -> vec2<real> {
    return vec2<real>(v.g[j], v.rate[j]);
}

// Surface j's (g, rate) in values v, oriented so that > 0 lies across it
// for a trajectory in `region`: the value and rate its crossing is
// detected and located on, as a stop's (gap, speed) is.
fn oriented(region: u32, j: u32, v: SurfaceValues) -> vec2<real> {
    return orient(orientation(region, SURFACE_BIT[j]), surface_pair(j, v));
}

// The step loop's test over every surface, written out per surface as the
// stops' is (SURFACES is a constant).
fn crosses_a_surface(region: u32, before: SurfaceValues, after: SurfaceValues, h: real) -> bool {
    var hit = may_cross(region, 0u, before, after, h);
    if (SURFACES > 1u) {
        hit = hit || may_cross(region, 1u, before, after, h);
    }
    if (SURFACES > 2u) {
        hit = hit || may_cross(region, 2u, before, after, h);
    }
    if (SURFACES > 3u) {
        hit = hit || may_cross(region, 3u, before, after, h);
    }
    return hit;
}

// Surface j's oriented distance and rate at (s into the step from phase0,
// y): the `distance` and `rate` of `locate` in impact.rs for a surface.
fn surface_at(p: Params, omega: real, j: u32, phase0: vec2<real>, s: real, y: State) -> vec2<real> {
    return oriented(p.region, j, surface_values(p, rotate(phase0, cos_sin(omega * s)), y));
}

// Surface j's crossing in the step [0, h] from (phase0, y0) to y1, given
// its values at both ends: the stops' location on its oriented g instead
// of a gap (`locate` in impact.rs).
fn locate_surface(p: Params, omega: real, walls: Stops, j: u32, phase0: vec2<real>, y0: State, h: real, y1: State, before: SurfaceValues, after: SurfaceValues) -> Hit {
    return locate(p, omega, walls, WALLS + j, phase0, y0, h, y1, oriented(p.region, j, before), oriented(p.region, j, after));
}

// A crossing of a general surface, applied (cross in impact.rs).
struct Crossing {
    // Applied; else flagged (chattering or sliding), the state left at the
    // crossing.
    resolved: bool,
    y: State,
    region: u32,
    // ln |det S|, 0 where none applies.
    log_det: real,
    // Counted in the crossings (a touch of a switch in rounding is not).
    counted: bool,
    // The oriented approach rate: the crossing's "impact speed".
    approach: real,
    chattering: bool,
    sliding: bool,
    // det S = 0 (the reset collapsed a direction), or a sliding phase.
    rank_loss: bool,
    // The motion slides on the switch from here.
    slides: bool,
}

// The sum of a_i·b_i in index order from 0, as the CPU's iterator sum.
fn dot_in_order(a: State, b: State) -> real {
    var sum = real(0.0);
    for (var i = 0u; i < DIM; i = i + 1u) {
        sum = sum + a[i] * b[i];
    }
    return sum;
}

// ln |det S| of an event's crossing, S = DR + (F⁺ - DR·F⁻ - ∂R/∂t) ∇gᵀ /
// rate (surface::event_log_det), det by elimination with partial pivoting.
fn event_log_det(r: Reset, gradient: State, rate: real, before: State, after: State) -> real {
    var s: array<State, DIM>;
    for (var i = 0u; i < DIM; i = i + 1u) {
        let dr_f = dot_in_order(r.dr[i], before);
        for (var k = 0u; k < DIM; k = k + 1u) {
            s[i][k] = r.dr[i][k] + (after[i] - dr_f - r.rate[i]) * gradient[k] / rate;
        }
    }
    var det = real(1.0);
    for (var col = 0u; col < DIM; col = col + 1u) {
        var pivot = col;
        for (var row = col + 1u; row < DIM; row = row + 1u) {
            if (abs(s[row][col]) > abs(s[pivot][col])) {
                pivot = row;
            }
        }
        if (pivot != col) {
            let swap = s[col];
            s[col] = s[pivot];
            s[pivot] = swap;
            det = -det;
        }
        let d = s[col][col];
        det = det * d;
        if (d == real(0.0)) {
            break;
        }
        for (var row = col + 1u; row < DIM; row = row + 1u) {
            let factor = s[row][col] / d;
            for (var k = col; k < DIM; k = k + 1u) {
                s[row][k] = s[row][k] - factor * s[col][k];
            }
        }
    }
    if (det == real(0.0)) {
        // -∞, made at run time (a constant 1/0 is a shader-creation error).
        var zero = real(0.0);
        return real(-1.0) / zero;
    }
    return log_r(abs(det));
}

// Crosses general surface j at y (on it, at `phase`) for a trajectory in
// p.region: an event's reset, a switch's flip of the region, with its
// ln |det S|, or the start of a sliding phase on a switch both fields
// point into (or its stick limit holds).
fn cross(p: Params, j: u32, phase: vec2<real>, y: State) -> Crossing {
    let bit = SURFACE_BIT[j];
    let before = surface_values(p, phase, y);
    let approach_rate = before.rate[j];
    var out = Crossing(false, y, p.region, real(0.0), true, orientation(p.region, SURFACE_BIT[j]) * approach_rate, false, false, false, false);
    if (bit == EVENT) {
        let r = reset(p, phase, y, j);
        // The reset may jump across a switch: what follows is that side's
        // field (F⁺ of the saltation below, the rate leaving).
        var after = p;
        after.region = jumped(p, phase, y, r.y);
        let now = surface_values(after, phase, r.y);
        let scale = state_scale(y);
        // Back where the motion lives, and leaving the surface.
        if (!(now.g[j] <= real(4.0) * EPSILON * scale && now.rate[j] < real(0.0))) {
            out.chattering = true;
            return out;
        }
        out.region = after.region;
        out.log_det = event_log_det(r, surface_gradient(p, phase, y, j), approach_rate, rhs(p, phase, y), rhs(after, phase, r.y));
        out.rank_loss = !(abs(out.log_det) <= MAX_REAL);
        out.resolved = true;
        out.y = r.y;
        return out;
    }
    // The stick margins of the two sides (joining_margins: the stick
    // limit, or Filippov's, the half jump). The trajectory is on one side
    // (resolve_impacts slides a sliding one before it looks for crossings).
    let margins = switch_sides(p, j, phase, y).margins;
    if (holds(margins)) {
        // Both fields point into the switch (or the stick limit holds the
        // motion): it slides, where its Filippov combination exists, and
        // forgets how far from the surface it came (one direction); the
        // volume law no longer applies (ln |det S| NaN).
        var joined = p;
        joined.region = p.region | (1u << (SLIDING_SHIFT + j));
        if (!(abs(equivalent(joined, phase, y).alpha) <= MAX_REAL)) {
            out.sliding = true;
            return out;
        }
        out.region = joined.region;
        out.resolved = true;
        out.slides = true;
        out.rank_loss = true;
        var zero = real(0.0);
        out.log_det = zero / zero;
        return out;
    }
    let to_plus = margins.x <= margins.y;
    if (to_plus == (((p.region >> bit) & 1u) == 1u)) {
        // Only touched the surface (in rounding): no crossing.
        out.counted = false;
        out.resolved = true;
        return out;
    }
    var flipped = p;
    flipped.region = p.region ^ (1u << bit);
    out.region = flipped.region;
    let leaving = surface_values(flipped, phase, y).rate[j];
    if (leaving * approach_rate <= real(0.0)) {
        out.sliding = true;
        return out;
    }
    // det S = (∇g·F⁺)/(∇g·F⁻).
    out.log_det = log_r(leaving / approach_rate);
    out.resolved = true;
    return out;
}

// General surface met.stop - WALLS crossed at met.hit (the surface branch
// of resolve): the crossing applied, counted and, in `crossed`, its region,
// ln |det S| and flags; the rest of the step is stepped again unless the
// motion now slides (resolve_impacts' next pass slides it).
fn cross_surface(p: Params, omega: real, met: Met, r_in: Resolution) -> Resolution {
    var r = r_in;
    let phase_c = rotate(r.phase0, cos_sin(omega * met.hit.s));
    r.done = r.done + met.hit.s;
    let crossing = cross(p, met.stop - WALLS, phase_c, met.hit.y);
    r.slowest = min(r.slowest, crossing.approach);
    if (crossing.counted) {
        r.crossings[met.stop] = r.crossings[met.stop] + 1u;
    }
    if (crossing.rank_loss) {
        r.rank_loss = max(r.rank_loss, 1u);
    }
    crossed.region = crossing.region;
    crossed.log_flux = crossed.log_flux + crossing.log_det;
    crossed.sliding = crossed.sliding || crossing.sliding;
    r.phase0 = phase_c;
    if (!crossing.resolved) {
        // Flagged: the rest of the step in the field now in force, and the
        // step ends there.
        r.y0 = met.hit.y;
        r.restep = true;
        r.unresolved = true;
        r.chattering = crossing.chattering;
        return r;
    }
    if (crossing.slides) {
        crossed.sliding_phases = crossed.sliding_phases + 1u;
    }
    r.y0 = crossing.y;
    r.restep = !is_sliding(crossing.region);
    return r;
}
#endif
