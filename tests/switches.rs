//! Switches of the field and general event surfaces: the soft stop (a
//! spring that engages at a gap) on the RK4 path against the exact
//! piecewise-linear backend, general resets whose saltation determinant
//! changes crossing by crossing, the exact backend of the impact
//! oscillator's model against the seed's hand-written closed form, and
//! sliding flagged, never silently wrong.

mod common;

use lyapsweep::method::LaneStatus;
use lyapsweep::scene::DEFAULT_ALIGN_FRACTION;
use lyapsweep::{scene, Report, Scene};
use nalgebra::{DMatrix, Matrix2, Matrix4, SMatrix, SVector, Vector2, Vector4};

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
    // periodic orbit repeats the same Jacobian every iteration, and with it
    // the same two errors, which therefore do not average out over the
    // iterations: the volume error of RK4 itself (its stability function's
    // modulus on an oscillation iy is 1 - y⁶/144: the stiff contact
    // spring, ω = √21, dominates at η = 0.4, 1.1e-9 at 1800 steps, 5.1e-8
    // at 900, 1.2e-11 at 3600), and the rounding of the finite differences
    // (about ε·√steps/δ relative: 2.7e-9 at η = 1.0 with δ = 1e-6, 3.4e-10
    // with 3e-6). Measured 0.3 to 2.7e-9 here.
    let exact_sum = worst_sum_error(&exact);
    assert!(exact_sum <= 1e-12, "exact sum rule: {exact_sum:e}");
    let cpu_sum = worst_sum_error(&cpu);
    assert!(cpu_sum <= 1e-8, "RK4 sum rule: {cpu_sum:e}");
    // With both below it, 3600 steps and δ = 3e-6, the sum rule holds to
    // 1e-9 on every lane (4.6e-10 at worst, measured) and the exponents
    // meet the exact backend's to 1.3e-9.
    let fine = run(&model_scene(
        &model,
        &sweep(&etas, 3600, "cpu"),
        &["integration.perturbation=3e-6"],
    ));
    let exact_fine = run(&model_scene(&model, &sweep(&etas, 3600, "exact"), &[]));
    let worst = worst_difference(&fine, &exact_fine, 1);
    assert!(worst <= 1e-8, "RK4 against exact, 3600 steps: {worst:e}");
    let fine_sum = worst_sum_error(&fine);
    assert!(fine_sum <= 1e-9, "RK4 sum rule, 3600 steps: {fine_sum:e}");
}

#[test]
fn the_seed_model_s_exact_backend_is_the_seed_s_closed_form() {
    // The piecewise-linear propagator read off the model file's
    // expressions against the seed's hand-written closed form, which the
    // `impact-oscillator` kind (the same file) keeps as its exact backend.
    let etas = [0.8, 1.1, 1.5, 2.5];
    let body = sweep(&etas, 1800, "exact");
    for e in ["1.0", "0.8"] {
        let restitution = format!("model.parameters.restitution={e}");
        let model = run(&model_scene(
            &file("impact-oscillator.toml"),
            &body,
            &[&restitution],
        ));
        let closed_form = run(&common::scene(
            &format!("[system]\nkind = \"impact-oscillator\"\n{body}"),
            &[&format!("system.restitution={e}")],
        ));
        let worst = worst_difference(&model, &closed_form, 1);
        assert!(worst <= 1e-12, "e = {e}: {worst:e}");
    }
}

