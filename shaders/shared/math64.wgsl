// f64 transcendental functions from arithmetic alone. WGSL's sin, cos,
// exp, log and pow compile on f64 but return garbage under Vulkan
// (GLSL.std.450 defines them for 16- and 32-bit floats only; see
// ../shared/NOTES-gpu.md), so generated model kernels call these instead.
// Only + - * /, sqrt, abs, floor, round, select and comparisons are used,
// all defined on f64. Each is within a few ulp of Rust's over the ranges
// tests/math64.rs sweeps (ωt in one period and well beyond it, exp over its
// whole range).

// 2^k, exactly, for |k| ≤ 1074 (binary powering; every product is a power
// of two).
fn pow2i_64(k: i32) -> f64 {
    var base = select(f64(2.0), f64(0.5), k < 0);
    var n = abs(k);
    var result = f64(1.0);
    for (var i = 0; i < 11 && n > 0; i = i + 1) {
        if ((n & 1) != 0) {
            result = result * base;
        }
        base = base * base;
        n = n >> 1u;
    }
    return result;
}

// ∞ and NaN, made at run time (as constant expressions they would be
// shader-creation errors).
fn inf64() -> f64 {
    var big = f64(1.0e308);
    return big * f64(10.0);
}

fn nan64() -> f64 {
    var zero = f64(0.0);
    return zero / zero;
}

const LN2_HI_64: f64 = 6.93147180369123816490e-01lf;
const LN2_LO_64: f64 = 1.90821492927058770002e-10lf;
const INV_LN2_64: f64 = 1.44269504088896338700e+00lf;

// e^x: x = k·ln 2 + r with |r| ≤ ln 2 / 2 (Cody-Waite, ln 2 in two parts),
// e^r by its Taylor series to r^13 (error below 1e-17), times 2^k.
fn exp64(x: f64) -> f64 {
    if (x > f64(709.782712893384)) {
        return inf64();
    }
    if (x < f64(-745.1332191019412)) {
        return f64(0.0);
    }
    let k = round(x * INV_LN2_64);
    // k·LN2_HI and x - k·LN2_HI are exact; fma keeps a driver from folding
    // the two constants into one rounded ln 2 (see cos_sin64).
    let r = fma(-k, LN2_HI_64, x) - k * LN2_LO_64;
    var p = f64(1.0);
    for (var n = 13; n >= 1; n = n - 1) {
        p = f64(1.0) + r * p / f64(n);
    }
    // Two factors, so that 2^k itself never overflows or underflows.
    let ki = i32(k);
    let half = ki / 2;
    return p * pow2i_64(half) * pow2i_64(ki - half);
}

// ln x: x = m·2^e with m in [√½, √2), ln m = 2·atanh(s), s = (m-1)/(m+1),
// |s| ≤ 0.172, by its series to s^31. (A device that flushes subnormals to
// zero, as lavapipe does, gives -∞ for a subnormal x.)
fn log64(x: f64) -> f64 {
    if (!(x > f64(0.0))) {
        return select(nan64(), -inf64(), x == f64(0.0));
    }
    if (x > f64(1.7976931348623157e308)) {
        return x;
    }
    var m = x;
    var e = 0;
    // Binary search of the exponent, each scaling exact.
    for (var b = 512; b >= 1; b = b / 2) {
        let up = pow2i_64(b);
        if (m >= up) {
            m = m / up;
            e = e + b;
        }
        if (m * up < f64(1.0)) {
            m = m * up;
            e = e - b;
        }
    }
    // Now 1 ≤ m < 2 (subnormals took the downward steps twice over).
    if (m < f64(1.0)) {
        m = m * f64(2.0);
        e = e - 1;
    }
    if (m > f64(1.4142135623730951)) {
        m = m * f64(0.5);
        e = e + 1;
    }
    let s = (m - f64(1.0)) / (m + f64(1.0));
    let s2 = s * s;
    var series = f64(0.0);
    for (var n = 31; n >= 1; n = n - 2) {
        series = f64(1.0) / f64(n) + s2 * series;
    }
    let fe = f64(e);
    // fe·LN2_HI is exact: as fma, a driver cannot fold it with fe·LN2_LO.
    return fma(fe, LN2_HI_64, f64(2.0) * s * series + fe * LN2_LO_64);
}

// π/2 in three parts of 33, 33 and 53 bits (Cody-Waite, as in fdlibm):
// k·PIO2_1 and k·PIO2_2 are exact for |k| < 2^20.
const PIO2_1_64: f64 = 1.57079632673412561417e+00lf;
const PIO2_2_64: f64 = 6.07710050630396597660e-11lf;
const PIO2_3_64: f64 = 2.02226624879595063154e-21lf;
const TWO_OVER_PI_64: f64 = 6.36619772367581382433e-01lf;

// fdlibm's kernels of sin and cos on |r| ≤ π/4 (k_sin.c, k_cos.c; Sun
// Microsystems, freely usable): minimax polynomials of degree 13 and 14.
const SIN1_64: f64 = -1.66666666666666324348e-01lf;
const SIN2_64: f64 = 8.33333333332248946124e-03lf;
const SIN3_64: f64 = -1.98412698298579493134e-04lf;
const SIN4_64: f64 = 2.75573137070700676789e-06lf;
const SIN5_64: f64 = -2.50507602534068634195e-08lf;
const SIN6_64: f64 = 1.58969099521155010221e-10lf;
const COS1_64: f64 = 4.16666666666666019037e-02lf;
const COS2_64: f64 = -1.38888888888741095749e-03lf;
const COS3_64: f64 = 2.48015872894767294178e-05lf;
const COS4_64: f64 = -2.75573143513906633035e-07lf;
const COS5_64: f64 = 2.08757232129817482790e-09lf;
const COS6_64: f64 = -1.13596475577881948265e-11lf;

