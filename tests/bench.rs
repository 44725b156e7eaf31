//! `lyapsweep bench`: the error-against-time study measures against the
//! exact backend, not against itself, and writes its three outputs.

use lyapsweep::bench::{self, Plan, PERIODIC};
use lyapsweep::integrate::ImpactLocation;
use lyapsweep::scene::Backend;

#[test]
fn errors_are_measured_against_the_exact_backend() {
    let plan = Plan::new(true, false, false);
    let ms = bench::run(&plan).expect("the quick study runs");
    assert_eq!(ms.len(), plan.configs.len());

    // Recompute one configuration's periodic error independently.
    let linear = ms
        .iter()
        .find(|m| m.config.backend == Backend::Cpu && m.config.location == ImpactLocation::Linear)
        .unwrap();
    let values: Vec<String> = PERIODIC.iter().map(|v| format!("{v}")).collect();
    let text = format!(
        "[system]\nkind = \"impact-oscillator\"\n[sweep]\nvalues = [{}]\n[integration]\ntransient = {}\niterations = {}\nsteps_per_period = {}\nimpact_location = \"linear\"\ndifference = \"{}\"\nperturbation = {:e}\n",
        values.join(", "),
        plan.transient,
        plan.iterations,
        linear.config.steps,
        linear.config.difference.name(),
        linear.config.perturbation
    );
    let run = |backend: &str| {
        let overrides = [format!("run.backend=\"{backend}\"")];
        lyapsweep::run(&lyapsweep::scene::parse(&text, "t", "t", &overrides).unwrap()).unwrap()
    };
    let (cpu, exact) = (run("cpu"), run("exact"));
    let expected = cpu
        .lanes
        .iter()
        .zip(&exact.lanes)
        .flat_map(|(a, b)| {
            a.exponents
                .iter()
                .zip(&b.exponents)
                .map(|(x, y)| (x - y).abs())
        })
        .fold(0.0, f64::max);
    assert_eq!(linear.periodic_error, expected);
    assert!(
        expected > 1e-5,
        "linear location at {} steps must show its error: {expected:e}",
        linear.config.steps
    );

    // The exact backend against itself is exact; the newton location at the
    // same steps is far better than linear: errors are not self-comparisons.
    let exact_row = ms
        .iter()
        .find(|m| m.config.backend == Backend::Exact)
        .unwrap();
    assert_eq!(exact_row.periodic_error, 0.0);
    let newton = ms
        .iter()
        .find(|m| {
            m.config.backend == Backend::Cpu
                && m.config.location == ImpactLocation::Newton
                && m.config.steps == linear.config.steps
                && m.config.perturbation == linear.config.perturbation
        })
        .unwrap();
    assert!(newton.periodic_error * 10.0 < linear.periodic_error);
    assert!(ms.iter().any(|m| m.pareto));
    assert!(ms.iter().all(|m| m.seconds > 0.0 && m.error().is_finite()));
}

#[test]
fn the_quick_bench_command_writes_csv_markdown_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(["bench", "--quick", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    assert!(csv.starts_with(
        "path,steps_per_period,impact_location,perturbation,difference,periodic_error,chaotic_sum_error,grazing_sum_error,sweep_sum_error,error,seconds,device_seconds,lane_steps,pareto\n"
    ));
    assert!(csv.lines().count() > 8);
    let md = std::fs::read_to_string(dir.path().join("bench.md")).unwrap();
    assert!(md.contains("Fastest configuration per error target") && md.contains("| 1e-7 |"));
    let png = std::fs::read(dir.path().join("bench.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert!(
        png.len() > 10_000,
        "a plot with points and labels, not a blank image"
    );
}

/// `lyapsweep bench SCENE`: the same study on a piecewise-linear model
/// (the soft stop), against the exact backend the model's linearity gives.
#[test]
fn a_piecewise_linear_scene_is_measured_against_its_exact_backend() {
    use lyapsweep::bench::Subject;
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("soft-stop.toml");
    let model = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/soft-stop.toml");
    std::fs::write(
        &scene,
        format!(
            "model = {model:?}\n[sweep]\nparameter = \"eta\"\nvalues = [0.6, 1.0, 2.2]\n\
             [integration]\ntransient = 50\niterations = 100\n"
        ),
    )
    .unwrap();
    let plan = Plan::on_scene(true, false, false, &scene).expect("a scene with an exact backend");
    assert_eq!(plan.subject, Subject::Scene(scene.clone()));
    let ms = bench::run(&plan).expect("the quick study runs");
    let exact_row = ms
        .iter()
        .find(|m| m.config.backend == Backend::Exact)
        .unwrap();
    assert_eq!(exact_row.periodic_error, 0.0);
    // The seed's chaotic and grazing points have no counterpart on a scene.
    assert!(ms
        .iter()
        .all(|m| m.chaotic_sum_error.is_nan() && m.grazing_sum_error.is_nan()));
    // RK4 with newton location against the closed form: the periodic error
    // is RK4's (2.6e-7 measured on six η, at the steps the plan raises these lanes
    // to); linear location (the paper's) is far worse at a switch.
    let worst = |location: ImpactLocation| {
        ms.iter()
            .filter(|m| m.config.backend == Backend::Cpu && m.config.location == location)
            .map(|m| m.periodic_error)
            .fold(0.0, f64::max)
    };
    let (newton, linear) = (worst(ImpactLocation::Newton), worst(ImpactLocation::Linear));
    assert!(newton > 0.0 && newton < 1e-6, "newton: {newton:e}");
    assert!(
        linear > 100.0 * newton,
        "linear {linear:e} against newton {newton:e}"
    );
    assert!(ms.iter().all(|m| m.error().is_finite()));

    // A system without an exact backend is refused, naming the command.
    let lorenz = dir.path().join("lorenz.toml");
    std::fs::write(&lorenz, "[system]\nkind = \"lorenz\"\n").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .arg("bench")
        .arg(&lorenz)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("bench") && stderr.contains("no exact backend"),
        "{stderr}"
    );
}
