//! Models run: the seed oscillator's model (the `impact-oscillator` kind)
//! agrees with the seed's closed form at periodic η; the impact pair and the two-mass chain agree with an
//! independent reference written here (RK4 at 40 000 steps per period with
//! the variational equation, crossings located by bisection, saltation
//! matrices at the stops) and keep the sum rule; a model's parameters are
//! swept and overridden like a built-in's.

mod common;

use lyapsweep::method::LaneStatus;
use lyapsweep::scene::DEFAULT_ALIGN_FRACTION;
use lyapsweep::{scene, Report, Scene};
use nalgebra::{DMatrix, SMatrix, SVector};

fn model_path(name: &str) -> String {
    format!("{}/models/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// A scene running `models/<name>` over `values` of η.
fn model_scene(name: &str, body: &str, overrides: &[&str]) -> Scene {
    let text = format!("model = {:?}\n{body}", model_path(name));
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    scene::parse(&text, "test scene", "test", &overrides).expect("a valid scene")
}

fn run(scene: &Scene) -> Report {
    lyapsweep::run(scene).expect("runs")
}

/// A stop of the reference: wall on `coordinate` (rate `velocity`) at
/// `position`, from `side`, with restitution e.
struct RefStop {
    coordinate: usize,
    velocity: usize,
    side: f64,
    position: f64,
    e: f64,
}

/// An independent reference for a forced flow that is linear between
/// impacts, y' = A·y + b·cos(ηt): RK4 at 40 000 steps per period for the
/// state, the exact flow matrix exp(A·s) (RK4's polynomial, exact to
/// O(s⁵)) for its fundamental matrix, crossings located by bisection on
/// re-stepped RK4 to the last bits, the reset y_v → -e·y_v with Φ → S·Φ,
/// S = DR + (F⁺ - DR·F⁻)·∇gᵀ/(∇g·F⁻), and QR accumulated once per period
/// over `iterations` periods after `transient`, the frame turned over the
/// transient's last tenth first (the tool's protocol). Returns the exponents
/// (sorted) and the crossings per period of each stop.
fn reference_exponents<const N: usize>(
    a: SMatrix<f64, N, N>,
    b: [f64; N],
    eta: f64,
    stops: &[RefStop],
    transient: usize,
    iterations: usize,
) -> (Vec<f64>, Vec<f64>)
where
    nalgebra::Const<N>: nalgebra::DimMin<nalgebra::Const<N>, Output = nalgebra::Const<N>>,
{
    let period = std::f64::consts::TAU / eta;
    let steps = 40_000;
    let h = period / steps as f64;
    let field = |t: f64, y: &SVector<f64, N>| -> SVector<f64, N> {
        a * y + SVector::from(b) * (eta * t).cos()
    };
    let rk4 = |t: f64, y: &SVector<f64, N>, s: f64| -> SVector<f64, N> {
        let k1 = field(t, y);
        let k2 = field(t + 0.5 * s, &(y + k1 * (0.5 * s)));
        let k3 = field(t + 0.5 * s, &(y + k2 * (0.5 * s)));
        let k4 = field(t + s, &(y + k3 * s));
        y + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (s / 6.0)
    };
    let flow_matrix = |s: f64| -> SMatrix<f64, N, N> {
        let m = a * s;
        let m2 = m * m;
        let m3 = m2 * m;
        SMatrix::identity() + m + m2 / 2.0 + m3 / 6.0 + m3 * m / 24.0
    };
    let gap =
        |stop: &RefStop, y: &SVector<f64, N>| stop.side * (y[stop.coordinate] - stop.position);
    let mut y = SVector::<f64, N>::zeros();
    // The frame the tool starts from: a complex pair's split over a finite
    // window depends on it.
    let mut q = lyapsweep::method::qr::generic_frame::<N>();
    let mut logs = [0.0; N];
    let mut crossings = vec![0usize; stops.len()];
    let full_step = flow_matrix(h);
    // The tool's protocol: the transient's last tenth turns the frame.
    let align = transient.div_ceil(DEFAULT_ALIGN_FRACTION);
    for iteration in 0..transient + iterations {
        let averaging = iteration >= transient;
        let mut phi = SMatrix::<f64, N, N>::identity();
        for step in 0..steps {
            let t0 = step as f64 * h;
            let mut done = 0.0;
            let mut y1 = rk4(t0, &y, h);
            // Every crossing inside the step, in order.
            while let Some(j) = stops.iter().position(|s| gap(s, &y1) > 0.0) {
                let stop = &stops[j];
                let (mut lo, mut hi) = (0.0, h - done);
                loop {
                    let mid = 0.5 * (lo + hi);
                    if mid == lo || mid == hi {
                        break;
                    }
                    if gap(stop, &rk4(t0 + done, &y, mid)) > 0.0 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                let mut yc = rk4(t0 + done, &y, hi);
                phi = flow_matrix(hi) * phi;
                done += hi;
                yc[stop.coordinate] = stop.position;
                let before = field(t0 + done, &yc);
                yc[stop.velocity] *= -stop.e;
                let after = field(t0 + done, &yc);
                let mut dr = SMatrix::<f64, N, N>::identity();
                dr[(stop.velocity, stop.velocity)] = -stop.e;
                let mut grad = SMatrix::<f64, 1, N>::zeros();
                grad[(0, stop.coordinate)] = stop.side;
                let rate = stop.side * before[stop.coordinate];
                let saltation = dr + (after - dr * before) * grad / rate;
                phi = saltation * phi;
                if averaging {
                    crossings[j] += 1;
                }
                y = yc;
                y1 = rk4(t0 + done, &y, h - done);
            }
            phi = if done == 0.0 {
                full_step * phi
            } else {
                flow_matrix(h - done) * phi
            };
            y = y1;
        }
        if iteration + align >= transient {
            let qr = DMatrix::from_column_slice(N, N, (phi * q).as_slice()).qr();
            let r = qr.r();
            q = SMatrix::from_column_slice(qr.q().as_slice());
            for (i, l) in logs.iter_mut().enumerate() {
                *l += r[(i, i)].abs().ln();
            }
        }
        if iteration + 1 == transient {
            logs = [0.0; N];
        }
    }
    let mut exponents: Vec<f64> = logs
        .iter()
        .map(|l| l / (iterations as f64 * period))
        .collect();
    exponents.sort_by(|a, b| b.total_cmp(a));
    let per_period = crossings
        .iter()
        .map(|&c| c as f64 / iterations as f64)
        .collect();
    (exponents, per_period)
}

fn assert_agree(report: &Report, references: &[(Vec<f64>, Vec<f64>)], what: &str) {
    for (k, (lane, (exponents, crossings))) in report.lanes.iter().zip(references).enumerate() {
        assert_eq!(lane.status, LaneStatus::Ok, "{what}, lane {k}");
        for (i, c) in crossings.iter().enumerate() {
            assert_eq!(
                lane.crossings_per_period[i], *c,
                "{what}, lane {k}, stop {i}"
            );
        }
        for (x, y) in lane.exponents.iter().zip(exponents) {
            assert!(
                (x - y).abs() <= 1e-7,
                "{what}, lane {k}: model {:?} vs reference {exponents:?}",
                lane.exponents
            );
        }
        let expected = report.expected_sums[k];
        assert!(
            (lane.exponent_sum() - expected).abs() <= 1e-8,
            "{what}, lane {k}: sum {} vs expected {expected}",
            lane.exponent_sum()
        );
        // The reference's sum is the volume law too.
        let reference_sum: f64 = exponents.iter().sum();
        assert!((reference_sum - expected).abs() <= 1e-9, "{what}, lane {k}");
    }
}

const RUN: &str = "[integration]\nsteps_per_period = 1800\ntransient = 200\niterations = 200\n[run]\nbackend = \"cpu\"\n";

#[test]
fn the_impact_pair_agrees_with_an_independent_reference_and_keeps_the_sum_rule() {
    let etas = [0.5, 0.8, 1.2];
    let values: Vec<String> = etas.iter().map(|v| v.to_string()).collect();
    let body = format!(
        "[sweep]\nparameter = \"eta\"\nvalues = [{}]\n{RUN}",
        values.join(", ")
    );
    let report = run(&model_scene("impact-pair.toml", &body, &[]));
    let (zeta, f, gap, e) = (0.05, 1.0, 1.0, 0.8);
    let a = SMatrix::<f64, 2, 2>::from_row_slice(&[0.0, 1.0, -1.0, -2.0 * zeta]);
    let stops = [
        RefStop {
            coordinate: 0,
            velocity: 1,
            side: 1.0,
            position: gap,
            e,
        },
        RefStop {
            coordinate: 0,
            velocity: 1,
            side: -1.0,
            position: -gap,
            e,
        },
    ];
    let references: Vec<_> = etas
        .iter()
        .map(|&eta| reference_exponents(a, [0.0, f], eta, &stops, 200, 200))
        .collect();
    // Both stops are hit at every η.
    assert!(references.iter().all(|(_, c)| c.iter().all(|&c| c >= 1.0)));
    assert_agree(&report, &references, "impact pair");
}

#[test]
fn the_two_mass_chain_has_four_exponents_that_agree_with_an_independent_reference() {
    let etas = [0.6, 0.9, 1.7];
    let values: Vec<String> = etas.iter().map(|v| v.to_string()).collect();
    let body = format!(
        "[sweep]\nparameter = \"eta\"\nvalues = [{}]\n{RUN}",
        values.join(", ")
    );
    let report = run(&model_scene("two-mass-chain.toml", &body, &[]));
    let (zeta, k, m, f, gap, e) = (0.05, 1.0, 1.0, 1.0, 1.0, 0.8);
    #[rustfmt::skip]
    let a = SMatrix::<f64, 4, 4>::from_row_slice(&[
        0.0, 1.0, 0.0, 0.0,
        -1.0 - k, -2.0 * zeta, k, 0.0,
        0.0, 0.0, 0.0, 1.0,
        k / m, 0.0, -k / m, -2.0 * zeta / m,
    ]);
    let stops = [RefStop {
        coordinate: 2,
        velocity: 3,
        side: 1.0,
        position: gap,
        e,
    }];
    let references: Vec<_> = etas
        .iter()
        .map(|&eta| reference_exponents(a, [0.0, f, 0.0, 0.0], eta, &stops, 200, 200))
        .collect();
    assert!(references.iter().all(|(_, c)| c[0] >= 0.5));
    for lane in &report.lanes {
        assert_eq!(lane.exponents.len(), 4);
    }
    assert_agree(&report, &references, "two-mass chain");
}

#[test]
fn a_model_parameter_is_overridden_and_swept_like_a_built_in_s() {
    let body = "[sweep]\nparameter = \"e\"\nvalues = [0.5, 0.9]\n[integration]\nsteps_per_period = 600\ntransient = 100\niterations = 100\n[run]\nbackend = \"cpu\"\n";
    let report = run(&model_scene(
        "impact-pair.toml",
        body,
        &["model.parameters.eta=1.2"],
    ));
    for (lane, (expected, e)) in report
        .lanes
        .iter()
        .zip(report.expected_sums.iter().zip([0.5_f64, 0.9]))
    {
        let crossings: f64 = lane.crossings_per_period[..2].iter().sum();
        assert!(crossings > 0.0);
        let rule = -0.1 + 2.0 * e.ln() * crossings / lane.period;
        assert!((expected - rule).abs() < 1e-14, "{expected} vs {rule}");
        assert!((lane.exponent_sum() - expected).abs() < 1e-6);
        assert!((lane.period - std::f64::consts::TAU / 1.2).abs() < 1e-15);
    }
}

/// The impact pair inline, for malformed variants.
const PAIR: &str = r#"
[model]
name = "impact-pair"
states = ["x", "v"]
[model.parameters]
zeta = 0.05
f = 1.0
gap = 1.0
e = 0.8
eta = 0.8
[model.equations]
x = "v"
v = "-2*zeta*v - x + f*cos(eta*t)"
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
[integration]
steps_per_period = 100
transient = 2
iterations = 2
"#;

/// Runs `scene` with the binary and checks: exit code 2, one line naming
/// `message`, nothing written.
fn refused(scene: &str, extra: &[&str], message: &str) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, scene).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .arg("run")
        .arg(&path)
        .arg("--out")
        .arg(dir.path().join("out"))
        .args(extra)
        .output()
        .expect("the binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{message}: {stderr}");
    assert!(
        stderr.contains(message),
        "expected {message:?} in: {stderr}"
    );
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        !dir.path().join("out").exists(),
        "output written for {message}"
    );
}

