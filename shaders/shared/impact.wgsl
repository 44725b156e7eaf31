// Wall impacts inside an RK4 step, twin of src/integrate/impact.rs: split
// the step at the impact, reset V -> -e·V with X = X_w exactly, integrate the
// rest, look again. The system file provides wall_position and
// wall_restitution; coordinate 0 is the position, 1 its velocity.

const MAX_IMPACTS_PER_STEP: u32 = 64u;
// See ACCUMULATION_FRACTION in src/integrate/impact.rs.
const ACCUMULATION_FRACTION: f32 = 1e-3;

struct WallStep {
    y: State,
    impacts: u32,
    chattering: bool,
    // Dimensions collapsed: 1 after an impact with e = 0, 2 after sticking.
    rank_loss: u32,
    // The slowest approach speed of the step's impacts (NO_IMPACT if none).
    slowest: real,
    // From resolve_impacts: the mass came to rest on the wall `rest_at`
    // into the step, at `rest_phase`, and stuck_step takes the rest of the
    // step from there (`y` is then meaningless).
    sticks: bool,
    rest_at: real,
    rest_phase: vec2<real>,
}

// At rest on the wall: the sticking state, X = X_w and V = 0.
fn at_rest_on(xw: real, y: State) -> bool {
    return y.x == xw && y.y == real(0.0);
}

// The acceleration at rest on the wall at `phase`: > 0 presses the mass into
// the wall.
fn pressing(p: Params, xw: real, phase: vec2<real>) -> real {
    var rest = State();
    rest.x = xw;
    return rhs(p, phase, rest).y;
}