#[test]
fn a_general_reset_keeps_the_sum_rule_crossing_by_crossing() {
    let etas = [0.5, 0.8, 1.2];
    let exact = run(&model_scene(
        common::KICKED_PAIR,
        &sweep(&etas, 1800, "exact"),
        &[],
    ));
    let cpu = run(&model_scene(
        common::KICKED_PAIR,
        &sweep(&etas, 1800, "cpu"),
        &[],
    ));
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

#[test]
fn stops_and_a_switch_together_agree_with_the_exact_backend() {
    // The impact pair (f = 2, e = 0.8) with a spring engaging at x = 0.5:
    // both stops and the spring's contact are met in every lane but the
    // last (η = 2.5, which stays clear of both).
    let etas = [0.4, 0.8, 1.3, 1.8, 2.5];
    let exact = run(&model_scene(
        common::PAIR_AND_SPRING,
        &sweep(&etas, 1800, "exact"),
        &[],
    ));
    let cpu = run(&model_scene(
        common::PAIR_AND_SPRING,
        &sweep(&etas, 1800, "cpu"),
        &[],
    ));
    let both = exact
        .lanes
        .iter()
        .filter(|l| l.crossings_per_period[..3].iter().all(|&c| c >= 1.0))
        .count();
    assert_eq!(both, 4, "the sweep must exercise the stops and the switch");
    // Measured: 1.1e-9 at worst (η = 0.4); sum rule 1.1e-9 on the RK4 path
    // (η = 1.3), 9e-16 exact.
    let worst = worst_difference(&cpu, &exact, 3);
    assert!(worst <= 1e-8, "RK4 against exact: {worst:e}");
    let (exact_sum, cpu_sum) = (worst_sum_error(&exact), worst_sum_error(&cpu));
    assert!(exact_sum <= 1e-12, "exact sum rule: {exact_sum:e}");
    assert!(cpu_sum <= 1e-8, "RK4 sum rule: {cpu_sum:e}");
}

#[test]
fn a_rebound_across_a_switch_takes_the_field_of_its_other_side() {
    // Each lane meets the stop (once a period, or every other at η = 2.5)
    // at v > vb and rebounds to v < vb: the rebound crosses the slip
    // switch, which the flow crosses back upwards once between impacts
    // (the slip column counts the flow's crossings only). The exact
    // backend takes the new side after a reset; the RK4 path kept the old
    // side's friction until the next crossing before `surface::jumped`.
    let etas = [1.0, 1.3, 1.6, 1.9, 2.2, 2.5];
    let exact = run(&model_scene(
        &common::belt_into_stop(),
        &sweep(&etas, 1800, "exact"),
        &[],
    ));
    let cpu = run(&model_scene(
        &common::belt_into_stop(),
        &sweep(&etas, 1800, "cpu"),
        &[],
    ));
    for lane in &exact.lanes {
        assert!(
            lane.crossings_per_period[0] > 0.0 && lane.crossings_per_period[1] > 0.0,
            "the stop and the slip: {:?}",
            lane.crossings_per_period
        );
    }
    // Measured: 6.4e-9 at worst; sum rule 7.3e-9 on the RK4 path, 2e-15
    // exact.
    let worst = worst_difference(&cpu, &exact, 2);
    assert!(worst <= 1e-8, "RK4 against exact: {worst:e}");
    let (exact_sum, cpu_sum) = (worst_sum_error(&exact), worst_sum_error(&cpu));
    assert!(exact_sum <= 1e-12, "exact sum rule: {exact_sum:e}");
    assert!(cpu_sum <= 1e-8, "RK4 sum rule: {cpu_sum:e}");
}

#[test]
fn a_mass_held_on_a_stop_in_the_exact_backend_is_the_closed_form_s() {
    // The seed oscillator at f = 3, e = 0.5 (tests/stability.rs for the
    // RK4 path): at η = 0.3 the bounces accumulate and the mass rests on
    // the wall every period until the forcing pulls it off. The model's
    // piecewise-linear exact backend holds it there (as the RK4 path does) instead of
    // stopping the iteration: the same orbit as the seed's own closed form
    // (measured 6e-15 at the sampled point), both exponents -∞.
    let body = "[sweep]\nparameter = \"eta\"\nvalues = [0.3, 0.5, 0.8, 1.2]\n\
                [integration]\ntransient = 100\niterations = 200\n\
                [output]\nbifurcation_points = 1\n[run]\nbackend = \"exact\"\n";
    let model = run(&model_scene(
        &file("impact-oscillator.toml"),
        body,
        &["model.parameters.f=3", "model.parameters.restitution=0.5"],
    ));
    let closed_form = run(&common::scene(
        &format!("[system]\nkind = \"impact-oscillator\"\n{body}"),
        &["system.f=3", "system.restitution=0.5"],
    ));
    for (k, (a, b)) in model.lanes.iter().zip(&closed_form.lanes).enumerate() {
        assert_eq!(a.status, b.status, "lane {k}");
        assert_eq!(a.impacts_per_period, b.impacts_per_period, "lane {k}");
        for (x, y) in a.bifurcation.iter().zip(&b.bifurcation) {
            assert!((x - y).abs() <= 1e-12, "lane {k}: point {x} vs {y}");
        }
        for (x, y) in a.exponents.iter().zip(&b.exponents) {
            assert!(x == y || (x - y).abs() <= 1e-12, "lane {k}: {x} vs {y}");
        }
    }
    assert_eq!(
        model.lanes[0].status,
        LaneStatus::Collapsed { exponents: 2 }
    );
    // Four states, the second mass held on its stop (e = 0: it stops dead
    // and the forcing presses it there): two exponents -∞, the first
    // mass's two against the RK4 path's (1800 steps): measured 4.4e-7 at
    // worst (η = 1.2, a strongly contracting third one), 1.1e-9 where two
    // collapse.
    let chain = |backend: &str| {
        run(&model_scene(
            &file("two-mass-chain.toml"),
            &sweep(&[0.3, 0.5, 0.8, 1.2, 1.6], 1800, backend),
            &["model.parameters.f=3", "model.parameters.e=0"],
        ))
    };
    let (exact, rk4) = (chain("exact"), chain("cpu"));
    let mut held = 0;
    for (k, (a, b)) in exact.lanes.iter().zip(&rk4.lanes).enumerate() {
        assert_eq!(a.status, b.status, "lane {k}");
        held += usize::from(a.status == LaneStatus::Collapsed { exponents: 2 });
        for (x, y) in a.exponents.iter().zip(&b.exponents) {
            assert!(x == y || (x - y).abs() <= 1e-6, "lane {k}: {x} vs {y}");
        }
    }
    assert!(held >= 3, "the sweep must hold the mass on its stop");
}

#[test]
fn sliding_collapses_a_direction_on_both_paths() {
    // Started at rest inside the sticking band |x| < μ - f: it sticks at
    // once and for good (the forcing never overcomes friction).
    let scene = |backend: &str| {
        format!(
            "{}\n[sweep]\nparameter = \"eta\"\nvalues = [0.8]\n[integration]\n\
             steps_per_period = 200\ntransient = 5\nalign = 1\niterations = 5\n\
             initial_state = [0.1, 0.0]\n\
             [output]\nbifurcation_points = 5\n[run]\nbackend = \"{backend}\"\n",
            common::FRICTION
        )
    };
    let cpu = run(&model_scene(&scene("cpu"), "", &[]));
    let lane = &cpu.lanes[0];
    assert_eq!(lane.status, LaneStatus::Collapsed { exponents: 1 });
    assert_eq!(lane.exponents[1], f64::NEG_INFINITY);
    // The mass never moves: its position is kept, its velocity forgotten,
    // so the map is (x, v) → (x, 0) and the surviving exponent is 0.
    assert!(lane.exponents[0].abs() <= 1e-9, "{:?}", lane.exponents);
    assert!(
        lane.bifurcation
            .chunks(2)
            .all(|p| (p[0] - 0.1).abs() <= 1e-12 && p[1].abs() <= 1e-12),
        "{:?}",
        lane.bifurcation
    );
    // The volume law does not apply to a sliding orbit: no expected sum.
    assert!(cpu.expected_sums[0].is_nan());
    // The exact propagator slides in closed form: the same collapse.
    let exact = run(&model_scene(&scene("exact"), "", &[]));
    assert_eq!(
        exact.lanes[0].status,
        LaneStatus::Collapsed { exponents: 1 }
    );
    assert!(exact.lanes[0].exponents[0].abs() <= 1e-12);
}

#[test]
fn stick_slip_on_the_rk4_path_agrees_with_the_exact_backend() {
    // The friction belt with its static limit (mus = 0.6 > mu = 0.5) and
    // with Filippov's rule, across sticking and slipping values of η: the
    // RK4 path's finite differences through entry into sticking, sliding
    // and the exit against the closed form's flow and saltation matrices.
    let etas = [0.3, 0.4, 0.6, 0.8, 1.9];
    for mus in ["0.6", "0.5"] {
        let set = format!("model.parameters.mus={mus}");
        let exact = run(&model_scene(
            &file("friction-belt.toml"),
            &sweep(&etas, 1800, "exact"),
            &[&set],
        ));
        let cpu = run(&model_scene(
            &file("friction-belt.toml"),
            &sweep(&etas, 1800, "cpu"),
            &[&set],
        ));
        let mut sticking = 0;
        for (k, (a, b)) in cpu.lanes.iter().zip(&exact.lanes).enumerate() {
            assert_eq!(a.status, b.status, "mus = {mus}, lane {k}");
            // Where the mass sticks across the period's end, the RK4 path
            // meets the belt again at the period's start (its region is
            // read from the state each period) and counts an entry the
            // closed form, which starts that period sliding, does not.
            if a.status == LaneStatus::Ok {
                assert_eq!(a.crossings_per_period[0], b.crossings_per_period[0]);
            }
            sticking += usize::from(a.exponents[1] == f64::NEG_INFINITY);
            for (x, y) in a.exponents.iter().zip(&b.exponents) {
                assert!(
                    x == y || (x - y).abs() <= 1e-8,
                    "mus = {mus}, η = {}: {:?} vs exact {:?}",
                    etas[k],
                    a.exponents,
                    b.exponents
                );
            }
        }
        assert!(sticking >= 3, "the sweep must exercise sticking");
    }
}

/// The Lyapunov exponents of a smooth forced flow y' = F(t, y) with
/// Jacobian J(t, y) (`field` returns both), integrated with its
/// variational equation Φ' = J·Φ by classical RK4, `steps` steps per
/// period from y = 0, QR accumulated once per period; in QR order.
fn smooth_spectrum<const D: usize>(
    field: impl Fn(f64, &SVector<f64, D>) -> (SVector<f64, D>, SMatrix<f64, D, D>),
    period: f64,
    steps: usize,
    transient: usize,
    iterations: usize,
) -> [f64; D] {
    let h = period / steps as f64;
    let variational = |t: f64, y: &SVector<f64, D>, phi: &SMatrix<f64, D, D>| {
        let (f, jacobian) = field(t, y);
        (f, jacobian * phi)
    };
    let (mut y, mut q) = (SVector::<f64, D>::zeros(), SMatrix::<f64, D, D>::identity());
    let mut logs = [0.0; D];
    // The tool's protocol: the transient's last tenth turns the frame.
    let align = transient.div_ceil(DEFAULT_ALIGN_FRACTION);
    for n in 0..transient + iterations {
        let mut phi = SMatrix::<f64, D, D>::identity();
        for k in 0..steps {
            let t = k as f64 * h;
            let (k1, l1) = variational(t, &y, &phi);
            let (k2, l2) = variational(t + 0.5 * h, &(y + k1 * (0.5 * h)), &(phi + l1 * (0.5 * h)));
            let (k3, l3) = variational(t + 0.5 * h, &(y + k2 * (0.5 * h)), &(phi + l2 * (0.5 * h)));
            let (k4, l4) = variational(t + h, &(y + k3 * h), &(phi + l3 * h));
            y += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
            phi += (l1 + l2 * 2.0 + l3 * 2.0 + l4) * (h / 6.0);
        }
        if n + align >= transient {
            // (Dynamic storage: a static QR needs bounds no const D has.)
            let qr = DMatrix::from_column_slice(D, D, (phi * q).as_slice()).qr();
            let r = qr.r();
            q = SMatrix::from_column_slice(qr.q().as_slice());
            for (i, l) in logs.iter_mut().enumerate() {
                *l += r[(i, i)].abs().ln();
            }
        }
        if n + 1 == transient {
            logs = [0.0; D];
        }
    }
    logs.map(|l| l / (iterations as f64 * period))
}

/// RK4 steps per period that resolve a tanh(s/ε) friction layer's fast
/// time scale ε/μ: h = ε/(20μ), so hλ ≤ 0.05 and RK4's error there is
/// ~1e-7 relative.
fn layer_steps(period: f64, mu: f64, epsilon: f64) -> usize {
    (period * 20.0 * mu / epsilon).ceil() as usize
}

/// The friction oscillator with sign(v - vb) smoothed to tanh((v - vb)/ε)
/// ([`smooth_spectrum`]). Returns (λ1, λ2).
fn smoothed_friction(
    (zeta, mu, vb, f, eta): (f64, f64, f64, f64, f64),
    epsilon: f64,
    transient: usize,
    iterations: usize,
) -> (f64, f64) {
    let period = std::f64::consts::TAU / eta;
    let field = |t: f64, y: &SVector<f64, 2>| {
        let slip = ((y[1] - vb) / epsilon).tanh();
        let jacobian = Matrix2::new(
            0.0,
            1.0,
            -1.0,
            -2.0 * zeta - mu / epsilon * (1.0 - slip * slip),
        );
        (
            Vector2::new(
                y[1],
                -2.0 * zeta * y[1] - y[0] - mu * slip + f * (eta * t).cos(),
            ),
            jacobian,
        )
    };
    let steps = layer_steps(period, mu, epsilon);
    let [l1, l2] = smooth_spectrum(field, period, steps, transient, iterations);
    (l1, l2)
}

#[test]
fn stick_slip_s_largest_exponent_is_the_smoothed_system_s_limit() {
    // Filippov's rule (mus = mu): the smoothed system tanh((v - vb)/ε)
    // tends to it as ε → 0. Its largest exponent converges about linearly
    // in ε here (the rungs' differences halve), so the smoothing error of
    // the finest rung is about the last difference, and the Richardson
    // extrapolate 2λ(ε/2) - λ(ε) removes most of it.
    let (zeta, mu, vb, f) = (0.05, 0.5, 0.2, 1.0);
    for eta in [0.3, 0.4] {
        let body = format!(
            "[sweep]\nparameter = \"eta\"\nvalues = [{eta}]\n[integration]\nsteps_per_period = 1800\n\
             transient = 200\niterations = 300\n[run]\nbackend = \"cpu\"\n"
        );
        let report = run(&model_scene(
            &file("friction-belt.toml"),
            &body,
            &["model.parameters.mus=0.5"],
        ));
        let lane = &report.lanes[0];
        // Sticking collapses the velocity: one exponent is -∞, exactly.
        assert_eq!(
            lane.status,
            LaneStatus::Collapsed { exponents: 1 },
            "η = {eta}"
        );
        assert_eq!(lane.exponents[1], f64::NEG_INFINITY);
        let model = lane.exponents[0];
        let ladder: Vec<f64> = [2e-3, 1e-3, 5e-4]
            .iter()
            .map(|&eps| smoothed_friction((zeta, mu, vb, f, eta), eps, 60, 60).0)
            .collect();
        let (first, last) = (ladder[1] - ladder[0], ladder[2] - ladder[1]);
        assert!(
            last.abs() < 0.7 * first.abs(),
            "η = {eta}: the ladder {ladder:?} converges"
        );
        let smoothing_error = last.abs();
        assert!(
            (model - ladder[2]).abs() <= 2.0 * smoothing_error,
            "η = {eta}: model {model} against the finest rung {ladder:?}"
        );
        let extrapolate = 2.0 * ladder[2] - ladder[1];
        assert!(
            (model - extrapolate).abs() <= 1e-4,
            "η = {eta}: model {model} against the extrapolate {extrapolate} of {ladder:?}"
        );
    }
}

#[test]
fn a_vibrating_table_s_impacts_keep_e_squared_per_impact() {
    // The table's surface and the ball's reset move with the clock: the
    // saltation matrix needs ∂g/∂t and ∂R/∂t, and with them its
    // determinant is e² per impact, as for a fixed wall. Computed crossing
    // by crossing from the general formula, it must equal 2·ln e per impact.
    // (Below a ≈ 1.3 the ball locks onto the table, which general events
    // do not follow: those rows are `chattering`.)
    let body = "[sweep]\nparameter = \"a\"\nvalues = [1.5, 2.5, 3.5, 4.0]\n[integration]\n\
                steps_per_period = 900\ntransient = 100\n\
                iterations = 200\n[run]\nbackend = \"cpu\"\n";
    let report = run(&model_scene(&file("vibrating-table.toml"), body, &[]));
    let e: f64 = 0.8;
    let mut chaotic = 0;
    for (k, (lane, expected)) in report.lanes.iter().zip(&report.expected_sums).enumerate() {
        // A chaotic bounce over 200 iterations is `uncertain` (its λ1's
        // standard error is over a tenth of it); the sum rule is exact all
        // the same.
        let chaotic_enough =
            matches!(lane.status, LaneStatus::Uncertain { .. }) && lane.exponents[0] > 0.0;
        assert!(
            lane.status == LaneStatus::Ok || chaotic_enough,
            "lane {k}: {}",
            lane.status
        );
        let impacts_per_time = lane.crossings_per_period[0] / lane.period;
        assert!(impacts_per_time > 0.0);
        let e_squared = 2.0 * e.ln() * impacts_per_time;
        assert!(
            (expected - e_squared).abs() <= 1e-12,
            "lane {k}: expected sum {expected} against 2 ln e per impact {e_squared}"
        );
        assert!(
            (lane.exponent_sum() - expected).abs() <= 1e-8,
            "lane {k}: sum {} against {expected}",
            lane.exponent_sum()
        );
        chaotic += usize::from(lane.exponents[0] > 0.05);
    }
    assert!(
        chaotic >= 2,
        "the table's chaos: {:?}",
        report
            .lanes
            .iter()
            .map(|l| l.exponents.clone())
            .collect::<Vec<_>>()
    );
}

#[test]
fn model_check_describes_switches_events_and_the_exact_backend() {
    let check = |name: &str| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
            .args(["model", "check", &model_path(name)])
            .output()
            .expect("the binary runs");
        assert!(out.status.success(), "{name}");
        String::from_utf8(out.stdout).expect("utf-8")
    };
    let friction = check("friction-belt.toml");
    for expected in [
        "mu * (2 * step(slip) - 1)",
        "switch 'slip': the field changes where v - vb crosses 0",
        "slides while the mean rate of the two sides is below mus in size",
        "ln|det S| per crossing of the other events and switches",
        "piecewise linear: backend = \"exact\"",
        "GPU: runs on the kernels",
        // CI has a C compiler: the regions' loop is built, not skipped.
        "CPU: the step loop between stops and crossings is built by the C compiler",
        "CPU: a slide on 'slip' is stepped by the C compiler too",
    ] {
        assert!(friction.contains(expected), "{expected:?} in:\n{friction}");
    }
    let blocks = check("two-block-belt.toml");
    let expected =
        "CPU: slides on 'slip1', 'slip2', one or two at once, are stepped by the C compiler too";
    assert!(blocks.contains(expected), "{expected:?} in:\n{blocks}");
    let table = check("vibrating-table.toml");
    for expected in [
        "event 'table' (a general surface): fires where a * cos(w * t) - a - 1 - x crosses 0",
        "reset v -> -e * v - (1 + e) * a * w * sin(w * t)",
    ] {
        assert!(table.contains(expected), "{expected:?} in:\n{table}");
    }
    // A moving surface is not piecewise linear in the state alone.
    assert!(!table.contains("piecewise linear"));
}