/// Edits of the pair model that make it malformed: (text, replacement,
/// the message naming the key).
const MALFORMED: &[(&str, &str, &str)] = &[
        (
            "v = \"-2*zeta*v - x + f*cos(eta*t)\"",
            "v = \"-2*zeta2*v - x + f*cos(eta*t)\"",
            "model.equations.v: unknown name 'zeta2' (column 4)",
        ),
        (
            "x = \"v\"\n",
            "",
            "model.equations: no equation for the state 'x'",
        ),
        (
            "x = \"v\"\n",
            "x = \"v\"\ny = \"x\"\n",
            "model.equations.y: 'y' is not a state",
        ),
        (
            "reset = { v = \"-e*v\" }\n[[",
            "reset = { w = \"-e*v\" }\n[[",
            "model.events[0].reset.w: 'w' is not a state",
        ),
        (
            "zeta = 0.05",
            "zeta = 0.05\nx = 1.0",
            "model.parameters.x: 'x' is both a state and a parameter",
        ),
        (
            "x = \"v\"",
            "x = \"v*t\"",
            "model.equations.x: time may appear only as cos(w*t) or sin(w*t)",
        ),
        (
            "surface = \"x - gap\"",
            "surface = \"x - gap*cos(2*t)\"",
            "model.events[0].surface: a second forcing frequency",
        ),
        (
            "reset = { v = \"-e*v\" }\n[[",
            "reset = { v = \"-e*v*cos(t)\" }\n[[",
            "model.events[0].reset.v: a second forcing frequency",
        ),
        (
            "x = \"v\"\n",
            "x = \"v*step(contact)\"\n",
            "model.equations.x: step(...) takes the name of a switch (the model has none: declare [[model.switches]]) (column 8)",
        ),
        (
            "[model.map]",
            "[[model.switches]]\nname = \"contact\"\nsurface = \"x - t\"\n[model.map]",
            "model.switches[0].surface: may not use the time 't'",
        ),
        (
            "[model.map]",
            "[[model.switches]]\nname = \"zeta\"\nsurface = \"x\"\n[model.map]",
            "model.switches[0].name: 'zeta' is already a state or a parameter",
        ),
        (
            "e = 0.8",
            "e = 1.5",
            "model.events[0].reset.v: the restitution e must lie in [0, 1], got 1.5",
        ),
        (
            "period = \"2*pi/eta\"",
            "period = \"2*pi/(eta - 1)\"",
            "model.map.period: must be a finite number > 0",
        ),
        (
            "name = \"left stop\"",
            "name = \"right-stop\"",
            "model.events[1].name: 'right-stop' names the column right_stop_per_period",
        ),
        // A parameter's allowed range: its table, and its value inside it.
        (
            "zeta = 0.05",
            "zeta = { value = 0.05, min = 1 }",
            "model.parameters.zeta.value: 0.05 lies outside [1, inf]",
        ),
        (
            "zeta = 0.05",
            "zeta = { value = 0.05, min = 1, max = 0 }",
            "model.parameters.zeta: min 1 exceeds max 0",
        ),
        (
            "zeta = 0.05",
            "zeta = { value = 0.05, minimum = 0 }",
            "model.parameters.zeta.minimum: unknown key (a parameter has value, min and max)",
        ),
        (
            "zeta = 0.05",
            "zeta = { min = 0 }",
            "model.parameters.zeta: a parameter's table needs `value`",
        ),
];

