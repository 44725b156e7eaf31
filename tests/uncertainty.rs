//! A row says how sure it is: the `lambda_error` estimate against the
//! errors it estimates, and the statuses of rows the tool cannot stand
//! behind (docs/STABILITY.md, "How sure a row is").

mod common;

use common::SEED;
use lyapsweep::method::LaneStatus;
use lyapsweep::Summary;

/// The seed's oscillator's free orbit (its amplitude f/|1 - η²| stays far
/// from the wall at η ≥ 10) has the complex pair of multipliers
/// e^{(-ζ ± i√(1-ζ²))T}: both exponents are -ζ = -0.05. Over 1000
/// iterations of a map period 2π/η the average spans 2π·1000/η time units
/// against the free motion's 1/|μ| = 1.
#[test]
fn an_average_short_against_the_motion_says_so_and_its_error_covers_it() {
    let etas = [1e6, 1e4, 1e3, 100.0, 10.0];
    let scene = common::scene(
        SEED,
        &[
            "sweep.values=[1e6, 1e4, 1e3, 100, 10]",
            "run.backend=\"cpu\"",
        ],
    );
    let report = common::run(&scene);
    for (lane, eta) in report.lanes.iter().zip(etas) {
        let spanned = std::f64::consts::TAU * 1000.0 / eta;
        let off = lane
            .exponents
            .iter()
            .map(|l| (l + 0.05).abs())
            .fold(0.0, f64::max);
        // Whatever the status, the stated error covers the actual one
        // (measured: 0.049 against 0.099 at η = 1e6, 0.041 against 0.088 at
        // 1e4, 6e-5 against 7.5e-4 at 100).
        assert!(
            off <= lane.error,
            "η = {eta}: off by {off:e}, error {:e}",
            lane.error
        );
        assert!(
            (lane.exponent_sum() + 0.1).abs() < 1e-6,
            "η = {eta}: the sum rule"
        );
        if spanned < lyapsweep::driver::SHORT_AVERAGE {
            match lane.status {
                LaneStatus::ShortAverage { scales } => {
                    assert!(
                        (scales - spanned).abs() < 1e-9 * spanned,
                        "η = {eta}: {scales}"
                    )
                }
                other => panic!("η = {eta}: {other}, not short-average"),
            }
        } else {
            assert_eq!(lane.status, LaneStatus::Ok, "η = {eta}");
            assert!(lane.error < 0.1 * 0.05, "η = {eta}: error {:e}", lane.error);
        }
    }
    // η = 1e6 was λ = -0.000676, -0.0993 with status ok.
    assert!(matches!(
        report.lanes[0].status,
        LaneStatus::ShortAverage { .. }
    ));
    let summary = Summary::of(&scene, &report);
    assert_eq!(summary.flagged_by_status.get("short-average"), Some(&3));
    let largest = report.lanes.iter().map(|l| l.error).fold(0.0, f64::max);
    assert_eq!(summary.max_error, Some(largest));
}

/// The over-damped oscillator (ζ = 1e4, no wall in reach) has exponents
/// -ζ ± √(ζ²-1): its slow mode's time scale is 1/5e-5 = 2e4. A transient of
/// 5 iterations once aligned no frame (a tenth of 5, rounded down), and 20
/// iterations gave λ1 58% off with status ok; now one iteration aligns it
/// and λ1 is right, but the 126 time units averaged are short against the
/// slow mode, and the row says so.
#[test]
fn a_short_transient_still_aligns_the_frame_and_a_stiff_lane_says_its_average_is_short() {
    let scene = common::scene(
        SEED,
        &[
            "system.zeta=1e4",
            "sweep.values=[1.0]",
            "integration.transient=5",
            "integration.iterations=20",
            "run.backend=\"cpu\"",
        ],
    );
    assert_eq!(scene.integration.align, 1);
    let lane = &common::run(&scene).lanes[0];
    let slow = -1e4 + (1e8f64 - 1.0).sqrt();
    let off = (lane.exponents[0] - slow).abs() / slow.abs();
    assert!(
        off < 1e-6,
        "λ1 = {} against {slow}: off by {off:e}",
        lane.exponents[0]
    );
    match lane.status {
        LaneStatus::ShortAverage { scales } => {
            let expected = std::f64::consts::TAU * 20.0 * slow.abs();
            assert!((scales - expected).abs() < 1e-6 * expected, "{scales}");
        }
        other => panic!("{other}, not short-average"),
    }
}

/// Hénon's map (a = 1.4, b = 0.3; λ1 = 0.41922 published) from 200 random
/// starts, 1000 iterations each: a chaotic average, whose error is a
/// sampling error. The estimate behaves as a standard error: about two
/// rows in three within it, nearly all within three (measured on 400
/// starts: 64%, 88% within two, 96% within three).
#[test]
fn a_chaotic_row_s_error_is_a_standard_error() {
    let scene = common::scene(
        r#"
[system]
kind = "henon"
[integration]
transient = 1000
iterations = 1000
[attractors]
starts = 200
box = { x = [-0.5, 0.5], y = [-0.3, 0.3] }
"#,
        &[],
    );
    let report = common::run(&scene);
    let ratios: Vec<f64> = report
        .lanes
        .iter()
        .map(|lane| {
            assert_eq!(lane.status, LaneStatus::Ok);
            (lane.exponents[0] - 0.41922).abs() / lane.error
        })
        .collect();
    let within = |k: f64| ratios.iter().filter(|&&r| r <= k).count() as f64 / ratios.len() as f64;
    assert!(
        (0.5..0.85).contains(&within(1.0)),
        "within 1: {}",
        within(1.0)
    );
    assert!(within(3.0) >= 0.9, "within 3: {}", within(3.0));
}

/// The seed's chaotic window at η = 0.73028 over 1000 iterations: λ1 =
/// 0.0116 with an estimated error of 0.0022, a fifth of itself. The row
/// says `uncertain`, and the error it states covers its distance from a
/// run fifty times as long.
#[test]
fn a_row_whose_error_passes_its_tolerance_is_uncertain() {
    let run = |iterations: usize| {
        let overrides = [
            "sweep.values=[0.7302808302808302]".to_owned(),
            "integration.steps_per_period=1800".to_owned(),
            format!("integration.iterations={iterations}"),
            "run.backend=\"exact\"".to_owned(),
        ];
        let overrides: Vec<&str> = overrides.iter().map(String::as_str).collect();
        common::run(&common::scene(SEED, &overrides)).lanes[0].clone()
    };
    let (short, long) = (run(1000), run(50_000));
    assert!(
        short.exponents[0] > 0.0 && long.exponents[0] > 0.0,
        "chaotic"
    );
    let tolerance = lyapsweep::driver::error_tolerance(&short);
    assert!(
        short.error > tolerance,
        "{} against {tolerance}",
        short.error
    );
    assert_eq!(short.status, LaneStatus::Uncertain { error: short.error });
    let off = (short.exponents[0] - long.exponents[0]).abs();
    assert!(
        off <= 2.0 * short.error,
        "off by {off:e}, error {:e}",
        short.error
    );
    assert!(
        long.error < short.error / 3.0,
        "the error shrinks with the run"
    );
}
