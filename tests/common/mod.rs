//! Helpers shared by the integration tests.
#![allow(dead_code)]

use lyapsweep::method::LaneStatus;
use lyapsweep::{scene, Report, Scene};

/// Parses a scene from text, with `--set` style overrides.
pub fn scene(text: &str, overrides: &[&str]) -> Scene {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    scene::parse(text, "test scene", "test", &overrides).expect("test scene is valid")
}

/// Every lane of `scene` with the CPU path's f64 settings `settings`
/// (`plan::method_settings`), in sweep order.
pub fn cpu_lanes<'a>(
    scene: &Scene,
    settings: &'a lyapsweep::method::MethodSettings,
) -> Vec<lyapsweep::method::Lane<'a>> {
    (0..scene.lane_count())
        .map(|k| lyapsweep::method::Lane {
            params: scene.lane_params(k),
            settings,
            initial_state: scene.lane_initial_state(k).to_vec(),
            known: &[],
        })
        .collect()
}

/// Loads a committed scene from scenes/.
pub fn committed_scene(name: &str, overrides: &[&str]) -> Scene {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name);
    scene::load(&path, &overrides).expect("committed scene is valid")
}

pub fn run(scene: &Scene) -> Report {
    lyapsweep::run(scene).expect("scene runs")
}

/// The seed paper's oscillator: ζ = 0.05, f = 1, X_w = 2, e = 1, start
/// (0, 0), transient 500, iterations 1000.
pub const SEED: &str = r#"
[system]
kind = "impact-oscillator"
zeta = 0.05
f = 1.0
wall = 2.0
restitution = 1.0
[integration]
transient = 500
iterations = 1000
initial_state = [0.0, 0.0]
"#;

/// The η values at which the seed's oscillator settles on periodic orbits.
pub const PERIODIC_ETAS: [f64; 5] = [0.8, 0.95, 1.1, 1.25, 1.5];

pub fn assert_all_ok(report: &Report) {
    for (k, lane) in report.lanes.iter().enumerate() {
        assert_eq!(lane.status, LaneStatus::Ok, "lane {k} flagged");
    }
}

/// Every lane `ok`, or `uncertain` where its own error estimate is above a
/// tenth of its λ1: a chaotic average over the few iterations a test
/// affords, or one that took in the end of a transient. The status judges
/// how well the run pinned the numbers down, not the method that made
/// them; the tests that use this assert the numbers themselves.
pub fn assert_ok_or_uncertain(report: &Report) {
    for (k, lane) in report.lanes.iter().enumerate() {
        assert!(
            matches!(lane.status, LaneStatus::Ok | LaneStatus::Uncertain { .. }),
            "lane {k} flagged: {}",
            lane.status
        );
    }
}