#[test]
fn a_malformed_model_is_refused_naming_its_key_and_nothing_is_written() {
    for (from, to, message) in MALFORMED {
        assert!(PAIR.contains(from), "{from}");
        refused(&PAIR.replacen(from, to, 1), &[], message);
    }
}

#[test]
fn a_value_a_model_cannot_take_is_refused_naming_where_it_came_from() {
    // A swept value at which the period is not > 0 is named.
    refused(
        &format!("{PAIR}[sweep]\nparameter = \"eta\"\nvalues = [0.8, -0.5]\n"),
        &[],
        "model.map.period: must be a finite number > 0, got -12.566370614359172 (with eta = -0.5)",
    );
    // A swept or overridden value outside a parameter's range is named.
    let bounded = PAIR.replacen("zeta = 0.05", "zeta = { value = 0.05, min = 0 }", 1);
    refused(
        &format!("{bounded}[sweep]\nparameter = \"zeta\"\nvalues = [0.1, -0.5]\n"),
        &[],
        "sweep.values: zeta = -0.5: zeta must be >= 0, got -0.5",
    );
    refused(
        &bounded,
        &["--set", "model.parameters.zeta=-1"],
        "model.parameters.zeta.value: -1 lies outside [0, inf]",
    );
    // Overrides of a model's parameters are checked like the file.
    refused(
        PAIR,
        &["--set", "model.parameters.e=-0.1"],
        "model.events[0].reset.v",
    );
    refused(
        PAIR,
        &["--set", "model.parameters.zeta2=1"],
        "model.parameters",
    );
    // A model file that is not there, and a scene with both a system and a model.
    refused("model = \"no-such-model.toml\"\n", &[], "model: ");
    refused(
        &format!("[system]\nkind = \"impact-oscillator\"\n{PAIR}"),
        &[],
        "model: a scene gives [system] or [model], not both",
    );
}

