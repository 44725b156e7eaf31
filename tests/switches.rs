//! Switches of the field and general event surfaces: the soft stop (a
//! spring that engages at a gap) on the RK4 path against the exact
//! piecewise-linear backend, general resets whose saltation determinant
//! changes crossing by crossing, the exact backend of a model against the
//! built-in closed form, and sliding flagged, never silently wrong.

mod common;

use lyapsweep::method::LaneStatus;
use lyapsweep::{scene, Report, Scene};

fn model_path(name: &str) -> String {
    format!("{}/models/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn model_scene(model: &str, body: &str, overrides: &[&str]) -> Scene {
    let text = format!("{model}\n{body}");
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    scene::parse(&text, "test scene", "test", &overrides).expect("a valid scene")
}

fn file(name: &str) -> String {
    format!("model = {:?}", model_path(name))
}

fn run(scene: &Scene) -> Report {
    lyapsweep::run(scene).expect("runs")
}

fn sweep(etas: &[f64], steps: usize, backend: &str) -> String {
    let values: Vec<String> = etas.iter().map(|v| v.to_string()).collect();
    format!(
        "[sweep]\nparameter = \"eta\"\nvalues = [{}]\n[integration]\nsteps_per_period = {steps}\n\
         transient = 300\niterations = 300\n[run]\nbackend = \"{backend}\"\n",
        values.join(", ")
    )
}

/// The largest difference of exponents between two reports, after
/// checking that every lane is ok and the impacts and the crossings of the
/// first `events` events agree.
fn worst_difference(a: &Report, b: &Report, events: usize) -> f64 {
    let mut worst: f64 = 0.0;
    for (k, (x, y)) in a.lanes.iter().zip(&b.lanes).enumerate() {
        assert_eq!(x.status, LaneStatus::Ok, "lane {k}");
        assert_eq!(y.status, LaneStatus::Ok, "lane {k}");
        assert_eq!(x.impacts_per_period, y.impacts_per_period, "lane {k}");
        assert_eq!(
            x.crossings_per_period[..events],
            y.crossings_per_period[..events],
            "lane {k}"
        );
        for (p, q) in x.exponents.iter().zip(&y.exponents) {
            worst = worst.max((p - q).abs());
        }
    }
    worst
}

/// The sum rule's worst error over a report's lanes.
fn worst_sum_error(report: &Report) -> f64 {
    report
        .lanes
        .iter()
        .zip(&report.expected_sums)
        .map(|(lane, expected)| (lane.exponent_sum() - expected).abs())
        .fold(0.0, f64::max)
}

#[test]
fn the_soft_stop_agrees_with_its_exact_piecewise_linear_backend() {
    // Periodic orbits at these η, with 2 or 4 crossings of the contact a
    // period, and one (η = 2.2) that never reaches it.
    let etas = [0.4, 0.6, 0.8, 1.0, 1.2, 2.2];
    let model = file("soft-stop.toml");
    let exact = run(&model_scene(&model, &sweep(&etas, 1800, "exact"), &[]));
    let cpu = run(&model_scene(&model, &sweep(&etas, 1800, "cpu"), &[]));
    let reaching = exact
        .lanes
        .iter()
        .filter(|l| l.crossings_per_period[0] >= 2.0)
        .count();
    assert_eq!(reaching, 5, "the sweep must exercise the switch");
    let worst = worst_difference(&cpu, &exact, 1);
    assert!(worst <= 1e-8, "RK4 against exact: {worst:e}");
    // The field is continuous across the contact (det S = 1): the sum is
    // -2ζ, to rounding in the exact propagator. On the RK4 path each lane's
    // periodic orbit repeats the same Jacobian, and with it the same
    // rounding of its finite differences (about ε·√steps/δ = 4e-9 relative
    // at δ = 1e-6): measured 0.3 to 2.2e-9, unchanged over 2000 iterations
    // and at 5000 steps, so the floor is δ's, not the switch's.
    let exact_sum = worst_sum_error(&exact);
    assert!(exact_sum <= 1e-12, "exact sum rule: {exact_sum:e}");
    let cpu_sum = worst_sum_error(&cpu);
    assert!(cpu_sum <= 1e-8, "RK4 sum rule: {cpu_sum:e}");
}

#[test]
fn the_seed_model_s_exact_backend_is_the_built_in_closed_form() {
    // The piecewise-linear propagator read off the model's expressions
    // against the seed's hand-written closed form.
    let etas = [0.8, 1.1, 1.5, 2.5];
    let body = sweep(&etas, 1800, "exact");
    for e in ["1.0", "0.8"] {
        let model = run(&model_scene(
            &file("seed-oscillator.toml"),
            &body,
            &[&format!("model.parameters.e={e}")],
        ));
        let built_in = run(&common::scene(
            &format!("[system]\nkind = \"impact-oscillator\"\n{body}"),
            &[&format!("system.restitution={e}")],
        ));
        // (The built-in's exact path counts impacts, not crossings per wall.)
        let worst = worst_difference(&model, &built_in, 0);
        assert!(worst <= 1e-12, "e = {e}: {worst:e}");
    }
}

/// The impact pair whose stops also kick the mass away: v → -e·v ∓ kick.
/// Not a stop (the reset is not linear in v alone), so a general event;
/// its saltation determinant, -e·v⁺/v⁻, differs crossing by crossing.
const KICKED_PAIR: &str = r#"
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

#[test]
fn a_general_reset_keeps_the_sum_rule_crossing_by_crossing() {
    let etas = [0.5, 0.8, 1.2];
    let exact = run(&model_scene(KICKED_PAIR, &sweep(&etas, 1800, "exact"), &[]));
    let cpu = run(&model_scene(KICKED_PAIR, &sweep(&etas, 1800, "cpu"), &[]));
    for lane in &exact.lanes {
        assert!(
            lane.crossings_per_period[..2].iter().all(|&c| c >= 1.0),
            "both stops are hit: {:?}",
            lane.crossings_per_period
        );
    }
    let worst = worst_difference(&cpu, &exact, 2);
    assert!(worst <= 1e-8, "RK4 against exact: {worst:e}");
    // The kick makes the sum differ from the stops' 2·ln e per impact:
    // the expected sum follows the determinants along the orbit.
    for (lane, expected) in exact.lanes.iter().zip(&exact.expected_sums) {
        let stops_alone = -0.1 + 2.0 * 0.8_f64.ln() * lane.impacts_per_period / lane.period;
        assert!(
            (expected - stops_alone).abs() > 1e-3,
            "the kick must change the volume law: {expected} vs {stops_alone}"
        );
    }
    let (exact_sum, cpu_sum) = (worst_sum_error(&exact), worst_sum_error(&cpu));
    assert!(exact_sum <= 1e-12, "exact sum rule: {exact_sum:e}");
    assert!(cpu_sum <= 1e-8, "RK4 sum rule: {cpu_sum:e}");
}

/// A mass on a belt with Coulomb friction, written with a switch on the
/// slip velocity: where the spring force is below the friction limit, both
/// fields point into v = 0 (sticking, Filippov sliding).
const FRICTION: &str = r#"
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

#[test]
fn sliding_is_flagged_on_both_paths_never_silently_wrong() {
    // Started at rest inside the sticking band |x| < μ: it sticks at once.
    for backend in ["cpu", "exact"] {
        let scene = format!(
            "{FRICTION}\n[sweep]\nparameter = \"eta\"\nvalues = [0.8]\n[integration]\n\
             steps_per_period = 200\ntransient = 5\niterations = 5\ninitial_state = [0.1, 0.0]\n\
             [run]\nbackend = \"{backend}\"\n"
        );
        let report = run(&model_scene(&scene, "", &[]));
        assert!(
            matches!(report.lanes[0].status, LaneStatus::Sliding { .. }),
            "{backend}: {}",
            report.lanes[0].status
        );
    }
}
