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
// The stops' functions and the location of a crossing are generated from
// the step program (src/model/ir/events.rs), reading stops.wgsl's stops
// and locate.wgsl's event values; the general surfaces and sliding are in
// surfaces.wgsl.

const MAX_IMPACTS_PER_STEP: u32 = 64u;
// See ACCUMULATION_FRACTION in src/integrate/impact/hold.rs.
const ACCUMULATION_FRACTION: f32 = 1e-3;

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

// The state held on the stop for s from `rest` at `phase`: `rest` itself
// with two states, else one RK4 step of the held flow for the others
// (held_sub_step, generated from the step program, as the CPU's rk4::step
// of Held).
fn held_for(p: Params, w: Stop, omega: real, phase: vec2<real>, rest: State, s: real) -> State {
    if (DIM == 2u) {
        return rest;
    }
    return held_sub_step(p, w, omega, phase, rest, s).y;
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

// Generated from the step program (src/model/ir/events.rs): `Hit`, a
// crossing located in a step; the held flow `held_rhs` and `pressing`,
// `pressed` and `pressed_on`; `clamp_to`, `clamp_to_stops`,
// `behind_a_stop` and `state_scale`.

// The per-stop code below is written out per stop rather than as loops
// over them, as in the step loop's tests: a loop of one pass (the seed's
// single stop) still cost lavapipe 10% of the whole kernel's time.

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