#[test]
fn a_model_file_is_read_relative_to_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("models")).unwrap();
    std::fs::copy(
        model_path("impact-pair.toml"),
        dir.path().join("models/pair.toml"),
    )
    .unwrap();
    let scene = dir.path().join("scene.toml");
    std::fs::write(
        &scene,
        "model = \"models/pair.toml\"\n[integration]\nsteps_per_period = 200\ntransient = 10\niterations = 10\n[run]\nbackend = \"cpu\"\n",
    )
    .unwrap();
    let loaded = scene::load(&scene, &["model.parameters.e=0.5".into()]).unwrap();
    assert_eq!(loaded.system.kind, "impact-pair");
    assert_eq!(loaded.params.values[0], 0.5, "e is the first parameter");
    // The written scene holds the model itself, so that it reads back
    // wherever it is copied.
    assert!(
        loaded.source.contains("surface = \"x - gap\""),
        "{}",
        loaded.source
    );
    let report = run(&loaded);
    assert!(report.lanes[0].exponents.iter().all(|e| e.is_finite()));
}

#[test]
fn lorenz_on_its_section_has_the_flow_s_exponents_and_keeps_the_sum_rule() {
    // σ = 10, ρ = 28, β = 8/3 on z = 27: published 0.9056 and -14.5723.
    let body = "[integration]\nsteps_per_period = 2000\ntransient = 100\niterations = 3000\ninitial_state = [1.0, 1.0, 1.0]\n[run]\nbackend = \"cpu\"\n";
    let report = run(&model_scene("lorenz.toml", body, &[]));
    let lane = &report.lanes[0];
    assert_eq!(lane.status, LaneStatus::Ok);
    assert_eq!(lane.exponents.len(), 2);
    assert!(
        (lane.exponents[0] - 0.9056).abs() < 0.01,
        "{:?}",
        lane.exponents
    );
    assert!(
        (lane.exponents[1] + 14.5723).abs() < 0.02,
        "{:?}",
        lane.exponents
    );
    // The sum rule: -(σ + 1 + β) plus the section's flux term, which
    // telescopes to ln |F_z(x_0)/F_z(x_n)| over the averaging time.
    let divergence = -(10.0 + 1.0 + 8.0 / 3.0);
    let expected = report.expected_sums[0];
    assert!(
        (expected - divergence).abs() < 1e-2,
        "flux term {}",
        expected - divergence
    );
    assert!(
        (lane.exponent_sum() - expected).abs() <= 1e-8,
        "sum {} vs expected {expected}",
        lane.exponent_sum()
    );
    // The map period is the mean return time.
    assert!(lane.period > 0.5 && lane.period < 1.0, "{}", lane.period);
}

