// Stops inside an RK4 step, twin of src/integrate/impact/: split the step
// at the impact, reset V -> -e·V with X = X_w exactly, integrate the rest,
// look again (several impacts per step, on one stop or several, in the
// order they happen).
//
// General surfaces (events and switches, src/integrate/surface.rs), with
// SURFACES defined, go through the same loop: located on re-stepped RK4 as
// a stop's impact is, the first crossing of the step applied (an event's
// reset, a switch's flip of the trajectory's region, or the start of a
// sliding phase on it), counted in the same crossings (event index WALLS +
// j), and the step goes on from there; a sliding motion slides the rest
// of the step, or until it leaves the switch.
//
// Stop j of WALLS (0 to 4) acts on coordinate WALL_COORDINATE[j] (its
// position X), whose rate is coordinate WALL_VELOCITY[j] (V = X'), from
// side WALL_SIDE[j]: +1 confines X <= X_w (a stop approached from below),
// -1 X >= X_w. The system file gives those constants and, per stop as the
// components of a vec4, wall_position(p) and wall_restitution(p) (the
// components past WALLS are never read).

const MAX_IMPACTS_PER_STEP: u32 = 64u;
// See ACCUMULATION_FRACTION in src/integrate/impact/hold.rs.
const ACCUMULATION_FRACTION: f32 = 1e-3;

// Twin of integrate::impact::Wall.
struct Stop {
    position: real,
    restitution: real,
    coordinate: u32,
    velocity: u32,
    side: real,
}

// Every stop's position and restitution at a lane's parameters (twin of
// walls_at in src/system/model.rs), computed once per invocation: the step
// loop does not recompute a position that is an expression of parameters.
struct Stops {
    position: vec4<real>,
    restitution: vec4<real>,
}

fn stops_of(p: Params) -> Stops {
    return Stops(wall_position(p), wall_restitution(p));
}

fn stop(walls: Stops, j: u32) -> Stop {
    return Stop(walls.position[j], walls.restitution[j], WALL_COORDINATE[j], WALL_VELOCITY[j], WALL_SIDE[j]);
}

// How far y lies beyond the stop (> 0: behind it; Wall::gap).
fn gap(w: Stop, y: State) -> real {
    return w.side * (y[w.coordinate] - w.position);
}

// The speed towards the stop (> 0: approaching; Wall::speed).
fn speed(w: Stop, y: State) -> real {
    return w.side * y[w.velocity];
}

// y moved onto the stop with approach speed v (Wall::on_wall).
fn on_stop(w: Stop, y: State, v: real) -> State {
    var out = y;
    out[w.coordinate] = w.position;
    out[w.velocity] = w.side * v;
    return out;
}

// The stop's (gap, speed) at y: the value and rate its impact is detected
// and located on, as a surface's oriented (g, rate) is.
fn stop_values(w: Stop, y: State) -> vec2<real> {
    return vec2<real>(gap(w, y), speed(w, y));
}

// Whether a step of size h from y to y1 may meet the stop (twin of
// reaches_wall): the stop test `may_meet` of the step program
// (src/model/ir/step.rs), generated, shared with the surfaces.
fn reaches(w: Stop, y: State, h: real, y1: State) -> bool {
    return may_meet(stop_values(w, y), stop_values(w, y1), h);
}

// At rest on the stop: the sticking state, X = X_w and V = 0.
fn at_rest(w: Stop, y: State) -> bool {
    return y[w.coordinate] == w.position && y[w.velocity] == real(0.0);
}

// The step loop's two tests, over every stop. Written out per stop rather
// than as a loop: WALLS is a constant, so the branches of absent stops fold
// away, and a loop inside the step loop would cost every step on lavapipe
// (docs/BENCHMARKS.md, "What lavapipe runs").
fn reaches_a_stop(walls: Stops, y: State, h: real, y1: State) -> bool {
    var hit = reaches(stop(walls, 0u), y, h, y1);
    if (WALLS > 1u) {
        hit = hit || reaches(stop(walls, 1u), y, h, y1);
    }
    if (WALLS > 2u) {
        hit = hit || reaches(stop(walls, 2u), y, h, y1);
    }
    if (WALLS > 3u) {
        hit = hit || reaches(stop(walls, 3u), y, h, y1);
    }
    return hit;
}

