// Where in a step an event is crossed: linear interpolation (the paper's,
// with IMPACT_LINEAR) or RK4 re-stepped to the crossing by a safeguarded
// Newton from the Hermite root. Twin of src/integrate/locate.rs.

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