/// Two friction-belt oscillators (models/friction-belt.toml) side by side
/// in one four-state model, not coupled: the second with its own belt
/// speed vb2 and forcing amplitude f2. Both slide on their own switch,
/// separately or at once.
const TWO_BELTS: &str = r#"
[model]
name = "two-belts"
states = ["x1", "v1", "x2", "v2"]
[model.parameters]
zeta = 0.05
mu = 0.5
mus = 0.6
vb = 0.2
f = 1.0
vb2 = 0.2
f2 = 1.0
eta = 0.8
[[model.switches]]
name = "slip1"
surface = "v1 - vb"
stick_limit = "mus"
[[model.switches]]
name = "slip2"
surface = "v2 - vb2"
stick_limit = "mus"
[model.equations]
x1 = "v1"
v1 = "-2*zeta*v1 - x1 - mu*sign(slip1) + f*cos(eta*t)"
x2 = "v2"
v2 = "-2*zeta*v2 - x2 - mu*sign(slip2) + f2*cos(eta*t)"
[model.map]
period = "2*pi/eta"
"#;

/// A scene body of one value of η on the CPU, 1800 steps a period.
fn one_eta(eta: f64, transient: usize, iterations: usize) -> String {
    format!(
        "[sweep]\nparameter = \"eta\"\nvalues = [{eta}]\n[integration]\nsteps_per_period = 1800\n\
         submaps = 1\ntransient = {transient}\niterations = {iterations}\n[run]\nbackend = \"cpu\"\n"
    )
}

