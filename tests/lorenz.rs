//! The Lorenz flow: the engine at three dimensions (one zero exponent).

mod common;

#[test]
fn exponents_match_published_values() {
    let report = common::run(&common::committed_scene("lorenz.toml", &[]));
    common::assert_all_ok(&report);
    let l = &report.lanes[0].exponents;
    for (got, published) in l.iter().zip([0.9056, 0.0, -14.5723]) {
        assert!((got - published).abs() < 0.02, "exponents {l:?}");
    }
    let sum: f64 = l.iter().sum();
    let expected = -(10.0 + 1.0 + 8.0 / 3.0);
    assert!((sum - expected).abs() < 1e-3, "sum {sum} vs {expected}");
    assert!((report.expected_sums[0] - expected).abs() < 1e-12);
}

#[test]
fn a_period_too_long_for_the_difference_is_flagged_not_trusted() {
    // Over T = 1 the stable direction contracts by e^{-14.6} ≈ 5e-7, below the
    // rounding noise of a forward difference at δ = 1e-8: taken whole (one
    // part, as the scene forces here), the row must say so.
    let scene = common::committed_scene(
        "lorenz.toml",
        &[
            "system.period=1.0",
            "integration.steps_per_period=250",
            "integration.iterations=2000",
            "integration.difference=\"forward\"",
            "integration.perturbation=1e-8",
            "integration.submaps=1",
        ],
    );
    let report = common::run(&scene);
    match report.lanes[0].status {
        lyapsweep::method::LaneStatus::Unresolved { bound } => {
            assert!(bound > 0.1, "bound {bound}")
        }
        other => panic!("expected unresolved, got {other}"),
    }
}

#[test]
fn the_time_one_map_is_cut_into_parts_and_resolved() {
    // The same scene without forcing one part: the lane cuts each iteration
    // into sub-maps short enough for the difference, and λ3 comes out.
    let scene = common::committed_scene(
        "lorenz.toml",
        &[
            "system.period=1.0",
            "integration.steps_per_period=250",
            "integration.iterations=10000",
            "integration.difference=\"forward\"",
            "integration.perturbation=1e-8",
        ],
    );
    let report = common::run(&scene);
    let lane = &report.lanes[0];
    assert_eq!(lane.status, lyapsweep::method::LaneStatus::Ok);
    assert!(lane.plan.parts >= 2, "{:?}", lane.plan);
    for (got, published) in lane.exponents.iter().zip([0.9056, 0.0, -14.5723]) {
        assert!(
            (got - published).abs() < 0.02,
            "exponents {:?}",
            lane.exponents
        );
    }
    let sum: f64 = lane.exponents.iter().sum();
    assert!((sum - -(10.0 + 1.0 + 8.0 / 3.0)).abs() < 1e-3, "sum {sum}");
}
