//! Models at and past what the language takes, and rows a user would take
//! on trust: refused with exit code 2, the key and the reason, nothing
//! written and never a panic or an abort; or run, with exponents that are
//! right or a status that says why not.

mod common;

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use lyapsweep::scene::Precision;

/// The seed's impact oscillator as a model; `V`, `SURFACE`, `RESET` and
/// `PERIOD` are replaced by the tests.
const OSCILLATOR: &str = r#"
[model]
name = "oscillator"
states = ["x", "v"]
[model.parameters]
zeta = 0.05
f = 1.0
eta = 0.8
[model.equations]
x = "v"
v = "V"
[model.map]
period = "PERIOD"
[[model.events]]
name = "wall"
surface = "SURFACE"
reset = { v = "RESET" }
"#;

const PLAIN_V: &str = "-2*zeta*v - x + f*cos(eta*t)";

fn oscillator(v: &str, surface: &str, reset: &str, period: &str) -> String {
    OSCILLATOR
        .replace("V\"", &format!("{v}\""))
        .replace("SURFACE", surface)
        .replace("RESET", reset)
        .replace("PERIOD", period)
}

fn plain() -> String {
    oscillator(PLAIN_V, "x - 2", "-v", "2*pi/eta")
}

/// A scene of a few values of `parameter` on the model in `model.toml`.
fn scene(parameter: &str, values: &str, integration: &str) -> String {
    format!(
        "name = \"limits\"\nmodel = \"model.toml\"\n[sweep]\nparameter = \"{parameter}\"\n\
         values = {values}\n[integration]\n{integration}\n[output]\nplot = false\n"
    )
}

const SHORT: &str = "transient = 20\niterations = 50\ninitial_state = [0.0, 0.0]";

fn lyapsweep(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("the binary runs")
}

/// `model check` and `run` of `model` both refuse it with exit code 2, one
/// line naming `key` and saying `reason`, and write nothing.
fn refused(model: &str, key: &str, reason: &str) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.toml"), model).unwrap();
    std::fs::write(dir.path().join("scene.toml"), scene("eta", "[0.8]", SHORT)).unwrap();
    for args in [
        &["model", "check", "model.toml"][..],
        &[
            "run",
            "scene.toml",
            "--out",
            "out",
            "--backend",
            "cpu",
            "-q",
        ][..],
    ] {
        let out = lyapsweep(dir.path(), args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        // A run names the model's file too.
        let named = [
            format!("error: {key}: "),
            format!("error: {key} in model.toml: "),
        ];
        assert!(
            named.iter().any(|n| stderr.starts_with(n)) && stderr.contains(reason),
            "{args:?} should name {key} and say {reason:?}: {stderr}"
        );
        assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
        assert!(
            stderr.len() < 1000,
            "the message echoes the input: {stderr}"
        );
    }
    assert!(!dir.path().join("out").exists(), "output written for {key}");
}

/// Runs `scene` on `model` with `args`; returns the exit code, stderr and
/// spectrum.csv's rows (split at commas).
fn run(model: &str, scene: &str, args: &[&str]) -> (Option<i32>, String, Vec<Vec<String>>) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.toml"), model).unwrap();
    std::fs::write(dir.path().join("scene.toml"), scene).unwrap();
    let mut all = vec!["run", "scene.toml", "--out", "out", "-q"];
    all.extend(args);
    let out = lyapsweep(dir.path(), &all);
    let rows = std::fs::read_to_string(dir.path().join("out/spectrum.csv"))
        .unwrap_or_default()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
        rows,
    )
}

fn numbers(row: &[String], columns: std::ops::Range<usize>) -> Vec<f64> {
    row[columns].iter().map(|v| v.parse().unwrap()).collect()
}