#[test]
fn two_uncoupled_belts_give_the_union_of_their_spectra() {
    // (vb2, f2) of the second oscillator, and η: both slip throughout;
    // the first sticks once a period and the second slips; both stick, at
    // different times; both stick, at the same time (identical copies).
    let cases = [
        ("1.0", "1.0", 0.8, "both slip"),
        ("1.0", "1.0", 0.4, "the first sticks, the second slips"),
        ("0.2", "1.0", 0.4, "identical, sticking at once"),
        ("0.1", "1.0", 0.4, "both stick, at once for a while"),
        ("0.2", "-1.0", 0.6, "both stick, one after the other"),
    ];
    // Not to the bit: each block's RK4 steps are cut at the other block's
    // crossings, sliding entries and exits (a cut step has another
    // truncation error), and δ is relative to the largest of all four
    // states, not of the block's own two. Measured at 1800 steps a period:
    // 1e-9 where both slip (RK4's truncation at the cuts: 1e-11 at 3600
    // steps), 2.7e-9 at most where they stick (1.9e-9 at 3600 steps: the
    // finite differences' rounding, ε·√steps/δ ≈ 5e-9 relative a period,
    // which the other cuts and δ's scale redistribute).
    let mut worst: f64 = 0.0;
    for (vb2, f2, eta, what) in cases {
        let body = one_eta(eta, 200, 300);
        let pair = run(&model_scene(
            TWO_BELTS,
            &body,
            &[
                &format!("model.parameters.vb2={vb2}"),
                &format!("model.parameters.f2={f2}"),
            ],
        ));
        let first = run(&model_scene(&file("friction-belt.toml"), &body, &[]));
        let second = run(&model_scene(
            &file("friction-belt.toml"),
            &body,
            &[
                &format!("model.parameters.vb={vb2}"),
                &format!("model.parameters.f={f2}"),
            ],
        ));
        let mut union: Vec<f64> = first.lanes[0]
            .exponents
            .iter()
            .chain(&second.lanes[0].exponents)
            .copied()
            .collect();
        union.sort_by(|a, b| b.total_cmp(a));
        let lane = &pair.lanes[0];
        eprintln!(
            "{what}: pair {:?} {} vs union {union:?} ({}, {})",
            lane.exponents, lane.status, first.lanes[0].status, second.lanes[0].status
        );
        let collapsed = union.iter().filter(|x| x.is_infinite()).count();
        let expected = if collapsed == 0 {
            LaneStatus::Ok
        } else {
            LaneStatus::Collapsed {
                exponents: collapsed,
            }
        };
        assert_eq!(lane.status, expected, "{what}");
        // A block that slips has a complex pair of exponents, whose split
        // over a finite window depends on where the frame stands in the
        // pair's plane, and the four-state frame stands elsewhere than each
        // two-state one (docs/VALIDATION.md, "The QR frame's start"): a pair (neighbours of
        // the union within 1e-3) holds its sum to 1e-8 and each exponent to
        // the window's 1/(N·T); the other exponents hold to 1e-8.
        let window = 280.0 * std::f64::consts::TAU / eta;
        let mut groups: Vec<std::ops::Range<usize>> = Vec::new();
        for i in 0..union.len() {
            match groups.last_mut() {
                Some(g) if union[i].is_finite() && (union[i] - union[g.end - 1]).abs() < 1e-3 => {
                    g.end = i + 1
                }
                _ => groups.push(i..i + 1),
            }
        }
        for g in groups.iter().filter(|g| g.len() > 1) {
            let (p, q) = (
                lane.exponents[g.clone()].iter().sum::<f64>(),
                union[g.clone()].iter().sum::<f64>(),
            );
            assert!(
                (p - q).abs() <= 1e-8,
                "{what}: {:?} vs {union:?}",
                lane.exponents
            );
            worst = worst.max((p - q).abs());
            for i in g.clone() {
                let (p, q) = (lane.exponents[i], union[i]);
                assert!((p - q).abs() <= 1.0 / window, "{what}: {p} vs {q}");
            }
        }
        let single: Vec<usize> = groups
            .iter()
            .filter(|g| g.len() == 1)
            .map(|g| g.start)
            .collect();
        for (p, q) in single.iter().map(|&i| (&lane.exponents[i], &union[i])) {
            assert!(
                p == q || (p - q).abs() <= 1e-8,
                "{what}: {:?} vs {union:?}",
                lane.exponents
            );
            if p.is_finite() {
                worst = worst.max((p - q).abs());
            }
        }
    }
    eprintln!("worst difference from the union: {worst:e}");
}

