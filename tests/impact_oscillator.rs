//! The seed paper's impact oscillator on the CPU path, against the sum rule
//! and the exact (closed-form) backend.

mod common;

use common::{PERIODIC_ETAS, SEED};
use lyapsweep::scene::Backend;
use lyapsweep::Report;

fn sweep_values(values: &[f64]) -> String {
    let list: Vec<String> = values.iter().map(|v| format!("{v}")).collect();
    format!("sweep.values=[{}]", list.join(", "))
}

fn seed_run(values: &[f64], extra: &[&str]) -> Report {
    let mut overrides = vec![sweep_values(values)];
    overrides.extend(extra.iter().map(|s| s.to_string()));
    let overrides: Vec<&str> = overrides.iter().map(String::as_str).collect();
    common::run(&common::scene(SEED, &overrides))
}

#[test]
fn exponents_sum_to_minus_two_zeta_across_the_sweep() {
    // e = 1: every impact preserves area, so λ1 + λ2 = -2ζ = -0.1 whatever η,
    // including the near-grazing values around the onsets of impacts.
    let scene = common::scene(SEED, &["sweep.from=0.5", "sweep.to=1.5", "sweep.count=201"]);
    let report = common::run(&scene);
    common::assert_all_ok(&report);
    for (lane, eta) in report.lanes.iter().zip(&scene.sweep.first.values) {
        let sum = lane.exponent_sum();
        assert!((sum - -0.1).abs() < 1e-5, "η = {eta}: λ1 + λ2 = {sum}");
    }
    assert!(report.expected_sums.iter().all(|&e| e == -0.1));
    assert!(report.max_sum_error().unwrap() < 1e-5);
}

#[test]
fn the_chaotic_window_where_impacts_begin_has_a_positive_exponent() {
    let values: Vec<f64> = (0..=40).map(|k| 0.70 + 0.001 * k as f64).collect();
    let report = seed_run(&values, &[]);
    common::assert_ok_or_uncertain(&report);
    let (best, eta) = report
        .lanes
        .iter()
        .zip(&values)
        .map(|(l, eta)| (l.exponents[0], *eta))
        .fold(
            (f64::NEG_INFINITY, 0.0),
            |a, b| if b.0 > a.0 { b } else { a },
        );
    assert!(
        best > 0.01,
        "largest λ1 in [0.70, 0.74] is {best} at η = {eta}"
    );
    // Chaos here comes with impacts, and the sum rule still holds.
    let chaotic = report.lanes.iter().find(|l| l.exponents[0] > 0.01).unwrap();
    assert!(chaotic.impacts_per_period > 0.5);
    assert!((chaotic.exponent_sum() - -0.1).abs() < 1e-5);
}

#[test]
fn dissipative_impacts_follow_the_volume_law() {
    // e = 0.8: each impact multiplies area by e², so the sum is
    // -2ζ + 2 ln(e) · (impacts per unit time).
    let report = seed_run(&[0.8, 0.95, 1.1], &["system.restitution=0.8"]);
    common::assert_all_ok(&report);
    for (lane, expected) in report.lanes.iter().zip(&report.expected_sums) {
        assert!(lane.impacts_per_period > 0.0, "no impacts");
        let impact_term = 2.0 * 0.8_f64.ln() * lane.impacts_per_period / lane.period;
        assert!((expected - (-0.1 + impact_term)).abs() < 1e-15);
        let sum = lane.exponent_sum();
        assert!(
            (sum - expected).abs() < 1e-6,
            "sum {sum} vs expected {expected}"
        );
    }
}

#[test]
fn rk4_with_the_default_impact_location_agrees_with_the_exact_backend() {
    let rk4 = seed_run(&PERIODIC_ETAS, &[]);
    let exact = seed_run(&PERIODIC_ETAS, &["run.backend=\"exact\""]);
    assert_eq!(exact.backend, Backend::Exact);
    common::assert_all_ok(&rk4);
    common::assert_all_ok(&exact);
    for (k, eta) in PERIODIC_ETAS.iter().enumerate() {
        let (a, b) = (&rk4.lanes[k], &exact.lanes[k]);
        assert_eq!(
            a.impacts_per_period, b.impacts_per_period,
            "η = {eta}: impact counts differ"
        );
        for (x, y) in a.exponents.iter().zip(&b.exponents) {
            assert!(
                (x - y).abs() < 5e-6,
                "η = {eta}: RK4 {:?} vs exact {:?}",
                a.exponents,
                b.exponents
            );
        }
    }
    // The exact backend itself keeps the sum rule to rounding.
    assert!(
        exact.max_sum_error().unwrap() < 1e-9,
        "{:?}",
        exact.max_sum_error()
    );
}

#[test]
fn the_default_impact_location_is_ten_times_more_accurate_than_linear() {
    let exact = seed_run(&PERIODIC_ETAS, &["run.backend=\"exact\""]);
    let newton = seed_run(&PERIODIC_ETAS, &["integration.impact_location=\"newton\""]);
    let linear = seed_run(&PERIODIC_ETAS, &["integration.impact_location=\"linear\""]);
    // Only the η with impacts tell the methods apart.
    let with_impacts: Vec<usize> = (0..PERIODIC_ETAS.len())
        .filter(|&k| exact.lanes[k].impacts_per_period > 0.0)
        .collect();
    assert!(with_impacts.len() >= 3);
    let error = |r: &Report| {
        with_impacts
            .iter()
            .flat_map(|&k| {
                r.lanes[k]
                    .exponents
                    .iter()
                    .zip(&exact.lanes[k].exponents)
                    .map(|(a, b)| (a - b).abs())
            })
            .fold(0.0, f64::max)
    };
    let (e_newton, e_linear) = (error(&newton), error(&linear));
    assert!(
        e_linear >= 10.0 * e_newton,
        "linear error {e_linear:e} is not 10 × newton's {e_newton:e}"
    );
}