/// Whether a missing GPU adapter must fail the GPU tests instead of skipping
/// them (`.ci/run` sets it after installing Mesa's Vulkan driver).
pub fn gpu_required() -> bool {
    std::env::var("LYAPSWEEP_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// True when an adapter for `precision` exists; otherwise says SKIPPED
/// loudly (or fails under LYAPSWEEP_REQUIRE_GPU=1).
pub fn gpu_or_skip(test: &str, precision: lyapsweep::scene::Precision) -> bool {
    let adapters = lyapsweep::backend::gpu::context::list();
    if adapters
        .iter()
        .any(|a| precision == lyapsweep::scene::Precision::F32 || a.f64)
    {
        return true;
    }
    let found: Vec<String> = adapters
        .iter()
        .map(|a| format!("{} ({}, f64 {})", a.name, a.backend, a.f64))
        .collect();
    let message = format!(
        "SKIPPED {test}: no GPU adapter for {precision:?} (found: [{}])",
        found.join(", ")
    );
    assert!(
        !gpu_required(),
        "{message}, and LYAPSWEEP_REQUIRE_GPU=1 forbids skipping"
    );
    // Straight to the stream, not eprintln!: the test harness captures the
    // print macros of passing tests, and a skip must show.
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{message}");
    false
}

/// Extreme sweeps (docs/STABILITY.md, "Extreme sweeps") on any backend: η over three
/// decades (η = 0.01 raises the steps to 10·T), forcing up to 100 times the
/// seed's, every lane `ok` within `tolerance` of the sum rule; and a wall
/// never reached, where λ1 = λ2 = -ζ within 1e-4. `sweep` runs the seed's
/// scene with the overrides given; `label` names the run in messages.
pub fn assert_extreme_sweeps(sweep: impl Fn(&[&str]) -> Report, tolerance: f64, label: &str) {
    let etas = sweep(&["sweep.values=[0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 20.0]"]);
    assert!(etas.lanes[0].plan.steps_per_period >= 6283, "{label}");
    let forcing = sweep(&[
        "sweep.parameter=\"f\"",
        "sweep.values=[1.0, 10.0, 30.0, 100.0]",
        "system.eta=0.8",
    ]);
    assert!(forcing.lanes.iter().all(|l| l.impacts_per_period > 0.0));
    for report in [&etas, &forcing] {
        for lane in &report.lanes {
            assert_eq!(lane.status, LaneStatus::Ok, "{label} {:?}", lane.plan);
            let error = (lane.exponent_sum() - -0.1).abs();
            assert!(
                error < tolerance,
                "{label}: sum off by {error:e} ({:?})",
                lane.plan
            );
        }
    }
    let free = sweep(&["system.wall=100", "sweep.values=[0.5, 1.5]"]);
    for lane in &free.lanes {
        assert_eq!(lane.impacts_per_period, 0.0);
        for l in &lane.exponents {
            assert!((l - -0.05).abs() < 1e-4, "{label} {:?}", lane.exponents);
        }
    }
}

/// A run at an unusual δ: no NaN reaches the exponents, and every row the
/// status calls `ok` keeps the sum rule (-0.1) within 1e-3.
pub fn assert_answered_or_flagged(report: &Report, delta: f64) {
    for lane in &report.lanes {
        assert!(lane.exponents.iter().all(|l| !l.is_nan()), "δ = {delta:e}");
        let error = (lane.exponent_sum() - -0.1).abs();
        if lane.status == LaneStatus::Ok {
            assert!(
                error < 1e-3,
                "δ = {delta:e}: sum off by {error:e}, status ok"
            );
        }
    }
}

/// Asserts that two runs of the same sweep gave the same lanes to the bit
/// (exponents, Poincaré points, impacts, status), with the impacts on the
/// first wall all of them; returns the impacts per period summed over the
/// lanes, for the caller to check the sweep met the wall. `what` names
/// the comparison in messages.
pub fn assert_same_bits(model: &Report, reference: &Report, what: &str) -> f64 {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let mut impacts = 0.0;
    for (k, (a, b)) in model.lanes.iter().zip(&reference.lanes).enumerate() {
        assert_eq!(bits(&a.exponents), bits(&b.exponents), "{what}, lane {k}");
        assert_eq!(
            bits(&a.bifurcation),
            bits(&b.bifurcation),
            "{what}, lane {k}"
        );
        assert_eq!(
            a.impacts_per_period, b.impacts_per_period,
            "{what}, lane {k}"
        );
        assert_eq!(
            a.crossings_per_period[0], a.impacts_per_period,
            "{what}, lane {k}"
        );
        assert_eq!(a.status, b.status, "{what}, lane {k}");
        impacts += a.impacts_per_period;
    }
    impacts
}

/// The impact pair whose stops also kick the mass away: v → -e·v ∓ kick
/// (tests/switches.rs against the exact backend, tests/gpu_models.rs on
/// the GPU). Not a stop (the reset is not linear in v alone), so a general event;
/// its saltation determinant, -e·v⁺/v⁻, differs crossing by crossing.
pub const KICKED_PAIR: &str = r#"
[model]
name = "kicked-pair"
states = ["x", "v"]
[model.parameters]
zeta = 0.05
f = 1.0
gap = 1.0
e = 0.8
kick = 0.1
eta = 0.8
[model.equations]
x = "v"
v = "-2*zeta*v - x + f*cos(eta*t)"
[model.map]
period = "2*pi/eta"
[[model.events]]
name = "right stop"
surface = "x - gap"
reset = { v = "-e*v - kick" }
[[model.events]]
name = "left stop"
surface = "-gap - x"
reset = { v = "-e*v + kick" }
"#;

/// A mass on a spring with Coulomb friction against a fixed floor, written
/// with a switch on the velocity: where the spring force is below the
/// friction limit, both fields point into v = 0 (sticking, Filippov
/// sliding). (tests/switches.rs on the CPU, tests/gpu_models.rs on the
/// GPU.)
pub const FRICTION: &str = r#"
[model]
name = "friction"
states = ["x", "v"]
[model.parameters]
mu = 0.5
f = 0.3
eta = 0.8
[[model.switches]]
name = "slip"
surface = "v"
[model.equations]
x = "v"
v = "-x - mu*sign(slip) + f*cos(eta*t)"
[model.map]
period = "2*pi/eta"
"#;

/// The impact pair with a soft spring besides, engaging at x = `contact`
/// (a switch): stops and a general surface in one model, in the kernels'
/// one impact loop. (tests/switches.rs against the exact backend,
/// tests/gpu_models.rs on the GPU.)
pub const PAIR_AND_SPRING: &str = r#"
[model]
name = "pair-and-spring"
states = ["x", "v"]
[model.parameters]
zeta = 0.05
f = 2.0
gap = 1.0
e = 0.8
eta = 0.8
contact = 0.5
ks = 2.0
[[model.switches]]
name = "spring"
surface = "x - contact"
[model.equations]
x = "v"
v = "-2*zeta*v - x - ks*(x - contact)*step(spring) + f*cos(eta*t)"
[model.map]
period = "2*pi/eta"
[[model.events]]
name = "right stop"
surface = "x - gap"
reset = { v = "-e*v" }
[[model.events]]
name = "left stop"
surface = "-gap - x"
reset = { v = "-e*v" }
"#;

/// models/belt-into-stop.toml as a scene's `model` line: a mass driven
/// along a slow belt (Coulomb friction on the slip, switch `slip`) into a
/// rigid stop that reverses its velocity, every rebound jumping the
/// velocity from above the belt's to below it, across the switch.
/// (tests/switches.rs against the exact backend, tests/gpu_models.rs on the
/// GPU.)
pub fn belt_into_stop() -> String {
    format!(
        "model = {:?}",
        format!("{}/models/belt-into-stop.toml", env!("CARGO_MANIFEST_DIR"))
    )
}
