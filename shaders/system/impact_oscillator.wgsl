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

// The one stop, as shared/impact.wgsl reads stops (component 0 of each):
// X (coordinate 0) stopped from below, V (coordinate 1) its velocity.
const WALLS: u32 = 1u;
const WALL_COORDINATE = vec4<u32>(0u, 0u, 0u, 0u);
const WALL_VELOCITY = vec4<u32>(1u, 0u, 0u, 0u);
const WALL_SIDE = vec4<real>(real(1.0), real(0.0), real(0.0), real(0.0));

fn wall_position(p: Params) -> vec4<real> {
    return vec4<real>(p.wall, real(0.0), real(0.0), real(0.0));
}

fn wall_restitution(p: Params) -> vec4<real> {
    return vec4<real>(p.restitution, real(0.0), real(0.0), real(0.0));
}