// (cos x, sin x): x = k·π/2 + r with |r| ≤ π/4, fdlibm's kernels at r
// (without its correction for |r| > 0.3 in cos, which costs a fraction of
// an ulp), rotated by k quarter turns. The CPU's twin
// (src/model/math64.rs) makes the same operations in the same order, so
// that a model's sin θ, which the finite differences amplify by 1/δ, has
// the same bits on both paths (on lavapipe, tests/math64.rs; a driver
// that fuses a multiply-add of the polynomials differs by an ulp: NVIDIA's
// on an H100 did at 1 to 2% of the inputs).
// Accurate while |x| < 2^20·π/2 (ωt over about 10^5 periods).
fn cos_sin64(x: f64) -> vec2<f64> {
    let k = round(x * TWO_OVER_PI_64);
    // The first two steps are exact (Cody-Waite), and written as fma so
    // that no driver can fold them: NVIDIA's (H100, Vulkan) once turned
    // (x - k·P1) - k·P2 into x - k·(P1 + P2), π/2 rounded, and sin near π
    // came out 3304 ulp off. An exact product and one rounded difference
    // is what fma computes too, so the CPU's twin keeps its plain form.
    let r = fma(-k, PIO2_2_64, fma(-k, PIO2_1_64, x)) - k * PIO2_3_64;
    let z = r * r;
    let ps = SIN2_64 + z * (SIN3_64 + z * (SIN4_64 + z * (SIN5_64 + z * SIN6_64)));
    let s = r + (z * r) * (SIN1_64 + z * ps);
    let pc = z * (COS1_64 + z * (COS2_64 + z * (COS3_64 + z * (COS4_64 + z * (COS5_64 + z * COS6_64)))));
    let c = f64(1.0) - (f64(0.5) * z - z * pc);
    let q = i32(k - f64(4.0) * floor(k * f64(0.25)));
    if (q == 0) {
        return vec2<f64>(c, s);
    }
    if (q == 1) {
        return vec2<f64>(-s, c);
    }
    if (q == 2) {
        return vec2<f64>(-c, -s);
    }
    return vec2<f64>(s, -c);
}

fn sin64(x: f64) -> f64 {
    return cos_sin64(x).y;
}

fn cos64(x: f64) -> f64 {
    return cos_sin64(x).x;
}

fn tan64(x: f64) -> f64 {
    let cs = cos_sin64(x);
    return cs.y / cs.x;
}

fn tanh64(x: f64) -> f64 {
    let a = abs(x);
    var t: f64;
    if (a < f64(0.55)) {
        // Near 0, 1 - e^{-2a} cancels: tanh a = m/(m + 2), m = e^{2a} - 1
        // by its series (to (2a)^22/22!, below 1e-19).
        let y = f64(2.0) * a;
        var m = f64(0.0);
        for (var n = 22; n >= 1; n = n - 1) {
            m = y * (f64(1.0) + m) / f64(n);
        }
        t = m / (m + f64(2.0));
    } else {
        // 1 - 2/(e^{2a} + 1), from the side where e^{-2a} cannot overflow.
        let e = exp64(-f64(2.0) * a);
        t = (f64(1.0) - e) / (f64(1.0) + e);
    }
    return select(t, -t, x < f64(0.0));
}

// atan x: twice x → x / (1 + √(1 + x²)) (halving the angle, |x| ≤ 0.2
// after two from |x| ≤ 1), the series to x^41, the reciprocal for |x| > 1.
fn atan64(x: f64) -> f64 {
    let big = abs(x) > f64(1.0);
    var y = select(abs(x), f64(1.0) / abs(x), big);
    y = y / (f64(1.0) + sqrt(f64(1.0) + y * y));
    y = y / (f64(1.0) + sqrt(f64(1.0) + y * y));
    let y2 = y * y;
    var series = f64(0.0);
    // 1 - y²/3 + y⁴/5 - ..., from the top.
    for (var n = 41; n >= 1; n = n - 2) {
        series = f64(1.0) / f64(n) - y2 * series;
    }
    var a = f64(4.0) * y * series;
    if (big) {
        a = f64(1.5707963267948966) - a;
    }
    return select(a, -a, x < f64(0.0));
}

fn atan2_64(y: f64, x: f64) -> f64 {
    if (x > f64(0.0)) {
        return atan64(y / x);
    }
    if (x < f64(0.0)) {
        let a = atan64(y / x);
        return select(a - f64(3.141592653589793), a + f64(3.141592653589793), y >= f64(0.0));
    }
    if (y > f64(0.0)) {
        return f64(1.5707963267948966);
    }
    if (y < f64(0.0)) {
        return -f64(1.5707963267948966);
    }
    return f64(0.0);
}

// a^b for a > 0 as e^{b·ln a}; an integer b of a negative a by its parity.
fn pow64(a: f64, b: f64) -> f64 {
    if (a > f64(0.0)) {
        return exp64(b * log64(a));
    }
    if (a == f64(0.0)) {
        return select(f64(0.0), f64(1.0), b == f64(0.0));
    }
    if (b != floor(b)) {
        return nan64();
    }
    let magnitude = exp64(b * log64(-a));
    let odd = b - f64(2.0) * floor(b * f64(0.5)) != f64(0.0);
    return select(magnitude, -magnitude, odd);
}
