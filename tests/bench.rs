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
