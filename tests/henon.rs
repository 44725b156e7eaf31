//! The Hénon map: the paper's worked example of the perturbation Jacobian
//! (eq. 7–10) and the published exponents.

mod common;

use lyapsweep::integrate::clock::ZERO_PHASE;
use lyapsweep::method::jacobian::{estimate, Difference};
use lyapsweep::system::henon::Henon;
use lyapsweep::system::{FlowSettings, IterationStats, Part};

#[test]
fn exponents_match_published_values_and_sum_to_ln_b() {
    let report = common::run(&common::committed_scene("henon.toml", &[]));
    common::assert_all_ok(&report);
    let lane = &report.lanes[0];
    let (l1, l2) = (lane.exponents[0], lane.exponents[1]);
    assert!((l1 - 0.41922).abs() < 2e-3, "λ1 = {l1}");
    assert!((l2 - -1.62319).abs() < 2e-3, "λ2 = {l2}");
    // det DU = -b at every point, so the sum is ln b up to the rounding of
    // each difference column (about 1e-16/δ, averaging out).
    assert!((l1 + l2 - 0.3_f64.ln()).abs() < 1e-9, "sum = {}", l1 + l2);
    assert!((report.expected_sums[0] - 0.3_f64.ln()).abs() < 1e-15);
}

#[test]
fn estimated_jacobian_is_the_papers_eq_10() {
    let (a, b) = (1.4, 0.3);
    let henon = Henon { a, b };
    let settings = FlowSettings {
        steps_per_period: 1,
        impact_location: Default::default(),
        stop: Default::default(),
    };
    for (x, y) in [(0.1, 0.2), (-0.7, 0.15), (1.2, -0.3)] {
        for delta in [1e-3, 1e-5, 1e-7] {
            let mut stats = IterationStats::default();
            let (image, j) = estimate(
                &henon,
                &settings,
                Part::WHOLE,
                &mut ZERO_PHASE.clone(),
                &[x, y],
                delta,
                Difference::Forward,
                &mut stats,
            );
            assert_eq!(image, [1.0 - a * x * x + y, b * x]);
            // Eq. 9: the first column is (U(x + δ, y) - U(x, y))/δ, whose top
            // entry is -a((x + δ)² - x²)/δ = -2a(x + δ/2). (The paper prints
            // -2a(x + δ); the δ/2 is what the algebra gives, and what the
            // estimate must equal.) Exact up to the rounding of the
            // differences, about 1e-16/δ.
            let tolerance = 1e-15 / delta;
            let d = (x + delta) - x;
            let j11 = -2.0 * a * (x + d / 2.0);
            assert!(
                (j[(0, 0)] - j11).abs() < tolerance * 10.0,
                "J11 = {} vs {j11}",
                j[(0, 0)]
            );
            assert!((j[(0, 1)] - 1.0).abs() < tolerance, "J12 = {}", j[(0, 1)]);
            assert!((j[(1, 0)] - b).abs() < tolerance, "J21 = {}", j[(1, 0)]);
            assert_eq!(j[(1, 1)], 0.0);
        }
    }
}

/// The transient's aligning iterations (`integration.align`): the QR frame
/// starts the averaging turned towards the directions of growth, not at I.
/// At a = 0.2 the map has a stable fixed point with real multipliers μ1, μ2;
/// once the frame is aligned, every R_n is the same triangular Schur factor
/// with diagonal |μ1|, |μ2|, so the exponents are ln|μ_i| to rounding
/// whatever the window. From I the frame's first column carries its
/// projection onto the slow direction into the sums: a bias of O(1/N).
#[test]
fn an_aligned_frame_leaves_no_window_bias_at_a_fixed_point() {
    let (a, b) = (0.2_f64, 0.3_f64);
    // x* = 1 - a x*² + b x*, and the Jacobian [[-2a x*, 1], [b, 0]] has
    // μ² + 2a x* μ - b = 0.
    let x = (-(1.0 - b) + ((1.0 - b).powi(2) + 4.0 * a).sqrt()) / (2.0 * a);
    let p = 2.0 * a * x;
    let root = (p * p + 4.0 * b).sqrt();
    let (slow, fast) = ((-p - root) / 2.0, (-p + root) / 2.0);
    let exact = [slow.abs().ln(), fast.abs().ln()];
    let run = |align: usize| {
        let text = format!(
            "[system]\nkind = \"henon\"\na = {a}\nb = {b}\n\
             [integration]\ntransient = 200\nalign = {align}\niterations = 100\n"
        );
        let report = common::run(&common::scene(&text, &[]));
        common::assert_all_ok(&report);
        let e = &report.lanes[0].exponents;
        (e[0] - exact[0]).abs().max((e[1] - exact[1]).abs())
    };
    let (aligned, from_identity) = (run(20), run(0));
    eprintln!("error aligned {aligned:e}, from I {from_identity:e}");
    // Central differences of a quadratic map are exact but for rounding
    // (about 1e-16/δ = 1e-10 per Jacobian entry, the same at every
    // iteration of a fixed point: 5.2e-10 measured).
    assert!(aligned < 2e-9, "aligned: error {aligned:e}");
    // The bias from I: ln of the cosine between e1 and the slow direction,
    // over N = 100 iterations (3.1e-3 measured).
    assert!(from_identity > 1e-3, "from I: error {from_identity:e}");
    // The default aligns the transient's last tenth.
    let default = common::scene(
        "[system]\nkind = \"henon\"\n[integration]\ntransient = 200\n",
        &[],
    );
    assert_eq!(default.integration.align, 20);
}
