//! The forcing clock: cos(ωt) and sin(ωt) from arithmetic alone.
//!
//! WGSL's transcendental builtins return garbage on f64 under Vulkan, so the
//! GPU kernels cannot call cos(ηt). Both paths therefore carry the forcing as
//! a phase (cos ωt, sin ωt), restarted at (1, 0) every map period (where the
//! stroboscopic section puts ωt ≡ 0) and advanced by exact rotations:
//! a grid step by the host-computed rotation through ωh/2 twice, a partial
//! step (to an impact) by the rotation through ωs from [`cos_sin`]. The
//! Rust here is the reference for the clock's step programs, `rotate`
//! and `cos_sin` (`model::ir::integrator`), which the kernels run
//! generated.

/// (cos ωt, sin ωt).
pub type Phase = [f64; 2];

/// The phase at t = 0.
pub const ZERO_PHASE: Phase = [1.0, 0.0];

/// The rotation through ωh/2 of a grid of `steps` steps of h per map
/// period. Where the period is a whole number m of forcing cycles (a
/// stroboscopic map, ω·steps·h = 2πm to rounding), the angle is taken as
/// exactly πm/steps: ω·h/2 rounds differently for every ω of a sweep, and
/// with this every lane turns its phase through the same bits, so lanes
/// stepped together in lockstep share one phase (`library::Native::walk`)
/// instead of each turning its own.
pub fn half_turn(omega: f64, h: f64, steps: usize) -> Phase {
    let steps = steps as f64;
    let cycles = omega * h * steps / std::f64::consts::TAU;
    let whole = cycles.round();
    if whole >= 1.0 && (cycles - whole).abs() <= 1e-12 * whole {
        cos_sin(std::f64::consts::PI * whole / steps)
    } else {
        cos_sin(0.5 * omega * h)
    }
}

/// The phase rotated by the angle whose (cos, sin) is `by`, renormalised to
/// the unit circle (one Newton step for 1/√(c² + s²)) so rounding cannot make
/// the forcing amplitude drift over thousands of rotations.
#[inline]
pub fn rotate(phase: &Phase, by: &Phase) -> Phase {
    let c = phase[0] * by[0] - phase[1] * by[1];
    let s = phase[1] * by[0] + phase[0] * by[1];
    let scale = 1.5 - 0.5 * (c * c + s * s);
    [c * scale, s * scale]
}

/// (cos φ, sin φ) by Taylor polynomials, halving φ until |φ| ≤ 1/2 and
/// doubling back; accurate to a few ulp for the angles the integrator uses
/// (|φ| ≤ ωh, small) and to about 1e-14 up to |φ| = 2π.
pub fn cos_sin(angle: f64) -> Phase {
    let mut phi = angle;
    let mut halvings = 0;
    while phi.abs() > 0.5 && halvings < 8 {
        phi *= 0.5;
        halvings += 1;
    }
    let x2 = phi * phi;
    // cos φ = Σ (-1)^k φ^{2k}/(2k)!, sin φ = φ Σ (-1)^k φ^{2k}/(2k+1)!, to φ^14 and φ^15:
    // the first omitted terms are below 1e-19 for |φ| ≤ 1/2.
    let [mut c, mut s] = TAYLOR_TOP;
    for k in (0..7).rev() {
        c = INV_FACT[2 * k] - x2 * c;
        s = INV_FACT[2 * k + 1] - x2 * s;
    }
    let mut result = [c, phi * s];
    for _ in 0..halvings {
        let [c, s] = result;
        result = [c * c - s * s, 2.0 * s * c];
    }
    result
}

/// The Taylor polynomials' last coefficients, 1/14! and 1/15!, where
/// [`cos_sin`]'s Horner sums start (the step program's `cos_sin` reads
/// them and [`INV_FACT`] from here).
pub const TAYLOR_TOP: [f64; 2] = [1.0 / 87_178_291_200.0, 1.0 / 1_307_674_368_000.0];

/// 1/n! for n = 0..=13.
pub const INV_FACT: [f64; 14] = [
    1.0,
    1.0,
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5040.0,
    1.0 / 40320.0,
    1.0 / 362_880.0,
    1.0 / 3_628_800.0,
    1.0 / 39_916_800.0,
    1.0 / 479_001_600.0,
    1.0 / 6_227_020_800.0,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cos_sin_matches_libm() {
        for k in -400..=400 {
            let phi = k as f64 * 0.0157;
            let [c, s] = cos_sin(phi);
            assert!(
                (c - phi.cos()).abs() < 1e-14,
                "cos {phi}: {c} vs {}",
                phi.cos()
            );
            assert!(
                (s - phi.sin()).abs() < 1e-14,
                "sin {phi}: {s} vs {}",
                phi.sin()
            );
        }
        for phi in [1e-9, 1e-4, 0.003, 0.25, 0.5] {
            let [c, s] = cos_sin(phi);
            assert!((c - phi.cos()).abs() <= 2.0 * f64::EPSILON);
            assert!((s - phi.sin()).abs() <= 2.0 * f64::EPSILON * phi.max(1e-300) + 1e-300);
        }
    }

    #[test]
    fn a_whole_number_of_cycles_turns_every_frequency_by_the_same_bits() {
        let steps = 1800;
        let first = half_turn(0.5, std::f64::consts::TAU / 0.5 / steps as f64, steps);
        for k in 0..=1000 {
            let omega = 0.5 + k as f64 * 1e-3;
            let h = std::f64::consts::TAU / omega / steps as f64;
            assert_eq!(half_turn(omega, h, steps), first, "ω = {omega}");
            // Two forcing cycles per period: the half turn of 2π·2/steps.
            let twice = half_turn(omega, 2.0 * h, steps);
            assert_eq!(twice, cos_sin(std::f64::consts::TAU / steps as f64));
        }
        // A period that is not a whole number of cycles keeps ωh/2.
        assert_eq!(half_turn(0.7, 0.01, 100), cos_sin(0.5 * 0.7 * 0.01));
        assert_eq!(half_turn(0.0, 0.01, 100), ZERO_PHASE);
    }

    #[test]
    fn a_period_of_rotations_returns_to_phase_zero() {
        // 2·1800 half-step rotations through 2π/3600: the seed's grid.
        let by = cos_sin(std::f64::consts::TAU / 3600.0);
        let mut p = ZERO_PHASE;
        for k in 1..=3600 {
            p = rotate(&p, &by);
            let exact = (std::f64::consts::TAU * k as f64 / 3600.0).cos();
            assert!((p[0] - exact).abs() < 1e-13, "step {k}");
        }
        assert!((p[0] - 1.0).abs() < 1e-13 && p[1].abs() < 1e-13);
    }
}