#[test]
fn rossler_s_strongly_contracting_direction_is_resolved_on_its_section() {
    // a = b = 0.2, c = 5.7: about 0.0714 and -5.39; one return contracts
    // by e^-32, far below what one finite difference resolves.
    let body = "[integration]\nsteps_per_period = 400\ntransient = 100\niterations = 2000\n[run]\nbackend = \"cpu\"\n";
    let report = run(&model_scene("rossler.toml", body, &[]));
    let lane = &report.lanes[0];
    assert_eq!(lane.status, LaneStatus::Ok);
    assert!(
        (lane.exponents[0] - 0.0714).abs() < 0.005,
        "{:?}",
        lane.exponents
    );
    assert!(
        (lane.exponents[1] + 5.39).abs() < 0.02,
        "{:?}",
        lane.exponents
    );
    // Its divergence a + x - c depends on the state: integrated along the
    // reference's returns, with the flux term (measured 2.6e-8 at 400 steps
    // per unit time; RK4's error in the integral).
    let expected = report.expected_sums[0];
    assert!(
        (lane.exponent_sum() - expected).abs() <= 1e-7,
        "sum {} vs expected {expected}",
        lane.exponent_sum()
    );
}

#[test]
fn a_section_needs_an_autonomous_flow_without_events() {
    let lorenz = std::fs::read_to_string(model_path("lorenz.toml")).unwrap();
    let forced = lorenz.replace("x = \"sigma*(y - x)\"", "x = \"sigma*(y - x) + cos(2*t)\"");
    refused(
        &forced,
        &[],
        "model.map.section: a Poincaré section needs an autonomous flow",
    );
    let with_event =
        format!("{lorenz}\n[[model.events]]\nsurface = \"x - 30\"\nreset = {{ y = \"-y\" }}\n");
    refused(
        &with_event,
        &[],
        "model.events: events and switches in a model with a Poincaré section",
    );
    refused(
        &format!("{lorenz}\n[integration]\ninitial_state = [1.0, 1.0]\n"),
        &[],
        "integration.initial_state: lorenz has a 3-dimensional state (a point of the flow from which it reaches its Poincaré section: x, y, z)",
    );
}

