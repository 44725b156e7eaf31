//! The Rust twins of `shaders/shared/math64.wgsl`'s f64 functions that a
//! model's expressions call, computing the same bits as the GPU (on
//! lavapipe: tests/math64.rs): the finite differences amplify any
//! difference between the CPU's and the GPU's sin θ by 1/δ (the forced
//! pendulum's exponents differed by 2.4e-9 at δ = 1e-6 with the C
//! library's sin on the CPU, by 8e-12 with this one). Only sin, cos and
//! tan so far: the others (exp, log, tanh, atan2, pow) still differ from
//! the C library's by an ulp or so.

/// fdlibm's kernels of sin and cos on |r| ≤ π/4 (k_sin.c, k_cos.c; Sun
/// Microsystems, freely usable), math64.wgsl's `SINn_64` and `COSn_64`,
/// with fdlibm's digits as published (more than an f64 holds).
#[allow(clippy::excessive_precision)]
const SIN: [f64; 6] = [
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
];
#[allow(clippy::excessive_precision)]
const COS: [f64; 6] = [
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
];

/// π/2 in three parts of 33, 33 and 53 bits (Cody-Waite, as in fdlibm).
#[allow(clippy::excessive_precision)]
const PIO2_1: f64 = 1.57079632673412561417e+00;
#[allow(clippy::excessive_precision)]
const PIO2_2: f64 = 6.07710050630396597660e-11;
#[allow(clippy::excessive_precision)]
const PIO2_3: f64 = 2.02226624879595063154e-21;
/// 2/π, fdlibm's `invpio2` (0x3FE45F306DC9C883).
const TWO_OVER_PI: f64 = std::f64::consts::FRAC_2_PI;

/// (cos x, sin x), as `cos_sin64` of math64.wgsl, operation for operation:
/// within a few ulp of the C library's while |x| < 2^20·π/2.
pub fn cos_sin(x: f64) -> (f64, f64) {
    let k = (x * TWO_OVER_PI).round_ties_even();
    // math64.wgsl writes the first two (exact) steps as fma, which a
    // driver cannot fold: the same bits as these.
    let r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3;
    let z = r * r;
    let [s1, s2, s3, s4, s5, s6] = SIN;
    let ps = s2 + z * (s3 + z * (s4 + z * (s5 + z * s6)));
    let s = r + (z * r) * (s1 + z * ps);
    let [c1, c2, c3, c4, c5, c6] = COS;
    let pc = z * (c1 + z * (c2 + z * (c3 + z * (c4 + z * (c5 + z * c6)))));
    let c = 1.0 - (0.5 * z - z * pc);
    match (k - 4.0 * (k * 0.25).floor()) as i32 {
        0 => (c, s),
        1 => (-s, c),
        2 => (-c, -s),
        _ => (s, -c),
    }
}

pub fn sin(x: f64) -> f64 {
    cos_sin(x).1
}

pub fn cos(x: f64) -> f64 {
    cos_sin(x).0
}

/// tan x = sin x / cos x, as `tan64`.
pub fn tan(x: f64) -> f64 {
    let (c, s) = cos_sin(x);
    s / c
}

#[cfg(test)]
mod tests {
    /// Distance in units of `want`'s last place (as tests/math64.rs).
    fn ulps(got: f64, want: f64) -> f64 {
        (got - want).abs() / (want.abs().max(f64::MIN_POSITIVE) * f64::EPSILON)
    }

    /// Within the bounds tests/math64.rs holds the GPU's to (which the
    /// GPU meets by computing these very bits): sin and cos over the
    /// phases of many periods, tan away from its poles.
    #[test]
    fn sin_cos_and_tan_are_within_a_few_ulp_of_the_c_library() {
        let (mut sin, mut cos, mut tan): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for i in 0..2_000_001 {
            let x = -100.0 + i as f64 * 1e-4;
            sin = sin.max(ulps(super::sin(x), x.sin()));
            cos = cos.max(ulps(super::cos(x), x.cos()));
            if x.abs() <= 1.5 {
                tan = tan.max(ulps(super::tan(x), x.tan()));
            }
        }
        assert!(sin <= 4.0 && cos <= 4.0 && tan <= 8.0, "{sin} {cos} {tan}");
    }
}