/// The two blocks of models/two-block-belt.toml (γ = 0) with each
/// sign(v_i - vb) smoothed to tanh((v_i - vb)/ε) ([`smooth_spectrum`]):
/// its four exponents in QR order.
fn smoothed_two_blocks(
    (zeta, k, mu, vb, f, eta): (f64, f64, f64, f64, f64, f64),
    epsilon: f64,
    transient: usize,
    iterations: usize,
) -> [f64; 4] {
    let period = std::f64::consts::TAU / eta;
    let field = |t: f64, y: &SVector<f64, 4>| {
        let s1 = ((y[1] - vb) / epsilon).tanh();
        let s2 = ((y[3] - vb) / epsilon).tanh();
        let d1 = -2.0 * zeta - mu / epsilon * (1.0 - s1 * s1);
        let d2 = -2.0 * zeta - mu / epsilon * (1.0 - s2 * s2);
        #[rustfmt::skip]
        let jacobian = Matrix4::new(
            0.0, 1.0, 0.0, 0.0,
            -1.0 - k, d1, k, 0.0,
            0.0, 0.0, 0.0, 1.0,
            k, 0.0, -1.0 - k, d2,
        );
        (
            Vector4::new(
                y[1],
                -2.0 * zeta * y[1] - y[0] - k * (y[0] - y[2]) - mu * s1 + f * (eta * t).cos(),
                y[3],
                -2.0 * zeta * y[3] - y[2] - k * (y[2] - y[0]) - mu * s2,
            ),
            jacobian,
        )
    };
    let steps = layer_steps(period, mu, epsilon);
    smooth_spectrum(field, period, steps, transient, iterations)
}