// The first stop y rests on, or WALLS (twin of resting_on).
fn resting_on(walls: Stops, y: State) -> u32 {
    var on = WALLS;
    if (WALLS > 3u && at_rest(stop(walls, 3u), y)) {
        on = 3u;
    }
    if (WALLS > 2u && at_rest(stop(walls, 2u), y)) {
        on = 2u;
    }
    if (WALLS > 1u && at_rest(stop(walls, 1u), y)) {
        on = 1u;
    }
    if (at_rest(stop(walls, 0u), y)) {
        on = 0u;
    }
    return on;
}

struct WallStep {
    y: State,
    impacts: u32,
    // Of these, the impacts on each stop.
    crossings: vec4<u32>,
    chattering: bool,
    // Dimensions collapsed: 1 after an impact with e = 0, 2 (all of them
    // with two states) after sticking.
    rank_loss: u32,
    // The slowest approach speed of the step's impacts (NO_IMPACT if none).
    slowest: real,
    // From resolve_impacts: the mass came to rest on stop `stuck` (WALLS:
    // it did not) `rest_at` into the step, at `rest_phase`, in the state
    // `y` (its stop's reset not applied), and stuck_step takes the rest of
    // the step from there.
    stuck: u32,
    rest_at: real,
    rest_phase: vec2<real>,
}

// The acceleration towards the stop at rest on it (y moved onto it at
// speed 0) at `phase`: > 0 presses the mass into the stop (pressing in
// impact.rs).
fn pressing(p: Params, w: Stop, phase: vec2<real>, y: State) -> real {
    return w.side * rhs(p, phase, on_stop(w, y, real(0.0)))[w.velocity];
}

// The flow with a mass held at rest on the stop (Held in
// src/integrate/impact/): its position and velocity do not move.
fn held_rhs(p: Params, w: Stop, phase: vec2<real>, y: State) -> State {
    var f = rhs(p, phase, y);
    f[w.coordinate] = real(0.0);
    f[w.velocity] = real(0.0);
    return f;
}

// The state held on the stop for s from `rest` at `phase`: `rest` itself
// with two states, else one RK4 step of the held flow for the others
// (rk4_step's arithmetic, as the CPU's rk4::step of Held).
fn held_for(p: Params, w: Stop, omega: real, phase: vec2<real>, rest: State, s: real) -> State {
    if (DIM == 2u) {
        return rest;
    }
    let half = cos_sin(real(0.5) * omega * s);
    let mid = rotate(phase, half);
    let end = rotate(mid, half);
    let h2 = real(0.5) * s;
    let k1 = held_rhs(p, w, phase, rest);
    let k2 = held_rhs(p, w, mid, rest + h2 * k1);
    let k3 = held_rhs(p, w, mid, rest + h2 * k2);
    let k4 = held_rhs(p, w, end, rest + s * k3);
    let sixth = s / real(6.0);
    return rest + sixth * (k1 + real(2.0) * (k2 + k3) + k4);
}

