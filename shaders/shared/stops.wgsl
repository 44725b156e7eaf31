// The lane's stops, read from the system file's tables. The stops'
// functions (`Stop`, gap, speed, the stop test over every stop, rest on a
// stop) are generated from the step program (src/model/ir/events.rs).
//
// Stop j of WALLS (0 to 4) acts on coordinate WALL_COORDINATE[j], whose
// rate is coordinate WALL_VELOCITY[j], from side WALL_SIDE[j]. The system
// file gives those constants and, per stop as the components of a vec4,
// wall_position(p) and wall_restitution(p) (the components past WALLS are
// never read).

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