#[test]
fn two_blocks_leading_exponents_are_the_smoothed_system_s_limit() {
    // Filippov's rule (mus = mu, γ = 0), as for one block: the smoothed
    // system's leading exponents tend to the sliding one's as ε → 0. At
    // η = 0.8 both blocks stick at once for a while each period (two
    // directions lost); at 1.2 one after the other (one lost). Both sides
    // over the same window (60 + 60 periods from rest, the QR frame
    // aligned over the transient's last 6). At 1.2, λ1 and λ2 lie 4e-4
    // apart: over 120 periods the frame does not separate them, and how a
    // window splits their sum depends on where its frame starts (the
    // split moved by 4e-4 when the frame's start changed from I to
    // aligned). Their sum, the growth of areas in the leading plane, is
    // set by the gap to λ3 = -0.62 and settles at once: it is what the
    // window resolves, and what is compared there. The rungs' differences
    // halve about: Aitken's extrapolate of the three finest rungs,
    // λ4 + (λ4 - λ3)/(r - 1) with r the ratio of the differences, is
    // within 1.7e-4 of the sliding model's λ1 at 0.8, and its sum of the
    // leading pair within 5.1e-6 at 1.2.
    let (zeta, k, mu, vb, f) = (0.05, 1.0, 0.5, 0.2, 1.0);
    for (eta, leading) in [(0.8, 1), (1.2, 2)] {
        let report = run(&model_scene(
            &file("two-block-belt.toml"),
            &one_eta(eta, 60, 60),
            &["model.parameters.mus=0.5", "model.parameters.gamma=0"],
        ));
        let lane = &report.lanes[0];
        let model: f64 = lane.exponents[..leading].iter().sum();
        let ladder: Vec<f64> = [1e-3, 5e-4, 2.5e-4]
            .iter()
            .map(|&eps| {
                smoothed_two_blocks((zeta, k, mu, vb, f, eta), eps, 60, 60)[..leading]
                    .iter()
                    .sum()
            })
            .collect();
        let (first, last) = (ladder[1] - ladder[0], ladder[2] - ladder[1]);
        let ratio = first / last;
        let extrapolate = ladder[2] + last / (ratio - 1.0);
        eprintln!(
            "η = {eta}: {:?} {}; leading {leading}: ladder {ladder:?}, extrapolate {extrapolate}, \
             difference {:e}",
            lane.exponents,
            lane.status,
            model - extrapolate
        );
        assert!(ratio > 1.5, "η = {eta}: the ladder {ladder:?} converges");
        assert!(
            (model - extrapolate).abs() <= 0.5 * last.abs().min(4e-4),
            "η = {eta}: model {model} against the extrapolate {extrapolate} of {ladder:?}"
        );
    }
}