fn model_check(path: &std::path::Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(["model", "check"])
        .arg(path)
        .output()
        .expect("the binary runs")
}

#[test]
fn model_check_prints_the_equations_the_sum_rule_the_events_and_the_kernel() {
    let out = model_check(std::path::Path::new(&model_path("impact-pair.toml")));
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8(out.stdout).unwrap();
    for line in [
        "v' = (-2) * zeta * v - x + f * cos(eta * t)",
        "div F = (-2) * zeta (a function of the parameters)",
        "+ 2·ln(e) per impact on 'right stop'",
        "'left stop': x >= -gap, velocity v, reset v -> -(e)·v",
        "GPU: runs on the kernels; the generated system file:",
        "const WALLS: u32 = 2u;",
    ] {
        assert!(text.contains(line), "{line:?} not in:\n{text}");
    }
    // A model the kernels run shows its generated system file.
    let seed = model_check(std::path::Path::new(&model_path("impact-oscillator.toml")));
    let text = String::from_utf8(seed.stdout).unwrap();
    assert!(
        text.contains("fn rhs(p: Params, phase: vec2<real>, y: State) -> State"),
        "{text}"
    );
    assert!(
        text.contains("fn wall_position(p: Params) -> vec4<real>"),
        "{text}"
    );
    let lorenz = model_check(std::path::Path::new(&model_path("lorenz.toml")));
    let text = String::from_utf8(lorenz.stdout).unwrap();
    assert!(
        text.contains("Poincaré section z = rho - 1, crossed increasing; coordinates x, y"),
        "{text}"
    );
    assert!(text.contains("ln|F_z(x_0) / F_z(x_n)|"), "{text}");
    assert!(
        text.contains("GPU: runs on the section kernel")
            && text.contains("const SECTION_STATE: u32 = 2u;"),
        "{text}"
    );
    // A problem is reported with its key and column, exit code 2.
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, PAIR.replace("-2*zeta*v", "-2*zeta2*v")).unwrap();
    let out = model_check(&bad);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("model.equations.v: unknown name 'zeta2' (column 4)"),
        "{stderr}"
    );
}