#[test]
fn deep_and_long_expressions_are_refused_in_linear_time() {
    let deep = |open: &str, close: &str, n: usize| {
        format!("{}{PLAIN_V}{}", open.repeat(n), close.repeat(n))
    };
    let cases = [
        // Nested past the depth at which the stack overflowed (8 000) and
        // within the length limit.
        (
            "9 000 parentheses",
            deep("(", ")", 9_000),
            "nested more than 1000",
        ),
        (
            "sin 3 000 deep",
            deep("sin(", ")", 3_000),
            "nested more than 1000",
        ),
        (
            "10 000 minus signs",
            deep("-", "", 10_000),
            "nested more than 1000",
        ),
        (
            "a tower of powers",
            format!("x{}", "^x".repeat(9_000)),
            "nested more than 1000",
        ),
        (
            "sin 10 000 deep",
            deep("sin(", ")", 10_000),
            "longer than 20000",
        ),
        (
            "a flat sum of 1 MB",
            format!("{PLAIN_V}{}", " + x".repeat(250_000)),
            "longer than 20000",
        ),
        (
            "30 000 terms",
            format!("{PLAIN_V}{}", "+x".repeat(30_000)),
            "longer than 20000",
        ),
        (
            "a sum 2 000 levels deep",
            format!("{PLAIN_V}{}", "+x".repeat(2_000)),
            "levels deep",
        ),
    ];
    for (what, text, reason) in &cases {
        let places = [
            (
                "model.equations.v",
                oscillator(text, "x - 2", "-v", "2*pi/eta"),
            ),
            (
                "model.events[0].surface",
                oscillator(PLAIN_V, text, "-v", "2*pi/eta"),
            ),
            (
                "model.events[0].reset.v",
                oscillator(PLAIN_V, "x - 2", text, "2*pi/eta"),
            ),
        ];
        for (key, model) in &places {
            let start = Instant::now();
            refused(model, key, reason);
            // Two processes, each refusing at once (0.01 s measured): a
            // quadratic or recursive refusal of 1 MB takes seconds or aborts.
            assert!(
                start.elapsed() < Duration::from_secs(5),
                "{what} at {key} took {:?}",
                start.elapsed()
            );
        }
    }
    let period = oscillator(
        PLAIN_V,
        "x - 2",
        "-v",
        &deep("(", ")", 9_000).replace(PLAIN_V, "2*pi/eta"),
    );
    refused(&period, "model.map.period", "nested more than 1000");
}

