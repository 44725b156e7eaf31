// The seed paper's impact oscillator, twin of src/system/impact_oscillator.rs:
// X'' = -2ζX' - X + f·cos(ητ), rigid wall at X = X_w, X' -> -e·X' on contact.

struct Params {
    zeta: real,
    f: real,
    wall: real,
    restitution: real,
    eta: real,
}

// X' = V, V' = -2ζV - X + f·cos(ητ), with phase = (cos ητ, sin ητ).
fn rhs(p: Params, phase: vec2<real>, y: State) -> State {
    return State(y.y, -real(2.0) * p.zeta * y.y - y.x + p.f * phase.x);
}

fn wall_position(p: Params) -> real {
    return p.wall;
}

fn wall_restitution(p: Params) -> real {
    return p.restitution;
}