#[test]
fn collapsed_exponents_are_minus_infinity_as_many_as_the_jacobians_lose() {
    // The coupled blocks (models/two-block-belt.toml) where both stick at
    // once for a while (η = 0.4, 0.6), one after the other (1.2, 1.5: two
    // sliding phases a period, yet the flow between them couples the
    // blocks and the map loses one direction, not two), and the chaotic
    // stick-slip of the model's own velocity weakening (γ = 1, η = 0.4,
    // two belt speeds). Each iteration's Jacobian, by its singular values,
    // says how many directions it lost: exactly that many exponents are
    // -∞, and the others are far above the finite differences' rounding.
    use lyapsweep::backend::RunOptions;
    let keep = RunOptions {
        keep_jacobians: true,
        ..Default::default()
    };
    let cases: [(&str, &[&str]); 2] = [
        (
            "[sweep]\nparameter = \"eta\"\nvalues = [0.4, 0.6, 1.2, 1.5]",
            &["model.parameters.gamma=0"],
        ),
        ("[sweep]\nparameter = \"vb\"\nvalues = [0.2, 0.45]", &[]),
    ];
    let mut seen = [0usize; 3];
    for (sweep, sets) in cases {
        let body = format!(
            "{sweep}\n[integration]\nsteps_per_period = 900\ntransient = 100\niterations = 150\n\
             [run]\nbackend = \"cpu\"\n"
        );
        let scene = model_scene(&file("two-block-belt.toml"), &body, sets);
        let report = lyapsweep::driver::run_with(&scene, &keep).expect("runs");
        for lane in &report.lanes {
            let lost = lane
                .jacobians
                .chunks(16)
                .map(|j| {
                    let s = nalgebra::Matrix4::from_row_slice(j).singular_values();
                    let largest = s.max();
                    s.iter().filter(|&&x| x < 1e-5 * largest).count()
                })
                .max()
                .unwrap();
            let minus_infinity = lane
                .exponents
                .iter()
                .filter(|x| **x == f64::NEG_INFINITY)
                .count();
            eprintln!("{sweep}: {:?} {}, lost {lost}", lane.exponents, lane.status);
            assert_eq!(minus_infinity, lost, "{:?}", lane.exponents);
            assert_eq!(
                lane.status,
                LaneStatus::Collapsed { exponents: lost },
                "{:?}",
                lane.exponents
            );
            for x in lane.exponents.iter().filter(|x| x.is_finite()) {
                // Rounding would be ln(1e-9) ≈ -21 a period.
                assert!(x * lane.period > -10.0, "{:?}", lane.exponents);
            }
            seen[lost] += 1;
        }
    }
    assert!(seen[1] >= 2 && seen[2] >= 2, "{seen:?}");
}