#[test]
fn expressions_at_the_limits_run_to_the_plain_model_s_bits() {
    let scene = scene("eta", "[0.8, 1.3]", SHORT);
    let (code, stderr, reference) = run(&plain(), &scene, &["--backend", "cpu"]);
    assert_eq!(code, Some(0), "{stderr}");
    // The expression, 998 parentheses and the argument of cos inside them:
    // 1000 levels, the limit.
    let nested = format!("{}{PLAIN_V}{}", "(".repeat(998), ")".repeat(998));
    // A sum 205 levels deep: the CPU runs it, the GPU's WGSL compiler
    // cannot, and x - x adds exactly 0 to every evaluation.
    let long = format!("{PLAIN_V}{}", " + (x - x)".repeat(200));
    for v in [&nested, &long] {
        let model = oscillator(v, "x - 2", "-v", "2*pi/eta");
        let (code, stderr, rows) = run(&model, &scene, &["--backend", "cpu"]);
        assert_eq!(code, Some(0), "{stderr}");
        assert_eq!(rows, reference, "the same numbers as the plain model");
    }
    let over = format!("{}{PLAIN_V}{}", "(".repeat(999), ")".repeat(999));
    refused(
        &oscillator(&over, "x - 2", "-v", "2*pi/eta"),
        "model.equations.v",
        "nested more than 1000 levels deep",
    );
    // The GPU refuses what its compiler cannot take, saying so, before any work.
    if !common::gpu_or_skip("expressions_at_the_limits", Precision::F64) {
        return;
    }
    let model = oscillator(&long, "x - 2", "-v", "2*pi/eta");
    let (code, stderr, rows) = run(&model, &scene, &["--backend", "gpu"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("levels deep: the GPU kernels' WGSL compiler takes 150"),
        "{stderr}"
    );
    assert!(rows.is_empty());
}

/// A model with a switch `c` (the sign of v) beside the wall, `text` put in
/// at `place`.
fn switched(place: &str, text: &str) -> String {
    let mut model = plain();
    model = model.replace(
        "[model.map]",
        "[[model.switches]]\nname = \"c\"\nsurface = \"SWITCH\"\nLIMIT\n[model.map]",
    );
    let surface = if place == "switch" { text } else { "v" };
    let limit = if place == "limit" {
        format!("stick_limit = \"{text}\"")
    } else {
        String::new()
    };
    model = model.replace("SWITCH", surface).replace("LIMIT", &limit);
    match place {
        "surface" => model.replace("\"x - 2\"", &format!("\"{text}\"")),
        "reset" => model.replace("\"-v\"", &format!("\"{text}\"")),
        "period" => model.replace("\"2*pi/eta\"", &format!("\"{text}\"")),
        _ => model,
    }
}

#[test]
fn only_the_equations_read_a_switch_s_side() {
    let reason = "may not read the switch 'c' (step or sign)";
    refused(
        &switched("reset", "-v*step(c)"),
        "model.events[0].reset.v",
        reason,
    );
    refused(
        &switched("reset", "-v*sign(c)"),
        "model.events[0].reset.v",
        reason,
    );
    refused(
        &switched("surface", "x - 2*step(c)"),
        "model.events[0].surface",
        reason,
    );
    refused(
        &switched("switch", "v*sign(c)"),
        "model.switches[0].surface",
        reason,
    );
    refused(
        &switched("limit", "step(c)"),
        "model.switches[0].stick_limit",
        reason,
    );
    refused(
        &switched("period", "2*pi/eta*step(c)"),
        "model.map.period",
        reason,
    );
    // The equations may: the model runs.
    let model = switched("", "").replace(PLAIN_V, "-2*zeta*v - x + f*cos(eta*t) + 0.01*sign(c)");
    let (code, stderr, rows) = run(&model, &scene("eta", "[0.8]", SHORT), &["--backend", "cpu"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(rows.len(), 1);
}

/// x_i' = -a_i x_i + cos t, i = 1..n: the period map contracts each state
/// by exp(-2π a_i) exactly, so the exponents are -a_i.
fn decoupled(n: usize) -> String {
    let states: Vec<String> = (1..=n).map(|i| format!("x{i}")).collect();
    let mut model = format!(
        "[model]\nname = \"decoupled\"\nstates = {states:?}\n[model.parameters]\nw = 1.0\n\
         [model.equations]\n"
    );
    for (i, s) in states.iter().enumerate() {
        model += &format!("{s} = \"-{}*{s} + cos(w*t)\"\n", 0.1 * (i + 1) as f64);
    }
    model + "[model.map]\nperiod = \"2*pi/w\"\n"
}

#[test]
fn five_and_six_state_period_maps_run() {
    for n in [5, 6] {
        // The whole transient turns the frame: the exponents' gaps, 0.1 per
        // unit time, align it to e^-38 over 60 periods.
        let integration = format!(
            "transient = 60\nalign = 60\niterations = 40\ninitial_state = {:?}",
            vec![0.5; n]
        );
        for backend in ["cpu", "auto"] {
            let (code, stderr, rows) = run(
                &decoupled(n),
                &scene("w", "[1.0]", &integration),
                &["--backend", backend],
            );
            assert_eq!(code, Some(0), "{n} states on {backend}: {stderr}");
            let exponents = numbers(&rows[0], 1..1 + n);
            for (i, l) in exponents.iter().enumerate() {
                let exact = -(0.1 * (i + 1) as f64);
                assert!(
                    (l - exact).abs() < 1e-9,
                    "{n} states: λ{} = {l}, not {exact}",
                    i + 1
                );
            }
            assert_eq!(rows[0].last().unwrap(), "ok");
        }
    }
}

const LORENZ_AND_A_DECAYING_STATE: &str = r#"
[model]
name = "lorenz-r"
states = ["x", "y", "z", "r"]
[model.parameters]
sigma = 10.0
rho = 27.0
beta = 2.6666666666666665
[model.equations]
x = "sigma*(y - x)"
y = "x*(rho - z) - y"
z = "x*y - beta*z"
r = "-5*r"
[model.map]
section = { state = "z", at = "rho - 1", direction = "increasing" }
"#;

#[test]
fn a_state_the_rest_barely_feeds_gets_its_own_exponent() {
    // From the identity frame, r = 1 (1e-152 by the averaging) left the
    // frame's first two columns in the Lorenz plane: λ2 = -5.865 for -5.
    let spectrum = |r: &str| {
        let integration =
            format!("transient = 100\niterations = 400\ninitial_state = [1.0, 1.0, 1.0, {r}]");
        let (code, stderr, rows) = run(
            LORENZ_AND_A_DECAYING_STATE,
            &scene("rho", "[27.0]", &integration),
            &["--backend", "cpu"],
        );
        assert_eq!(code, Some(0), "{stderr}");
        assert_eq!(rows[0].last().unwrap(), "ok");
        numbers(&rows[0], 1..4)
    };
    let decoupled = spectrum("0.0");
    for r in ["1.0", "1e-300"] {
        let with_r = spectrum(r);
        assert!(
            (with_r[1] + 5.0).abs() < 1e-6,
            "r(0) = {r}: λ2 = {}",
            with_r[1]
        );
        for (a, b) in with_r.iter().zip(&decoupled) {
            assert!(
                (a - b).abs() < 1e-6,
                "r(0) = {r}: {with_r:?} against {decoupled:?}"
            );
        }
    }
    assert!((decoupled[0] - 0.877).abs() < 1e-3 && (decoupled[2] + 14.543).abs() < 1e-3);
}

const DADRAS: &str = r#"
[model]
name = "dadras"
states = ["x", "y", "z"]
[model.parameters]
p = 3.0
o = 2.7
r = 1.7
c = 2.0
e = 9.0
period = 0.5
[model.equations]
x = "y - p*x + o*y*z"
y = "r*y - x*z + z"
z = "c*x*y - e*z"
[model.map]
period = "period"
"#;

#[test]
fn a_flow_expanding_in_bursts_meets_its_sum_rule_and_a_row_that_misses_it_does_not_say_ok() {
    let integration = "transient = 200\niterations = 16000\n\
                       initial_state = [1.0284085, -3.5348655, -0.72081646]";
    let scene = scene("p", "[3.0]", integration);
    let sum_error = |row: &[String]| {
        let [sum, expected] = numbers(row, 4..6)[..] else {
            unreachable!()
        };
        (sum - expected).abs()
    };
    // Default settings: bursts of expansion within one period of 0.5 carry
    // the central copies at δ = 1e-6 out of the linear regime in a few
    // iterations (their miss was 1.8e-5 with every iteration kept). Their
    // asymmetry |U₊ + U₋ - 2U₀| / |U₊ - U₋| finds them, and the δ ladder
    // re-estimates them: within the rule, ok, on either path to the bit.
    let gpu = common::gpu_or_skip("a_flow_expanding_in_bursts", Precision::F64);
    let mut rows_of = Vec::new();
    for backend in ["cpu", "gpu"].into_iter().filter(|&b| b == "cpu" || gpu) {
        let (code, stderr, rows) = run(DADRAS, &scene, &["--backend", backend]);
        assert_eq!(code, Some(0), "{stderr}");
        assert!(sum_error(&rows[0]) < 1e-6, "{backend}: {rows:?}");
        assert_eq!(rows[0].last().unwrap(), "ok", "{backend}");
        let grazing: usize = rows[0][8].parse().unwrap();
        assert!(grazing > 0, "{backend}: no iteration re-estimated");
        rows_of.push(rows);
    }
    if let [cpu, gpu] = &rows_of[..] {
        assert_eq!(cpu, gpu, "the GPU's f64 rows are the CPU's");
    }
    // Forward differences have no second copy to measure the departure
    // with: their miss is the truncation's O(δ·growth), and the row says so.
    let (code, stderr, rows) = run(
        DADRAS,
        &scene,
        &[
            "--backend",
            "cpu",
            "--set",
            "integration.difference=forward",
        ],
    );
    assert_eq!(code, Some(0), "{stderr}");
    let miss = sum_error(&rows[0]);
    let scale: f64 = numbers(&rows[0], 1..4).iter().map(|l| l.abs()).sum();
    assert!(
        miss > 1e-6 * scale,
        "forward differences now meet the rule ({miss:e})"
    );
    assert_eq!(
        rows[0].last().unwrap(),
        &format!("sum-rule(miss={miss:.1e})")
    );
}

#[test]
fn a_section_never_reached_says_no_return() {
    let model = "[model]\nname = \"away\"\nstates = [\"x\", \"y\"]\n[model.parameters]\na = 1.0\n\
                 [model.equations]\nx = \"-x\"\ny = \"-y\"\n[model.map]\nsection = { state = \"x\", at = \"a\" }\n";
    let integration = "transient = 5\niterations = 10\ninitial_state = [0.5, 0.5]";
    let gpu = common::gpu_or_skip("a_section_never_reached", Precision::F64);
    for backend in ["cpu", "gpu"].into_iter().filter(|&b| b == "cpu" || gpu) {
        let (code, stderr, rows) = run(
            model,
            &scene("a", "[1.0, 2.0]", integration),
            &["--backend", backend],
        );
        assert_eq!(code, Some(1), "{stderr}");
        assert!(
            stderr.contains("every lane failed (2 no-return)"),
            "{stderr}"
        );
        for row in &rows {
            assert_eq!(row.last().unwrap(), "no-return(iteration=0)", "{backend}");
        }
    }
}

#[test]
fn numbers_surfaces_names_and_limits_that_mean_nothing_are_refused() {
    refused(
        &oscillator(
            "-2*zeta*v - x + 1e999*cos(eta*t)",
            "x - 2",
            "-v",
            "2*pi/eta",
        ),
        "model.equations.v",
        "'1e999' is beyond the largest number",
    );
    for surface in ["0", "x - x", "2*zeta", "0*x"] {
        refused(
            &oscillator(PLAIN_V, surface, "-v", "2*pi/eta"),
            "model.events[0].surface",
            "does not depend on the state or the time",
        );
        refused(
            &switched("switch", surface),
            "model.switches[0].surface",
            "does not depend on the state",
        );
    }
    for name in ["", " ", "--"] {
        refused(
            &plain().replace("name = \"wall\"", &format!("name = \"{name}\"")),
            "model.events[0].name",
            "has no letter or digit",
        );
    }
    refused(
        &switched("limit", "-1"),
        "model.switches[0].stick_limit",
        "must be a finite number ≥ 0",
    );
    refused(
        &switched("limit", "zeta - 1"),
        "model.switches[0].stick_limit",
        "got -0.95 at the defaults",
    );
    // A limit of the parameters that a swept value makes negative: refused
    // before the run, naming the parameter.
    let (code, stderr, rows) = run(
        &switched("limit", "zeta"),
        &scene("zeta", "[0.05, -0.5]", SHORT),
        &["--backend", "cpu"],
    );
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("zeta") && stderr.contains("stick limit"),
        "{stderr}"
    );
    assert!(rows.is_empty());
}

#[test]
fn model_check_refuses_a_period_that_is_not_positive_at_the_defaults() {
    let model = oscillator(PLAIN_V, "x - 2", "-v", "2*pi/eta").replace("eta = 0.8", "eta = -0.8");
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.toml"), model).unwrap();
    let out = lyapsweep(dir.path(), &["model", "check", "model.toml"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("model.map.period: must be a finite number > 0, got -7.85")
            && stderr.contains("(at the model's defaults)"),
        "{stderr}"
    );
    assert!(out.stdout.is_empty());
}

#[test]
fn a_lane_that_fails_in_the_transient_is_dated_alike_on_both_paths() {
    // x' = x² from x = 1 reaches infinity at t = 1, in the first period.
    let model = "[model]\nname = \"blow-up\"\nstates = [\"x\", \"v\"]\n[model.parameters]\nw = 1.0\n\
                 [model.equations]\nx = \"x*x\"\nv = \"-v + cos(w*t)\"\n[model.map]\nperiod = \"2*pi/w\"\n";
    let integration = "transient = 18\niterations = 10\ninitial_state = [1.0, 0.0]";
    let gpu = common::gpu_or_skip("a_lane_that_fails_in_the_transient", Precision::F64);
    for backend in ["cpu", "gpu"].into_iter().filter(|&b| b == "cpu" || gpu) {
        let (code, stderr, rows) = run(
            model,
            &scene("w", "[1.0]", integration),
            &["--backend", backend],
        );
        assert_eq!(code, Some(1), "{stderr}");
        assert_eq!(
            rows[0].last().unwrap(),
            "non-finite(iteration=0)",
            "{backend}"
        );
    }
}

#[test]
fn a_reset_that_leaves_the_state_past_its_surface_says_chattering() {
    // Started on the surface x = 2, moving out: the event fires at once, and
    // each reset leaves the state where the surface is not crossed from
    // below again (x put back on it; v doubled with the surface reading v).
    let integration = "transient = 20\niterations = 50\ninitial_state = [2.0, 1.0]";
    let models = [
        oscillator(PLAIN_V, "x - 2", "-v", "2*pi/eta").replace("{ v = \"-v\" }", "{ x = \"2\" }"),
        oscillator(PLAIN_V, "x - 2 + 0*v*v", "2*v", "2*pi/eta"),
    ];
    let gpu = common::gpu_or_skip("a_reset_that_leaves_the_state_past", Precision::F64);
    for model in &models {
        for backend in ["cpu", "gpu"].into_iter().filter(|&b| b == "cpu" || gpu) {
            let (code, stderr, rows) = run(
                model,
                &scene("eta", "[0.8, 0.9]", integration),
                &["--backend", backend],
            );
            assert_eq!(code, Some(0), "{stderr}");
            for row in &rows {
                assert_eq!(
                    row.last().unwrap(),
                    "chattering(iterations=50)",
                    "{backend}"
                );
            }
        }
    }
}
