// The functions a generated model's system file calls (src/model/codegen/wgsl.rs),
// one name per function for both precisions. On f64 they are math64.wgsl's,
// built from arithmetic, because WGSL's transcendental builtins compile on
// f64 but return garbage under Vulkan; on f32 they are WGSL's builtins.
// abs, sqrt, min, max and sign are builtins on both and need no wrapper.

#ifdef F64
fn sin_r(x: real) -> real {
    return sin64(x);
}

fn cos_r(x: real) -> real {
    return cos64(x);
}

fn tan_r(x: real) -> real {
    return tan64(x);
}

fn exp_r(x: real) -> real {
    return exp64(x);
}

fn log_r(x: real) -> real {
    return log64(x);
}

fn tanh_r(x: real) -> real {
    return tanh64(x);
}

fn atan2_r(y: real, x: real) -> real {
    return atan2_64(y, x);
}

fn pow_r(a: real, b: real) -> real {
    return pow64(a, b);
}
#else
fn sin_r(x: real) -> real {
    return sin(x);
}

fn cos_r(x: real) -> real {
    return cos(x);
}

fn tan_r(x: real) -> real {
    return tan(x);
}

fn exp_r(x: real) -> real {
    return exp(x);
}

fn log_r(x: real) -> real {
    return log(x);
}

fn tanh_r(x: real) -> real {
    return tanh(x);
}

fn atan2_r(y: real, x: real) -> real {
    return atan2(y, x);
}

// WGSL's pow is undefined for a ≤ 0, where Rust's powf (the CPU path) is
// not: the same cases as pow64, so both precisions give x^3 of a negative x.
fn pow_r(a: real, b: real) -> real {
    if (a > real(0.0)) {
        return pow(a, b);
    }
    if (a == real(0.0)) {
        return select(real(0.0), real(1.0), b == real(0.0));
    }
    if (b != floor(b)) {
        // NaN made at run time (a constant 0/0 is a shader-creation error).
        var zero = real(0.0);
        return zero / zero;
    }
    let magnitude = pow(-a, b);
    let odd = b - real(2.0) * floor(b * real(0.5)) != real(0.0);
    return select(magnitude, -magnitude, odd);
}
#endif
