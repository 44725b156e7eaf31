// The classical RK4 step, twin of src/integrate/rk4.rs. `half` rotates the
// forcing phase through ωh/2.

struct Stepped {
    y: State,
    phase: vec2<real>,
}

// The increment y(t + h) - y(t) of one RK4 step, and the phase at t + h;
// separate from the update so the f32 path can compensate it.
fn rk4_increment(p: Params, phase: vec2<real>, half: vec2<real>, y: State, h: real) -> Stepped {
    let mid = rotate(phase, half);
    let end = rotate(mid, half);
    let h2 = real(0.5) * h;
    let k1 = rhs(p, phase, y);
    let k2 = rhs(p, mid, y + h2 * k1);
    let k3 = rhs(p, mid, y + h2 * k2);
    let k4 = rhs(p, end, y + h * k3);
    let sixth = h / real(6.0);
    return Stepped(sixth * (k1 + real(2.0) * (k2 + k3) + k4), end);
}

fn rk4_step(p: Params, phase: vec2<real>, half: vec2<real>, y: State, h: real) -> Stepped {
    let inc = rk4_increment(p, phase, half, y, h);
    return Stepped(y + inc.y, inc.phase);
}