// A step of size h from rest on stop j (y moved onto it): the mass stays
// while the force presses it there (the other coordinates move on) and
// leaves when the force reverses (bisection for the release). Twin of
// stuck_step in src/integrate/impact/resolve.rs, except that the rest of the step
// after a release (or a free departure) is one plain RK4 step held off the
// stops (WGSL has no recursion; the force pulls away right after a release).
fn stuck_step(p: Params, walls: Stops, j: u32, omega: real, phase: vec2<real>, y: State, h: real) -> WallStep {
    let w = stop(walls, j);
    let rest = on_stop(w, y, real(0.0));
    // The plain RK4 step that ends the step, from `start` at `start_phase`
    // for `left`: of the whole step on a free departure, of its rest after
    // a release. One call site (see locate_newton).
    var start = rest;
    var start_phase = phase;
    var left = h;
    var rank_loss = 0u;
    // (The comparisons are the CPU's, negated: NaN takes the same branch.)
    if (!(pressing(p, w, phase, rest) <= real(0.0))) {
        rank_loss = min(2u, DIM);
        let held = held_for(p, w, omega, phase, rest, h);
        if (!(pressing(p, w, rotate(phase, cos_sin(omega * h)), held) <= real(0.0))) {
            return WallStep(held, 0u, vec4<u32>(), false, rank_loss, NO_IMPACT, WALLS, h, phase);
        }
        var lo = real(0.0);
        var hi = h;
        for (var k = 0u; k < 64u; k = k + 1u) {
            let mid = real(0.5) * (lo + hi);
            let at = rotate(phase, cos_sin(omega * mid));
            if (pressing(p, w, at, held_for(p, w, omega, phase, rest, mid)) > real(0.0)) {
                lo = mid;
            } else {
                hi = mid;
            }
            if (hi - lo <= EPSILON * h) {
                break;
            }
        }
        start_phase = rotate(phase, cos_sin(omega * hi));
        start = held_for(p, w, omega, phase, rest, hi);
        left = h - hi;
    }
    let out = clamp_to_stops(walls, sub_step(p, omega, start_phase, start, left).y);
    return WallStep(out, 0u, vec4<u32>(), false, rank_loss, NO_IMPACT, WALLS, h, phase);
}

struct Hit {
    found: bool,
    s: real,
    y: State,
}

// max(1, |y_i|): the size of a state, which a surface's tolerances are
// relative to (the CPU's fold over the state).
fn state_scale(y: State) -> real {
    var scale = real(1.0);
    for (var i = 0u; i < DIM; i = i + 1u) {
        scale = max(scale, abs(y[i]));
    }
    return scale;
}

// An RK4 step of any size s from a given phase: the re-steps of impact location.
fn sub_step(p: Params, omega: real, phase: vec2<real>, y: State, s: real) -> Stepped {
    return rk4_step(p, phase, cos_sin(real(0.5) * omega * s), y, s);
}

// The per-stop code below is written out per stop rather than as loops
// over them, as in the step loop's tests: a loop of one pass (the seed's
// single stop) still cost lavapipe 10% of the whole kernel's time.

// y moved back onto a stop it lies behind, moving towards it at most
// (clamp_to_wall).
fn clamp_to(w: Stop, y: State) -> State {
    if (gap(w, y) > real(0.0)) {
        return on_stop(w, y, min(speed(w, y), real(0.0)));
    }
    return y;
}

// y moved back onto every stop it lies behind, in their order.
fn clamp_to_stops(walls: Stops, y: State) -> State {
    var out = clamp_to(stop(walls, 0u), y);
    if (WALLS > 1u) {
        out = clamp_to(stop(walls, 1u), out);
    }
    if (WALLS > 2u) {
        out = clamp_to(stop(walls, 2u), out);
    }
    if (WALLS > 3u) {
        out = clamp_to(stop(walls, 3u), out);
    }
    return out;
}

// Whether y lies behind a stop (a sliding motion meeting one is flagged, as
// in the CPU's slide).
fn behind_a_stop(walls: Stops, y: State) -> bool {
    var behind = WALLS > 0u && gap(stop(walls, 0u), y) > real(0.0);
    if (WALLS > 1u) {
        behind = behind || gap(stop(walls, 1u), y) > real(0.0);
    }
    if (WALLS > 2u) {
        behind = behind || gap(stop(walls, 2u), y) > real(0.0);
    }
    if (WALLS > 3u) {
        behind = behind || gap(stop(walls, 3u), y) > real(0.0);
    }
    return behind;
}

// The first stop y lies on with a force pressing it there, or WALLS.
fn pressed_on(p: Params, walls: Stops, phase: vec2<real>, y: State) -> u32 {
    var on = WALLS;
    if (WALLS > 3u && pressed(p, stop(walls, 3u), phase, y)) {
        on = 3u;
    }
    if (WALLS > 2u && pressed(p, stop(walls, 2u), phase, y)) {
        on = 2u;
    }
    if (WALLS > 1u && pressed(p, stop(walls, 1u), phase, y)) {
        on = 1u;
    }
    if (pressed(p, stop(walls, 0u), phase, y)) {
        on = 0u;
    }
    return on;
}