/// The vibrating table (models/vibrating-table.toml, w = 1) with e = 0.5:
/// the ball's bounces accumulate and it locks onto the table, held there
/// by the table's push while the table's acceleration -a·cos t stays above
/// gravity's -1, released where it falls below (cos t = 1/a).
fn vibrating_table(amplitudes: &[f64]) -> Report {
    let values: Vec<String> = amplitudes.iter().map(|v| v.to_string()).collect();
    let body = format!(
        "[sweep]\nparameter = \"a\"\nvalues = [{}]\n\
         [integration]\nsteps_per_period = 1800\ntransient = 100\niterations = 50\n\
         initial_state = [0.0, 0.0]\n[output]\nbifurcation_points = 50\n[run]\nbackend = \"cpu\"\n",
        values.join(", ")
    );
    run(&model_scene(
        &file("vibrating-table.toml"),
        &body,
        &["model.parameters.e=0.5"],
    ))
}

#[test]
fn a_ball_locked_onto_a_vibrating_table_is_held_there_and_released_on_time() {
    let report = vibrating_table(&[0.8, 1.5]);
    for lane in &report.lanes {
        // Held phases forget both directions: the exponents collapse, and
        // no iteration is left unresolved (before holding, every lane was
        // flagged `chattering`).
        assert!(
            matches!(lane.status, LaneStatus::Collapsed { .. }),
            "{}",
            lane.status
        );
        assert!(lane.exponents.iter().all(|&l| l == f64::NEG_INFINITY));
    }
    // a = 0.8: the table never accelerates down faster than gravity, so
    // the ball stays on it; at t = 0 the table is at x = -1, at rest.
    let held = &report.lanes[0].bifurcation;
    for point in held.chunks(2) {
        assert!(
            (point[0] + 1.0).abs() <= 1e-12 && point[1].abs() <= 1e-12,
            "{point:?}"
        );
    }
    // a = 1.5: released at t_r = -acos(1/a) from the table's state there,
    // it flies freely (x'' = -1, which RK4 integrates exactly) to t = 0:
    // every period the same point, in closed form.
    let a: f64 = 1.5;
    let tau = (1.0 / a).acos();
    let (x_r, v_r) = (a * (1.0 / a) - a - 1.0, a * tau.sin());
    let expected = [x_r + v_r * tau - 0.5 * tau * tau, v_r - tau];
    let released = &report.lanes[1].bifurcation;
    assert_eq!(released.len(), 100);
    for point in released.chunks(2) {
        let error = (point[0] - expected[0])
            .abs()
            .max((point[1] - expected[1]).abs());
        assert!(error <= 1e-10, "{point:?} vs {expected:?}: {error:e}");
    }
    eprintln!("released: {:?} vs closed form {expected:?}", &released[..2]);
}