#[test]
fn an_angle_is_wrapped_after_the_jacobian_and_keeps_the_pendulum_s_sum_rule() {
    // f through the cascade into chaos, where the pendulum goes over the
    // top and θ winds without bound unless wrapped.
    let body = "[sweep]\nparameter = \"f\"\nfrom = 0.5\nto = 1.5\ncount = 64\n[integration]\ntransient = 100\niterations = 100\n[output]\nbifurcation_points = 20\n[run]\nbackend = \"cpu\"\n";
    let wrapped = run(&model_scene("forced-pendulum.toml", body, &[]));
    let unwrapped = {
        let file = std::fs::read_to_string(model_path("forced-pendulum.toml")).unwrap();
        let text = format!("{}\n{body}", file.replace("angles = [\"theta\"]\n", ""));
        run(&scene::parse(&text, "test", "test", &[]).unwrap())
    };
    let worst = |r: &Report| r.max_sum_error().unwrap();
    for lane in &wrapped.lanes {
        for theta in lane.bifurcation.chunks_exact(2).map(|p| p[0]) {
            assert!(
                (-std::f64::consts::PI..std::f64::consts::PI).contains(&theta),
                "θ = {theta}"
            );
        }
    }
    assert!(
        unwrapped
            .lanes
            .iter()
            .any(|l| l.bifurcation.chunks_exact(2).any(|p| p[0].abs() > 100.0)),
        "the sweep must contain rotating lanes"
    );
    // Measured: 6.4e-6 wrapped, 8.8e-5 unwrapped (δ grown with θ). Both
    // re-estimate the iterations whose central copies turn out asymmetric
    // (`jacobian::Copies::difference`), which rescues much of the
    // unwrapped run (2.8e-2 with every iteration kept) but not all of it.
    assert!(worst(&wrapped) < 2e-5, "{}", worst(&wrapped));
    assert!(
        worst(&unwrapped) > 10.0 * worst(&wrapped),
        "{} vs {}",
        worst(&unwrapped),
        worst(&wrapped)
    );
}

