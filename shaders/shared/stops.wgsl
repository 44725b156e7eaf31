// Stops (walls) of the step loop: their positions, gaps and speeds, the
// stop test over every stop, and rest on a stop. Twin of
// src/integrate/wall.rs and the stop parts of src/integrate/impact/.
//
// Stop j of WALLS (0 to 4) acts on coordinate WALL_COORDINATE[j] (its
// position X), whose rate is coordinate WALL_VELOCITY[j] (V = X'), from
// side WALL_SIDE[j]: +1 confines X <= X_w (a stop approached from below),
// -1 X >= X_w. The system file gives those constants and, per stop as the
// components of a vec4, wall_position(p) and wall_restitution(p) (the
// components past WALLS are never read).

// Twin of integrate::impact::Wall.
struct Stop {
    position: real,
    restitution: real,
    coordinate: u32,
    velocity: u32,
    side: real,
}

// Every stop's position and restitution at a lane's parameters (twin of
// walls_at in src/model/compiled.rs), computed once per invocation: the step
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
