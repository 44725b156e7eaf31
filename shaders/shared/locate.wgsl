// Where in a step an event is crossed: linear interpolation (the paper's,
// with IMPACT_LINEAR) or RK4 re-stepped to the crossing by a safeguarded
// Newton from the Hermite root, both generated from the step program
// (src/model/ir/events.rs; twin of src/integrate/locate.rs). What the
// Newton reads of an event, a stop's or a surface's, is here.

#ifndef IMPACT_LINEAR
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
#endif