fn pressed(p: Params, w: Stop, phase: vec2<real>, y: State) -> bool {
    return y[w.coordinate] == w.position && pressing(p, w, phase, y) > real(0.0);
}

// Event `which`'s crossing in the rest of a step [0, h] from (phase0, y0)
// to y1, if any, given its value and rate at both ends (`start`, `end`).
// Events are numbered as first_met's: the stops, then the general surfaces
// (which - WALLS); stops and surfaces share every location below, and only
// event_at, event_scale and crossing_fraction tell them apart.
fn locate(p: Params, omega: real, walls: Stops, which: u32, phase0: vec2<real>, y0: State, h: real, y1: State, start: vec2<real>, end: vec2<real>) -> Hit {
#ifdef IMPACT_LINEAR
    return locate_linear(walls, which, y0, h, y1, start, end);
#else
    return locate_newton(p, omega, walls, which, phase0, y0, h, y1, start, end);
#endif
}

// Stop j's impact in the rest of a step, if any (the stops' call of
// locate_linear or locate_newton in impact.rs's resolve).
fn locate_stop(p: Params, omega: real, walls: Stops, j: u32, phase0: vec2<real>, y0: State, h: real, y1: State) -> Hit {
    let w = stop(walls, j);
    return locate(p, omega, walls, j, phase0, y0, h, y1, stop_values(w, y0), stop_values(w, y1));
}

// The first stop (or surface) met, and where.
struct Met {
    hit: Hit,
    stop: u32,
}

// Event indices: the stops, then the general surfaces; NONE_MET is none.
#ifdef SURFACES
const NONE_MET: u32 = WALLS + SURFACES;
#else
const NONE_MET: u32 = WALLS;
#endif

// `met`, or event j's hit if found earlier (on a tie the lower index, as on
// the CPU).
fn earlier(met: Met, found: Hit, j: u32) -> Met {
    if (found.found && (met.stop == NONE_MET || found.s < met.hit.s)) {
        return Met(found, j);
    }
    return met;
}

// The first stop or surface met in the step [0, h] from (phase0, y0) to y1
// (NONE_MET: none): the search for the earliest event in resolve.
fn first_met(p: Params, walls: Stops, omega: real, phase0: vec2<real>, y0: State, h: real, y1: State) -> Met {
    var met = Met(Hit(false, real(0.0), y0), NONE_MET);
    if (WALLS > 0u) {
        met = earlier(met, locate_stop(p, omega, walls, 0u, phase0, y0, h, y1), 0u);
    }
    if (WALLS > 1u) {
        met = earlier(met, locate_stop(p, omega, walls, 1u, phase0, y0, h, y1), 1u);
    }
    if (WALLS > 2u) {
        met = earlier(met, locate_stop(p, omega, walls, 2u, phase0, y0, h, y1), 2u);
    }
    if (WALLS > 3u) {
        met = earlier(met, locate_stop(p, omega, walls, 3u, phase0, y0, h, y1), 3u);
    }
#ifdef SURFACES
    // The surfaces' values at both ends of the rest of the step, in the
    // trajectory's region (a surface may move with the forcing).
    let before = surface_values(p, phase0, y0);
    let after = surface_values(p, rotate(phase0, cos_sin(omega * h)), y1);
    met = earlier(met, locate_surface(p, omega, walls, 0u, phase0, y0, h, y1, before, after), WALLS);
    if (SURFACES > 1u) {
        met = earlier(met, locate_surface(p, omega, walls, 1u, phase0, y0, h, y1, before, after), WALLS + 1u);
    }
    if (SURFACES > 2u) {
        met = earlier(met, locate_surface(p, omega, walls, 2u, phase0, y0, h, y1, before, after), WALLS + 2u);
    }
    if (SURFACES > 3u) {
        met = earlier(met, locate_surface(p, omega, walls, 3u, phase0, y0, h, y1, before, after), WALLS + 3u);
    }
#endif
    return met;
}