// A step of size h from rest on the wall: the mass stays while the force
// presses it there and leaves when the force reverses (bisection for the
// release). Twin of stuck_step in src/integrate/impact.rs, except that after
// a release the rest of the step is one plain RK4 step held off the wall
// (WGSL has no recursion; the force pulls away right after a release).
fn stuck_step(p: Params, omega: real, phase: vec2<real>, h: real) -> WallStep {
    let xw = wall_position(p);
    var rest = State();
    rest.x = xw;
    if (pressing(p, xw, phase) <= real(0.0)) {
        let free = sub_step(p, omega, phase, rest, h);
        return WallStep(clamp_to_wall(xw, free.y), 0u, false, 0u, NO_IMPACT, false, h, phase);
    }
    var out = rest;
    if (pressing(p, xw, rotate(phase, cos_sin(omega * h))) <= real(0.0)) {
        var lo = real(0.0);
        var hi = h;
        for (var k = 0u; k < 64u; k = k + 1u) {
            let mid = real(0.5) * (lo + hi);
            if (pressing(p, xw, rotate(phase, cos_sin(omega * mid))) > real(0.0)) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let release = rotate(phase, cos_sin(omega * hi));
        out = clamp_to_wall(xw, sub_step(p, omega, release, rest, h - hi).y);
    }
    return WallStep(out, 0u, false, DIM, NO_IMPACT, false, h, phase);
}

struct Hit {
    found: bool,
    s: real,
    y: State,
}

// An RK4 step of any size s from a given phase: the re-steps of impact location.
fn sub_step(p: Params, omega: real, phase: vec2<real>, y: State, s: real) -> Stepped {
    return rk4_step(p, phase, cos_sin(real(0.5) * omega * s), y, s);
}

fn clamp_to_wall(xw: real, y: State) -> State {
    var out = y;
    if (out.x > xw) {
        out.x = xw;
        out.y = min(out.y, real(0.0));
    }
    return out;
}

// Applies every impact inside the step [0, h] from (phase, y), whose plain
// RK4 image y1 reached the wall or turned back inside the step; a mass that
// comes to rest is handed back with `sticks`, and the integrate kernel's
// one call of stuck_step takes the rest of the step (every inlined copy of
// its bisection loop costs loop iterations on lavapipe, whose budget per
// invocation is small: see loop_budget_exhausted).
fn resolve_impacts(p: Params, omega: real, phase: vec2<real>, y: State, h: real, y1_plain: State) -> WallStep {
    let xw = wall_position(p);
    let e = wall_restitution(p);
    var done = real(0.0);
    var phase0 = phase;
    var y0 = y;
    var y1 = y1_plain;
    var impacts = 0u;
    var slowest = NO_IMPACT;
    // How the loop ended: 0 no further impact in the step, 1 at rest on the
    // wall (stuck_step takes the rest of the step from phase0), 2 out of
    // impacts.
    var ending = 2u;
    var rank_loss = 0u;
    for (var n = 0u; n < MAX_IMPACTS_PER_STEP; n = n + 1u) {
        let rest = h - done;
#ifdef IMPACT_LINEAR
        let hit = locate_linear(xw, y0, rest, y1);
#else
        let hit = locate_newton(p, omega, xw, phase0, y0, rest, y1);
#endif
        if (!hit.found) {
            ending = 0u;
            break;
        }
        let phase_c = rotate(phase0, cos_sin(omega * hit.s));
        var yc = hit.y;
        if (yc.y <= real(0.0)) {
            // Arriving at rest, pressed into the wall: it sticks.
            done = done + hit.s;
            phase0 = phase_c;
            ending = 1u;
            break;
        }
        impacts = impacts + 1u;
        slowest = min(slowest, yc.y);
        let rebound = e * yc.y;
        let push = pressing(p, xw, phase_c);
        done = done + hit.s;
        phase0 = phase_c;
        // e = 0 stops the mass dead; bounces that would accumulate within a
        // sliver of the step (2v/(a(1 - e)) in all) end at rest as well.
        if (rebound == real(0.0) || (push > real(0.0) && real(2.0) * rebound < real(ACCUMULATION_FRACTION) * h * push * (real(1.0) - e))) {
            rank_loss = 1u;
            ending = 1u;
            break;
        }
        yc.x = xw;
        yc.y = -rebound;
        y0 = yc;
        y1 = sub_step(p, omega, phase0, y0, h - done).y;
    }
    if (ending == 2u && y0.x == xw && pressing(p, xw, phase0) > real(0.0)) {
        // Bounces this dense under a pressing force: the mass is at rest.
        ending = 1u;
    }
    if (ending == 1u) {
        return WallStep(y0, impacts, false, rank_loss, slowest, true, done, phase0);
    }
    if (ending == 0u) {
        return WallStep(y1, impacts, false, rank_loss, slowest, false, h, phase0);
    }
    return WallStep(clamp_to_wall(xw, y1), impacts, true, rank_loss, slowest, false, h, phase0);
}

#ifdef IMPACT_LINEAR
// The paper's location: linear interpolation between the step's ends.
fn locate_linear(xw: real, y0: State, h: real, y1: State) -> Hit {
    if (y1.x <= xw) {
        return Hit(false, real(0.0), y0);
    }
    let theta = clamp((xw - y0.x) / (y1.x - y0.x), real(0.0), real(1.0));
    return Hit(true, theta * h, y0 + theta * (y1 - y0));
}

#else
// Re-steps RK4 to the impact (Newton from the Hermite root), so the impact
// lies on the RK4 solution itself; also finds an excursion past the wall
// between the step's ends.
fn locate_newton(p: Params, omega: real, xw: real, phase0: vec2<real>, y0: State, h: real, y1: State) -> Hit {
    let herm = hermite_new(y0.x - xw, y0.y, y1.x - xw, y1.y, h);
    var hi: real;
    var guess: real;
    if (y1.x > xw) {
        hi = h;
        guess = hermite_first_root(herm, real(0.0), real(1.0));
    } else if (y0.y > real(0.0) && y1.y < real(0.0)) {
        let peak = hermite_peak(herm);
        if (peak < real(0.0)) {
            return Hit(false, real(0.0), y0);
        }
        if (sub_step(p, omega, phase0, y0, peak * h).y.x <= xw) {
            return Hit(false, real(0.0), y0);
        }
        hi = peak * h;
        guess = hermite_first_root(herm, real(0.0), peak);
    } else {
        return Hit(false, real(0.0), y0);
    }
    // Safeguarded Newton on g(s) = X(RK4(y0, s)) - X_w, g'(s) ≈ V(s), in [0, hi].
    let tolerance = real(4.0) * EPSILON * max(abs(xw), real(1.0));
    var lo = real(0.0);
    var s = guess * h;
    var y = sub_step(p, omega, phase0, y0, s).y;
    for (var k = 0u; k < 32u; k = k + 1u) {
        let g = y.x - xw;
        if (abs(g) <= tolerance) {
            break;
        }
        if (g > real(0.0)) {
            hi = s;
        } else {
            lo = s;
        }
        let newton = s - g / y.y;
        if (newton > lo && newton < hi) {
            s = newton;
        } else {
            s = real(0.5) * (lo + hi);
        }
        if (hi - lo <= EPSILON * abs(hi)) {
            break;
        }
        y = sub_step(p, omega, phase0, y0, s).y;
    }
    return Hit(true, s, y);
}

// The cubic Hermite interpolant of g = X - X_w over the step, θ in [0, 1]:
// g(θ) = c0 + c1 θ + c2 θ² + c3 θ³.
fn hermite_new(g0: real, v0: real, g1: real, v1: real, h: real) -> vec4<real> {
    let d0 = v0 * h;
    let d1 = v1 * h;
    let c2 = real(3.0) * (g1 - g0) - real(2.0) * d0 - d1;
    let c3 = real(2.0) * (g0 - g1) + d0 + d1;
    return vec4<real>(g0, d0, c2, c3);
}

fn hermite_value(c: vec4<real>, th: real) -> real {
    return c.x + th * (c.y + th * (c.z + th * c.w));
}

fn hermite_slope(c: vec4<real>, th: real) -> real {
    return c.y + th * (real(2.0) * c.z + th * real(3.0) * c.w);
}

// Where the slope turns from positive to negative inside (0, 1), or -1:
// safeguarded Newton from the midpoint, twin of Hermite::peak.
fn hermite_peak(c: vec4<real>) -> real {
    var a = real(0.0);
    var b = real(1.0);
    if (!(hermite_slope(c, a) > real(0.0) && hermite_slope(c, b) < real(0.0))) {
        return real(-1.0);
    }
    var th = real(0.5);
    for (var k = 0u; k < 64u; k = k + 1u) {
        let g = hermite_slope(c, th);
        if (g > real(0.0)) {
            a = th;
        } else {
            b = th;
        }
        let curvature = real(2.0) * c.z + real(6.0) * c.w * th;
        var next = th - g / curvature;
        if (!(next > a && next < b)) {
            next = real(0.5) * (a + b);
        }
        if (next == th) {
            break;
        }
        th = next;
    }
    return th;
}

// The first upward root of the cubic in [a, b]: Newton's starting guess.
fn hermite_first_root(c: vec4<real>, a_in: real, b_in: real) -> real {
    var a = a_in;
    var b = b_in;
    let ga = hermite_value(c, a);
    let gb = hermite_value(c, b);
    var th = a + (b - a) * clamp(-ga / (gb - ga), real(0.0), real(1.0));
    for (var k = 0u; k < 8u; k = k + 1u) {
        let g = hermite_value(c, th);
        if (g > real(0.0)) {
            b = th;
        } else {
            a = th;
        }
        let next = th - g / hermite_slope(c, th);
        if (next > a && next < b) {
            th = next;
        } else {
            th = real(0.5) * (a + b);
        }
    }
    return th;
}
#endif
