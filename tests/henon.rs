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