// resolve_impacts' account of its step so far (the locals of the CPU's
// resolve): how far into the step its events reach, the phase and state
// there, and what they did.
struct Resolution {
    done: real,
    phase0: vec2<real>,
    y0: State,
    impacts: u32,
    crossings: vec4<u32>,
    slowest: real,
    rank_loss: u32,
    // The mass came to rest on this stop (WALLS: it did not).
    stuck: u32,
    // The rest of the step from (phase0, y0) is to be stepped, at the top
    // of the next pass.
    restep: bool,
#ifdef SURFACES
    // A crossing flagged unresolved ends the step once its rest is taken;
    // whether it was a chattering one.
    unresolved: bool,
    chattering: bool,
#endif
}

// Applies every impact inside the step [0, h] from (phase, y), whose plain
// RK4 image y1 reached a stop or turned back inside the step; a mass that
// comes to rest is handed back with `stuck`, and the integrate kernel's
// one call of stuck_step takes the rest of the step (every inlined copy of
// its bisection loop costs loop iterations on lavapipe, whose budget per
// invocation is small: see loop_budget_exhausted). The loop of the CPU's
// resolve: each pass finds the first event and hands it to impact or
// cross_surface, or slides on a switch (slide).
#ifdef SURFACES
fn resolve_impacts(p_lane: Params, walls: Stops, omega: real, phase: vec2<real>, y: State, h: real, y1_plain: State) -> WallStep {
    // A copy, whose region follows the crossings.
    var p = p_lane;
#else
fn resolve_impacts(p: Params, walls: Stops, omega: real, phase: vec2<real>, y: State, h: real, y1_plain: State) -> WallStep {
#endif
#ifdef SURFACES
    var r = Resolution(real(0.0), phase, y, 0u, vec4<u32>(), NO_IMPACT, 0u, WALLS, false, false, false);
#else
    var r = Resolution(real(0.0), phase, y, 0u, vec4<u32>(), NO_IMPACT, 0u, WALLS, false);
#endif
    var y1 = y1_plain;
    // How the loop ended: 0 no further impact in the step, 1 at rest on
    // stop r.stuck (stuck_step takes the rest of the step from r.phase0),
    // 2 out of impacts.
    var ending = 2u;
    for (var n = 0u; n <= MAX_IMPACTS_PER_STEP; n = n + 1u) {
        // The rest of the step from (phase0, y0) is stepped in one place:
        // NIR inlines every call, and each call site of sub_step is a copy
        // of the RK4 step (a kernel with switches had four here). The
        // extra pass only steps, so that the last event's rest of the step
        // is taken as before the loop ran out.
        if (r.restep) {
            y1 = sub_step(p, omega, r.phase0, r.y0, h - r.done).y;
            r.restep = false;
        }
#ifdef SURFACES
        if (r.unresolved) {
            return WallStep(y1, r.impacts, r.crossings, r.chattering, r.rank_loss, r.slowest, WALLS, h, r.phase0);
        }
#endif
        if (n == MAX_IMPACTS_PER_STEP) {
            break;
        }
#ifdef SURFACES
        if (is_sliding(p.region)) {
            // On a switch: the rest of the step slides, unless the motion
            // leaves it (twin of the sliding branch of resolve).
            let slid = slide(p, omega, r.phase0, r.y0, h - r.done);
            crossed.sliding = crossed.sliding || slid.flagged;
            if (!slid.leaves) {
                return WallStep(slid.y, r.impacts, r.crossings, false, r.rank_loss, r.slowest, WALLS, h, r.phase0);
            }
            r.done = r.done + slid.s;
            r.phase0 = rotate(r.phase0, cos_sin(omega * slid.s));
            r.y0 = slid.y;
            p.region = slid.region;
            crossed.region = slid.region;
            r.restep = true;
            continue;
        }
#endif
        let met = first_met(p, walls, omega, r.phase0, r.y0, h - r.done, y1);
        if (met.stop == NONE_MET) {
            ending = 0u;
            break;
        }
#ifdef SURFACES
        if (met.stop >= WALLS) {
            r = cross_surface(p, omega, met, r);
            p.region = crossed.region;
            continue;
        }
#endif
        r = impact(p, walls, omega, met, h, r);
        if (r.stuck < WALLS) {
            ending = 1u;
            break;
        }
#ifdef SURFACES
        // The rebound may jump across a switch (a velocity reversed across
        // a friction's slip): the field after it is that side's.
        p.region = jumped(p, r.phase0, met.hit.y, r.y0);
        crossed.region = p.region;
#endif
    }
    return resolved(p, walls, h, y1, r, ending);
}

// Stop met.stop's impact at met.hit (the stop branch of resolve): the mass
// arriving at rest, or with bounces accumulating, stays on the stop
// (r.stuck); else it rebounds, V -> -e·V, and the rest of the step is
// stepped again.
fn impact(p: Params, walls: Stops, omega: real, met: Met, h: real, r_in: Resolution) -> Resolution {
    var r = r_in;
    let w = stop(walls, met.stop);
    let phase_c = rotate(r.phase0, cos_sin(omega * met.hit.s));
    let v = speed(w, met.hit.y);
    r.done = r.done + met.hit.s;
    r.phase0 = phase_c;
    if (v <= real(0.0)) {
        // Arriving at rest, pressed into the stop: it sticks.
        r.y0 = met.hit.y;
        r.stuck = met.stop;
        return r;
    }
    r.impacts = r.impacts + 1u;
    r.crossings[met.stop] = r.crossings[met.stop] + 1u;
    r.slowest = min(r.slowest, v);
    let e = w.restitution;
    let rebound = e * v;
    let push = pressing(p, w, phase_c, met.hit.y);
    // e = 0 stops the mass dead; bounces that would accumulate within a
    // sliver of the step (2v/(a(1 - e)) in all) end at rest as well.
    if (rebound == real(0.0) || (push > real(0.0) && real(2.0) * rebound < real(ACCUMULATION_FRACTION) * h * push * (real(1.0) - e))) {
        r.rank_loss = 1u;
        r.y0 = met.hit.y;
        r.stuck = met.stop;
        return r;
    }
    r.y0 = on_stop(w, met.hit.y, -rebound);
    r.restep = true;
    return r;
}

// The step's outcome once resolve_impacts' loop has ended (`ending` as
// there): at rest on a stop, with the rest of the step to stuck_step; at
// y1 after the last event; or, out of impacts, at rest if a force presses
// the mass onto a stop, else chattering, clamped to the stops.
fn resolved(p: Params, walls: Stops, h: real, y1: State, r: Resolution, ending_in: u32) -> WallStep {
    var ending = ending_in;
    var stuck = r.stuck;
    if (ending == 2u) {
        // Bounces this dense under a pressing force: the mass is at rest.
        stuck = pressed_on(p, walls, r.phase0, r.y0);
        if (stuck < WALLS) {
            ending = 1u;
        }
    }
    if (ending == 1u) {
        return WallStep(r.y0, r.impacts, r.crossings, false, r.rank_loss, r.slowest, stuck, r.done, r.phase0);
    }
    if (ending == 0u) {
        return WallStep(y1, r.impacts, r.crossings, false, r.rank_loss, r.slowest, WALLS, h, r.phase0);
    }
    return WallStep(clamp_to_stops(walls, y1), r.impacts, r.crossings, true, r.rank_loss, r.slowest, WALLS, h, r.phase0);
}

#ifdef IMPACT_LINEAR
// The paper's location: linear interpolation between the step's ends, for
// a stop (locate_linear in impact.rs) or a surface (the linear branch of
// `locate` there).
fn locate_linear(walls: Stops, which: u32, y0: State, h: real, y1: State, start: vec2<real>, end: vec2<real>) -> Hit {
    if (end.x <= real(0.0)) {
        return Hit(false, real(0.0), y0);
    }
    let theta = clamp(crossing_fraction(walls, which, y0, y1, start, end), real(0.0), real(1.0));
    return Hit(true, theta * h, y0 + theta * (y1 - y0));
}

// Where the straight line from y0 to y1 crosses event `which`, as a
// fraction of the step: a stop's from its coordinate and position, a
// surface's from its values at the ends (each as its twin computes it).
fn crossing_fraction(walls: Stops, which: u32, y0: State, y1: State, start: vec2<real>, end: vec2<real>) -> real {
    if (which < WALLS) {
        let w = stop(walls, which);
        let c = w.coordinate;
        return (w.position - y0[c]) / (y1[c] - y0[c]);
    }
    return -start.x / (end.x - start.x);
}

#else
// Re-steps RK4 to the crossing (Newton from the Hermite root), so that it
// lies on the RK4 solution itself; also finds an excursion across between
// the step's ends. The CPU's locate_newton (stops), `locate` (surfaces)
// and newton_from, the same steps in the same order, written once for
// both, with every re-step in one place: NIR inlines every call, and each
// call site of sub_step is a copy of the RK4 step and its right-hand sides
// in the compiled kernel (three call sites here cost lavapipe a quarter of
// the wall kernel's compile time).

// The safeguarded Newton of locate_newton (newton_in_bracket in
// impact.rs): s in the bracket [lo, hi] of the step, hi at the step's end
// or the Hermite peak of an excursion that turns back.
struct Bracket {
    found: bool,
    at_peak: bool,
    lo: real,
    hi: real,
    s: real,
}

// The bracket of a step whose function goes from start to end (value,
// rate), with the Hermite interpolant's first root as the first guess; not
// found where the step cannot cross (the interpolant's peak short of 0).
fn bracket_of(start: vec2<real>, end: vec2<real>, h: real) -> Bracket {
    let herm = hermite_new(start.x, start.y, end.x, end.y, h);
    if (end.x > real(0.0)) {
        return Bracket(true, false, real(0.0), h, hermite_first_root(herm, real(0.0), real(1.0)) * h);
    }
    if (start.y > real(0.0) && end.y < real(0.0)) {
        let peak = hermite_peak(herm);
        // (Written so that a NaN peak counts as found, as the CPU's does.)
        if (!(peak < real(0.0))) {
            return Bracket(true, true, real(0.0), peak * h, hermite_first_root(herm, real(0.0), peak) * h);
        }
    }
    return Bracket(false, false, real(0.0), real(0.0), real(0.0));
}

// One update from the function's value g and rate at b.s: the bracket
// shrinks to the side of the root, and s moves by Newton where that stays
// inside, else to the middle.
fn newton_update(b: Bracket, g: real, rate: real) -> Bracket {
    var out = b;
    if (g > real(0.0)) {
        out.hi = b.s;
    } else {
        out.lo = b.s;
    }
    let newton = b.s - g / rate;
    if (newton > out.lo && newton < out.hi) {
        out.s = newton;
    } else {
        out.s = real(0.5) * (out.lo + out.hi);
    }
    return out;
}

// Event `which`'s crossing (see `locate`) by Newton on re-stepped RK4.
fn locate_newton(p: Params, omega: real, walls: Stops, which: u32, phase0: vec2<real>, y0: State, h: real, y1: State, start: vec2<real>, end: vec2<real>) -> Hit {
    let fine = event_scale(walls, which, y0);
    // A step the stop test rules out has no crossing (the CPU's resolve
    // locates only the events that test lets through).
    if (!may_meet(start, end, h)) {
        return Hit(false, real(0.0), y0);
    }
    // Turning back inside the step: the first re-step, to the Hermite
    // peak, decides whether the excursion crosses.
    var b = bracket_of(start, end, h);
    if (!b.found) {
        return Hit(false, real(0.0), y0);
    }
    var at_peak = b.at_peak;
    // Safeguarded Newton on g(s) = the event's value at RK4(y0, s), g'(s)
    // ≈ its rate, in the bracket: the step to s, then (at most 32 times) a
    // Newton update and the step to the new s.
    let tolerance = real(4.0) * EPSILON * max(abs(fine.x), real(1.0));
    var to = select(b.s, b.hi, at_peak);
    var y = y0;
    var updates = 0u;
    loop {
        y = sub_step(p, omega, phase0, y0, to).y;
        if (at_peak) {
            if (event_at(p, omega, walls, which, phase0, to, y).x <= fine.y) {
                return Hit(false, real(0.0), y0);
            }
            at_peak = false;
            to = b.s;
            continue;
        }
        if (updates == 32u) {
            break;
        }
        updates = updates + 1u;
        let v = event_at(p, omega, walls, which, phase0, b.s, y);
        if (abs(v.x) <= tolerance) {
            break;
        }
        b = newton_update(b, v.x, v.y);
        if (b.hi - b.lo <= EPSILON * abs(b.hi)) {
            // As the CPU: s updated, y the last step's.
            break;
        }
        to = b.s;
    }
    return Hit(true, b.s, y);
}

// Event `which`'s value and rate at y, s into the step from phase0: a
// stop's (gap, speed), a surface's oriented (g, rate) (the CPU's
// `distance` and `rate` closures of locate and locate_newton).
fn event_at(p: Params, omega: real, walls: Stops, which: u32, phase0: vec2<real>, s: real, y: State) -> vec2<real> {
#ifdef SURFACES
    if (which >= WALLS) {
        return surface_at(p, omega, which - WALLS, phase0, s, y);
    }
#endif
    return stop_values(stop(walls, which), y);
}

// How finely event `which` is located from the step's start y0: the size
// its value is resolved to 4 ulp of (x), and how far past it an excursion
// must reach to cross (y). A stop: its position, and any depth > 0 (the
// CPU's locate_newton); a surface: the state's size, and more than the
// tolerance itself, shallower being a touch in rounding (its `locate`).
fn event_scale(walls: Stops, which: u32, y0: State) -> vec2<real> {
#ifdef SURFACES
    if (which >= WALLS) {
        let scale = state_scale(y0);
        return vec2<real>(scale, real(4.0) * EPSILON * scale);
    }
#endif
    return vec2<real>(walls.position[which], real(0.0));
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
// the quadratic slope's one root there in closed form, twin of
// Hermite::peak (which says why not Newton).
fn hermite_peak(c: vec4<real>) -> real {
    if (!(hermite_slope(c, real(0.0)) > real(0.0) && hermite_slope(c, real(1.0)) < real(0.0))) {
        return real(-1.0);
    }
    let a = real(3.0) * c.w;
    let b = real(2.0) * c.z;
    let root = sqrt(max(b * b - real(4.0) * a * c.y, real(0.0)));
    var th: real;
    if (b >= real(0.0)) {
        th = real(-0.5) * (b + root) / a;
    } else {
        th = c.y / (real(-0.5) * (b - root));
    }
    return clamp(th, real(0.0), real(1.0));
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
// lo + α(hi - lo), and the stick margins (L - m, L + m), m = (a + b)/2, L
// the stick limit or the half jump (a - b)/2.
struct Equivalent {
    field: State,
    alpha: real,
    margins: vec2<real>,
}

fn equivalent(p: Params, phase: vec2<real>, y: State) -> Equivalent {
    let s = switch_sides(p, firstTrailingBit(p.region >> SLIDING_SHIFT), phase, y);
    let alpha = s.a / (s.a - s.b);
    return Equivalent(s.lo + alpha * (s.hi - s.lo), alpha, s.margins);
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
                let o = orientation(sides.region, k);
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

// +1 where the crossing to watch for is g rising through 0 (an event, or a
// switch on its negative side), -1 where it is g falling (Surface::orientation).
fn orientation(region: u32, j: u32) -> real {
    let bit = SURFACE_BIT[j];
    if (bit != EVENT && ((region >> bit) & 1u) == 1u) {
        return real(-1.0);
    }
    return real(1.0);
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
// leaving inside it within reach of the surface (surface::may_cross).
fn may_cross(region: u32, j: u32, before: SurfaceValues, after: SurfaceValues, h: real) -> bool {
    return may_meet(oriented(region, j, before), oriented(region, j, after), h);
}

// Surface j's (g, rate) in values v, oriented so that > 0 lies across it
// for a trajectory in `region`: the value and rate its crossing is
// detected and located on, as a stop's (gap, speed) is.
fn oriented(region: u32, j: u32, v: SurfaceValues) -> vec2<real> {
    return orientation(region, j) * vec2<real>(v.g[j], v.rate[j]);
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
    var out = Crossing(false, y, p.region, real(0.0), true, orientation(p.region, j) * approach_rate, false, false, false, false);
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
