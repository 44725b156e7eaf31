// The Hénon map, twin of src/system/henon.rs: x' = 1 - a·x² + y, y' = b·x.

struct Params {
    a: real,
    b: real,
}

fn map_step(p: Params, y: State) -> State {
    return State(real(1.0) - p.a * y.x * y.x + y.y, p.b * y.x);
}
