// The forcing clock: (cos ωt, sin ωt) from arithmetic alone, because WGSL's
// transcendental builtins are undefined on f64 under Vulkan. Twin of
// src/integrate/clock.rs; its rotation, `rotate`, is generated from the
// integrator's step program (src/model/ir/step.rs), with RK4.

// (cos φ, sin φ) by Taylor polynomials to φ^14 and φ^15, halving φ until
// |φ| <= 1/2 and doubling back.
fn cos_sin(angle: real) -> vec2<real> {
    var phi = angle;
    var halvings = 0u;
    while (abs(phi) > real(0.5) && halvings < 8u) {
        phi = phi * real(0.5);
        halvings = halvings + 1u;
    }
    let x2 = phi * phi;
    var c = real(1.0 / 87178291200.0);
    var s = real(1.0 / 1307674368000.0);
    for (var k = 6i; k >= 0i; k = k - 1i) {
        c = inv_factorial(u32(2 * k)) - x2 * c;
        s = inv_factorial(u32(2 * k + 1)) - x2 * s;
    }
    var result = vec2<real>(c, phi * s);
    for (var i = 0u; i < halvings; i = i + 1u) {
        result = vec2<real>(result.x * result.x - result.y * result.y, real(2.0) * result.y * result.x);
    }
    return result;
}

fn inv_factorial(n: u32) -> real {
    switch n {
        case 0u, 1u: { return real(1.0); }
        case 2u: { return real(1.0 / 2.0); }
        case 3u: { return real(1.0 / 6.0); }
        case 4u: { return real(1.0 / 24.0); }
        case 5u: { return real(1.0 / 120.0); }
        case 6u: { return real(1.0 / 720.0); }
        case 7u: { return real(1.0 / 5040.0); }
        case 8u: { return real(1.0 / 40320.0); }
        case 9u: { return real(1.0 / 362880.0); }
        case 10u: { return real(1.0 / 3628800.0); }
        case 11u: { return real(1.0 / 39916800.0); }
        case 12u: { return real(1.0 / 479001600.0); }
        default: { return real(1.0 / 6227020800.0); }
    }
}
