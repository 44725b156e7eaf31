// The Lorenz flow, twin of src/system/lorenz.rs.

struct Params {
    sigma: real,
    rho: real,
    beta: real,
    period: real,
}

fn rhs(p: Params, phase: vec2<real>, s: State) -> State {
    return State(p.sigma * (s.y - s.x), s.x * (p.rho - s.z) - s.y, s.x * s.y - p.beta * s.z);
}