#[test]
fn a_state_dependent_divergence_is_averaged_along_a_period_map_s_reference() {
    // van der Pol: div F = μ(1 - x²), far from constant on the relaxation
    // cycle. Its contraction is on the cycle, not at the (unstable)
    // origin: the plan finds it from a pilot along the orbit and cuts the
    // iterations into parts by itself (lanes `unresolved` before it did).
    let body = "[sweep]\nparameter = \"eta\"\nvalues = [1.0, 1.5, 2.0]\n[integration]\nsteps_per_period = 1800\ntransient = 100\niterations = 100\n[run]\nbackend = \"cpu\"\n";
    // Measured: 1.3e-6 with the plan's parts (up to 7), 2.4e-7 with 16:
    // the finite difference across a part that contracts more is noisier.
    for (submaps, tolerance) in [(None, 3e-6), (Some(16), 1e-6)] {
        let overrides: Vec<String> = submaps
            .map(|n| format!("integration.submaps={n}"))
            .into_iter()
            .collect();
        let overrides: Vec<&str> = overrides.iter().map(String::as_str).collect();
        let report = run(&model_scene("van-der-pol.toml", body, &overrides));
        for (lane, expected) in report.lanes.iter().zip(&report.expected_sums) {
            assert_eq!(lane.status, LaneStatus::Ok);
            assert!(lane.plan.parts > 1, "{:?}", lane.plan);
            // μ = 3 at x = 0; the average over the cycle is far below.
            assert!(*expected < -1.0, "{expected}");
            assert!(
                (lane.exponent_sum() - expected).abs() <= tolerance,
                "{submaps:?}: sum {} vs expected {expected}",
                lane.exponent_sum()
            );
        }
    }
}

#[test]
fn the_seed_oscillator_as_a_model_agrees_with_its_closed_form_at_periodic_eta() {
    // The seed's hand-written closed form (the kind's exact backend) is the
    // ground truth; the kind's model file is integrated by RK4 at the
    // paper's 1800 steps.
    let etas = [0.8, 0.95, 1.1, 1.25, 1.5];
    let values: Vec<String> = etas.iter().map(|v| v.to_string()).collect();
    let body = format!(
        "[sweep]\nparameter = \"eta\"\nvalues = [{}]\n[integration]\nsteps_per_period = 1800\ntransient = 500\niterations = 1000\n",
        values.join(", ")
    );
    let model = run(&model_scene(
        "impact-oscillator.toml",
        &format!("{body}[run]\nbackend = \"cpu\"\n"),
        &[],
    ));
    let closed = run(&common::scene(
        &format!("[system]\nkind = \"impact-oscillator\"\n{body}[run]\nbackend = \"exact\"\n"),
        &[],
    ));
    let mut worst: f64 = 0.0;
    for (a, b) in model.lanes.iter().zip(&closed.lanes) {
        assert_eq!(a.status, LaneStatus::Ok);
        assert_eq!(a.impacts_per_period, b.impacts_per_period);
        for (x, y) in a.exponents.iter().zip(&b.exponents) {
            worst = worst.max((x - y).abs());
        }
    }
    assert!(worst <= 1e-9, "model against the closed form: {worst:e}");
}

#[test]
fn a_mass_that_sticks_to_its_stop_collapses_its_own_two_exponents_only() {
    // e = 0 on the chain's stop: at η = 0.6 the second mass is pressed onto
    // the stop and rests there while the first moves on (the held flow),
    // so its position and velocity are forgotten (two exponents -∞) and
    // the first mass's two stay finite.
    let body = "[sweep]\nparameter = \"eta\"\nvalues = [0.6]\n[integration]\ntransient = 100\niterations = 100\n[run]\nbackend = \"cpu\"\n";
    let report = run(&model_scene(
        "two-mass-chain.toml",
        body,
        &["model.parameters.e=0.0"],
    ));
    let lane = &report.lanes[0];
    assert_eq!(lane.status, LaneStatus::Collapsed { exponents: 2 });
    assert!(
        lane.exponents[..2]
            .iter()
            .all(|e| e.is_finite() && *e < 0.0),
        "{:?}",
        lane.exponents
    );
    assert!(lane.exponents[2..].iter().all(|e| *e == f64::NEG_INFINITY));
    assert!(lane.crossings_per_period[0] > 0.0);
}
